r"""Measured BRDFs of the RGL-EPFL database (Mitsuba 3's ``measured`` format), evaluated as the authors' code does.

Dupuy and Jakob, "An Adaptive Parameterization for Efficient Material Acquisition and Rendering", ACM TOG 37(6),
2018. A file is a ``tensor_file`` (:mod:`polyjax.data._tensor_file`) with the fields ``theta_i`` ``(T,)`` and
``phi_i`` ``(P,)`` (the incident directions of the tables), ``ndf`` and ``sigma`` (2-d tables), ``vndf`` and
``luminance`` ``(P, T, H, W)``, ``rgb`` ``(P, T, 3, S, S)`` or, in a spectral file, ``spectra`` ``(P, T, N, S, S)``
with ``wavelengths`` ``(N,)`` (nm), ``jacobian`` uint8 ``(1,)`` and ``description`` (text).

Evaluation of ``f cos theta_o`` at an incident direction ``wi`` and an outgoing ``wo`` (``eval`` of the reference
``powitacq_rgb.inl`` / ``powitacq.inl``, and of Mitsuba 3's ``src/bsdfs/measured.cpp``), both above the surface:

1. (anisotropic files, Mitsuba) ``reduction = rint(2 pi / (phi_i[-1] - phi_i[0]))``; for a reduction of 2 (4) the
   pair is mirrored so that ``wi_y <= 0`` (and ``wi_x <= 0``): the tables cover that part of the azimuths;
2. ``wm = (wi + wo) / |wi + wo|``; elevations ``theta = 2 asin(|d - z| / 2)``, azimuths ``atan2(d_y, d_x)``;
3. unit coordinates ``u_wi = (sqrt(2 theta_i / pi), (phi_i + pi) / 2 pi)`` and
   ``u_wm = (sqrt(2 theta_m / pi), frac((phi_m - phi_i + pi) / 2 pi))`` (isotropic files: ``P <= 2``, the azimuth
   relative to ``phi_i``; anisotropic: ``phi_m`` itself);
4. the inverse of the VNDF warp: ``sample = vndf.invert(u_wm | phi_i, theta_i)``, the exact inverse of the
   marginal-conditional sampling of the bilinear interpolant of ``vndf`` (``Marginal2D<2, continuous>``: the
   conditional CDF of the cell's row density along ``x``, then the marginal CDF along ``y``), every table
   interpolated linearly in ``(phi_i, theta_i)`` between its nodes (weights clamped to ``[0, 1]``);
5. ``f cos theta_o = spectra.eval(sample | phi_i, theta_i, channel)``, the bilinear interpolant of each channel
   (RGB: channel ``c`` of ``rgb``; spectral: ``spectra`` at each of the file's ``wavelengths``: the node itself);
6. when ``jacobian`` is set, times ``ndf.eval(u_wm) / (4 sigma.eval(u_wi))`` (Mitsuba reads the flag; the
   reference code always multiplies, and every database file has the flag set);
7. RGB only: negative values (out of the sRGB gamut) clipped to 0, as ``powitacq_rgb`` does by default
   (``POWITACQ_CLIP_RGB``); Mitsuba does not clip, the spectral reference code neither.

``luminance`` warps the samples before the VNDF warp when sampling; ``eval`` does not use it (it is checked, not
used). The BRDF ``f`` is the value above divided by ``cos theta_o``. In polyjax's convention (``u`` towards the
light, ``v`` towards the viewer; docs/conventions.md) Mitsuba's ``si.wi`` is ``v`` and ``wo`` is ``u``, so
:func:`load_rgl` evaluates ``wi = v``, ``wo = u`` and divides by ``u_z``.
"""

from __future__ import annotations

import os
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._arrays import device_array
from .._config import given_or_under_root
from .._errors import DataNotFoundError, InputError
from .._measurements import Measurements
from ._errors import HeaderError, NonFiniteValueError
from ._merl import MERL_RESOLUTION, _above_index, _choose_bins, _default_float_name, _device_grid, merl_grid
from ._tensor_file import read_tensor_file

_CHUNK = 1 << 17  # rows per evaluation on the MERL grid: one compiled program, bounded memory
_HORIZON = 2.0**-23


