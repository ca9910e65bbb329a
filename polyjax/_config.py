"""Paths: where the measured data lives (one setting, an argument or the ``POLYJAX_DATA`` variable), and the
checks of output paths, made before any work so that a typo costs nothing.

One rule for every command: the folder an output goes into must already exist (a missing parent folder is an
error, never created silently); an output *folder* itself (``svbrdf --out``) is created when missing, inside an
existing parent.
"""

from __future__ import annotations

import os
from pathlib import Path

from ._errors import DataNotFoundError, InputError
from ._files.atomic import check_output_path

DATA_ENV = "POLYJAX_DATA"


def data_root(root: str | os.PathLike | None = None, *, must_exist: bool = True) -> Path:
    """Resolve the data root.

    Args:
        root: an explicit folder; wins over the environment.
        must_exist: raise :class:`DataNotFoundError` when the folder is missing.

    Returns:
        The folder holding ``curet/``, ``cornell/``, ``nbrdf_sztrajman2021/`` ...

    Raises:
        DataNotFoundError: neither ``root`` nor ``$POLYJAX_DATA`` names an existing folder.
    """
    if root is None:
        env = os.environ.get(DATA_ENV)
        if not env:
            if must_exist:
                raise DataNotFoundError(
                    f"no data root: pass root=... or set the environment variable {DATA_ENV} "
                    "to the folder that holds curet/, cornell/ and nbrdf_sztrajman2021/"
                )
            return Path()
        root = env
        origin = f"${DATA_ENV}"
    else:
        origin = "the root argument"
    path = Path(root).expanduser()
    if must_exist and not path.is_dir():
        raise DataNotFoundError(f"data root {str(path)!r} (from {origin}) is not a folder")
    return path


def configured_data_root(root: str | os.PathLike | None = None) -> Path | None:
    """The data root if one is configured (``root`` or a non-empty ``$POLYJAX_DATA``), else None.

    A configured root that does not exist is an error, never silently "no data".

    Raises:
        DataNotFoundError: the configured folder does not exist (the message names it and where it came from).
    """
    if root is None and not os.environ.get(DATA_ENV):
        return None
    return data_root(root)


def has_data_root(root: str | os.PathLike | None = None) -> bool:
    """True when a data root is configured and exists."""
    try:
        data_root(root)
    except DataNotFoundError:
        return False
    return True


def given_or_under_root(path: str | os.PathLike, relatives, exists, root: str | os.PathLike | None = None):
    """``(found, tried)``: ``path`` itself when ``exists(path)``, else the first ``<data root>/<r>`` of ``relatives``
    that exists (looked for only when ``path`` is relative and a data root is given or configured), or None; and
    every place looked at, in order (for the caller's error)."""
    p = Path(path)
    tried = [str(p)]
    if exists(p):
        return path, tried
    if (root is not None or has_data_root()) and not p.is_absolute():
        base = data_root(root)
        for r in relatives:
            if exists(base / r):
                return base / r, tried + [str(base / r)]
            tried.append(str(base / r))
    return None, tried


def data_file(relative: str, root: str | os.PathLike | None = None) -> Path:
    """A file below the data root, with an error saying where it looked when missing."""
    base = data_root(root)
    path = base / relative
    if not path.is_file():
        raise DataNotFoundError(
            f"expected the file {relative!r} below the data root {str(base)!r}; looked at {str(path)!r}")
    return path


def check_output_file(path: str | os.PathLike, flag: str) -> Path:
    """``path`` can be written: its folder exists and is writable, and it is not itself a folder
    (:func:`polyjax._files.check_output_path`).

    Raises:
        InputError: naming ``flag`` and the path.
    """
    return check_output_path(path, flag)


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
