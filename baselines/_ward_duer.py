"""Ward-Duer (Ward's lobe with Duer's normalisation, Lambertian diffuse)."""

from __future__ import annotations

import jax.numpy as jnp

from ._common import (
    POSITIVE,
    BaselineModel,
    Geometry,
    LogBounded,
    diffuse_specular_columns,
    grid,
    lobe,
    uniform_sampler,
)


def _specular(alpha, g):
    a2 = alpha * alpha
    return lobe(g, jnp.exp(-g.tan2_h / a2) / (4.0 * jnp.pi * a2 * g.cu * g.cv))


def ward_duer(params, u, v):
    r"""Ward-Duer BRDF (Ward's Gaussian lobe, ``1 / sqrt(cos cos)`` replaced by ``1 / (cos cos)``):

    .. math::
        f = \frac{\rho_d}{\pi} + \rho_s \frac{\exp(-\tan^2\delta / \alpha^2)}{4\pi\alpha^2\,(n\cdot u)(n\cdot v)} .

    Reference: A. Duer, "An improved normalization for the Ward reflectance model", Journal of
    Graphics Tools 11(1), 2006; as fitted by Ngan, Durand, Matusik 2005.

    Args:
        params: ``(rho_d, rho_s, alpha)``: diffuse albedo, specular albedo, roughness in (1e-3, 3).
        u, v: ``(..., 3)`` light and view directions.

    Returns:
        ``f`` with the shape of ``u[..., 0]``; the lobe is 0 below the horizon.
    """
    return params[0] / jnp.pi + params[1] * _specular(params[2], Geometry(u, v))


MODEL = BaselineModel(
    name="ward-duer",
    param_names=("rho_d", "rho_s", "alpha"),
    transforms=(POSITIVE, POSITIVE, LogBounded(1e-3, 3.0)),
    evaluate=ward_duer,
    n_linear=2,
    columns=diffuse_specular_columns(_specular),
    guesses=grid([0.3, 0.1, 0.6, 0.05, 0.2, 1.0]),
    sample=uniform_sampler([(0.02, 1.5, True)]),
    reference="Duer, J. Graphics Tools 11(1) 2006",
)
