"""Shifted Gamma Distribution micro-facet model (SGD; Bagher, Soler, Holzschuch 2012)."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .common import POSITIVE, REAL, BaselineModel, Geometry, LogBounded, lobe, uniform_sampler


def _theta(w):
    """Polar angle of unit directions, ``atan2(|w_xy|, w_z)``: equal to ``acos(w_z)``, finite gradient at the pole."""
    r2 = w[..., 0] ** 2 + w[..., 1] ** 2
    pos = r2 > 0
    return jnp.arctan2(jnp.where(pos, jnp.sqrt(jnp.where(pos, r2, 1.0)), 0.0), w[..., 2])


def _g1(theta, lam, c, k, theta0):
    """``clamp(1 + lambda (1 - exp(c max(0, theta - theta0)^k)), 0, 1)`` for ``lambda > 0``.

    ``t = c x^k`` is formed in log space and capped at ``log(1 + 1/lambda)``, the value where the clamp
    reaches 0, so huge ``c`` (the table holds ``1e38``) or ``k`` (up to ~900) overflow neither the value
    nor its gradient. For ``lambda <= 0`` the clamp gives 1.
    """
    x = theta - theta0
    pos = x > 0
    log_t = jnp.where(pos, jnp.log(jnp.maximum(c, 1e-300)) + k * jnp.log(jnp.where(pos, x, 1.0)), -1e3)
    lam_pos = lam > 0
    lam_s = jnp.where(lam_pos, lam, 1.0)
    t_max = jnp.log1p(1.0 / lam_s)
    t = jnp.exp(jnp.minimum(log_t, jnp.log(t_max)))
    return jnp.where(lam_pos, jnp.clip(1.0 + lam_s * (1.0 - jnp.exp(t)), 0.0, 1.0), 1.0)


def _specular(nl, g):
    """``F D G1 G1 / (u.z v.z)`` with ``kap = 1`` (the scale is ``rho_s``); ``nl`` the nonlinear parameters."""
    alpha, p, f0, f1, lam, c, k, theta0 = (nl[i] for i in range(8))
    cos_h = g.nh
    a = alpha + g.tan2_h / alpha
    d = jnp.exp(-a - p * jnp.log(a)) / (jnp.pi * cos_h**4)
    cos_d = jnp.clip(g.vh, 0.0, 1.0)
    fres = f0 - cos_d * f1 + (1.0 - cos_d) ** 5 * (1.0 - f0)
    shadow = _g1(_theta(g.u), lam, c, k, theta0) * _g1(_theta(g.v), lam, c, k, theta0)
    return lobe(g, fres * d * shadow / (g.cu * g.cv))


def sgd(params, u, v):
    r"""Shifted Gamma Distribution BRDF (Bagher et al. 2012), as evaluated by ``dj_brdf``:

    .. math::
        f = \frac{1}{\pi}\Big(\rho_d + \rho_s \frac{F(\cos\theta_d)\, D(\cos\theta_h)\, G_1(u) G_1(v)}
            {(n\cdot u)(n\cdot v)}\Big),
        \quad D = \frac{e^{-a}}{\pi a^p \cos^4\theta_h},\ a = \alpha + \frac{\tan^2\theta_h}{\alpha},

    ``F(c) = f_0 - c f_1 + (1 - c)^5 (1 - f_0)``,
    ``G_1(w) = clamp(1 + lambda (1 - exp(c_G max(0, theta_w - theta_0)^k)), 0, 1)``.

    The published model also has a scale ``kap`` on ``D``; it multiplies ``rho_s`` exactly, so it is
    folded into ``rho_s`` here (:func:`baselines.published` returns ``rho_s kap``): 10 parameters per
    channel, none redundant.

    Reference: M. M. Bagher, C. Soler, N. Holzschuch, "Accurate fitting of measured reflectances using
    a Shifted Gamma micro-facet distribution", Computer Graphics Forum 31(4), 2012.

    Args:
        params: ``(rho_d, rho_s, alpha, p, f0, f1, lambda, c, k, theta0)``.
        u, v: ``(..., 3)`` light and view directions.

    Returns:
        ``f`` with the shape of ``u[..., 0]``; 0 below the horizon.
    """
    rho_d, rho_s = params[0], params[1]
    g = Geometry(u, v)
    return lobe(g, rho_d / jnp.pi) + rho_s * _specular(params[2:], g) / jnp.pi


def _columns(nl, u, v):
    g = Geometry(u, v)
    return jnp.stack([lobe(g, jnp.full_like(g.cu, 1.0 / jnp.pi)), _specular(nl, g) / jnp.pi], -1)


def _guesses():
    rows = []
    for alpha in (0.003, 0.03, 0.3):
        for f0 in (0.05, 0.5):
            rows.append([alpha, 0.45, f0, 0.0, 3.0, 1e-5, 25.0, 0.25])
    return np.asarray(rows)


MODEL = BaselineModel(
    name="sgd",
    param_names=("rho_d", "rho_s", "alpha", "p", "f0", "f1", "lambda", "c", "k", "theta0"),
    transforms=(POSITIVE, POSITIVE, LogBounded(1e-6, 2.0), LogBounded(1e-3, 3.0), REAL, REAL,
                LogBounded(1e-6, 1e6), LogBounded(1e-12, 1e6), LogBounded(1.0, 1000.0), REAL),
    evaluate=sgd,
    n_linear=2,
    columns=_columns,
    guesses=_guesses(),
    sample=uniform_sampler([(1e-4, 1.0, True), (0.05, 1.5, False), (0.01, 1.0, True), (-0.5, 0.5, False),
                            (0.1, 30.0, True), (1e-8, 1e-2, True), (5.0, 100.0, True), (-0.5, 1.0, False)]),
    reference="Bagher, Soler & Holzschuch, CGF 31(4) 2012",
)
