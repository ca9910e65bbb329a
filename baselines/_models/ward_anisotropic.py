"""Anisotropic Ward (elliptical Gaussian lobe, Lambertian diffuse)."""

from __future__ import annotations

import jax.numpy as jnp

from .common import POSITIVE, BaselineModel, Geometry, LogBounded, diffuse_specular_columns, grid, lobe, uniform_sampler


def _specular(ax, ay, g):
    hz2 = g.nh * g.nh
    e = ((g.h[..., 0] / ax) ** 2 + (g.h[..., 1] / ay) ** 2) / hz2
    return lobe(g, jnp.exp(-e) / (4.0 * jnp.pi * ax * ay * jnp.sqrt(g.cu * g.cv)))


def ward_anisotropic(params, u, v):
    r"""Anisotropic Ward BRDF:

    .. math::
        f = \frac{\rho_d}{\pi} + \frac{\rho_s}{4\pi\alpha_x\alpha_y\sqrt{(n\cdot u)(n\cdot v)}}
            \exp\!\big(-\tan^2\delta\,(\cos^2\phi_h/\alpha_x^2 + \sin^2\phi_h/\alpha_y^2)\big),

    computed as ``exp(-((h_x/alpha_x)^2 + (h_y/alpha_y)^2) / h_z^2)`` (no azimuth needed);
    ``x``, ``y`` are the principal directions of anisotropy.

    Reference: G. J. Ward, "Measuring and modeling anisotropic reflection", SIGGRAPH 1992.

    Args:
        params: ``(rho_d, rho_s, alpha_x, alpha_y)``; roughnesses in (1e-3, 3).
        u, v: ``(..., 3)`` light and view directions.

    Returns:
        ``f`` with the shape of ``u[..., 0]``; the lobe is 0 below the horizon.
    """
    return params[0] / jnp.pi + params[1] * _specular(params[2], params[3], Geometry(u, v))


MODEL = BaselineModel(
    name="ward-anisotropic",
    param_names=("rho_d", "rho_s", "alpha_x", "alpha_y"),
    transforms=(POSITIVE, POSITIVE, LogBounded(1e-3, 3.0), LogBounded(1e-3, 3.0)),
    evaluate=ward_anisotropic,
    n_linear=2,
    columns=diffuse_specular_columns(_specular),
    guesses=grid([0.3, 0.1, 0.6], [0.3, 0.1, 0.6])[[0, 4, 8, 1, 3, 2, 6, 5, 7]],
    sample=uniform_sampler([(0.02, 1.5, True), (0.02, 1.5, True)]),
    reference="Ward, SIGGRAPH 1992",
    anisotropic=True,
)
