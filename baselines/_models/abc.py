"""ABC micro-facet model (Low, Kronander, Ynnerman, Unger 2012)."""

from __future__ import annotations

import jax.numpy as jnp

from .common import POSITIVE, BaselineModel, Geometry, LogBounded, grid, lobe, uniform_sampler


def fresnel_dielectric(ior, c):
    """Unpolarised Fresnel reflectance of a dielectric of index ``ior`` at incidence cosine ``c`` in [0, 1]."""
    g = jnp.sqrt(ior * ior + c * c - 1.0)
    a = (g - c) / (g + c)
    b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
    return 0.5 * a * a * (1.0 + b * b)


def _specular(nl, g):
    """``F D G / (pi u.z v.z)`` with ``A = 1``; ``nl = (B, C, ior)``."""
    b, c, ior = nl[0], nl[1], nl[2]
    d = jnp.exp(-c * jnp.log1p(b * (1.0 - g.nh)))
    shadow = jnp.minimum(jnp.minimum(1.0, 2.0 * g.nh * g.cu / g.vh), jnp.minimum(1.0, 2.0 * g.nh * g.cv / g.vh))
    fres = fresnel_dielectric(ior, jnp.clip(g.vh, 0.0, 1.0))
    return lobe(g, fres * d * shadow / (jnp.pi * g.cu * g.cv))


def abc(params, u, v):
    r"""ABC BRDF (Low et al. 2012), as evaluated by ``dj_brdf``:

    .. math::
        f = \frac{k_D}{\pi} + \frac{F(\cos\theta_d)\, D(\cos\theta_h)\, G}{\pi (n\cdot u)(n\cdot v)},
        \quad D = \frac{A}{(1 + B (1 - \cos\theta_h))^C},
        \quad G = \min\Big(1, \frac{2\cos\theta_h (n\cdot u)}{h\cdot u}, \frac{2\cos\theta_h (n\cdot v)}{h\cdot v}\Big),

    ``F`` the unpolarised Fresnel reflectance of a dielectric of index ``ior`` (:func:`fresnel_dielectric`).

    The published fits share ``B``, ``C`` and ``ior`` between the R, G, B channels (9 parameters per
    material); :func:`baselines.fit` fits every channel on its own (5 per channel, 15 per material).

    Reference: J. Low, J. Kronander, A. Ynnerman, J. Unger, "BRDF models for accurate and efficient
    rendering of glossy surfaces", ACM TOG 31(1), 2012.

    Args:
        params: ``(kD, A, B, C, ior)``.
        u, v: ``(..., 3)`` light and view directions.

    Returns:
        ``f`` with the shape of ``u[..., 0]``; 0 below the horizon.
    """
    g = Geometry(u, v)
    return lobe(g, params[0] / jnp.pi) + params[1] * _specular(params[2:], g)


def _columns(nl, u, v):
    g = Geometry(u, v)
    return jnp.stack([lobe(g, jnp.full_like(g.cu, 1.0 / jnp.pi)), _specular(nl, g)], -1)


MODEL = BaselineModel(
    name="abc",
    param_names=("kD", "A", "B", "C", "ior"),
    transforms=(POSITIVE, POSITIVE, LogBounded(1.0, 1e8), LogBounded(1e-3, 5.0), LogBounded(1.001, 100.0)),
    evaluate=abc,
    n_linear=2,
    columns=_columns,
    guesses=grid([1e2, 1e4, 1e6], [0.6, 1.5], [1.5]),
    sample=uniform_sampler([(10.0, 1e7, True), (0.05, 3.0, True), (1.05, 10.0, True)]),
    reference="Low, Kronander, Ynnerman & Unger, ACM TOG 31(1) 2012",
)
