"""The cache folder's housekeeping: what it holds (``polyjax cache info``), emptying it (``polyjax cache clear``) and
a size cap applied after every command-line run that used the cache (least recently used entries removed first).

The folder holds JAX's persistent compilation cache (its entries at the top level, ``<name>-<sha256>-cache`` and
``-atime``), the command line's saved executables (``polyjax-programs/``, :mod:`polyjax._fit.saved`) and the
streamed fits' geometry (:mod:`polyjax._cache.geometry`). Only those entries, found by their name patterns
(:data:`_OWN`), are ever removed, and only in a folder that polyjax created (its marker
:data:`polyjax._files.MARKER`): any other file, and any folder without the marker, is never touched.
"""

from __future__ import annotations

import os
import re
import stat
from pathlib import Path

from .._cache.compilation import default_cache_dir
from .._errors import InputError
from .._files import MARKER, is_polyjax_folder

#: environment variable: the cache folder's size cap in MiB (``0`` or ``off``: no cap)
MAX_ENV = "POLYJAX_CACHE_MAX_MB"
#: the default cap, MiB
DEFAULT_MAX_MB = 2048


def cache_cap_bytes() -> int | None:
    """The size cap in bytes from ``$POLYJAX_CACHE_MAX_MB`` (default :data:`DEFAULT_MAX_MB`); None for no cap.

    Raises:
        InputError: a value that is not a non-negative number.
    """
    text = os.environ.get(MAX_ENV, str(DEFAULT_MAX_MB)).strip().lower()
    if text in ("off", "none", ""):
        return None
    try:
        mb = float(text)
    except ValueError:
        mb = -1.0
    if mb < 0:
        raise InputError(f"${MAX_ENV}: expected a size in MiB (a non-negative number) or 'off', found {text!r}")
    return None if mb == 0 else int(mb * 2**20)


#: polyjax's and JAX's own entries: (subfolder or "", pattern of the file name); a temporary file of the atomic
#: writer (``.<stem>.<random>.tmp<suffix>``) left by a crash counts as its entry
_HEX = "[0-9a-f]"
_OWN = (
    ("", re.compile(rf"[A-Za-z0-9_.]+-{_HEX}{{64}}-(cache|atime)")),
    ("polyjax-programs", re.compile(rf"\.?(fit|baseline)-{_HEX}{{32}}(\.[A-Za-z0-9_]+\.tmp)?\.bin")),
    ("polyjax-geometry", re.compile(rf"\.?geometry-{_HEX}+(\.[A-Za-z0-9_]+\.tmp)?\.npz")),
)


def _entries(folder: Path) -> tuple[list[tuple[Path, int, float]], int]:
    """polyjax's and JAX's own entries in ``folder`` (:data:`_OWN`: ``(path, bytes, last use)``, last use the later of
    access and change), and how many other files sit beside them (never removed). Symbolic links are never entries."""
    out, others = [], 0
    for sub, pattern in _OWN:
        d = folder / sub if sub else folder
        try:
            names = os.listdir(d) if d.is_dir() and not d.is_symlink() else []
        except OSError:
            continue
        for name in names:
            p = d / name
            try:
                st = os.lstat(p)
            except OSError:  # removed meanwhile
                continue
            if not stat.S_ISREG(st.st_mode):
                continue
            if pattern.fullmatch(name):
                out.append((p, st.st_size, max(st.st_atime, st.st_mtime)))
            elif name != MARKER and name != ".lockfile":
                others += 1
    return out, others


def _files_of(folder) -> tuple[Path, list[tuple[Path, int, float]]]:
    """``folder`` as a path and its own entries (:func:`_entries`): none when it is not a folder polyjax made."""
    folder = Path(folder)
    return folder, _entries(folder)[0] if is_polyjax_folder(folder) else []


def _remove(files, enough=lambda removed: False) -> tuple[int, int]:
    """Remove ``files`` (``(path, bytes, last use)``) in their order until ``enough(bytes removed)``; a file that
    cannot be removed is skipped. Returns ``(files, bytes)`` removed."""
    n = removed = 0
    for p, s, _ in files:
        if enough(removed):
            break
        try:
            p.unlink()
        except OSError:
            continue
        n, removed = n + 1, removed + s
    return n, removed


