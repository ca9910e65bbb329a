"""A streamed fit's geometry kept on disk beside the compilation cache: the first tall fit of a process on a grid
it has seen before (a MERL material: every ``.binary`` file has the same directions, weights and mask) loads it.

The geometry (:func:`polyjax._fit.stream.stream_geometry`) of a grid is a few ``m x m`` matrices (the PCA and scaling,
the CholeskyQR2 factors, the SVD of ``R``, ``G``) besides the per-sample rows, which are recomputed from the
directions inside the first fit's program, block by block before its pass over the values
(:func:`polyjax._fit.stream.kept_rows`). It is kept in ``<cache folder>/polyjax-geometry/``,
the folder of JAX's persistent compilation cache when that is on (:func:`polyjax.enable_compilation_cache`; on by
default in the command line), and never otherwise; ``POLYJAX_CACHE=off`` or ``POLYJAX_SAVED_GEOMETRY=off`` turns
it off.

Keyed by a hash of everything the geometry depends on: the CRC-32 of the bytes of the directions, weights and mask
(which changes with any change of up to 32 adjacent bits, and by chance once in ``2^32`` otherwise; it costs about
one and a half times the time to copy them; arrays a loader made from its own code, as the MERL grid's directions,
are named instead, :func:`polyjax._cache.memo.remember_content`), their shapes and dtypes, the fit's options and
degrees, the versions of JAX and jaxlib and polyjax's source files. A file is used only when it holds that key, a
checksum of its arrays that matches, the shapes and dtypes the geometry has, finite numbers, and the same samples
used and total weight as the rows made in the fit's program (a fit whose rows disagree is thrown away); anything
else (a missing, stale, damaged or foreign file) is ignored and the geometry is computed and written again. Nothing
here is ever an error.
"""

from __future__ import annotations

import hashlib
import io
import os
from pathlib import Path

import jax
import numpy as np

from .._files import make_cache_folder, trusted, write_bytes_atomically
from .compilation import cache_disabled_by_env, note_cache_write

#: subfolder of the compilation cache folder holding the geometries
FOLDER = "polyjax-geometry"
#: environment variable: ``off`` (or ``0``, ``no``, ``false``) keeps no geometry on disk
ENV = "POLYJAX_SAVED_GEOMETRY"
#: the geometry's fields kept on disk (the per-sample rows are recomputed)
FIELDS = ("mean", "rotation", "centre", "halfwidth", "g", "den", "n_used", "scale", "r1inv", "r2", "u", "s", "vt",
          "ok", "passes", "sampled")
_OFF = ("off", "0", "no", "false", "none")


def store_folder() -> Path | None:
    """``<compilation cache folder>/polyjax-geometry`` when JAX's persistent compilation cache is on and neither
    ``POLYJAX_CACHE`` nor ``POLYJAX_SAVED_GEOMETRY`` is off; else None."""
    if os.environ.get(ENV, "").strip().lower() in _OFF or cache_disabled_by_env():
        return None
    folder = jax.config.jax_compilation_cache_dir
    return Path(folder) / FOLDER if folder and jax.config.jax_enable_compilation_cache else None


def template(k: int, m: int, n_degrees: int, dtype) -> dict:
    """The shapes and dtypes of the kept fields of a geometry with ``k`` components, ``m`` columns and
    ``n_degrees`` degrees (those :func:`polyjax._fit.stream.stream_geometry` returns; a test checks them against
    :func:`jax.eval_shape`), without tracing it."""
    f, i = np.dtype(dtype), np.dtype(jax.dtypes.canonicalize_dtype(np.int64))
    d, b = n_degrees, np.dtype(bool)
    shapes = dict(mean=((k,), f), rotation=((k, k), f), centre=((k,), f), halfwidth=((k,), f), g=((m, m), f),
                  den=((), f), n_used=((), i), scale=((d, m), f), r1inv=((d, m, m), f), r2=((d, m, m), f),
                  u=((d, m, m), f), s=((d, m), f), vt=((d, m, m), f), ok=((), b), passes=((), np.dtype(np.int32)),
                  sampled=((), b))
    return {name: jax.ShapeDtypeStruct(shape, dt) for name, (shape, dt) in shapes.items()}


def _checksum(arrays: dict) -> str:
    h = hashlib.sha256()
    for name in FIELDS:
        a = np.ascontiguousarray(arrays[name])
        h.update(f"{name}:{a.dtype.str}:{a.shape};".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def load(folder: Path, key: str, template: dict) -> dict | None:
    """The kept geometry of ``key`` as numpy arrays, or None unless every check of the module docstring that can be
    made without the rows passes (``template``: the shapes and dtypes, :func:`template`)."""
    path = folder / f"geometry-{key}.npz"
    if not path.is_file() or not trusted(folder, path, what="saved geometries"):
        return None
    try:
        with np.load(path, allow_pickle=False) as f:
            arrays = {name: f[name] for name in FIELDS}
            stored_key, checksum = str(f["key"]), str(f["checksum"])
    except Exception:  # noqa: BLE001 - missing, truncated, not a zip, fields missing: not used
        return None
    if stored_key != key or checksum != _checksum(arrays):
        return None
    for name, a in arrays.items():
        want = template[name]
        if a.shape != tuple(want.shape) or a.dtype != want.dtype:
            return None
        if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
            return None
    return arrays


def save(folder: Path, key: str, geo: dict) -> None:
    """Write the geometry's small fields for ``key`` (atomically: a whole file or none)."""
    try:
        arrays = {name: np.asarray(geo[name]) for name in FIELDS}
        buf = io.BytesIO()
        np.savez(buf, key=np.asarray(key), checksum=np.asarray(_checksum(arrays)), **arrays)
        make_cache_folder(folder, mark=False)
        write_bytes_atomically(folder / f"geometry-{key}.npz", buf.getvalue(), mode=0o600)
        note_cache_write()
    except OSError:  # a read-only or full disk: nothing kept
        pass
