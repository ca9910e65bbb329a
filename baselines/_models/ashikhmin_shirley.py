"""Ashikhmin-Shirley (isotropic, one lobe, Lambertian diffuse)."""

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
    safe_pow,
    schlick,
    uniform_sampler,
)


def ashikhmin_shirley(params, u, v):
    r"""Isotropic Ashikhmin-Shirley BRDF, in the form fitted by Ngan et al. 2005:

    .. math::
        f = \frac{\rho_d}{\pi} + \rho_s \frac{n + 1}{8\pi}
            \frac{(n\cdot h)^{n}}{(v\cdot h)\,\max(n\cdot u, n\cdot v)} F(F_0, v\cdot h),
        \qquad F = F_0 + (1 - F_0)(1 - v\cdot h)^5 .

    Reference: M. Ashikhmin, P. Shirley, "An anisotropic Phong BRDF model", Journal of Graphics
    Tools 5(2), 2000 (the paper's equation (8) with ``mu = rho_d / pi``).

    Args:
        params: ``(rho_d, rho_s, n, F0)``: diffuse albedo, specular scale, Phong exponent
            (in (0.1, 1e5)), Fresnel reflectance at normal incidence (in (0, 1)).
        u, v: ``(..., 3)`` light and view directions (normal ``+z``).

    Returns:
        ``f`` with the shape of ``u[..., 0]``; the lobe is 0 below the horizon.
    """
    rho_d, rho_s, n, f0 = params[0], params[1], params[2], params[3]
    return rho_d / jnp.pi + rho_s * _specular(n, f0, Geometry(u, v))


def _specular(n, f0, g):
    spec = (n + 1.0) / (8.0 * jnp.pi) * safe_pow(g.nh, n) / (g.vh * jnp.maximum(g.cu, g.cv)) * schlick(f0, g.vh)
    return lobe(g, spec)


MODEL = BaselineModel(
    name="ashikhmin-shirley",
    param_names=("rho_d", "rho_s", "n", "F0"),
    transforms=(POSITIVE, POSITIVE, LogBounded(0.1, 1e5), UNIT),
    evaluate=ashikhmin_shirley,
    n_linear=2,
    columns=diffuse_specular_columns(_specular),
    guesses=grid([2.0, 10.0, 50.0, 300.0], [0.1, 0.6]),
    sample=uniform_sampler([(0.5, 2000.0, True), (0.02, 0.95, False)]),
    reference="Ashikhmin & Shirley, J. Graphics Tools 5(2) 2000",
)
