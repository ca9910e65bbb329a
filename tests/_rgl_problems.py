"""Tensor files in the RGL-EPFL layout written by the tests themselves: a writer of Mitsuba's ``tensor_file``
container (independent of polyjax's reader: Mitsuba reads the same files), and small measured-BSDF tables
(isotropic or anisotropic, RGB or spectral) with smooth positive contents."""

from __future__ import annotations

from pathlib import Path

import numpy as np

_CODES = {np.dtype("uint8"): 1, np.dtype("uint32"): 5, np.dtype("float32"): 10, np.dtype("float64"): 11}
RGL_FILES = ("paper_white_rgb", "satin_rosaline_rgb")
WAVELENGTHS = (450.0, 520.0, 600.0, 680.0)


def write_tensor_file(path, fields: dict) -> Path:
    """``{name: array}`` as a ``tensor_file``: magic, version (1, 0), count, per field (name length, name, ndim,
    dtype code, offset, shape), then the data, each field 8-byte aligned, little-endian."""
    arrays = {k: np.ascontiguousarray(v) for k, v in fields.items()}
    pos = 18 + sum(2 + len(k) + 11 + 8 * a.ndim for k, a in arrays.items())
    offsets = []
    for a in arrays.values():
        pos += -pos % 8
        offsets.append(pos)
        pos += a.nbytes
    head = bytearray(b"tensor_file\0" + bytes((1, 0)) + np.uint32(len(arrays)).tobytes())
    for (name, a), off in zip(arrays.items(), offsets):
        head += np.uint16(len(name)).tobytes() + name.encode() + np.uint16(a.ndim).tobytes()
        head += bytes((_CODES[a.dtype],)) + np.uint64(off).tobytes() + np.asarray(a.shape, "<u8").tobytes()
    for a, off in zip(arrays.values(), offsets):
        head += bytes(off - len(head)) + a.tobytes()
    Path(path).write_bytes(bytes(head))
    return Path(path)


def rgl_fields(*, n_phi=1, phi_range=(-np.pi, np.pi), spectral=False, seed=0, constant=False, res=(9, 12), s=5,
               jacobian=1, negative=False):
    """Fields of a small RGL-EPFL file: ``n_phi`` incident azimuths over ``phi_range`` (1: isotropic), 4 incident
    elevations, a ``res = (H, W)`` VNDF, ``s x s`` sample tables, 3 RGB channels or :data:`WAVELENGTHS`.
    ``constant``: a uniform VNDF (its warp is the identity), ``ndf = 2``, ``sigma = 0.25`` and channel ``c`` of the
    values ``(c + 1) x`` (``x`` the sample's first coordinate), so ``f cos = 2 (c + 1) sqrt(2 theta_m / pi)``."""
    rng = np.random.default_rng(seed)
    n_t, c = 4, (len(WAVELENGTHS) if spectral else 3)
    phi = np.linspace(*phi_range, n_phi) if n_phi > 1 else np.zeros(1)
    theta = np.linspace(0.0, np.pi / 2, n_t)
    h, w = res
    smooth = lambda *shape: 0.5 + rng.random(shape) + np.linspace(0, 1, shape[-1])  # noqa: E731
    if constant:
        vndf = np.ones((n_phi, n_t, h, w))
        x = np.linspace(0.0, 1.0, s)[None, :].repeat(s, 0)
        vals = np.broadcast_to((np.arange(c) + 1.0)[:, None, None] * x, (n_phi, n_t, c, s, s))
        ndf, sigma = np.full((max(n_phi, 2), 16), 2.0), np.full((max(n_phi, 2), 16), 0.25)
    else:
        vndf, vals = smooth(n_phi, n_t, h, w), 0.2 * smooth(n_phi, n_t, c, s, s)
        if negative:
            vals = np.where(rng.random(vals.shape) < 1 / 3, -vals, vals)
        ndf, sigma = smooth(max(n_phi, 2), 16), smooth(max(n_phi, 2), 16)
        if n_phi == 1:  # isotropic, as the database's files: the NDF's two azimuth rows equal, the tables
            # symmetric in the relative azimuth (Mitsuba leaves its azimuthal reduction unset for isotropic files, so
            # it may mirror the directions, which changes nothing for such tables)
            ndf, sigma = ndf[:1].repeat(2, 0), sigma[:1].repeat(2, 0)
            vndf, vals = 0.5 * (vndf + vndf[..., ::-1, :]), 0.5 * (vals + vals[..., ::-1, :])
    f32 = lambda a: np.asarray(a, np.float32)  # noqa: E731
    fields = {"version": np.array([1, 0], np.uint32), "description": np.frombuffer(b"test table", np.uint8),
              "phi_i": f32(phi), "theta_i": f32(theta), "sigma": f32(sigma), "ndf": f32(ndf), "vndf": f32(vndf),
              "luminance": f32(smooth(n_phi, n_t, s, s))}
    if spectral:
        fields["wavelengths"] = f32(WAVELENGTHS)
    fields["spectra" if spectral else "rgb"] = f32(vals)
    fields["jacobian"] = np.array([jacobian], np.uint8)
    fields["valid"] = np.ones(s * s, np.uint8)
    return fields


def hemisphere(n, seed, min_cos=0.0):
    """``n`` unit vectors uniform on the upper hemisphere with ``z >= min_cos``."""
    rng = np.random.default_rng(seed)
    out = np.empty((0, 3))
    while out.shape[0] < n:
        d = rng.normal(size=(2 * n, 3))
        d[:, 2] = np.abs(d[:, 2])
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        out = np.concatenate([out, d[d[:, 2] >= min_cos]])
    return out[:n]


def mitsuba_measured(path, u, v, variant="scalar_rgb", wavelengths=None):
    """Mitsuba 3's ``measured`` plugin: ``f(u, v)`` ``(n, C)`` (its ``eval`` divided by ``cos theta_u``; ``si.wi``
    is the view ``v``, ``wo`` the light ``u``). Spectral variants evaluate at the given ``wavelengths`` (nm)."""
    import mitsuba as mi

    mi.set_variant(variant)
    bsdf = mi.load_dict({"type": "measured", "filename": str(path)})
    ctx, si = mi.BSDFContext(), mi.SurfaceInteraction3f()
    si.sh_frame = mi.Frame3f(mi.Vector3f(0.0, 0.0, 1.0))
    if wavelengths is not None:
        si.wavelengths = mi.Spectrum(wavelengths)
    out = []
    for ui, vi in zip(np.asarray(u, float), np.asarray(v, float)):
        si.wi = mi.Vector3f(*vi)
        out.append(np.asarray(bsdf.eval(ctx, si, mi.Vector3f(*ui)), float).ravel() / ui[2])
    return np.asarray(out)
