"""Oren-Nayar (qualitative model: a rough diffuse surface, no specular lobe)."""

from __future__ import annotations

import jax.numpy as jnp

from .common import POSITIVE, BaselineModel, Bounded, Geometry, grid, uniform_sampler


def _shape(sigma, g):
    s2 = sigma * sigma
    a = 1.0 - 0.5 * s2 / (s2 + 0.33)
    b = 0.45 * s2 / (s2 + 0.09)
    # cos(phi_u - phi_v) sin(alpha) tan(beta) = (u_x v_x + u_y v_y) / cos(beta), beta = min(theta_u, theta_v)
    dot_xy = g.u[..., 0] * g.v[..., 0] + g.u[..., 1] * g.v[..., 1]
    return (a + b * jnp.maximum(dot_xy, 0.0) / jnp.maximum(g.cu, g.cv)) / jnp.pi


def oren_nayar(params, u, v):
    r"""Oren-Nayar BRDF (the qualitative model of their equation (30)):

    .. math::
        f = \frac{\rho}{\pi}\big(A + B \max(0, \cos(\phi_u - \phi_v)) \sin\alpha \tan\beta\big),
        \quad A = 1 - \frac{\sigma^2}{2(\sigma^2 + 0.33)}, \quad B = \frac{0.45\sigma^2}{\sigma^2 + 0.09},

    ``alpha = max(theta_u, theta_v)``, ``beta = min(theta_u, theta_v)``. It is computed as
    ``B max(0, u_x v_x + u_y v_y) / max(cos theta_u, cos theta_v)`` (the same number), which
    needs no azimuths and stays finite at the normal and at grazing angles.

    Reference: M. Oren, S. K. Nayar, "Generalization of Lambert's reflectance model", SIGGRAPH 1994.

    Args:
        params: ``(rho, sigma)``: albedo and the roughness (standard deviation of facet slopes,
            radians, in [0, 2]; only ``sigma^2`` enters).
        u, v: ``(..., 3)`` light and view directions.

    Returns:
        ``f`` with the shape of ``u[..., 0]``.
    """
    return params[0] * _shape(params[1], Geometry(u, v))


MODEL = BaselineModel(
    name="oren-nayar",
    param_names=("rho", "sigma"),
    transforms=(POSITIVE, Bounded(2.0)),
    evaluate=oren_nayar,
    n_linear=1,
    columns=lambda nl, u, v: _shape(nl[0], Geometry(u, v))[..., None],
    guesses=grid([0.3, 0.05, 0.6, 1.0, 0.15, 1.5]),
    sample=uniform_sampler([(0.01, 1.8, True)]),
    reference="Oren & Nayar, SIGGRAPH 1994",
)
