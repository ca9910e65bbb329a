"""Coefficient textures written shard by shard: one ``.npz`` and/or one OpenEXR file per shard, and a JSON manifest.

A fitted texture (a :class:`polyjax.PolynomialBRDF` whose leading batch axis is the texel rows) is written by
every process for the shards it holds (:attr:`jax.Array.addressable_shards`), so nothing is gathered to one host.
Shard files are named by their rows, ``rows-<start>-<stop>.npz`` (every array field of the model for those rows,
exact, plus ``row_start``/``row_stop``) and ``rows-<start>-<stop>.exr`` (one multi-channel image per shard, one
channel per coefficient and colour; float64 as a pair of float32 channels, see ``polyjax/svbrdf/_exr.py``). The
manifest ``manifest.json`` (written by process 0, from the sharding alone, without reading any data) lists the
texture's shape, the model's static description (variables, basis, interactions, max_degree, link, eps), every
field's global shape and dtype (and its EXR encoding and channel names), the formats written, and every shard:
its rows, files and the process that writes it.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import jax
import numpy as np

from .._arrays import device_array
from .._errors import DataFormatError, DataNotFoundError, InputError
from .._files import inside_folder, write_bytes_atomically, write_npz_atomically
from .._model import PolynomialBRDF
from .._reading.bounded import load_json, read_npz
from .._reading.model import check_polynomial_fields
from ._exr import channel_layout, read_exr_shard, write_exr_shard

MANIFEST = "manifest.json"
FORMAT = "polyjax-texture-shards/2"
_READABLE = ("polyjax-texture-shards/1", FORMAT)  # /1: npz only, no link/eps (identity link)
#: the shard file formats
FORMATS = ("npz", "exr")
_FIELDS = ("coefficients", "degree", "mean", "rotation", "centre", "halfwidth", "l2", "rank", "condition", "n_used",
           "status")
#: the fields written only where the model has them (:attr:`polyjax.PolynomialBRDF.log_top`, the log link's bound)
_OPTIONAL = ("log_top",)


def _written(model: PolynomialBRDF) -> tuple[str, ...]:
    """The fields of ``model`` its shards hold: every one of :data:`_FIELDS`, and the optional ones it has."""
    return _FIELDS + tuple(n for n in _OPTIONAL if getattr(model, n) is not None)


def _listed(meta: dict) -> tuple[str, ...]:
    """The fields a manifest's shards hold: :data:`_FIELDS` and the optional ones its ``fields`` lists."""
    listed = meta.get("fields")
    return _FIELDS + tuple(n for n in _OPTIONAL if isinstance(listed, dict) and n in listed)


def _rows(index) -> tuple[int, int]:
    s = index[0] if index else slice(None)
    return (s.start or 0), s.stop


def _check_formats(formats, model: PolynomialBRDF, exr_precision: str) -> tuple[str, ...]:
    formats = (formats,) if isinstance(formats, str) else tuple(formats)
    if not formats or any(f not in FORMATS for f in formats) or len(set(formats)) != len(formats):
        raise InputError(f"formats: expected one or more of {FORMATS}, found {formats!r}")
    if "exr" in formats:
        if len(model.batch_shape) < 2:
            raise InputError(f"model: expected a texture of batch shape (H, W, ...) for EXR shards, found batch "
                             f"shape {model.batch_shape}")
        channel_layout("coefficients", (), np.float64, 0, False, exr_precision)  # checks exr_precision
    return formats


def _shard_map(ref) -> dict[tuple[int, int], int]:
    """Rows ``(start, stop)`` of every shard of ``ref`` -> the process holding it."""
    height = ref.shape[0]
    sharding = getattr(ref, "sharding", None)
    shards = {}
    if sharding is not None:
        for dev, idx in sharding.devices_indices_map(ref.shape).items():
            shards.setdefault(_rows(idx), dev.process_index)
    else:
        shards[(0, height)] = jax.process_index()
    return {(a, height if b is None else b): p for (a, b), p in shards.items()}


def _local_rows(model: PolynomialBRDF, start: int, stop: int) -> dict[str, np.ndarray]:
    """Every field of ``model`` for rows ``start .. stop``, from this process's shard (never a gather)."""
    parts = {}
    for name in _written(model):
        a = getattr(model, name)
        local = [s for s in getattr(a, "addressable_shards", []) if _rows(s.index)[0] == start]
        arr = np.asarray(local[0].data) if local else np.asarray(a[start:stop])
        if arr.shape[0] != stop - start:  # replicated over rows: this shard's rows of it
            arr = arr[start:stop]
        parts[name] = arr
    return parts


