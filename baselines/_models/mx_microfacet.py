r"""The BSDF pieces of MaterialX 1.39's physically based shading library (``libraries/pbrlib``), as its GLSL code
generator writes them (``pbrlib/genglsl/lib/mx_microfacet*.glsl``), in JAX: the closures OpenPBR Surface is built of
(:mod:`baselines._models.openpbr`).

Each function names the GLSL function it follows. Cosines are clamped to ``[M_FLOAT_EPS, 1]`` as the GLSL does
(``M_FLOAT_EPS = 1e-8``); square roots that the GLSL takes of values that may reach 0 (``sin`` at normal incidence)
take a floor of ``1e-30`` instead, so that derivatives stay finite (the values differ by less than ``1e-15``).
Directional albedos use the analytic fits (``DIRECTIONAL_ALBEDO_METHOD 0``, the GLSL generator's default).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

#: ``M_FLOAT_EPS`` of MaterialX's ``stdlib/genglsl/lib/mx_math.glsl``.
EPS = 1e-8
_FUJII_1 = 0.5 - 2.0 / (3.0 * np.pi)
_FUJII_2 = 2.0 / 3.0 - 28.0 / (15.0 * np.pi)

# Rows of the rational fit of GGX directional albedo (mx_ggx_dir_albedo_analytic): the coefficients of
# 1, x, y, x y, x^2, y^2, x^2 y, x y^2, x^2 y^2 for the four components r.x, r.y, r.z, r.w.
_ALBEDO_FIT = np.array([
    [0.1003, 0.9345, 1.0, 1.0], [-0.6303, -2.323, -1.765, 0.2281], [9.748, 2.229, 8.263, 15.94],
    [-2.038, -3.748, 11.53, -55.83], [29.34, 1.424, 28.96, 13.08], [-8.245, -0.7684, -7.507, 41.26],
    [-26.44, 1.436, -36.11, 54.9], [19.99, 0.2913, 15.86, 300.2], [-5.448, 0.6286, 33.37, -285.1],
])


def clamp_cos(c):
    """``clamp(c, M_FLOAT_EPS, 1)``, the GLSL's clamp of every cosine."""
    return jnp.clip(c, EPS, 1.0)


def ggx_ndf(h, ax, ay):
    r"""``mx_ggx_NDF``: anisotropic GGX, :math:`D = 1 / (\pi a_x a_y ((h_x/a_x)^2 + (h_y/a_y)^2 + h_z^2)^2)`
    with the half vector ``h`` in the tangent frame (``x`` the tangent) and ``a`` clamped to ``[eps, 1]``."""
    d = (h[..., 0] / ax) ** 2 + (h[..., 1] / ay) ** 2 + h[..., 2] ** 2
    return 1.0 / (np.pi * ax * ay * d * d)


def smith_g2_over_4(nl, nv, alpha):
    r"""``mx_ggx_smith_G2(NdotL, NdotV, alpha) / (4 NdotL NdotV)``: the height-correlated Smith masking-shadowing
    (Heitz 2014, eqs. 72 and 99) divided by the microfacet denominator,
    :math:`1 / (2 (\lambda_L n\cdot v + \lambda_V n\cdot l))`, :math:`\lambda = \sqrt{a^2 + (1 - a^2) c^2}`."""
    a2 = alpha * alpha
    lam_l = jnp.sqrt(a2 + (1.0 - a2) * nl * nl)
    lam_v = jnp.sqrt(a2 + (1.0 - a2) * nv * nv)
    return 0.5 / (lam_l * nv + lam_v * nl)


def ggx_dir_albedo(nv, alpha, f0, f90):
    """``mx_ggx_dir_albedo_analytic``: the rational fit of GGX's directional albedo, ``F0 A + F90 B``."""
    x, y = nv, alpha
    terms = (jnp.ones_like(x * y), x, y, x * y, x * x, y * y, x * x * y, x * y * y, x * x * y * y)
    r = [sum(t * _ALBEDO_FIT[i, k] for i, t in enumerate(terms)) for k in range(4)]
    a = jnp.clip(r[0] / r[2], 0.0, 1.0)
    b = jnp.clip(r[1] / r[3], 0.0, 1.0)
    return f0 * a + f90 * b


