"""Coefficient textures written shard by shard: one ``.npz`` per shard of the texture, and a JSON manifest.

A fitted texture (a :class:`polyjax.PolynomialBRDF` whose leading batch axis is the texel rows) is written by
every process for the shards it holds (:attr:`jax.Array.addressable_shards`), so nothing is gathered to one host.
Shard files are named by their rows, ``rows-<start>-<stop>.npz``, and hold every array field of the model for
those rows plus ``row_start``/``row_stop``. The manifest ``manifest.json`` (written by process 0, from the
sharding alone, without reading any data) lists the texture's shape, the model's static description
(variables, basis, interactions, max_degree), every field's global shape and dtype, and every shard: its rows,
file name and the process that writes it.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import jax
import numpy as np

from .._errors import DataFormatError, DataNotFoundError
from .._model import PolynomialBRDF

MANIFEST = "manifest.json"
FORMAT = "polyjax-texture-shards/1"
_FIELDS = ("coefficients", "degree", "mean", "rotation", "centre", "halfwidth", "l2", "rank", "condition", "n_used",
           "status")


def _rows(index) -> tuple[int, int]:
    s = index[0] if index else slice(None)
    return (s.start or 0), s.stop


def write_texture_shards(directory: str | os.PathLike, model: PolynomialBRDF, *, row0: int = 0) -> Path:
    """Write the shards of ``model`` this process holds, and (process 0) the manifest; returns the manifest path.

    Args:
        directory: output folder (created).
        model: a texture of models, batch ``(H, ...)``, its arrays sharded (or not) over the rows ``H``.
        row0: the global row of the model's first row (for a model holding only part of the texture).
    """
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    ref = model.coefficients
    height = ref.shape[0]
    sharding = getattr(ref, "sharding", None)
    shards = {}  # rows -> process index
    if sharding is not None:
        for dev, idx in sharding.devices_indices_map(ref.shape).items():
            shards.setdefault(_rows(idx), dev.process_index)
    else:
        shards[(0, height)] = jax.process_index()
    shards = {(a, height if b is None else b): p for (a, b), p in shards.items()}
    mine = sorted(r for r, p in shards.items() if p == jax.process_index())
    for start, stop in mine:
        parts = {}
        for name in _FIELDS:
            a = getattr(model, name)
            local = [s for s in getattr(a, "addressable_shards", []) if _rows(s.index)[0] == start]
            arr = np.asarray(local[0].data) if local else np.asarray(a[start:stop])
            if arr.shape[0] != stop - start:  # replicated over rows: this shard's rows of it
                arr = arr[start:stop]
            parts[name] = arr
        np.savez(out / f"rows-{row0 + start}-{row0 + stop}.npz", row_start=row0 + start, row_stop=row0 + stop,
                 **parts)
    manifest = out / MANIFEST
    if jax.process_index() == 0:
        meta = dict(
            format=FORMAT, height=int(row0 + height), batch_shape=list(model.batch_shape), variables=model.variables,
            basis=model.basis, interactions=model.interactions, max_degree=model.max_degree,
            fields={n: dict(shape=list(getattr(model, n).shape), dtype=str(getattr(model, n).dtype)) for n in _FIELDS},
            shards=[dict(rows=[row0 + a, row0 + b], file=f"rows-{row0 + a}-{row0 + b}.npz", process=p)
                    for (a, b), p in sorted(shards.items())],
            processes=jax.process_count(),
        )
        manifest.write_text(json.dumps(meta, indent=1))
    return manifest


def read_texture_shards(directory: str | os.PathLike, rows: tuple[int, int] | None = None) -> PolynomialBRDF:
    """Read a texture written by :func:`write_texture_shards` (all of it, or the shards covering ``rows``).

    Raises :class:`polyjax.DataNotFoundError` when the manifest or a shard is missing and
    :class:`polyjax.DataFormatError` when a file does not match the manifest.
    """
    d = Path(directory)
    path = d / MANIFEST
    if not path.is_file():
        raise DataNotFoundError(f"expected a texture manifest {MANIFEST} in {str(d)!r}; none there")
    meta = json.loads(path.read_text())
    if meta.get("format") != FORMAT:
        raise DataFormatError(f"{path}: expected format {FORMAT!r}, found {meta.get('format')!r}")
    lo, hi = (0, meta["height"]) if rows is None else rows
    pieces = {n: [] for n in _FIELDS}
    for shard in meta["shards"]:
        a, b = shard["rows"]
        if b <= lo or a >= hi:
            continue
        f = d / shard["file"]
        if not f.is_file():
            raise DataNotFoundError(f"expected the texture shard {str(f)!r} listed in {str(path)!r}; it is missing")
        with np.load(f) as z:
            for n in _FIELDS:
                if n not in z or z[n].shape[0] != b - a:
                    raise DataFormatError(f"{f}: expected field {n!r} with {b - a} rows, found "
                                          f"{z[n].shape if n in z else 'none'}")
                pieces[n].append(z[n][max(lo, a) - a: min(hi, b) - a])
    arrays = {n: np.concatenate(p, axis=0) for n, p in pieces.items()}
    return PolynomialBRDF(**{n: jax.numpy.asarray(a) for n, a in arrays.items()}, variables=meta["variables"],
                          basis=meta["basis"], interactions=bool(meta["interactions"]),
                          max_degree=int(meta["max_degree"]))


def local_part(model: PolynomialBRDF) -> PolynomialBRDF:
    """The rows of a row-sharded ``model`` held by this process, as an ordinary unsharded model on this process's
    default device (for per-process work such as re-rendering its rows; the other processes' rows are not read)."""
    def part(a):
        shards = getattr(a, "addressable_shards", None)
        if not shards:
            return a
        seen = {}
        for s in shards:
            seen.setdefault(_rows(s.index)[0], np.asarray(s.data))
        return jax.numpy.asarray(np.concatenate([seen[k] for k in sorted(seen)], axis=0))

    return jax.tree.map(part, model)
