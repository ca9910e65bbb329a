"""Paths written inside input files (a photograph folder's ``filenames.txt``, a texture's shard manifest, the
``fit-images`` scene JSON) name files of the input's own folder only: relative, with no ``..`` part. An absolute path
or one that climbs out is refused, so an input file cannot make polyjax read (and a page it writes inline) any other
file of the machine."""

from __future__ import annotations

import os
from pathlib import Path, PurePosixPath, PureWindowsPath

from .._errors import DataFormatError


def inside_folder(folder: str | os.PathLike, relative, source: str | os.PathLike, what: str) -> Path:
    """``folder / relative`` when ``relative`` is a relative path inside ``folder``.

    Args:
        folder: the input's folder.
        relative: the path as the input file wrote it.
        source: the input file (named in the error).
        what: where in it (``"line 3"``, ``"images[0].file"``).

    Raises:
        DataFormatError: naming ``source`` and ``what``: not a string, empty, absolute (POSIX or Windows, a drive
        included) or holding a ``..`` part.
    """
    expected = f"{what}: a relative path inside the folder {str(folder)!r} (no absolute path, no '..')"
    if not isinstance(relative, str) or not relative.strip() or "\0" in relative:
        raise DataFormatError(source, expected, repr(relative))
    posix, windows = PurePosixPath(relative), PureWindowsPath(relative)
    if posix.is_absolute() or windows.is_absolute() or windows.drive or windows.root or ".." in windows.parts:
        raise DataFormatError(source, expected, repr(relative))
    return Path(folder) / relative


__all__ = ["inside_folder"]