class RGLBRDF(eqx.Module):
    """The tables of an RGL-EPFL file, ready to evaluate (module docstring); ``brdf(u, v)`` is the BRDF.

    Attributes:
        phi_i, theta_i: the tables' incident azimuths ``(P,)`` and elevations ``(T,)`` (radians).
        vndf, vndf_cond, vndf_marg: the VNDF warp of each ``(phi_i, theta_i)`` node: its density ``(P, T, H, W)``
            normalised to integrate to 1 over the unit square, the conditional CDFs ``(P, T, H, W - 1)`` along
            ``x`` of each row and the marginal CDF ``(P, T, H - 1)`` (trapezoidal, exact for the bilinear
            interpolant; Mitsuba's ``Marginal2D`` with ``Continuous = true``).
        ndf, sigma: the 2-d tables of the Jacobian factor ``ndf / (4 sigma)``.
        spectra: ``(P, T, C, S, S)``, ``f cos theta_o`` at the warp's sample points, ``C`` channels.
        channels: channel labels (``("R", "G", "B")`` or the wavelengths, e.g. ``"450nm"``).
        wavelengths: the spectral file's wavelengths in nm (empty for RGB).
        isotropic: ``P <= 2``; jacobian: the file's flag; reduction: the azimuthal symmetry (anisotropic files).
        clip: clip negative values to 0 (RGB files).
        name, description: file stem, the file's description text.
    """

    phi_i: Float[Array, " P"]
    theta_i: Float[Array, " T"]
    vndf: Float[Array, "P T H W"]
    vndf_cond: Float[Array, "P T H W1"]
    vndf_marg: Float[Array, "P T H1"]
    ndf: Float[Array, "a b"]
    sigma: Float[Array, "c d"]
    spectra: Float[Array, "P T C S S"]
    channels: tuple[str, ...] = eqx.field(static=True)
    wavelengths: tuple[float, ...] = eqx.field(static=True, default=())
    isotropic: bool = eqx.field(static=True, default=True)
    jacobian: bool = eqx.field(static=True, default=True)
    reduction: int = eqx.field(static=True, default=1)
    clip: bool = eqx.field(static=True, default=True)
    name: str = eqx.field(static=True, default="")
    description: str = eqx.field(static=True, default="")

    def __call__(self, u, v) -> Array:
        """The BRDF ``f(u, v)`` in 1/sr, ``(C, *n)``, at light ``u`` and view ``v`` unit vectors ``(*n, 3)``
        (0 where either is below the horizon)."""
        u, v = jnp.asarray(u), jnp.asarray(v)
        return _brdf(self, u, v)

    def eval_cos(self, wi, wo) -> Array:
        """The reference ``eval(wi, wo)``: ``f cos theta_o`` ``(C, *n)`` with ``wi`` the tables' incident
        direction (Mitsuba's ``si.wi``) and ``wo`` the outgoing one (module docstring, steps 1-7)."""
        return _eval_cos(self, jnp.asarray(wi), jnp.asarray(wo))


# ---------------------------------------------------------------------------------------------- evaluation


def _param_weights(nodes, x):
    """Interval ``(i0, i1)`` and weights ``(w0, w1)`` of ``x`` among increasing ``nodes`` (Mitsuba's
    ``interpolate_weights``: ``i0 = clip(#{nodes < x} - 1, 0, K - 2)``, ``w1 = clip((x - p0)/(p1 - p0), 0, 1)``);
    one node: ``(0, 0)``, ``(1, 0)``."""
    k = nodes.shape[0]
    if k == 1:
        zero = jnp.zeros(x.shape, jnp.int32)
        return (zero, zero), (jnp.ones_like(x), jnp.zeros_like(x))
    i0 = jnp.clip(jnp.searchsorted(nodes, x, side="left") - 1, 0, k - 2).astype(jnp.int32)
    p0, p1 = nodes[i0], nodes[i0 + 1]
    w1 = jnp.clip((x - p0) / (p1 - p0), 0.0, 1.0)
    return (i0, i0 + 1), (1.0 - w1, w1)