def write_texture_shards(directory: str | os.PathLike, model: PolynomialBRDF, *, row0: int = 0,
                         formats: str | tuple[str, ...] = "npz", exr_precision: str = "hi-lo") -> Path:
    """Write the shards of ``model`` this process holds, and (process 0) the manifest; returns the manifest path.

    Args:
        directory: output folder (created).
        model: a texture of models, batch ``(H, ...)`` (``(H, W, ...)`` for EXR), its arrays sharded (or not) over
            the rows ``H``.
        row0: the global row of the model's first row (for a model holding only part of the texture).
        formats: ``"npz"`` (exact), ``"exr"`` (one multi-channel OpenEXR image per shard) or both,
            e.g. ``("npz", "exr")``.
        exr_precision: ``"hi-lo"`` (float64 fields as two float32 channels, ``hi + lo`` within ``2^-48``
            relative) or ``"float32"`` (one channel, rounded to float32); see ``polyjax/svbrdf/_exr.py``.

    Raises :class:`polyjax.InputError` (before anything is written) for an unknown format or precision, or a model
    that is not a 2-D texture when EXR is asked for.
    """
    formats = _check_formats(formats, model, exr_precision)
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    height = model.coefficients.shape[0]
    shards = _shard_map(model.coefficients)
    n_lane = len(model.batch_shape) - 2
    rgb = tuple(model.batch_shape[2:]) == (3,)
    fields = {n: dict(shape=list(getattr(model, n).shape), dtype=str(getattr(model, n).dtype)) for n in _written(model)}
    if "exr" in formats:
        for n, meta in fields.items():
            meta["exr"] = channel_layout(n, tuple(meta["shape"][2:]), meta["dtype"], n_lane, rgb, exr_precision)
    name = lambda a, b, ext: f"rows-{row0 + a}-{row0 + b}.{ext}"  # noqa: E731
    for start, stop in sorted(r for r, p in shards.items() if p == jax.process_index()):
        parts = _local_rows(model, start, stop)
        if "npz" in formats:
            write_npz_atomically(out / name(start, stop, "npz"), row_start=row0 + start, row_stop=row0 + stop, **parts)
        if "exr" in formats:
            write_exr_shard(out / name(start, stop, "exr"), parts, {n: fields[n]["exr"] for n in fields},
                            (row0 + start, row0 + stop))
    manifest = out / MANIFEST
    if jax.process_index() == 0:
        meta = dict(
            format=FORMAT, height=int(row0 + height), batch_shape=list(model.batch_shape), variables=model.variables,
            basis=model.basis, interactions=model.interactions, max_degree=model.max_degree, link=model.link,
            eps=float(model.eps), clamp=bool(model.clamp), formats=list(formats),
            exr_precision=exr_precision if "exr" in formats else None,
            fields=fields,
            shards=[dict(rows=[row0 + a, row0 + b], file=name(a, b, formats[0]),
                         files={f: name(a, b, f) for f in formats}, process=p) for (a, b), p in sorted(shards.items())],
            processes=jax.process_count(),
        )
        write_bytes_atomically(manifest, json.dumps(meta, indent=1).encode())  # last: the shards are complete
    return manifest


def _read_manifest(d: Path, fmt: str | None) -> tuple[dict, str]:
    path = d / MANIFEST
    if not path.is_file():
        raise DataNotFoundError(f"expected a texture manifest {MANIFEST} in {str(d)!r}; none there")
    meta = load_json(path, f"a texture manifest ({FORMAT})")
    if not isinstance(meta, dict) or meta.get("format") not in _READABLE:
        raise DataFormatError(path, f"format {FORMAT!r}", repr(meta.get("format") if isinstance(meta, dict)
                                                               else meta)[:80])
    _check_manifest(path, meta)
    have = meta.get("formats", ["npz"])
    fmt = have[0] if fmt is None else fmt
    if fmt not in have:
        raise InputError(f"format: expected one of the formats written, {have}, found {fmt!r}")
    return meta, fmt


def _is_int(x) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


def _check_manifest(path: Path, meta: dict) -> None:
    """The manifest's structure, checked before any shard is read: a positive ``height``, a list of formats, a
    dict of fields, and shards of ``rows [start, stop]`` within the height naming a file (per format) each."""
    def bad(what, found):
        raise DataFormatError(path, what, repr(found)[:80])

    height = meta.get("height")
    if not _is_int(height) or height < 1:
        bad("'height': a positive integer", height)
    formats = meta.get("formats", ["npz"])
    if not isinstance(formats, list) or not formats or any(f not in FORMATS for f in formats):
        bad(f"'formats': a list of {FORMATS}", formats)
    if not isinstance(meta.get("fields", {}), dict):
        bad("'fields': an object", meta.get("fields"))
    shards = meta.get("shards")
    if not isinstance(shards, list) or not shards:
        bad("'shards': a non-empty list", shards)
    for i, shard in enumerate(shards):
        rows = shard.get("rows") if isinstance(shard, dict) else None
        if not (isinstance(rows, list) and len(rows) == 2 and all(map(_is_int, rows))
                and 0 <= rows[0] < rows[1] <= height):
            bad(f"shards[{i}].rows: [start, stop] with 0 <= start < stop <= height {height}", rows)
        files = shard.get("files", {"npz": shard.get("file")})
        if not isinstance(files, dict) or not all(isinstance(files.get(f), str) for f in formats):
            bad(f"shards[{i}]: a file name for each format {formats}", files)


