"""Blinn-Phong (one lobe, Lambertian diffuse)."""

from __future__ import annotations

import jax.numpy as jnp

from .common import POSITIVE, BaselineModel, Geometry, LogBounded, grid, lobe, safe_pow, uniform_sampler


def blinn_phong(params, u, v):
    r"""Normalised Blinn-Phong BRDF:

    .. math:: f = \frac{\rho_d}{\pi} + \rho_s \frac{n + 2}{2\pi} (n\cdot h)^{n} .

    Reference: J. F. Blinn, "Models of light reflection for computer synthesized pictures",
    SIGGRAPH 1977; normalisation as in Ngan, Durand, Matusik 2005.

    Args:
        params: ``(rho_d, rho_s, n)``: diffuse albedo, specular scale, exponent in (0.1, 1e5).
        u, v: ``(..., 3)`` light and view directions.

    Returns:
        ``f`` with the shape of ``u[..., 0]``; the lobe is 0 below the horizon.
    """
    rho_d, rho_s, n = params[0], params[1], params[2]
    g = Geometry(u, v)
    return rho_d / jnp.pi + rho_s * lobe(g, (n + 2.0) / (2.0 * jnp.pi) * safe_pow(g.nh, n))


def _columns(nl, u, v):
    g = Geometry(u, v)
    n = nl[0]
    return jnp.stack([jnp.full_like(g.cu, 1.0 / jnp.pi), lobe(g, (n + 2.0) / (2.0 * jnp.pi) * safe_pow(g.nh, n))], -1)


MODEL = BaselineModel(
    name="blinn-phong",
    param_names=("rho_d", "rho_s", "n"),
    transforms=(POSITIVE, POSITIVE, LogBounded(0.1, 1e5)),
    evaluate=blinn_phong,
    n_linear=2,
    columns=_columns,
    guesses=grid([1.0, 4.0, 15.0, 50.0, 200.0, 1000.0]),
    sample=uniform_sampler([(0.5, 3000.0, True)]),
    reference="Blinn, SIGGRAPH 1977",
)
