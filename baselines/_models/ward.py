"""Ward (isotropic Gaussian lobe, Lambertian diffuse)."""

from __future__ import annotations

import jax.numpy as jnp

from .common import POSITIVE, BaselineModel, Geometry, LogBounded, diffuse_specular_columns, grid, lobe, uniform_sampler


def ward_lobe(alpha, g, normalise):
    """Ward's Gaussian lobe ``exp(-tan^2 delta / alpha^2) / normalise(4 pi alpha^2, g)``, 0 below the horizon: the
    normalisation (``4 pi alpha^2 sqrt(cos_u cos_v)`` for Ward, ``4 pi alpha^2 cos_u cos_v`` for Ward-Duer) is
    the models' only difference."""
    a2 = alpha * alpha
    return lobe(g, jnp.exp(-g.tan2_h / a2) / normalise(4.0 * jnp.pi * a2, g))


def _specular(alpha, g):
    return ward_lobe(alpha, g, lambda s, g: s * jnp.sqrt(g.cu * g.cv))


def ward(params, u, v):
    r"""Isotropic Ward BRDF (the paper's equation (4) with ``mu = rho_d / pi``):

    .. math::
        f = \frac{\rho_d}{\pi} + \rho_s \frac{1}{\sqrt{(n\cdot u)(n\cdot v)}}
            \frac{\exp(-\tan^2\delta / \alpha^2)}{4\pi\alpha^2},

    ``delta`` the angle between the normal and the half vector.

    Reference: G. J. Ward, "Measuring and modeling anisotropic reflection", SIGGRAPH 1992.

    Args:
        params: ``(rho_d, rho_s, alpha)``: diffuse albedo, specular albedo, roughness in (1e-3, 3).
        u, v: ``(..., 3)`` light and view directions.

    Returns:
        ``f`` with the shape of ``u[..., 0]``; the lobe is 0 below the horizon.
    """
    return params[0] / jnp.pi + params[1] * _specular(params[2], Geometry(u, v))


MODEL = BaselineModel(
    name="ward",
    param_names=("rho_d", "rho_s", "alpha"),
    transforms=(POSITIVE, POSITIVE, LogBounded(1e-3, 3.0)),
    evaluate=ward,
    n_linear=2,
    columns=diffuse_specular_columns(_specular),
    guesses=grid([0.3, 0.1, 0.6, 0.05, 0.2, 1.0]),
    sample=uniform_sampler([(0.02, 1.5, True)]),
    reference="Ward, SIGGRAPH 1992",
)
