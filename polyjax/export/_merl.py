"""MERL export: tabulate any BRDF on the 90 x 90 x 180 MERL grid and write the ``.binary`` layout.

The layout and the grid are those of :mod:`polyjax.data._merl` (header ``(90, 90, 180)``, channel-major float64,
``idx = phi_d + 180 (theta_d + 90 theta_h)``, values divided by MERL's per-channel scale). Each bin gets the
BRDF at its bin centre (the direction :func:`polyjax.data.load_merl_binary` attaches to it), so writing and
reading back returns the model's values there. Bins with either direction at or below the horizon are
written as -1 (MERL's "missing"), and negative BRDF values (a polynomial fit can dip below 0) are clamped to 0
(a negative number would read as missing). MERL's grid holds one value per pair of directions (``phi_d`` in
``[0, pi)``; a reader gives the other order the same value by reciprocity): each bin holds ``f`` at its own pair,
and a model that is not reciprocal is written so with a :class:`NotReciprocalWarning` saying by how much its two
orders differ (the viewer, the GLSL table and the Mitsuba plugin keep both orders). Its own order, not the mean of
the two: MERL's table is defined at the bins' own order, and that is where a neural BRDF of a MERL material
reproduces it (:func:`polyjax.data.load_merl_nbrdf` evaluates it there; the two orders of one such network, the
tests', differ by up to 15 % of its largest value).
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._files import check_output_path
from ..data._merl import MERL_RESOLUTION, merl_grid, write_merl_binary
from ..render._brdf import evaluate_rgb, rgb_brdf

_CHUNK = 1 << 16


@eqx.filter_jit
def _evaluate(brdf, u, v):
    n = u.shape[0]
    m = -(-n // _CHUNK) * _CHUNK

    def pad(a):
        return jnp.concatenate([a, jnp.tile(jnp.asarray([[0.0, 0.0, 1.0]], a.dtype), (m - n, 1))])

    uc, vc = pad(u).reshape(-1, _CHUNK, 3), pad(v).reshape(-1, _CHUNK, 3)
    out = jax.lax.map(lambda uv: evaluate_rgb(brdf, uv[0], uv[1]), (uc, vc))
    return out.reshape(m, 3)[:n]


#: a table whose two orders of the directions differ by more than this (relative to its largest value) is not
#: reciprocal (:func:`whole_turn`)
RECIPROCITY_TOL = 1e-6


def whole_turn(table, swapped, axis: int = -1) -> tuple[np.ndarray, bool]:
    """A table of ``f(u, v)`` at the MERL bins and ``swapped``, the same of ``f(v, u)``, ``phi_d`` along ``axis``:
    ``(table, False)`` when they agree to :data:`RECIPROCITY_TOL` of the largest value (a reciprocal BRDF: MERL's
    ``phi_d`` in ``[0, pi)`` holds it), else ``(both, True)``, ``both`` the two joined along ``axis``: ``phi_d``
    over the whole turn ``[0, 2 pi)``, bin ``k + N_p`` holding ``f(v, u)`` of bin ``k`` (swapping the directions
    keeps the half vector and turns the difference vector by ``pi``, Rusinkiewicz). Tables of the viewer and the
    GLSL export of a BRDF that is not reciprocal (a compact model's skew rows, an RGL-EPFL file) are such."""
    table, swapped = np.asarray(table), np.asarray(swapped)
    scale = float(np.max(np.abs(table), initial=0.0))
    if float(np.max(np.abs(table - swapped), initial=0.0)) <= RECIPROCITY_TOL * max(scale, 1e-30):
        return table, False
    return np.concatenate([table, swapped], axis=axis), True


def tabulate_both_orders(brdf, resolution=MERL_RESOLUTION) -> tuple[np.ndarray, np.ndarray, bool]:
    """``(values (3, N_h, N_d, N_p'), above (N_h, N_d, N_p'), turn)``: :func:`tabulate_merl` of ``f(u, v)`` and of
    ``f(v, u)`` joined by :func:`whole_turn` (``N_p' = 2 N_p`` and ``turn`` True for a BRDF that is not
    reciprocal), numpy float64."""
    brdf = rgb_brdf(brdf)
    res = tuple(int(r) for r in resolution)
    (a, above), (b, _) = (tabulate_merl(brdf, res, swap=swap) for swap in (False, True))
    values, turn = whole_turn(np.asarray(a, np.float64).reshape(3, *res), np.asarray(b, np.float64).reshape(3, *res))
    above = np.asarray(above).reshape(res)
    return values, (np.concatenate([above, above], -1) if turn else above), turn


def tabulate_merl(brdf, resolution=MERL_RESOLUTION, dtype=jnp.float64, *, swap: bool = False
                  ) -> tuple[Float[Array, "3 n"], np.ndarray]:
    """``(values (3, N), valid (N,))``: ``brdf`` (any model :func:`polyjax.render.rgb_brdf` accepts) at the bin
    centres of the MERL grid in file order, and where both directions are above the horizon; ``swap``: ``f(v, u)``
    instead of ``f(u, v)`` (the same compiled evaluation, the directions exchanged).

    Differentiable w.r.t. the model's parameters (a jitted, chunked evaluation); ``valid`` is numpy.
    """
    brdf = rgb_brdf(brdf)
    u, v, _, above = merl_grid(tuple(int(r) for r in resolution))
    u, v = (v, u) if swap else (u, v)
    vals = _evaluate(brdf, jnp.asarray(u, dtype), jnp.asarray(v, dtype))
    return jnp.where(jnp.asarray(above)[:, None], vals, 0.0).T, np.asarray(above)


class NotReciprocalWarning(UserWarning):
    """A model that is not reciprocal written to a format that holds one value per pair of directions (MERL's
    ``.binary``): the file holds ``f`` at each bin's own order of the pair only."""


def one_order(values, above, turn: bool, what: str) -> tuple[np.ndarray, np.ndarray]:
    """From :func:`tabulate_both_orders`' ``(values, above, turn)``: the table of each bin's own order, ``(3, N_h,
    N_d, N_p)`` and ``(N_h, N_d, N_p)``; for a model that is not reciprocal (``turn``) with a
    :class:`NotReciprocalWarning` naming ``what`` and the largest difference of the orders relative to the largest
    value."""
    if not turn:
        return values, above
    n_p = values.shape[-1] // 2
    a, b = values[..., :n_p], values[..., n_p:]
    with np.errstate(invalid="ignore"):
        scale = float(np.nanmax(np.abs(a), initial=0.0))
        gap = float(np.nanmax(np.abs(a - b), initial=0.0))
    warnings.warn(f"{what}: the model is not reciprocal (f(u, v) and f(v, u) differ by up to "
                  f"{gap / max(scale, 1e-300):.1%} of its largest value); MERL's format holds one value per pair of "
                  "directions: written f at each bin's own order (the viewer, GLSL and Mitsuba exports keep both "
                  "orders)", NotReciprocalWarning, stacklevel=3)
    return a, above[..., :n_p]


def merl_binary(brdf, path: str | os.PathLike, *, resolution=MERL_RESOLUTION) -> Path:
    """Write ``brdf`` as a MERL ``.binary`` file (ALTA's ``brdf2data``), readable by BRDF Explorer, MERL-reading
    renderers and :func:`polyjax.data.load_merl_binary`.

    Args:
        brdf: a :class:`polyjax.PolynomialBRDF` (batch ``()``, ``(1,)`` or ``(3,)``), ``NeuralBRDF``,
            ``TabulatedBRDF``, a baseline closure: any ``f(u, v) -> (..., 3)`` or ``(...)``.
        path: the file to write (34,992,012 bytes at MERL's resolution).
        resolution: ``(N_h, N_d, N_p)``; MERL's ``(90, 90, 180)`` by default.

    Returns:
        The path written. Not differentiable (file output); :func:`tabulate_merl` is.

    Warns:
        NotReciprocalWarning: a model that is not reciprocal, written at each bin's own order (module docstring).
    """
    path = check_output_path(path, "path")
    vals, above = one_order(*tabulate_both_orders(brdf, resolution), f"MERL export {str(path)!r}")
    vals, above = vals.reshape(3, -1), above.reshape(-1)  # max(f, 0) already: tabulated through evaluate_rgb
    mask = np.broadcast_to(above, vals.shape) & np.isfinite(vals)
    return write_merl_binary(path, vals, resolution=resolution, mask=mask)


__all__ = ["NotReciprocalWarning", "merl_binary", "tabulate_merl"]
