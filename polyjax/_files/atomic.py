"""One writer for every output: the target checked before any work, then written whole or not at all.

:func:`write_atomically` hands the caller's ``write`` a temporary file created by ``tempfile.mkstemp`` (``O_EXCL``:
an unpredictable name that no existing file or symbolic link can stand in for) in the target's own folder and with
the target's suffix (MaterialX, USD and OpenEXR writers pick their format by it). The file is flushed to disk
(``fsync``), given the permissions of the file it replaces or of a new file of the user (``0666`` less the umask),
or ``mode``, and renamed over the target with ``os.replace``, which is atomic on one file system: a reader sees the
old file or the new one, never half of one (a symbolic link at the target is replaced, not written through). On
any failure, ``KeyboardInterrupt`` included, the temporary file is removed and the target is left as it was.
"""

from __future__ import annotations

import os
import stat
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

from .._errors import InputError


def check_output_path(path: str | os.PathLike, name: str) -> Path:
    """``path`` can be written: its folder exists and is writable, and it is not itself a folder. Run it before any
    work, so a command fails on its arguments rather than after a fit.

    Args:
        path: the output file.
        name: the argument or flag naming it in the error (``"--out"``, ``"save_model: path"``).

    Returns:
        ``path`` as a :class:`~pathlib.Path` (``~`` expanded).

    Raises:
        InputError: naming ``name``, the path and the reason.
    """
    p, parent = _target(path, f"{name} ")
    if not os.access(parent, os.W_OK | os.X_OK) or (p.exists() and not os.access(p, os.W_OK)):
        raise InputError(f"{name} {str(p)!r}: not writable")
    return p


def _target(path: str | os.PathLike, label: str) -> tuple[Path, Path]:
    """``path`` (``~`` expanded) and its folder, which must exist, ``path`` not being a folder itself; the error
    starts with ``label``."""
    p = Path(path).expanduser()
    parent = p.parent if str(p.parent) else Path(".")
    if p.is_dir():
        raise InputError(f"{label}{str(p)!r}: expected a file name, found a folder")
    if not parent.is_dir():
        raise InputError(f"{label}{str(p)!r}: the folder {str(parent)!r} does not exist")
    return p, parent


def _umask() -> int:
    """The process's umask, read without changing it (Linux's ``/proc``), else by setting and restoring it."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _mode_for(path: Path) -> int:
    """The permission bits of the regular file ``path`` replaces, else those of a new file (``0o666`` less the
    umask)."""
    try:
        st = os.lstat(path)
        if stat.S_ISREG(st.st_mode):
            return stat.S_IMODE(st.st_mode)
    except OSError:
        pass
    return 0o666 & ~_umask()


def _fsync_path(path: str | os.PathLike) -> None:
    """Flush a file (or a folder's entries) to disk; a file system that cannot is left as it is."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


#: the temporary files of the writes under way in this process (a set: several threads may write at once)
_IN_FLIGHT: set[Path] = set()


def write_atomically(path: str | os.PathLike, write: Callable[[Path], object], *, mode: int | None = None) -> Path:
    """Write ``path`` whole or not at all.

    Args:
        path: the target file; its folder must exist (see :func:`check_output_path`).
        write: called once as ``write(tmp)`` with the temporary file's path (already created, empty, same folder
            and suffix as ``path``); it writes the whole content there (by name: it may reopen or truncate it).
        mode: the new file's permission bits; by default those of the file it replaces, else ``0o666`` less the
            umask, as a plain ``open`` makes.

    Returns:
        ``path`` as a :class:`~pathlib.Path`.

    Raises:
        InputError: ``path`` is a folder, or its folder is missing. Anything ``write`` raises, after the temporary
        file is removed.
    """
    path, folder = _target(path, "")
    fd, name = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=f".tmp{path.suffix}", dir=folder)
    os.close(fd)
    tmp = Path(name)
    done = False
    _IN_FLIGHT.add(tmp)
    try:
        write(tmp)
        _fsync_path(tmp)
        os.chmod(tmp, _mode_for(path) if mode is None else mode)
        os.replace(tmp, path)
        done = True
    finally:
        if not done:
            tmp.unlink(missing_ok=True)
        _IN_FLIGHT.discard(tmp)
    _fsync_path(folder)
    return path


def remove_temporary_files() -> None:
    """Remove the temporary files of the writes under way in this process (exactly those :func:`write_atomically`
    made, nothing else): for a process that ends before their ``finally`` runs (Ctrl-C's watchdog,
    :mod:`polyjax._run.interrupt`)."""
    for tmp in list(_IN_FLIGHT):
        Path(tmp).unlink(missing_ok=True)
        _IN_FLIGHT.discard(tmp)


def write_bytes_atomically(path: str | os.PathLike, data: bytes, *, mode: int | None = None) -> Path:
    """:func:`write_atomically` of the bytes ``data``."""

    def write(tmp: Path) -> None:
        with open(tmp, "wb") as f:
            f.write(data)

    return write_atomically(path, write, mode=mode)


def write_npz_atomically(path: str | os.PathLike, **arrays) -> Path:
    """:func:`write_atomically` of ``np.savez(file, **arrays)`` (written into the open file: numpy would append
    ``.npz`` to a name that does not end with it)."""

    def write(tmp: Path) -> None:
        with open(tmp, "wb") as f:
            np.savez(f, **arrays)

    return write_atomically(path, write)


__all__ = ["check_output_path", "write_atomically", "write_bytes_atomically", "write_npz_atomically"]
