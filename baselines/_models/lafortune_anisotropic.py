"""Anisotropic Lafortune (one generalised cosine lobe, Lambertian diffuse)."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .common import POSITIVE, REAL, BaselineModel, Geometry, LogBounded, lobe, safe_pow, uniform_sampler


def lafortune_anisotropic(params, u, v):
    r"""Anisotropic one-lobe Lafortune BRDF (the paper's equation (10)):

    .. math::
        f = \frac{\rho_d}{\pi} + \max\big(0,\; C_x u_x v_x + C_y u_y v_y + C_z u_z v_z\big)^{n},

    with ``x``, ``y`` the principal directions of anisotropy of the local frame.

    Reference: Lafortune, Foo, Torrance, Greenberg, SIGGRAPH 1997.

    Args:
        params: ``(rho_d, C_x, C_y, C_z, n)``; exponent in (0.1, 1e4).
        u, v: ``(..., 3)`` light and view directions.

    Returns:
        ``f`` with the shape of ``u[..., 0]``; the lobe is 0 below the horizon.
    """
    g = Geometry(u, v)
    base = (params[1] * g.u[..., 0] * g.v[..., 0] + params[2] * g.u[..., 1] * g.v[..., 1]
            + params[3] * g.cu_raw * g.cv_raw)
    return params[0] / jnp.pi + lobe(g, safe_pow(base, params[4]))


def _columns(nl, u, v):
    g = Geometry(u, v)
    base = nl[0] * g.u[..., 0] * g.v[..., 0] + nl[1] * g.u[..., 1] * g.v[..., 1] + nl[2] * g.cu_raw * g.cv_raw
    return jnp.stack([jnp.full_like(g.cu, 1.0 / jnp.pi), lobe(g, safe_pow(base, nl[3]))], -1)


def _assemble(lin, nl):
    s = lin[1] ** (1.0 / nl[3])
    return jnp.stack([lin[0], nl[0] * s, nl[1] * s, nl[2] * s, nl[3]])


MODEL = BaselineModel(
    name="lafortune-anisotropic",
    param_names=("rho_d", "C_x", "C_y", "C_z", "n"),
    transforms=(POSITIVE, REAL, REAL, REAL, LogBounded(0.1, 1e4)),
    evaluate=lafortune_anisotropic,
    n_linear=2,
    columns=_columns,
    assemble=_assemble,
    guesses=np.array([
        [-1.0, -1.0, 1.0, 10.0], [-1.0, -0.6, 1.0, 10.0], [-0.6, -1.0, 1.0, 10.0], [-1.0, -1.0, 1.0, 2.0],
        [-1.0, -1.0, 1.0, 50.0], [-1.0, -0.6, 1.0, 50.0], [-0.6, -1.0, 1.0, 50.0], [-0.7, -0.7, 1.0, 5.0],
    ]),
    sample=uniform_sampler([(-1.2, 1.0, False), (-1.2, 1.0, False), (0.2, 1.2, False), (0.5, 300.0, True)]),
    reference="Lafortune et al., SIGGRAPH 1997",
    anisotropic=True,
)