def cache_usage(folder: str | os.PathLike) -> dict:
    """``{"folder", "owned", "files", "bytes", "parts": {subfolder or ".": [files, bytes]}, "others"}`` of the cache
    folder: ``owned`` whether polyjax made it (its marker), ``files``/``bytes``/``parts`` its own entries (what
    ``clear`` would remove; none in a folder polyjax did not make), ``others`` the other files beside them."""
    folder = Path(folder)
    owned = is_polyjax_folder(folder)
    files, others = _entries(folder) if folder.is_dir() else ([], 0)
    if not owned:
        files = []
    parts: dict[str, list[int]] = {}
    for p, size, _ in files:
        rel = p.relative_to(folder).parts
        key = rel[0] if len(rel) > 1 else "."
        entry = parts.setdefault(key, [0, 0])
        entry[0] += 1
        entry[1] += size
    return {"folder": str(folder), "owned": owned, "files": len(files), "bytes": sum(s for _, s, _ in files),
            "parts": parts, "others": others}


def clear_cache(folder: str | os.PathLike) -> tuple[int, int]:
    """Remove polyjax's and JAX's own entries from the cache folder (:data:`_OWN`; the folder, its marker and any
    other file stay; nothing in a folder polyjax did not make); returns ``(files, bytes)`` removed."""
    return _remove(_files_of(folder)[1])


def trim_cache(folder: str | os.PathLike, max_bytes: int | None) -> tuple[int, int]:
    """Keep polyjax's and JAX's own entries in the cache folder under ``max_bytes``: when over it, remove the least
    recently used until they take at most 80 % of it (so that not every run trims); other files are neither counted
    nor removed, and a folder polyjax did not make is left alone. Returns ``(files, bytes)`` removed; nothing is ever
    an error."""
    if max_bytes is None:
        return 0, 0
    _, files = _files_of(folder)
    total = sum(s for _, s, _ in files)
    if total <= max_bytes:
        return 0, 0
    return _remove(sorted(files, key=lambda f: f[2]), enough=lambda removed: total - removed <= 0.8 * max_bytes)


def add_parser(sub, common) -> None:
    """The ``cache`` command's parser."""
    c = sub.add_parser("cache", parents=[common], help="what the compilation cache folder holds, or empty it",
                       description="info: the cache folder's files and size, and its cap ($POLYJAX_CACHE_MAX_MB, "
                       "default 2048; after each run that used it the least recently used entries are removed beyond "
                       "it), and what clear would remove. clear: remove polyjax's and JAX's entries from a folder "
                       "polyjax created (later runs compile again); other files are never touched.")
    c.add_argument("action", choices=["info", "clear"], help="info or clear")
    c.set_defaults(func=cmd_cache)


def cmd_cache(args) -> int:
    """``polyjax cache info|clear``: what the cache folder holds (its own entries, what clear would remove, the cap),
    or remove those entries."""
    folder = default_cache_dir() if args.cache_dir is None else Path(args.cache_dir).expanduser()
    use, cap = cache_usage(folder), cache_cap_bytes()
    if folder.is_dir() and not use["owned"]:
        what = (f"not a polyjax cache folder (no {MARKER} marker: polyjax did not create it); the cap and "
                "'cache clear' never touch it")
        if args.action == "clear":
            raise InputError(f"cache folder {str(folder)!r}: {what}; nothing removed")
        print(f"cache folder: {folder}: {what}")
        return 0
    if args.action == "clear":
        n, size = clear_cache(folder)
        print(f"removed {n} file(s), {size / 2**20:.1f} MiB, from {folder}"
              + (f"; {use['others']} other file(s) left alone" if use["others"] else ""))
        return 0
    print(f"cache folder: {folder}{'' if folder.is_dir() else ' (not created yet)'}")
    print(f"  'cache clear' would remove {use['files']} file(s), {use['bytes'] / 2**20:.1f} MiB (polyjax's and "
          f"JAX's entries); cap " + (f"{cap / 2**20:.0f} MiB" if cap else "none")
          + f" (${MAX_ENV}; least recently used entries go first)")
    for part, (n, size) in sorted(use["parts"].items()):
        what = "JAX's compiled programs" if part == "." else part
        print(f"  {what}: {n} file(s), {size / 2**20:.1f} MiB")
    if use["others"]:
        print(f"  {use['others']} other file(s): never removed")
    return 0