def _sliced(table, pw, *index):
    """``table[phi, theta, *index]`` interpolated in ``(phi_i, theta_i)`` with the weights ``pw`` of
    :func:`_param_weights` (``((ip, wp), (it, wt))``): the sum over the 4 nodes."""
    (ip, wp), (it, wt) = pw
    out = 0.0
    for a in range(1 if table.shape[0] == 1 else 2):  # one azimuth node (isotropic): its weight is 1
        for b in range(1 if table.shape[1] == 1 else 2):
            val = table[(ip[a], it[b]) + tuple(index)]
            w = wp[a] * wt[b]
            out = out + w.reshape(w.shape + (1,) * (val.ndim - w.ndim)) * val
    return out


def _cell(shape_yx, pos):
    """Cell ``(ix, iy)`` and fractions ``(tx, ty)`` of the unit-square point ``pos = (x, y)`` on a grid of
    ``shape_yx = (H, W)`` nodes (``pos`` clipped to ``[0, 1]``; the last cell closed)."""
    h, w = shape_yx
    sx = jnp.clip(pos[0], 0.0, 1.0) * (w - 1)
    sy = jnp.clip(pos[1], 0.0, 1.0) * (h - 1)
    ix = jnp.minimum(jnp.floor(sx), w - 2).astype(jnp.int32)
    iy = jnp.minimum(jnp.floor(sy), h - 2).astype(jnp.int32)
    return ix, iy, sx - ix, sy - iy


def _bilinear(table, pos):
    """The bilinear interpolant of a 2-d ``table (H, W)`` at ``pos = (x, y)`` (``Marginal2D::eval`` unnormalised)."""
    ix, iy, tx, ty = _cell(table.shape, pos)
    top = table[iy, ix] * (1 - tx) + table[iy, ix + 1] * tx
    bottom = table[iy + 1, ix] * (1 - tx) + table[iy + 1, ix + 1] * tx
    return top * (1 - ty) + bottom * ty


def _safe_div(a, b):
    ok = b != 0
    return jnp.where(ok, a / jnp.where(ok, b, 1.0), 0.0)


def _invert_vndf(brdf: RGLBRDF, u_wm, pw):
    """``Marginal2D::invert`` of the VNDF warp at ``u_wm = (x, y)`` (module docstring, step 4)."""
    h, w = brdf.vndf.shape[2:]
    ix, iy, tx, ty = _cell((h, w), u_wm)
    d = brdf.vndf
    c0 = _sliced(d, pw, iy, ix) * (1 - ty) + _sliced(d, pw, iy + 1, ix) * ty
    c1 = _sliced(d, pw, iy, ix + 1) * (1 - ty) + _sliced(d, pw, iy + 1, ix + 1) * ty
    sx = tx * (c0 + (c1 - c0) * 0.5 * tx) / (w - 1)
    cond, prev = brdf.vndf_cond, jnp.maximum(ix - 1, 0)
    before = _sliced(cond, pw, iy, prev) * (1 - ty) + _sliced(cond, pw, iy + 1, prev) * ty
    sx = sx + jnp.where(ix > 0, before, 0.0)
    r0, r1 = _sliced(cond, pw, iy, w - 2), _sliced(cond, pw, iy + 1, w - 2)
    sx = _safe_div(sx, r0 * (1 - ty) + r1 * ty)
    sy = ty * (r0 + (r1 - r0) * 0.5 * ty) / (h - 1)
    sy = sy + jnp.where(iy > 0, _sliced(brdf.vndf_marg, pw, jnp.maximum(iy - 1, 0)), 0.0)
    return sx, sy


def _spectra_at(brdf: RGLBRDF, sample, pw):
    """Every channel's bilinear interpolant at ``sample``: ``(C, *n)`` (module docstring, step 5)."""
    s = brdf.spectra
    ix, iy, tx, ty = _cell(s.shape[3:], sample)
    last = jnp.moveaxis(s, 2, -1)  # (P, T, S, S, C)

    def at(y, x):  # (C, *n)
        return jnp.moveaxis(_sliced(last, pw, y, x), -1, 0)

    top = at(iy, ix) * (1 - tx) + at(iy, ix + 1) * tx
    bottom = at(iy + 1, ix) * (1 - tx) + at(iy + 1, ix + 1) * tx
    return top * (1 - ty) + bottom * ty


