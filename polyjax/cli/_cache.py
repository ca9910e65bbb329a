"""The cache folder's housekeeping: what it holds (``polyjax cache info``), emptying it (``polyjax cache clear``) and
a size cap applied after every command-line run (least recently used files removed first).

The folder holds JAX's persistent compilation cache (its entries at the top level), the command line's saved
executables (``polyjax-programs/``, :mod:`polyjax._fit.saved`) and the streamed fits' geometry
(:mod:`polyjax._cache.geometry`). Every file there is a cache entry that a later run can make again.
"""

from __future__ import annotations

import os
from pathlib import Path

from .._cache.compilation import default_cache_dir
from .._errors import InputError

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


def _files(folder: Path) -> list[tuple[Path, int, float]]:
    """Every file under ``folder``: ``(path, bytes, last use)`` (last use: the later of access and change)."""
    out = []
    for dirpath, _, names in os.walk(folder):
        for name in names:
            p = Path(dirpath) / name
            try:
                st = p.stat()
            except OSError:  # removed meanwhile
                continue
            out.append((p, st.st_size, max(st.st_atime, st.st_mtime)))
    return out


def _files_of(folder) -> tuple[Path, list[tuple[Path, int, float]]]:
    """``folder`` as a path and its files (:func:`_files`; none when it is not a folder): the one walk of every
    function below."""
    folder = Path(folder)
    return folder, _files(folder) if folder.is_dir() else []


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
    """``{"folder", "files", "bytes", "parts": {subfolder or ".": [files, bytes]}}`` of the cache folder."""
    folder, files = _files_of(folder)
    parts: dict[str, list[int]] = {}
    for p, size, _ in files:
        rel = p.relative_to(folder).parts
        key = rel[0] if len(rel) > 1 else "."
        entry = parts.setdefault(key, [0, 0])
        entry[0] += 1
        entry[1] += size
    return {"folder": str(folder), "files": len(files), "bytes": sum(s for _, s, _ in files), "parts": parts}


def clear_cache(folder: str | os.PathLike) -> tuple[int, int]:
    """Remove every file under the cache folder (the folder itself stays); returns ``(files, bytes)`` removed."""
    return _remove(_files_of(folder)[1])


def trim_cache(folder: str | os.PathLike, max_bytes: int | None) -> tuple[int, int]:
    """Keep the cache folder under ``max_bytes``: when over it, remove the least recently used files until it holds
    at most 80 % of it (so that not every run trims). Returns ``(files, bytes)`` removed; nothing is ever an error."""
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
                       "default 2048; after each run the least recently used files are removed beyond it). clear: "
                       "remove every file in it (later runs compile again).")
    c.add_argument("action", choices=["info", "clear"], help="info or clear")
    c.set_defaults(func=cmd_cache)


def cmd_cache(args) -> int:
    """``polyjax cache info|clear``: what the cache folder holds (files, size, cap), or empty it."""
    folder = default_cache_dir() if args.cache_dir is None else Path(args.cache_dir).expanduser()
    if args.action == "clear":
        n, size = clear_cache(folder)
        print(f"removed {n} file(s), {size / 2**20:.1f} MiB, from {folder}")
        return 0
    use, cap = cache_usage(folder), cache_cap_bytes()
    print(f"cache folder: {folder}{'' if folder.is_dir() else ' (not created yet)'}")
    print(f"  {use['files']} file(s), {use['bytes'] / 2**20:.1f} MiB; cap "
          + (f"{cap / 2**20:.0f} MiB" if cap else "none") + f" (${MAX_ENV}; least recently used files go first)")
    for part, (n, size) in sorted(use["parts"].items()):
        what = "JAX's compiled programs" if part == "." else part
        print(f"  {what}: {n} file(s), {size / 2**20:.1f} MiB")
    return 0


