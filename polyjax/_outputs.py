"""Checks of output paths given on the command line, made before any work so that a typo costs nothing.

One rule for every command: the folder an output goes into must already exist (a missing parent folder is an
error, never created silently); an output *folder* itself (``svbrdf --out``) is created when missing, inside an
existing parent.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

from ._errors import InputError


def check_output_file(path: str | os.PathLike, flag: str) -> Path:
    """``path`` can be written: its folder exists and is writable, and it is not itself a folder.

    Raises:
        InputError: naming ``flag`` and the path.
    """
    p = Path(path).expanduser()
    parent = p.parent if str(p.parent) else Path(".")
    if p.is_dir():
        raise InputError(f"{flag} {str(p)!r}: expected a file name, found a folder")
    if not parent.is_dir():
        raise InputError(f"{flag} {str(p)!r}: the folder {str(parent)!r} does not exist")
    if not os.access(parent, os.W_OK | os.X_OK) or (p.exists() and not os.access(p, os.W_OK)):
        raise InputError(f"{flag} {str(p)!r}: not writable")
    return p


def check_output_dir(path: str | os.PathLike, flag: str) -> Path:
    """Create the output folder ``path`` now when missing (its parent must exist, as for an output file), so that
    one that cannot be made fails early.

    Raises:
        InputError: naming ``flag``, the path and the reason.
    """
    p = Path(path).expanduser()
    parent = p.parent if str(p.parent) else Path(".")
    if not p.is_dir() and not parent.is_dir():
        raise InputError(f"{flag} {str(p)!r}: the folder {str(parent)!r} does not exist")
    try:
        p.mkdir(exist_ok=True)
    except OSError as e:
        raise InputError(f"{flag} {str(p)!r}: cannot create this folder ({e.strerror or e})") from None
    if not os.access(p, os.W_OK | os.X_OK):
        raise InputError(f"{flag} {str(p)!r}: folder not writable")
    return p


def check_model_file(path: str | os.PathLike, flag: str) -> Path:
    """:func:`check_output_file` for a saved model: also its suffix is ``.npz`` or ``.json`` (the format is chosen
    by it, and a file is never renamed behind the user's back).

    Raises:
        InputError: naming ``flag`` and the path.
    """
    p = check_output_file(path, flag)
    if p.suffix not in (".npz", ".json"):
        raise InputError(f"{flag} {str(p)!r}: expected a model file name ending in .npz or .json, found suffix "
                         f"{p.suffix or '(none)'!r}")
    return p


def _finite_or_none(x):
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    if isinstance(x, dict):
        return {k: _finite_or_none(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_finite_or_none(v) for v in x]
    return x


def strict_json(record) -> str:
    """``record`` as strict JSON (RFC 8259, which has no ``Infinity`` or ``NaN``): every non-finite float becomes
    ``null`` (e.g. the condition number of a rank-deficient fit, the PSNR of an exact re-rendering)."""
    return json.dumps(_finite_or_none(record), allow_nan=False)