def energy_compensation(nv, alpha, f):
    """``mx_ggx_energy_compensation``: Turquin's multiple-scattering factor ``1 + F (1 - Ess) / Ess``."""
    ess = ggx_dir_albedo(nv, alpha, 1.0, 1.0)
    return 1.0 + f * (1.0 - ess) / ess


def ior_to_f0(ior):
    """``mx_ior_to_f0``: ``((ior - 1) / (ior + 1))^2``."""
    return ((ior - 1.0) / (ior + 1.0)) ** 2


def fresnel_dielectric(c, ior):
    """``mx_fresnel_dielectric``: the unpolarised Fresnel reflectance of a dielectric of relative IOR ``ior`` at
    incidence cosine ``c`` (1 under total internal reflection)."""
    g2 = ior * ior + c * c - 1.0
    g = jnp.sqrt(jnp.maximum(g2, 1e-30))
    f = 0.5 * ((g - c) / (g + c)) ** 2 * (1.0 + (((g + c) * c - 1.0) / ((g - c) * c + 1.0)) ** 2)
    return jnp.where(g2 < 0.0, 1.0, f)


def fresnel_f82(c, f0, f82, f90=1.0, exponent=5.0):
    r"""``mx_fresnel_hoffman_schlick``: Hoffman's generalised Schlick with the F82 tint (``color82``), the
    conductor Fresnel of OpenPBR:

    .. math:: F = \mathrm{mix}(F_0, F_{90}, (1 - x)^e) - a\, x (1 - x)^6, \quad
              a = \mathrm{mix}(F_0, F_{90}, (1 - \bar\mu)^e) (1 - F_{82}) / (\bar\mu (1 - \bar\mu)^6),
              \quad \bar\mu = 1/7 .
    """
    mu = 1.0 / 7.0
    factor = 1.0 / (mu * (1.0 - mu) ** 6)
    x = jnp.clip(c, 0.0, 1.0)
    a = (f0 + (f90 - f0) * (1.0 - mu) ** exponent) * (1.0 - f82) * factor
    return f0 + (f90 - f0) * (1.0 - x) ** exponent - a * x * (1.0 - x) ** 6


def _fujii_dir_albedo(c, r):
    """``mx_oren_nayar_fujii_diffuse_dir_albedo`` (``acos c`` as ``atan2(sin, cos)``)."""
    a = 1.0 / (1.0 + _FUJII_1 * r)
    si = jnp.sqrt(jnp.maximum(1.0 - c * c, 1e-30))
    g = si * (jnp.arctan2(si, c) - si * c) + 2.0 * ((si / c) * (1.0 - si**3) - si) / 3.0
    return a + r * a * g / np.pi


def eon_diffuse(nv, nl, lv, r, color):
    """``mx_oren_nayar_compensated_diffuse``: OpenPBR's energy-conserving Oren-Nayar (EON, Fujii's single-scatter
    lobe plus the multiple-scatter lobe), without the ``1 / pi``: the BRDF is this over pi.

    Args:
        nv, nl: clamped cosines of view and light; lv: ``clamp(l . v, eps, 1)``; r: ``base_diffuse_roughness``;
        color: the albedo (one channel).
    """
    s = lv - nl * nv
    stinv = jnp.where(s > 0.0, s / jnp.maximum(nl, nv), s)
    a = 1.0 / (1.0 + _FUJII_1 * r)
    single = color * a * (1.0 + r * stinv)
    e_v, e_l = _fujii_dir_albedo(nv, r), _fujii_dir_albedo(nl, r)
    e_avg = a * (1.0 + _FUJII_2 * r)
    c_ms = color * color * e_avg / (1.0 - color * jnp.maximum(0.0, 1.0 - e_avg))
    multi = c_ms * jnp.maximum(EPS, 1.0 - e_v) * jnp.maximum(EPS, 1.0 - e_l) / jnp.maximum(EPS, 1.0 - e_avg)
    return single + multi