def _mirror(brdf: RGLBRDF, wi, wo):
    """Step 1: for a reduction of 2 (4), ``wi``'s ``y`` (and ``x``) made ``<= 0`` and ``wo`` mirrored with it
    (Dr.Jit's ``mulsign_neg(a, s)``: ``-a`` where ``s >= 0``)."""
    if brdf.isotropic or brdf.reduction < 2:
        return wi, wo
    sy = wi[..., 1]
    sx = wi[..., 0] if brdf.reduction == 4 else sy

    def flip(d):
        x = jnp.where(sx >= 0, -d[..., 0], d[..., 0])
        y = jnp.where(sy >= 0, -d[..., 1], d[..., 1])
        return jnp.stack([x, y, d[..., 2]], axis=-1)

    return flip(wi), flip(wo)


def _elevation(d):
    return 2.0 * jnp.arcsin(jnp.clip(0.5 * jnp.sqrt(d[..., 0] ** 2 + d[..., 1] ** 2 + (d[..., 2] - 1.0) ** 2),
                                     -1.0, 1.0))


@jax.jit
def _eval_cos(brdf: RGLBRDF, wi, wo):
    """Steps 1-7 of the module docstring: ``f cos theta_o`` ``(C, *n)``."""
    active = (wi[..., 2] > 0) & (wo[..., 2] > 0)
    wi, wo = _mirror(brdf, wi, wo)
    m = wi + wo
    m = m / jnp.maximum(jnp.linalg.norm(m, axis=-1, keepdims=True), 1e-300)
    theta_i, phi_i = _elevation(wi), jnp.arctan2(wi[..., 1], wi[..., 0])
    theta_m, phi_m = _elevation(m), jnp.arctan2(m[..., 1], m[..., 0])
    u_wi = (jnp.sqrt(theta_i * (2 / jnp.pi)), (phi_i + jnp.pi) / (2 * jnp.pi))
    y = ((phi_m - phi_i) if brdf.isotropic else phi_m) + jnp.pi
    y = y / (2 * jnp.pi)
    u_wm = (jnp.sqrt(theta_m * (2 / jnp.pi)), y - jnp.floor(y))
    pw = _param_weights(brdf.phi_i, phi_i), _param_weights(brdf.theta_i, theta_i)
    sample = _invert_vndf(brdf, u_wm, pw)
    spec = _spectra_at(brdf, sample, pw)
    if brdf.jacobian:
        spec = spec * _safe_div(_bilinear(brdf.ndf, u_wm), 4.0 * _bilinear(brdf.sigma, u_wi))
    if brdf.clip:
        spec = jnp.maximum(spec, 0.0)
    return jnp.where(active, spec, 0.0)


@jax.jit
def _brdf(brdf: RGLBRDF, u, v):
    """``f(u, v) = eval(wi = v, wo = u) / u_z`` (module docstring)."""
    cos_o = u[..., 2]
    return jnp.where(cos_o > 0, _eval_cos(brdf, v, u) / jnp.where(cos_o > 0, cos_o, 1.0), 0.0)


# ---------------------------------------------------------------------------------------------- reading


#: Fields of every RGL-EPFL file: ``name -> (dtype, ndim)``; RGB files add ``rgb``, spectral ones ``spectra`` and
#: ``wavelengths`` (both float32, 5-d and 1-d).
RGL_FIELDS = {"description": ("uint8", 1), "theta_i": ("float32", 1), "phi_i": ("float32", 1),
              "ndf": ("float32", 2), "sigma": ("float32", 2), "vndf": ("float32", 4),
              "luminance": ("float32", 4), "jacobian": ("uint8", 1)}


def _check_fields(path: Path, fields: dict) -> bool:
    """Names, dtypes and ranks of the fields (``RGL_FIELDS``); returns True for a spectral file."""
    spectral = "wavelengths" in fields
    want = dict(RGL_FIELDS, **({"spectra": ("float32", 5), "wavelengths": ("float32", 1)} if spectral
                               else {"rgb": ("float32", 5)}))
    for name, (dtype, ndim) in want.items():
        if name not in fields:
            kind = "spectral (it has 'wavelengths')" if spectral else "RGB"
            raise HeaderError(path, f"the field {name!r} of an RGL-EPFL {kind} measured BSDF file "
                                    f"(fields {sorted(want)})", f"the fields {sorted(fields)}")
        a = fields[name]
        if a.dtype != np.dtype(dtype) or a.ndim != ndim:
            raise HeaderError(path, f"field {name!r}: {dtype} with {ndim} dimension(s)",
                              f"{a.dtype.name} of shape {a.shape}")
    return spectral


