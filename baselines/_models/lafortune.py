"""Lafortune (one generalised cosine lobe, Lambertian diffuse): isotropic form."""

from __future__ import annotations

import jax.numpy as jnp

from .common import POSITIVE, REAL, BaselineModel, Geometry, LogBounded, grid, lobe, safe_pow, uniform_sampler


def lafortune(params, u, v):
    r"""Isotropic one-lobe Lafortune BRDF (the paper's equation (10) with ``C_x = C_y``):

    .. math::
        f = \frac{\rho_d}{\pi} + \max\big(0,\; C_{xy}(u_x v_x + u_y v_y) + C_z u_z v_z\big)^{n} .

    ``C_xy < 0 < C_z`` gives a forward (off-specular) lobe, ``C_xy > 0`` retro-reflection; the
    magnitude of ``C`` sets the lobe's albedo.

    Reference: E. P. F. Lafortune, S.-C. Foo, K. E. Torrance, D. P. Greenberg, "Non-linear
    approximation of reflectance functions", SIGGRAPH 1997.

    Args:
        params: ``(rho_d, C_xy, C_z, n)``: diffuse albedo, lobe coefficients (any real), exponent in (0.1, 1e4).
        u, v: ``(..., 3)`` light and view directions.

    Returns:
        ``f`` with the shape of ``u[..., 0]``; the lobe is 0 below the horizon.
    """
    rho_d, cxy, cz, n = params[0], params[1], params[2], params[3]
    g = Geometry(u, v)
    base = cxy * (g.u[..., 0] * g.v[..., 0] + g.u[..., 1] * g.v[..., 1]) + cz * g.cu_raw * g.cv_raw
    return rho_d / jnp.pi + lobe(g, safe_pow(base, n))


def _columns(nl, u, v):
    g = Geometry(u, v)
    base = nl[0] * (g.u[..., 0] * g.v[..., 0] + g.u[..., 1] * g.v[..., 1]) + nl[1] * g.cu_raw * g.cv_raw
    return jnp.stack([jnp.full_like(g.cu, 1.0 / jnp.pi), lobe(g, safe_pow(base, nl[2]))], -1)


def _assemble(lin, nl):
    """The lobe scale ``k`` is folded into ``C``: ``(k C)^n = k^n C^n``, so ``C <- C k^(1/n)``."""
    s = lin[1] ** (1.0 / nl[2])
    return jnp.stack([lin[0], nl[0] * s, nl[1] * s, nl[2]])


MODEL = BaselineModel(
    name="lafortune",
    param_names=("rho_d", "C_xy", "C_z", "n"),
    transforms=(POSITIVE, REAL, REAL, LogBounded(0.1, 1e4)),
    evaluate=lafortune,
    n_linear=2,
    columns=_columns,
    assemble=_assemble,
    # (C_xy, C_z) directions of unit size and exponents; the scale comes from the linear seed
    guesses=grid([-1.0, -0.7], [1.0, 0.7], [2.0, 10.0, 50.0])[[0, 1, 2, 6, 9, 4, 3, 11]],
    sample=uniform_sampler([(-1.2, 1.0, False), (0.2, 1.2, False), (0.5, 300.0, True)]),
    reference="Lafortune et al., SIGGRAPH 1997",
)
