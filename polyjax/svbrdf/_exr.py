r"""One shard of a coefficient texture as one multi-channel OpenEXR image.

A shard holds rows ``a .. b`` of a texture of models whose batch shape is ``(H, W, *lane)`` (``(H, W, 3)`` for a
capture's RGB channels). Every field of the model, ``(b - a, W, *lane, *tail)``, becomes one EXR channel per entry
of ``(*lane, *tail)``, each a ``(b - a) x W`` image. Channel names are ``<field>[.<tail index>...][.<lane>]``: with
an RGB lane axis the lane is the channel's last component, ``R``, ``G`` or ``B``, so that a viewer shows every
coefficient as an RGB layer (``coefficients.0.R``, ``coefficients.0.G``, ``coefficients.0.B`` form the layer
``coefficients.0``).

Pixel types (EXR has 16- and 32-bit floats and 32-bit unsigned integers, no float64):

* float64 fields, ``precision="hi-lo"`` (default): two FLOAT channels per entry, ``hi = float32(x)`` under the
  name above (the viewable texture) and ``lo = float32(x - hi)`` in the layer ``lo`` (``coefficients.0.lo.R``).
  Read back as ``hi + lo`` in float64: ``|x - (hi + lo)| <= 2^-48 |x|`` (about ``3.6e-15`` relative; absolute
  below ``1e-44`` for ``|x| < 1e-30``), not bit-exact. Non-finite values (an ``inf`` L2 of an empty lane) are
  kept (``lo = 0``). Finite values beyond float32's range (``|x| > 3.4e38``) cannot be written: an error names
  the field.
* float64 fields, ``precision="float32"``, and float32 fields: one FLOAT channel (float32 values are exact).
* integer fields (degree, rank, samples used, status): one UINT channel holding the int32 bit pattern (exact; an
  error names a field whose values do not fit in int32).

The manifest (``polyjax/svbrdf/_shards.py``) records every field's encoding and channel names; the reader needs it.
"""

from __future__ import annotations

import itertools
import os

import numpy as np
import OpenEXR

from .._errors import DataFormatError, InputError
from .._files import write_atomically

PRECISIONS = ("hi-lo", "float32")
_F32_MAX = float(np.finfo(np.float32).max)


def channel_layout(name: str, shape: tuple[int, ...], dtype, n_lane: int, rgb: bool, precision: str) -> dict:
    """The EXR encoding of a field of per-texel shape ``shape = (*lane, *tail)`` (``n_lane`` lane axes).

    Returns ``dict(encoding=, channels=[...], lo_channels=[...])`` with channel names in C order of ``shape``.
    """
    if precision not in PRECISIONS:
        raise InputError(f"exr_precision: expected one of {PRECISIONS}, found {precision!r}")
    dtype = np.dtype(dtype)
    names = []
    for idx in itertools.product(*(range(s) for s in shape)):
        lane, tail = idx[:n_lane], idx[n_lane:]
        parts = [name] + [str(i) for i in tail]
        if rgb:
            names.append(".".join(parts + ["RGB"[lane[0]]]))
        else:
            names.append(".".join(parts + [str(i) for i in lane]) if idx else name)
    if dtype.kind in "iub":
        return dict(encoding="int32-bits-uint32", channels=names, lo_channels=[])
    if dtype.kind != "f":
        raise InputError(f"{name}: expected a float or integer field for an EXR shard, found dtype {dtype}")
    if dtype == np.float64 and precision == "hi-lo":
        lo = [n.rsplit(".", 1)[0] + ".lo." + n.rsplit(".", 1)[1] if "." in n else n + ".lo" for n in names]
        return dict(encoding="float64-hi-lo-float32", channels=names, lo_channels=lo)
    return dict(encoding="float32", channels=names, lo_channels=[])