def _check_shapes(path: Path, f: dict, spec: str) -> None:
    """The shape relations of the reference loader (``measured.cpp``'s structure check), and tables of at least
    2 x 2 nodes, increasing ``theta_i``/``phi_i``, finite values."""
    p, t = f["phi_i"].shape[0], f["theta_i"].shape[0]
    s = f[spec]
    checks = [
        ("vndf", f["vndf"].shape[:2] == (p, t), f"leading shape ({p}, {t}) = (len(phi_i), len(theta_i))"),
        ("luminance", f["luminance"].shape[:2] == (p, t) and f["luminance"].shape[2] == f["luminance"].shape[3],
         f"shape ({p}, {t}, S, S)"),
        (spec, s.shape[:2] == (p, t) and s.shape[3:] == f["luminance"].shape[2:],
         f"shape ({p}, {t}, C, S, S) with S x S = luminance's {f['luminance'].shape[2:]}"),
        ("jacobian", f["jacobian"].shape == (1,), "shape (1,)"),
    ]
    if spec == "rgb":
        checks.append(("rgb", s.shape[2] == 3, "3 channels on axis 2"))
    else:
        checks.append(("spectra", s.shape[2] == f["wavelengths"].shape[0], "len(wavelengths) channels on axis 2"))
    for name in ("ndf", "sigma", "vndf", spec):
        checks.append((name, min(f[name].shape[-2:]) >= 2, "at least 2 x 2 table nodes"))
    for name in ("theta_i", "phi_i"):
        checks.append((name, f[name].size >= 1 and bool(np.all(np.diff(f[name]) > 0)), "increasing values"))
    for name, ok, what in checks:
        if not ok:
            raise HeaderError(path, f"field {name!r}: {what}", f"shape {f[name].shape}")
    for name in ("theta_i", "phi_i", "ndf", "sigma", "vndf", spec):
        if not np.all(np.isfinite(f[name])):
            raise NonFiniteValueError(path, f"finite values in field {name!r}", "NaN or infinite values")


def _warp_tables(vndf: np.ndarray):
    """``(density, conditional CDF, marginal CDF)`` of each ``(H, W)`` slice, normalised to integrate to 1
    (``Marginal2D`` continuous: trapezoids of the bilinear interpolant; a slice integrating to 0 stays 0)."""
    d = vndf.astype(np.float64)
    h, w = d.shape[-2:]
    cond = np.cumsum((0.5 / (w - 1)) * (d[..., :-1] + d[..., 1:]), axis=-1)
    rows = cond[..., -1]
    marg = np.cumsum((0.5 / (h - 1)) * (rows[..., :-1] + rows[..., 1:]), axis=-1)
    total = marg[..., -1]
    norm = np.where(total > 0, 1.0 / np.where(total > 0, total, 1.0), 0.0)
    return d * norm[..., None, None], cond * norm[..., None, None], marg * norm[..., None]


def read_rgl(path: str | os.PathLike, *, clip: bool | None = None) -> RGLBRDF:
    """Read an RGL-EPFL measured BSDF file (``*_rgb.bsdf`` or ``*_spec.bsdf``) into an :class:`RGLBRDF`.

    Args:
        path: the file.
        clip: clip negative values to 0 (default: True for RGB files as the reference RGB code, False for
            spectral files as the reference spectral code).

    Raises:
        DataNotFoundError: no such file.
        DataFormatError: not a tensor file, truncated, a missing field, a wrong dtype or shape (the message names
            the file and what was expected), all before any evaluation.
    """
    path = Path(path)
    f = read_tensor_file(path)
    spectral = _check_fields(path, f)
    spec = "spectra" if spectral else "rgb"
    _check_shapes(path, f, spec)
    phi = f["phi_i"].astype(np.float64)
    isotropic = phi.shape[0] <= 2
    reduction = 1 if isotropic else int(np.rint(2 * np.pi / (float(f["phi_i"][-1]) - float(f["phi_i"][0]))))
    wl = tuple(float(x) for x in f["wavelengths"]) if spectral else ()
    channels = tuple(f"{x:g}nm" for x in wl) if spectral else ("R", "G", "B")
    dens, cond, marg = _warp_tables(f["vndf"])
    arrays = [phi, f["theta_i"], dens, cond, marg, f["ndf"], f["sigma"], f[spec]]
    return RGLBRDF(*(device_array(np.asarray(a, np.float64)) for a in arrays), channels=channels, wavelengths=wl,
                   isotropic=isotropic, jacobian=bool(f["jacobian"][0]), reduction=reduction,
                   clip=(not spectral) if clip is None else bool(clip), name=path.stem,
                   description=bytes(f["description"]).decode("utf-8", "replace").rstrip("\0"))


