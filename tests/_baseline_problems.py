"""Shared problem definitions for the baseline tests: a dense synthetic geometry, known parameters
for every model, and scipy's least_squares as an independent reference solver."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

import baselines as bl
from baselines import _fit

#: Known constrained parameters per model (inside the transforms' ranges, away from the bounds).
TRUE_PARAMS = {
    "ashikhmin-shirley": [0.3, 0.4, 40.0, 0.3],
    "blinn-phong": [0.25, 0.3, 30.0],
    "cook-torrance": [0.3, 0.5, 0.25, 0.4],
    "lafortune": [0.35, -0.9, 0.85, 12.0],
    "oren-nayar": [0.6, 0.4],
    "ward": [0.3, 0.2, 0.15],
    "ward-duer": [0.3, 0.2, 0.2],
    "lafortune-anisotropic": [0.3, -1.0, -0.7, 0.9, 10.0],
    "ward-anisotropic": [0.3, 0.25, 0.12, 0.3],
}


def synthetic_geometry(n: int = 400, seed: int = 0, max_deg: float = 78.0):
    """``n`` random (u, v) pairs with polar angles up to ``max_deg`` and all azimuths, plus near-mirror pairs."""
    rng = np.random.default_rng(seed)

    def dirs(k):
        ct = rng.uniform(np.cos(np.deg2rad(max_deg)), 1.0, k)
        st = np.sqrt(1 - ct**2)
        ph = rng.uniform(-np.pi, np.pi, k)
        return np.stack([st * np.cos(ph), st * np.sin(ph), ct], -1)

    u = dirs(n)
    v = dirs(n)
    # a quarter of the views near the mirror direction so glossy lobes are sampled
    k = n // 4
    mirror = u[:k] * np.array([-1, -1, 1]) + 0.08 * rng.normal(size=(k, 3))
    mirror[:, 2] = np.abs(mirror[:, 2]) + 0.2
    v[:k] = mirror / np.linalg.norm(mirror, axis=-1, keepdims=True)
    return jnp.asarray(u), jnp.asarray(v)


def scipy_best_l2(name, u, v, values, starts, cutoff_deg=80.0):
    """Best L2 over ``starts`` (``(B, S, P)`` unconstrained) of scipy.optimize.least_squares (MINPACK LM).

    The residual function and its Jacobian are the same JAX functions :func:`baselines.fit` minimises
    (jitted), so only the solver differs. Returns ``(B,)`` L2 and the total number of fits.
    """
    from scipy.optimize import least_squares

    u, v, y, wl, wc2, _ = _fit._prepare(u, v, values, None, None, cutoff_deg)
    model = bl.get_model(name)
    den = jnp.sum(wl, -1, keepdims=True)
    sw = jnp.sqrt(wc2 / den)
    fn = _fit._residual_fn(model, u, v)
    res = jax.jit(lambda r, yb, s: fn(r, (yb, s)))
    jac = jax.jit(lambda r, yb, s: jax.jacfwd(fn)(r, (yb, s)))
    starts = np.asarray(starts)
    out = np.full(y.shape[0], np.inf)
    for b in range(y.shape[0]):
        yb, sb = y[b], sw[b]
        for s in range(starts.shape[1]):
            try:
                sol = least_squares(
                    lambda r: np.asarray(res(r, yb, sb)), starts[b, s], jac=lambda r: np.asarray(jac(r, yb, sb)),
                    method="lm",
                )
            except Exception:  # noqa: BLE001 - a failed reference start just does not count
                continue
            cost = float(np.sqrt(np.sum(sol.fun**2)))
            if np.isfinite(cost):
                out[b] = min(out[b], cost)
    return out