def _encode(name: str, a: np.ndarray, layout: dict) -> dict[str, np.ndarray]:
    """``a (h, W, *per_texel)`` -> ``{channel: (h, W) pixels}``."""
    h, w = a.shape[:2]
    flat = a.reshape(h, w, -1)
    enc = layout["encoding"]
    out = {}
    if enc == "int32-bits-uint32":
        info = np.iinfo(np.int32)
        if flat.size and (flat.min() < info.min or flat.max() > info.max):
            raise InputError(f"{name}: expected integers within int32 for an EXR shard, found {flat.min()} .. "
                             f"{flat.max()}")
        bits = flat.astype(np.int32).view(np.uint32)
        return {c: np.ascontiguousarray(bits[..., i]) for i, c in enumerate(layout["channels"])}
    big = np.isfinite(flat) & (np.abs(flat) > _F32_MAX)
    if np.any(big):
        raise InputError(f"{name}: expected values within float32's range (|x| <= 3.4e38) for an EXR shard, found "
                         f"{np.abs(flat[big]).max():.3g}; write this texture as npz")
    hi = flat.astype(np.float32)
    for i, c in enumerate(layout["channels"]):
        out[c] = np.ascontiguousarray(hi[..., i])
    if enc == "float64-hi-lo-float32":
        lo = np.subtract(flat, hi, out=np.zeros(flat.shape), where=np.isfinite(flat)).astype(np.float32)
        for i, c in enumerate(layout["lo_channels"]):
            out[c] = np.ascontiguousarray(lo[..., i])
    return out


def write_exr_shard(path: str | os.PathLike, fields: dict[str, np.ndarray], layouts: dict[str, dict],
                    rows: tuple[int, int]) -> None:
    """Write ``fields`` (each ``(h, W, *per_texel)``) as one scanline EXR (ZIP compression) with ``layouts``.

    The header carries ``polyjaxRows`` (``"a b"``: the texture rows of the shard)."""
    channels = {}
    for name, a in fields.items():
        channels.update(_encode(name, np.asarray(a), layouts[name]))
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage,
              "polyjaxRows": f"{rows[0]} {rows[1]}"}

    def write(tmp) -> None:
        with OpenEXR.File(header, channels) as f:
            f.write(str(tmp))

    write_atomically(path, write)


def read_exr_shard(path: str | os.PathLike, fields: dict[str, dict], rows: int) -> dict[str, np.ndarray]:
    """Read the fields of an EXR shard: ``fields`` maps a field name to its manifest entry (``shape`` of the whole
    texture, ``dtype``, ``exr`` layout); returns arrays of ``rows`` rows in the manifest's dtypes.

    Raises :class:`polyjax.DataFormatError` when the file is unreadable or a channel is missing or mis-sized.
    """
    try:
        with OpenEXR.File(str(path), separate_channels=True) as f:
            pix = {k: np.asarray(c.pixels) for k, c in f.channels().items()}
    except Exception as e:  # OpenEXR raises plain exceptions on malformed files
        raise DataFormatError(path, "an OpenEXR texture shard", f"an unreadable file ({e})") from None
    out = {}
    for name, meta in fields.items():
        layout = meta["exr"]
        shape = [rows] + list(meta["shape"][1:])
        want = layout["channels"] + layout["lo_channels"]
        missing = [c for c in want if c not in pix]
        if missing:
            raise DataFormatError(path, f"channel {missing[0]!r} of field {name!r}", f"channels {sorted(pix)[:8]}...")
        bad = [c for c in want if pix[c].shape != (shape[0], shape[1])]
        if bad:
            raise DataFormatError(path, f"channel {bad[0]!r} of {shape[0]} x {shape[1]} pixels",
                                  f"{pix[bad[0]].shape}")
        if layout["encoding"] == "int32-bits-uint32":
            a = np.stack([pix[c].astype(np.uint32).view(np.int32) for c in layout["channels"]], -1)
        else:
            a = np.stack([pix[c].astype(np.float64) for c in layout["channels"]], -1)
            if layout["lo_channels"]:
                a = a + np.stack([pix[c].astype(np.float64) for c in layout["lo_channels"]], -1)
        out[name] = a.reshape([rows] + list(meta["shape"][1:])).astype(meta["dtype"])
    return out