def _read_npz_shard(f: Path, rows: int, names: tuple[str, ...]) -> dict[str, np.ndarray]:
    z = read_npz(f, "an .npz texture shard")
    for n in names:
        if n not in z or z[n].ndim < 1 or z[n].shape[0] != rows:
            raise DataFormatError(f, f"field {n!r} with {rows} rows", f"{z[n].shape if n in z else 'none'}")
    return {n: z[n] for n in names}


def _covering(path: Path, meta: dict, lo: int, hi: int) -> list:
    """The shards of the manifest covering rows ``lo .. hi``, in order; a DataFormatError when they overlap or
    leave a gap."""
    shards = sorted((s for s in meta["shards"] if s["rows"][1] > lo and s["rows"][0] < hi), key=lambda s: s["rows"])
    at = lo
    for s in shards:
        a, b = s["rows"]
        if a > at or b <= at:
            raise DataFormatError(path, f"shards covering rows {lo} to {hi} once each",
                                  f"rows {a} to {b} after row {at}")
        at = b
    if at < hi:
        raise DataFormatError(path, f"shards covering rows {lo} to {hi}", f"none beyond row {at}")
    return shards


def read_texture_shards(directory: str | os.PathLike, rows: tuple[int, int] | None = None,
                        format: str | None = None) -> PolynomialBRDF:
    """Read a texture written by :func:`write_texture_shards` (all of it, or the shards covering ``rows``).

    Args:
        directory: the folder of the manifest and shards.
        rows: ``(start, stop)`` texture rows to read; all by default.
        format: ``"npz"`` or ``"exr"``, one of the formats written; the first written by default.

    Raises :class:`polyjax.DataNotFoundError` when the manifest or a shard is missing and
    :class:`polyjax.DataFormatError` when a file does not match the manifest.
    """
    d = Path(directory)
    meta, fmt = _read_manifest(d, format)
    lo, hi = (0, meta["height"]) if rows is None else _checked_rows(rows, meta["height"])
    names = _listed(meta)
    pieces = {n: [] for n in names}
    for shard in _covering(d / MANIFEST, meta, lo, hi):
        a, b = shard["rows"]
        f = inside_folder(d, shard.get("files", {"npz": shard.get("file")})[fmt], d / MANIFEST, f"shard rows {a}-{b}")
        if not f.is_file():
            raise DataNotFoundError(f"expected the texture shard {str(f)!r} listed in {str(d / MANIFEST)!r}; it is "
                                    "missing")
        got = _read_npz_shard(f, b - a, names) if fmt == "npz" else _read_exr(d / MANIFEST, f, meta, b - a, names)
        for n in names:
            pieces[n].append(got[n][max(lo, a) - a: min(hi, b) - a])
    return _texture(d / MANIFEST, meta, pieces)


def _checked_rows(rows, height: int) -> tuple[int, int]:
    try:
        lo, hi = (int(r) for r in rows)
    except (TypeError, ValueError):
        lo, hi = -1, -1
    if not 0 <= lo < hi <= height:
        raise InputError(f"rows: expected (start, stop) with 0 <= start < stop <= {height} (the texture's height), "
                         f"found {rows!r}")
    return lo, hi


def _read_exr(manifest: Path, f: Path, meta: dict, rows: int, names: tuple[str, ...]) -> dict[str, np.ndarray]:
    """An EXR shard's fields ``names``, the manifest's layout of them checked (a missing or mistyped entry named)."""
    try:
        return read_exr_shard(f, {n: meta["fields"][n] for n in names}, rows)
    except (KeyError, TypeError, ValueError, IndexError, AttributeError) as e:
        if isinstance(e, DataFormatError):
            raise
        raise DataFormatError(manifest, "the EXR layout of every field ('fields')",
                              f"{type(e).__name__}: {e}") from None


def _texture(manifest: Path, meta: dict, pieces: dict) -> PolynomialBRDF:
    """The model of the rows read, its fields and the manifest's static description checked together."""
    arrays = {n: np.concatenate(p, axis=0) for n, p in pieces.items()}
    static = dict(variables=meta.get("variables"), basis=meta.get("basis"), interactions=meta.get("interactions"),
                  max_degree=meta.get("max_degree"), link=meta.get("link", "identity"), eps=meta.get("eps", 0.0),
                  clamp=meta.get("clamp", False))
    try:
        check_polynomial_fields(manifest, static, arrays)
        return PolynomialBRDF(**{n: device_array(a) for n, a in arrays.items()}, **static)
    except (TypeError, ValueError) as e:
        if isinstance(e, DataFormatError):
            raise
        raise DataFormatError(manifest, "the shards of a polynomial texture", f"{type(e).__name__}: {e}") from None


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
