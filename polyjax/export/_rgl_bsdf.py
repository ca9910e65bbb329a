r"""A fitted model as an RGL-EPFL measured BSDF file: Mitsuba 3's own ``measured`` plugin renders it, no polyjax
needed in Mitsuba's Python (``polyjax export MODEL --to rgl-bsdf``).

The layout is the one :mod:`polyjax.data._rgl` reads (Dupuy and Jakob 2018; Mitsuba 3's ``measured.cpp``): for an
isotropic BRDF one incident azimuth ``phi_i = (0,)``, ``T`` incident elevations ``theta_i`` evenly spaced over
``[0, pi/2]``, and per elevation an ``S x S`` table of ``f cos theta_o`` over the unit square of the half vector's
coordinates ``u_wm = (sqrt(2 theta_m / pi), (phi_m - phi_i + pi) / 2 pi)``. The file's VNDF is uniform, so its warp
is the identity (``Marginal2D``'s inverse of a constant density: ``sample = u_wm``) and the table is read at
``u_wm`` itself; its ``ndf`` is 1 and ``sigma`` 1/4, so the Jacobian factor ``ndf / (4 sigma)`` is 1 in Mitsuba and
in the reference code (which always applies it). Node ``(t, j, i)`` holds ``f(u = wo, v = wi) cos theta_o`` at
``wi = (sin theta_t, 0, cos theta_t)`` (Mitsuba's ``si.wi`` is the view ``v``; the last elevation evaluated 0.06
degrees above the horizon), ``wm`` at ``theta_m = (i / (S - 1))^2 pi/2``, ``phi_m = (2 j / (S - 1) - 1) pi``, and
``wo = 2 (wi . wm) wm - wi``; 0 where ``wo`` is below the horizon. Between nodes the readers interpolate
bilinearly in ``u_wm`` and linearly in ``theta_i``: the ``sqrt`` in ``u_wm`` puts the nodes close near the half
vector's pole, where a specular peak lies at every ``theta_i``.

``luminance`` (what Mitsuba samples ``u_wm`` by) is the table's luminance (sRGB's Y) times the Jacobian of the map
from ``u_wm`` to ``wo``'s solid angle, ``2 pi^2 x sin(theta_m) 4 (wi . wm)`` (``measured.cpp``'s ``sample``), plus
``1e-6`` of its largest value so that every direction can be sampled: samples follow ``f cos theta_o``.

Mitsuba leaves its azimuthal reduction unset for isotropic files and may mirror a pair of directions; an isotropic
table symmetric in the relative azimuth (``phi_m`` against ``-phi_m``, bilateral symmetry) evaluates the same either
way. A model that is not symmetric so is written as the mean of the two with a :class:`NotSymmetricWarning`.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from .._errors import InputError
from .._files import check_output_path
from ..data._tensor_file import write_tensor_file
from ..render._brdf import rgb_brdf
from ._merl import _evaluate

#: ``(T, S)``: incident elevations and the side of each ``u_wm`` table (measured: ``benchmarks/bench_rgl_export.py``)
RESOLUTION = (32, 64)
#: the elevation of the last ``theta_i`` node's evaluation (radians below ``pi/2``): at the horizon itself the view
#: direction is outside every model's domain
_HORIZON_MARGIN = 1e-3
#: a table whose two relative azimuths differ by more than this (relative to its largest value) is not symmetric
SYMMETRY_TOL = 1e-6
#: sRGB's luminance weights (ITU-R BT.709)
_Y = np.array([0.2126, 0.7152, 0.0722])


class NotSymmetricWarning(UserWarning):
    """A model whose values at the relative azimuths ``phi`` and ``-phi`` differ, written to an isotropic RGL-EPFL
    file (which Mitsuba may read mirrored): the file holds their mean."""


def _check_resolution(resolution) -> tuple[int, int]:
    try:
        t, s = (int(r) for r in resolution)
        ok = (t, s) == tuple(resolution) and t >= 2 and s >= 2
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise InputError(f"resolution: expected (T, S), two integers of at least 2 (incident elevations, the side "
                         f"of each table), found {resolution!r}")
    return t, s


def table_directions(n_theta: int, size: int):
    """The directions of the table's nodes (module docstring): ``wi, wo`` ``(T, S, S, 3)`` (``wi`` repeated), the
    half vectors ``wm`` and ``theta_i`` ``(T,)``, numpy float64."""
    theta_i = np.linspace(0.0, np.pi / 2, n_theta)
    t = np.minimum(theta_i, np.pi / 2 - _HORIZON_MARGIN)
    wi = np.stack([np.sin(t), np.zeros_like(t), np.cos(t)], -1)[:, None, None, :]
    x = np.linspace(0.0, 1.0, size)
    theta_m = x**2 * (np.pi / 2)
    phi_m = (2.0 * np.linspace(0.0, 1.0, size) - 1.0) * np.pi
    tm, pm = theta_m[None, :], phi_m[:, None]  # (j, i): rows the azimuth, columns the elevation
    st = np.sin(tm)
    wm = np.stack([np.cos(pm) * st, np.sin(pm) * st, np.broadcast_to(np.cos(tm), (size, size))], -1)[None]
    wm = np.broadcast_to(wm, (n_theta, size, size, 3))
    dot = np.sum(wi * wm, -1, keepdims=True)
    wo = 2.0 * dot * wm - wi
    return np.broadcast_to(wi, wm.shape), wo, wm, theta_i


def rgl_fields(brdf, resolution=RESOLUTION, description: str = "") -> dict[str, np.ndarray]:
    """The fields of the RGL-EPFL file of ``brdf`` (module docstring): ``{name: array}`` in file order.

    Args:
        brdf: any model :func:`polyjax.render.rgb_brdf` accepts (a fitted model of batch ``()``, ``(1,)`` or
            ``(3,)``, a compact fit, a baseline, a closure ``f(u, v) -> (..., 3)``), isotropic.
        resolution: ``(T, S)``, :data:`RESOLUTION` by default.
        description: the file's description text (UTF-8).

    Warns:
        NotSymmetricWarning: the model's values at ``phi`` and ``-phi`` differ (module docstring).
    """
    n_theta, size = _check_resolution(resolution)
    f = rgb_brdf(brdf)
    wi, wo, wm, theta_i = table_directions(n_theta, size)
    above = wo[..., 2] > 0
    u = np.where(above[..., None], wo, np.array([0.0, 0.0, 1.0])).reshape(-1, 3)
    values = np.asarray(_evaluate(f, jnp.asarray(u), jnp.asarray(wi.reshape(-1, 3))), np.float64)
    cos_o = np.where(above, wo[..., 2], 0.0)
    table = np.moveaxis(values.reshape(n_theta, size, size, 3), -1, 1) * cos_o[:, None]  # (T, 3, S, S)
    table = np.where(np.isfinite(table), table, 0.0)
    mirrored = table[:, :, ::-1, :]
    scale = float(np.max(np.abs(table), initial=0.0))
    gap = float(np.max(np.abs(table - mirrored), initial=0.0))
    if gap > SYMMETRY_TOL * max(scale, 1e-300):
        warnings.warn(f"the model's values at the relative azimuths phi and -phi differ by up to "
                      f"{gap / max(scale, 1e-300):.1%} of its largest f cos; an isotropic RGL-EPFL file, which Mitsuba "
                      "may read mirrored, holds their mean", NotSymmetricWarning, stacklevel=3)
        table = 0.5 * (table + mirrored)
    x = np.linspace(0.0, 1.0, size)[None, None, :]
    sin_m = np.linalg.norm(wm[..., :2], axis=-1)  # the nodes' own half vectors: sin(theta_m)
    dot = np.maximum(np.sum(wi * wm, -1), 0.0)
    lum = np.einsum("c,tcji->tji", _Y, table) * np.maximum(2 * np.pi**2 * x * sin_m, 1e-6) * 4.0 * dot
    lum = np.maximum(lum, 0.0)
    top = lum.reshape(n_theta, -1).max(-1)[:, None, None]
    lum = np.where(top > 0, lum + 1e-6 * top, 1.0)
    f32 = lambda a: np.ascontiguousarray(a, np.float32)  # noqa: E731
    return {
        "description": np.frombuffer(description.encode("utf-8") or b"polyjax", np.uint8),
        "phi_i": f32([0.0]), "theta_i": f32(theta_i),
        "ndf": f32(np.ones((2, 2))), "sigma": f32(np.full((2, 2), 0.25)),
        "vndf": f32(np.ones((1, n_theta, 2, 2))), "luminance": f32(lum[None]),
        "rgb": f32(table[None]), "jacobian": np.array([1], np.uint8),  # max(f, 0) already: evaluate_rgb
    }


def rgl_bsdf(brdf, path: str | os.PathLike, *, resolution=RESOLUTION, description: str = "") -> Path:
    """Write ``brdf`` as an RGL-EPFL measured BSDF file (``*.bsdf``, module docstring), which Mitsuba 3's
    ``measured`` plugin renders (``<bsdf type="measured"><string name="filename" value="..."/></bsdf>``, RGB and
    spectral variants alike) and :func:`polyjax.data.load_rgl` reads back.

    Args:
        brdf: as :func:`rgl_fields`.
        path: the file to write (about 2 MB at the default resolution), whole or not at all.
        resolution: ``(T, S)``: incident elevations and the side of each half-vector table.
        description: the file's description text.

    Returns:
        The path written. Not differentiable (file output).

    Raises:
        InputError: a bad path or resolution, before any evaluation.

    Warns:
        NotSymmetricWarning: as :func:`rgl_fields`.
    """
    path = check_output_path(path, "path")
    _check_resolution(resolution)
    return write_tensor_file(path, rgl_fields(brdf, resolution, description))


__all__ = ["NotSymmetricWarning", "rgl_bsdf", "rgl_fields"]
