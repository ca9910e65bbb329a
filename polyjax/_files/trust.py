"""Which folders are polyjax's own, and which may hand it a program to load.

A cache folder is polyjax's only when polyjax created it: :func:`make_cache_folder` creates it with mode ``0700`` and
writes the marker file :data:`MARKER` into it at once; a folder that existed before is used but never marked, so the
size cap and ``polyjax cache clear`` (:mod:`polyjax.cli._cache`) never touch it.

A saved program is native code: before one is loaded, or JAX's persistent compilation cache is turned on in a
folder, :func:`untrusted_reason` checks that the folder and the file belong to the current user and that neither
group nor others may write them (anyone who can write there could plant a program). Otherwise
:func:`warn_untrusted` warns once per folder, naming it and the reason, and the caller compiles afresh.
"""

from __future__ import annotations

import os
import stat
import warnings
from pathlib import Path

#: the file whose presence makes a folder polyjax's own cache folder (written when polyjax creates the folder)
MARKER = "POLYJAX-CACHE"
_MARKER_TEXT = (b"This folder was created by polyjax as its cache. polyjax trims and clears only its own entries\n"
                b"here (JAX's compiled programs, polyjax-programs/, polyjax-geometry/); other files are left alone.\n")
_WARNED: set[str] = set()


class UntrustedFolderWarning(UserWarning):
    """A cache folder or file that others could have written: nothing in it is loaded."""


def make_cache_folder(folder: str | os.PathLike, *, mark: bool = True) -> Path:
    """Create the cache folder ``folder`` (mode ``0700``; missing parents as ``mkdir -p`` makes them) and, with
    ``mark``, mark it as polyjax's (:data:`MARKER`; subfolders of a cache folder are not marked); a folder that exists
    already is left as it is (and unmarked if it was).

    Raises:
        OSError: the folder cannot be created.
    """
    folder = Path(folder)
    if folder.is_dir():
        return folder
    folder.parent.mkdir(parents=True, exist_ok=True)
    try:
        folder.mkdir(mode=0o700)
    except FileExistsError:  # made meanwhile by another process: its creator marks it
        return folder
    os.chmod(folder, 0o700)  # whatever the umask
    if mark:
        mark_cache_folder(folder)
    return folder


def mark_cache_folder(folder: str | os.PathLike) -> None:
    """Write polyjax's marker (:data:`MARKER`) into ``folder`` unless it is there (``O_EXCL``: never through a
    planted link)."""
    folder = Path(folder)
    if is_polyjax_folder(folder):
        return
    try:
        fd = os.open(folder / MARKER, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except FileExistsError:
        return
    with os.fdopen(fd, "wb") as f:
        f.write(_MARKER_TEXT)


def is_polyjax_folder(folder: str | os.PathLike) -> bool:
    """True when ``folder`` holds polyjax's marker (:data:`MARKER`, a plain file): polyjax created it."""
    try:
        return stat.S_ISREG(os.lstat(Path(folder) / MARKER).st_mode)
    except OSError:
        return False


def untrusted_reason(path: str | os.PathLike) -> str | None:
    """Why ``path`` (a folder, or a file: a symbolic link is refused) may not be trusted to hold programs polyjax
    loads: not owned by the current user, or writable by group or others; None when it may."""
    try:
        st = os.stat(path) if Path(path).is_dir() else os.lstat(path)
    except OSError as e:
        return f"cannot be examined ({e.strerror or e})"
    if stat.S_ISLNK(st.st_mode):
        return "a symbolic link"
    if hasattr(os, "getuid") and st.st_uid != os.getuid():
        return f"owned by user id {st.st_uid}, not by the current user ({os.getuid()})"
    who = [w for w, bit in (("group", stat.S_IWGRP), ("others", stat.S_IWOTH)) if st.st_mode & bit]
    if who:
        return f"writable by {' and '.join(who)} (mode {stat.S_IMODE(st.st_mode):04o})"
    return None


def warn_untrusted(path: str | os.PathLike, reason: str, what: str) -> None:
    """Warn once per process and ``path`` that nothing is loaded from it (``what``: what is not used)."""
    key = str(path)
    if key not in _WARNED:
        _WARNED.add(key)
        warnings.warn(f"polyjax: {key}: {reason}; {what} not used (programs are compiled afresh)",
                      UntrustedFolderWarning, stacklevel=3)


def trusted(*paths: str | os.PathLike, what: str) -> bool:
    """True when every one of ``paths`` may be trusted (:func:`untrusted_reason`); else warns once for the first that
    may not (:func:`warn_untrusted`) and returns False."""
    for p in paths:
        reason = untrusted_reason(p)
        if reason is not None:
            warn_untrusted(p, reason, what)
            return False
    return True


__all__ = ["MARKER", "UntrustedFolderWarning", "is_polyjax_folder", "make_cache_folder", "mark_cache_folder", "trusted",
           "untrusted_reason", "warn_untrusted"]
