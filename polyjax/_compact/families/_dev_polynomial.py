r"""A log-space polynomial in two Rusinkiewicz angles: the simplest bounded compact family.

``f = max(exp(P(a, b)) - eps, 0)``, ``P`` a polynomial of total degree ``p`` in scaled Legendre polynomials of
``a = 2 sqrt(theta_h / (pi/2)) - 1`` and ``b = 2 theta_d / (pi/2) - 1`` (both in ``[-1, 1]`` above the horizon, so
``P`` is bounded) and capped at the largest fitted value, one per channel: ``3 ((p+1)(p+2)/2 + 1)`` numbers per
material. Fitted in closed form by
weighted least squares of ``log(f + eps)`` (the weights ``w`` for the log metric, ``w cos^2 theta_u`` for the L2).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from ..._basis import design_matrix, n_terms
from ..._directions import safe_normalize
from ..._solve.lstsq import weighted_lstsq

EPS = 1e-3
_MAX_DEGREE = 10


def _coordinates(u, v):
    """``(..., 2)`` scaled ``(a, b)`` of directions ``(..., 3)``."""
    h, _ = safe_normalize(u + v)
    theta_h = jnp.arctan2(jnp.sqrt(h[..., 0] ** 2 + h[..., 1] ** 2 + 1e-30), h[..., 2])
    d = jnp.cross(u, h)
    theta_d = jnp.arctan2(jnp.sqrt(jnp.sum(d * d, -1) + 1e-30), jnp.sum(u * h, -1))
    a = 2.0 * jnp.sqrt(jnp.clip(theta_h / (0.5 * jnp.pi), 1e-12, 1.0)) - 1.0
    b = 2.0 * jnp.clip(theta_d / (0.5 * jnp.pi), 0.0, 1.0) - 1.0
    return jnp.stack([a, b], -1)


@dataclasses.dataclass(frozen=True)
class DevPolynomial:
    name: str = "log-poly2"

    def configs(self, budget: int) -> list[int]:
        return [p for p in range(_MAX_DEGREE + 1) if self.n_numbers(p) <= budget]

    def n_numbers(self, config: int) -> int:
        return 3 * (n_terms(2, int(config), True) + 1)

    def fit(self, config, u, v, values, weights, mask, metric: str):
        x = design_matrix(_coordinates(u, v), int(config), "legendre", True)  # (n, m)
        w = jnp.broadcast_to(jnp.where(mask, weights, 0.0), values.shape)
        if metric == "l2":
            w = w * jnp.clip(u[..., 2], 0.0, 1.0) ** 2
        y = jnp.log(jnp.maximum(values, 0.0) + EPS)
        lead = values.shape[:-1]
        y2 = y.reshape((-1, y.shape[-1]))
        w2 = w.reshape((-1, w.shape[-1]))
        beta = jax.vmap(lambda yy, ww: weighted_lstsq(x, yy, ww).coefficients)(y2, w2)
        cap = jnp.max(jnp.where(w > 0, y, -jnp.inf), -1)  # the largest fitted log value: f never above the data
        return {"coefficients": beta.reshape(lead + (x.shape[-1],)), "cap": jnp.where(jnp.isfinite(cap), cap, 0.0)}

    def evaluate(self, config, params, u, v):
        x = design_matrix(_coordinates(u, v), int(config), "legendre", True)  # (n, m)
        p = params["coefficients"] @ x.T
        return jnp.maximum(jnp.exp(jnp.minimum(p, params["cap"][..., None])) - EPS, 0.0)


DEV_POLYNOMIAL = DevPolynomial()