# ---------------------------------------------------------------------------------------------- loading


def resolve_rgl_path(path: str | os.PathLike, root: str | os.PathLike | None = None) -> Path:
    """A file path as given, else ``<data root>/rgl_epfl/<name>`` (``.bsdf`` added when missing), e.g.
    ``"paper_white_rgb"``; :class:`polyjax.DataNotFoundError` naming both places when neither exists."""
    p = Path(path)
    found, tried = given_or_under_root(p, (Path("rgl_epfl") / p, Path("rgl_epfl") / (p.name + ".bsdf")), Path.is_file,
                                       root)
    if found is not None:
        return found
    raise DataNotFoundError(f"RGL-EPFL measured BSDF file {str(path)!r}: no such file (looked at {', '.join(tried)})")


def _evaluate_rows(brdf: RGLBRDF, u: np.ndarray, v: np.ndarray, dtype) -> np.ndarray:
    """``brdf(u, v)`` ``(C, n)`` on the host, in chunks of :data:`_CHUNK` rows, each padded to a power of two (at
    least 256) with normal-incidence rows: a few compiled programs serve every size."""
    n = u.shape[0]
    size = min(_CHUNK, max(256, 1 << (n - 1).bit_length()))
    out = np.empty((len(brdf.channels), n), dtype)
    for a in range(0, n, size):
        b = min(a + size, n)
        pu, pv = (np.tile(np.array([0.0, 0.0, 1.0], dtype), (size, 1)) for _ in range(2))
        pu[: b - a], pv[: b - a] = u[a:b], v[a:b]
        out[:, a:b] = np.asarray(brdf(device_array(pu, dtype), device_array(pv, dtype)))[:, : b - a]
    return out


