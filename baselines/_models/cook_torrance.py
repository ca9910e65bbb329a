"""Cook-Torrance (Beckmann distribution, Schlick Fresnel, one lobe, Lambertian diffuse)."""

from __future__ import annotations

import jax.numpy as jnp

from .common import (
    POSITIVE,
    UNIT,
    BaselineModel,
    Geometry,
    LogBounded,
    diffuse_specular_columns,
    grid,
    lobe,
    schlick,
    uniform_sampler,
)


def _specular(m, f0, g):
    m2 = m * m
    d = jnp.exp(-g.tan2_h / m2) / (m2 * g.nh**4)
    shadow = jnp.minimum(1.0, jnp.minimum(2.0 * g.nh * g.cv / g.vh, 2.0 * g.nh * g.cu / g.vh))
    return lobe(g, schlick(f0, g.vh) * d * shadow / (jnp.pi * g.cu * g.cv))


def cook_torrance(params, u, v):
    r"""Cook-Torrance BRDF:

    .. math::
        f = \frac{\rho_d}{\pi} + \rho_s \frac{F(F_0, v\cdot h)\, D(\theta_h)\, G}{\pi (n\cdot u)(n\cdot v)},
        \quad D = \frac{e^{-\tan^2\theta_h / m^2}}{m^2 \cos^4\theta_h},
        \quad G = \min\Big(1, \frac{2 (n\cdot h)(n\cdot v)}{v\cdot h}, \frac{2 (n\cdot h)(n\cdot u)}{v\cdot h}\Big),

    with Schlick's Fresnel ``F = F0 + (1 - F0)(1 - v.h)^5``.

    Reference: R. L. Cook, K. E. Torrance, "A reflectance model for computer graphics",
    ACM TOG 1(1), 1982.

    Args:
        params: ``(rho_d, rho_s, m, F0)``: diffuse albedo, specular scale, Beckmann RMS slope in
            (1e-3, 3), Fresnel reflectance at normal incidence in (0, 1).
        u, v: ``(..., 3)`` light and view directions.

    Returns:
        ``f`` with the shape of ``u[..., 0]``; the lobe is 0 below the horizon.
    """
    rho_d, rho_s, m, f0 = params[0], params[1], params[2], params[3]
    return rho_d / jnp.pi + rho_s * _specular(m, f0, Geometry(u, v))


MODEL = BaselineModel(
    name="cook-torrance",
    param_names=("rho_d", "rho_s", "m", "F0"),
    transforms=(POSITIVE, POSITIVE, LogBounded(1e-3, 3.0), UNIT),
    evaluate=cook_torrance,
    n_linear=2,
    columns=diffuse_specular_columns(_specular),
    guesses=grid([0.6, 0.3, 0.15, 0.07], [0.1, 0.6]),
    sample=uniform_sampler([(0.02, 1.5, True), (0.02, 0.95, False)]),
    reference="Cook & Torrance, ACM TOG 1(1) 1982",
)
