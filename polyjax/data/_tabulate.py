"""Any BRDF callable (a fitted model, a baseline fit, a neural network, a function) as :class:`Measurements`."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import jax.numpy as jnp
import numpy as np

from .._arrays import is_concrete
from .._directions import safe_normalize
from .._errors import InputError
from .._measurements import Measurements, lane_mask
from ._merl import MERL_RESOLUTION, _choose_bins, merl_grid

GRIDS = ("merl",)


def tabulate(
    brdf: Callable,
    *,
    grid: str | None = None,
    u=None,
    v=None,
    weights=None,
    subsample: int | float | None = None,
    seed: int = 0,
    names: Sequence[str] = (),
    channels: Sequence[str] | None = None,
    axes: Sequence[str] | None = None,
    source: str | None = None,
) -> Measurements:
    """Evaluate ``brdf(u, v)`` at a set of directions and return the values as :class:`polyjax.Measurements`,
    ready for :func:`polyjax.fit_polynomial`, ``baselines.fit`` or :func:`polyjax.l2_error`.

    Args:
        brdf: a callable of light ``u`` and view ``v`` directions ``(n, 3)``. Its output is either samples-last
            ``(*batch, n)`` (a :class:`polyjax.PolynomialBRDF`, a ``baselines.BaselineFit``) or samples-first
            ``(n, C)`` (a :class:`polyjax.data.NeuralBRDF`, the renderer's BRDFs: ``C = 3`` is RGB), which is
            transposed to ``(C, n)``. With ``n = C`` the samples-last reading wins.
        grid: ``"merl"``: the MERL bin centres with both directions above the horizon (1,111,432 bins,
            weights = the bins' solid angles, :func:`polyjax.data.merl_grid`), or a reproducible ``subsample``
            of them (a count or a fraction, from ``seed``), as the MERL loaders use.
        u, v: instead of ``grid``: ``(n, 3)`` directions (renormalised); ``weights`` ``(n,)`` default to 1.
        names, channels, axes: labels of the result (see :class:`polyjax.Measurements`); for samples-first
            output ``axes`` defaults to ``("channel",)`` and ``channels`` to ``("R", "G", "B")`` when ``C = 3``.
        source: description (default: the callable's type and the directions).

    Returns:
        :class:`polyjax.Measurements` with ``values`` in the callable's float type; non-finite values are
        masked out (and set to 0). The values are the callable's JAX output, so ``tabulate`` is
        differentiable (``grad``, ``jvp``, ``vmap``) in the callable's parameters and in ``u``, ``v``.

    Raises:
        InputError: neither or both of ``grid`` and ``u, v``, an unknown grid, bad directions, or an output
        of neither layout.
    """
    if grid is not None:
        u, v, w, where = _grid_directions(grid, u, v, weights, subsample, seed)
    else:
        u, v, w, where = _given_directions(u, v, weights)
    values, samples_first = _samples_last(brdf, u, v)
    if not jnp.issubdtype(values.dtype, jnp.floating):
        values = values.astype(u.dtype)
    finite = jnp.isfinite(values)
    values = jnp.where(finite, values, 0.0)
    if is_concrete(finite):  # (n,) when every lane is finite at the same samples, as every loader's mask
        finite = jnp.asarray(lane_mask(np.asarray(finite)))
    if axes is None:
        axes = ("channel",) if samples_first else ()
    if channels is None:
        channels = ("R", "G", "B") if samples_first and values.shape[0] == 3 else ()
    return Measurements(
        u=u, v=v, values=values, weights=w, mask=finite, names=tuple(names), channels=tuple(channels),
        axes=tuple(axes), source=source or f"{type(brdf).__name__} tabulated on {where}",
    )


def _grid_directions(grid, u, v, weights, subsample, seed):
    """``(u, v, weights, description)`` of the MERL grid's bins above the horizon (or a ``subsample`` of them)."""
    if u is not None or v is not None:
        raise InputError("grid, u, v: expected either grid= or u= and v=, found both")
    if str(grid).lower() not in GRIDS:
        raise InputError(f"grid: expected one of {list(GRIDS)} (or u= and v=), found {grid!r}")
    if weights is not None:
        raise InputError("weights: the MERL grid has its own solid-angle weights; pass u=, v= to give weights")
    gu, gv, gw, above = merl_grid(MERL_RESOLUTION)
    keep = _choose_bins(above, subsample, int(seed), "tabulate")
    dtype = jnp.result_type(float)
    u, v, w = (jnp.asarray(a[keep], dtype) for a in (gu, gv, gw))
    where = f"the MERL grid, {u.shape[0]} bins" + (f" (subsample {subsample}, seed {seed})" if subsample else "")
    return u, v, w, where


def _given_directions(u, v, weights):
    """``(u, v, weights, description)`` of given ``(n, 3)`` directions, renormalised; weights default to 1."""
    if u is None or v is None:
        raise InputError("u and v: expected both (n, 3) direction arrays, or grid='merl'")
    u, v = jnp.asarray(u), jnp.asarray(v)
    if not jnp.issubdtype(u.dtype, jnp.floating):
        u, v = u.astype(jnp.result_type(float)), v.astype(jnp.result_type(float))
    if u.ndim != 2 or u.shape[-1] != 3 or u.shape != v.shape:
        raise InputError(f"u and v: expected two (n, 3) arrays of the same shape, found {u.shape} and {v.shape}")
    u, _ = safe_normalize(u)
    v, _ = safe_normalize(v)
    n = u.shape[0]
    w = jnp.ones(n, u.dtype) if weights is None else jnp.asarray(weights, u.dtype)
    if w.shape[-1:] != (n,):
        raise InputError(f"weights: expected shape (..., {n}), found {w.shape}")
    return u, v, w, f"{n} given direction pairs"


def _samples_last(brdf, u, v):
    """``brdf(u, v)`` as ``(*batch, n)`` values and whether it came samples-first (``(n, C)``, transposed)."""
    n = u.shape[0]
    out = jnp.asarray(brdf(u, v))
    if out.ndim >= 1 and out.shape[-1] == n:
        return out, False
    if out.ndim == 2 and out.shape[0] == n:
        return out.T, True
    raise InputError(f"brdf {type(brdf).__name__}: expected an output of shape (..., {n}) or ({n}, C) for {n} "
                     f"direction pairs, found {out.shape}")
