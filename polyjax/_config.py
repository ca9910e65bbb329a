"""Where the measured data lives: one setting, an argument or the ``POLYJAX_DATA`` variable."""

from __future__ import annotations

import os
from pathlib import Path

from ._errors import DataNotFoundError

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


def data_file(relative: str, root: str | os.PathLike | None = None) -> Path:
    """A file below the data root, with an error saying where it looked when missing."""
    base = data_root(root)
    path = base / relative
    if not path.is_file():
        raise DataNotFoundError(
            f"expected the file {relative!r} below the data root {str(base)!r}; looked at {str(path)!r}")
    return path
