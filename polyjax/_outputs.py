"""Checks of output paths given on the command line, made before any work so that a typo costs nothing."""

from __future__ import annotations

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
    """Create the output folder ``path`` now (with its parents), so that one that cannot be made fails early.

    Raises:
        InputError: naming ``flag``, the path and the reason.
    """
    p = Path(path).expanduser()
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise InputError(f"{flag} {str(p)!r}: cannot create this folder ({e.strerror or e})") from None
    if not os.access(p, os.W_OK | os.X_OK):
        raise InputError(f"{flag} {str(p)!r}: folder not writable")
    return p