def _off_horizon(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rows with both directions above the horizon by more than float32's resolution (``cos > 2^-23``): at the
    others the reference's float32 evaluation cannot tell the direction from the horizon (where it returns 0),
    and ``f = (f cos) / cos`` is rounding divided by almost 0 (values of 1e13 on the MERL grid's edge bins)."""
    return (u[:, 2] > _HORIZON) & (v[:, 2] > _HORIZON)


def _check_directions(directions) -> tuple[np.ndarray, np.ndarray]:
    if not (isinstance(directions, (tuple, list)) and len(directions) == 2):
        raise InputError(f"directions: expected a pair (u, v) of (n, 3) arrays, found {type(directions).__name__}")
    u, v = (np.asarray(d, np.float64) for d in directions)
    if u.ndim != 2 or u.shape[-1] != 3 or u.shape != v.shape or u.shape[0] == 0:
        raise InputError(f"directions: expected u and v of the same shape (n, 3), n >= 1, found {u.shape} and "
                         f"{v.shape}")
    for name, d in (("u", u), ("v", v)):
        norm = np.linalg.norm(d, axis=-1)
        if not np.all(np.isfinite(d)) or np.any(norm == 0):
            raise InputError(f"directions: expected finite non-zero {name} vectors, found NaN, inf or zero rows")
    return u / np.linalg.norm(u, axis=-1, keepdims=True), v / np.linalg.norm(v, axis=-1, keepdims=True)


def _grid_rows(subsample, seed: int, source: str):
    """``(u, v, w, mask)`` of the MERL grid's bins above the horizon (the device arrays of the MERL loaders), or of
    a seeded subsample of them, as host arrays for the evaluation and device arrays for the measurements."""
    dtype = _default_float_name()
    if subsample is None:
        du, dv, dw, mask = _device_grid(MERL_RESOLUTION, dtype)
        idx = _above_index(MERL_RESOLUTION)
    else:
        idx = _choose_bins(merl_grid(MERL_RESOLUTION)[3], subsample, seed, source)
        du = dv = dw = mask = None
    u, v, w, _ = merl_grid(MERL_RESOLUTION)
    hu, hv = u[idx], v[idx]
    if du is None:
        du, dv, dw = (device_array(a, dtype) for a in (hu, hv, w[idx]))
        mask = jax.device_put(np.ones(idx.size, bool))
    return hu, hv, (du, dv, dw, mask)


def load_rgl(
    path: str | os.PathLike,
    subsample: int | float | None = None,
    seed: int = 0,
    directions=None,
    *,
    root: str | os.PathLike | None = None,
    clip: bool | None = None,
) -> Measurements:
    """Load an RGL-EPFL measured BSDF file (Mitsuba 3's ``measured`` format) as :class:`polyjax.Measurements`.

    The BRDF is evaluated as the authors' reference code and Mitsuba 3 evaluate it (module docstring): on the
    MERL grid (the bins with both directions above the horizon, directions at the Rusinkiewicz bin centres, weights
    the bins' solid-angle measure, as :func:`load_merl_binary`), on a seeded subsample of those bins, or at given
    directions. The mask is False (and the value 0) where either direction is below the horizon or within float32's
    resolution of it (``cos theta <= 2^-23``: ``f = (f cos) / cos`` is not defined there). An anisotropic file on
    the MERL grid gives the slice ``phi_h = 0`` (MERL's grid is isotropic): pass
    ``directions`` for other azimuths.

    Args:
        path: the ``.bsdf`` file, or a name in ``<data root>/rgl_epfl/`` (``"paper_white_rgb"``).
        subsample: None (all bins), a count, or a fraction in (0, 1) of the MERL grid's bins, reproducible from
            ``seed``.
        seed: seed of the subsample.
        directions: ``(u, v)``, light and view directions ``(n, 3)`` (normalised here): the BRDF there instead of
            on the grid; weights 1.
        root: data root for a bare name (default ``$POLYJAX_DATA``).
        clip: clip negative values to 0 (default: RGB files yes, spectral files no; :func:`read_rgl`).

    Returns:
        ``values`` ``(C, n)`` in 1/sr with ``axes=("channel",)``: ``channels=("R", "G", "B")`` (sRGB primaries) or
        one channel per wavelength of a spectral file (``"450nm"``, ...), ``names=(<file stem>,)``.

    Raises:
        DataNotFoundError: no such file. DataFormatError: a bad file (:func:`read_rgl`). InputError: bad arguments.
        All before any evaluation.
    """
    if directions is not None and subsample is not None:
        raise InputError("subsample: expected None when directions are given (the directions are the samples)")
    uv = _check_directions(directions) if directions is not None else None
    if uv is None and subsample is not None:
        _choose_bins(np.ones(2, bool), subsample, seed, "subsample")  # the argument's checks, before the file is read
    brdf = read_rgl(resolve_rgl_path(path, root), clip=clip)
    source = f"RGL-EPFL measured BSDF {brdf.name}" + (f" (subsample {subsample}, seed {seed})" if subsample else "")
    dtype = _default_float_name()
    if uv is not None:
        hu, hv = uv
        u, v = device_array(hu, dtype), device_array(hv, dtype)
        w, mask = device_array(np.ones(hu.shape[0]), dtype), None
    else:
        hu, hv, (u, v, w, mask) = _grid_rows(subsample, seed, source)
    values = _evaluate_rows(brdf, hu, hv, dtype)
    keep = _off_horizon(hu, hv)
    if mask is None or not keep.all():
        values[:, ~keep] = 0.0
        mask = jax.device_put(keep)
    return Measurements(u=u, v=v, values=device_array(values, dtype), weights=w, mask=mask, names=(brdf.name,),
                        channels=brdf.channels, axes=("channel",), source=source)


__all__ = ["RGLBRDF", "RGL_FIELDS", "load_rgl", "read_rgl", "resolve_rgl_path"]
