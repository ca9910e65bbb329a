"""What the caches on disk are keyed by: polyjax's source stamp, and the hashes naming a saved program
(:mod:`polyjax._fit.saved`) or a streamed fit's geometry (:mod:`polyjax._cache.geometry`).

Every key holds the versions of JAX and jaxlib and the stamp of polyjax's own source files (any edit gives new keys),
so a file written by other code is never found.
"""

from __future__ import annotations

import hashlib
import platform
import zlib
from pathlib import Path

import jax
import jaxlib
import numpy as np

from .memo import content_name

_SOURCE_STAMP: list[str] = []


def source_stamp() -> str:
    """Size and modification time of every polyjax source file: any edit gives new keys."""
    if not _SOURCE_STAMP:
        root = Path(__file__).resolve().parents[1]
        h = hashlib.sha256()
        for p in sorted(root.rglob("*.py")):
            st = p.stat()
            h.update(f"{p.relative_to(root)}:{st.st_size}:{st.st_mtime_ns};".encode())
        _SOURCE_STAMP.append(h.hexdigest())
    return _SOURCE_STAMP[0]


def program_key(arrays, options: dict) -> str:
    """The key of a saved program of these input arrays (their shapes and dtypes) and options, on this machine."""
    parts = [jax.__version__, jaxlib.__version__, platform.machine(), platform.node(), source_stamp(),
             str(jax.config.jax_enable_x64), repr(sorted(options.items()))]
    parts += [f"{a.shape}:{a.dtype}" for a in arrays]
    return hashlib.sha256("|".join(parts).encode()).hexdigest()[:32]


def fingerprint(a) -> str:
    """The name :func:`polyjax._cache.memo.remember_content` gave ``a``, else the CRC-32 of its bytes (read where
    they are)."""
    name = content_name(a)
    if name is not None:
        return name
    return f"{zlib.crc32(memoryview(np.ascontiguousarray(np.asarray(a))).cast('B')):08x}"


def geometry_key(inp, degrees, static: dict, stream_constants: tuple) -> str:
    """The hash of everything the geometry of the prepared inputs ``inp`` depends on (:mod:`polyjax._cache.geometry`):
    the fingerprints, shapes and dtypes of the directions, weights and mask, the options ``static``, the degrees and
    the streaming constants the geometry was made with."""
    arrays = (inp.u, inp.v, inp.weights, inp.mask)
    parts = [jax.__version__, jaxlib.__version__, source_stamp(), *(fingerprint(a) for a in arrays),
             repr(sorted(static.items())), repr([int(d) for d in degrees]), repr(tuple(stream_constants))]
    parts += [f"{a.shape}:{a.dtype}" for a in arrays]
    return hashlib.sha256("|".join(parts).encode()).hexdigest()[:32]
