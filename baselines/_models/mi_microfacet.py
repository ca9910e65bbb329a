r"""Mitsuba 3's isotropic microfacet distribution (``include/mitsuba/render/microfacet.h``) and Fresnel terms
(``fresnel.h``), as its ``roughconductor`` and ``roughplastic`` plugins evaluate them, in JAX:

- :func:`ndf`: ``MicrofacetDistribution::eval``, GGX ``1 / (pi a^2 (x^2/a^2 + y^2/a^2 + z^2)^2)`` or Beckmann
  ``exp(-tan^2(theta) / a^2) / (pi a^2 cos^4(theta))``, 0 where ``D cos(theta) <= 1e-20``;
- :func:`smith_g1`: ``smith_g1``, GGX ``2 / (1 + sqrt(1 + a^2 tan^2))``, Beckmann Mitsuba's rational fit
  ``(3.535 b + 2.181 b^2) / (1 + 2.276 b + 2.577 b^2)`` of ``b = 1 / (a tan)`` (1 for ``b >= 1.6``);
- :func:`fresnel_dielectric` and :func:`fresnel_conductor`: ``fresnel`` and ``fresnel_conductor``;
- :func:`eval_reflectance` and :func:`eval_transmittance`: the GGX rough interface's albedo and transmittance at
  ``cos(theta_i) = mu``, by the same quadrature Mitsuba uses (Gauss-Legendre in the unit square, 32 x 32 nodes for
  ``eta > 1`` and 128 x 128 otherwise, mapped to microfacet normals by visible-normal sampling ``sample`` with
  ``sample_visible_11``), so that ``roughplastic``'s tables are Mitsuba's (to rounding: Mitsuba computes them in
  float32).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from .._implicit import safe_sqrt as _sqrt0


def ndf(ch, a, beckmann: bool):
    """``D(m)`` at ``cos(theta_m) = ch`` (isotropic ``alpha = a``)."""
    c2 = ch * ch
    if beckmann:
        d = jnp.exp(-(1.0 - c2) / (a * a * jnp.where(c2 > 0, c2, 1.0))) / (jnp.pi * a * a * c2 * c2)
    else:
        d = 1.0 / (jnp.pi * a * a * ((1.0 - c2) / (a * a) + c2) ** 2)
    return jnp.where(d * ch > 1e-20, d, 0.0)


def smith_g1(w, m, a, beckmann: bool):
    """Smith's ``G_1(w, m)`` (0 where ``w`` sees the back of ``m``)."""
    xy = a * a * (w[..., 0] ** 2 + w[..., 1] ** 2)
    z2 = w[..., 2] ** 2
    t2 = xy / jnp.where(z2 > 0, z2, 1.0)
    if beckmann:
        b = 1.0 / jnp.sqrt(jnp.where(t2 > 0, t2, 1.0))
        g = jnp.where(b >= 1.6, 1.0, (3.535 * b + 2.181 * b * b) / (1.0 + 2.276 * b + 2.577 * b * b))
    else:
        g = 2.0 / (1.0 + jnp.sqrt(1.0 + t2))
    g = jnp.where(xy == 0, 1.0, g)
    return jnp.where(jnp.sum(w * m, -1) * w[..., 2] <= 0, 0.0, g)


def fresnel_dielectric(cos_i, eta):
    """``fresnel(cos_i, eta) -> (F, cos_t, eta_it, eta_ti)`` (unpolarised; 1 under total internal reflection)."""
    outside = cos_i >= 0
    eta_it, eta_ti = jnp.where(outside, eta, 1.0 / eta), jnp.where(outside, 1.0 / eta, eta)
    ct2 = 1.0 - (1.0 - cos_i * cos_i) * eta_ti * eta_ti
    ci, ct = jnp.abs(cos_i), _sqrt0(ct2)
    a_s = (ci - eta_it * ct) / (ci + eta_it * ct)
    a_p = (ct - eta_it * ci) / (ct + eta_it * ci)
    r = jnp.where(ci == 0, 1.0, 0.5 * (a_s * a_s + a_p * a_p))
    return r, jnp.where(cos_i >= 0, -ct, ct), eta_it, eta_ti


def fresnel_conductor(cos_i, eta, k):
    """Unpolarised reflectance of a conductor of complex index ``eta + i k`` (Moeller's form, as Mitsuba)."""
    c2 = cos_i * cos_i
    s2 = 1.0 - c2
    t1 = eta * eta - k * k - s2
    ab = _sqrt0(t1 * t1 + 4.0 * k * k * eta * eta)
    a = _sqrt0(0.5 * (ab + t1))
    t2 = 2.0 * cos_i * a
    rs = (ab + c2 - t2) / (ab + c2 + t2)
    t3, t4 = ab * c2 + s2 * s2, t2 * s2
    return 0.5 * (rs + rs * (t3 - t4) / (t3 + t4))


def _visible_slope(cos_i, s):
    """GGX's ``sample_visible_11(cos_i, s)``: a slope of the visible normals of the ``alpha = 1`` distribution."""
    x, y = 2.0 * s[..., 0] - 1.0, 2.0 * s[..., 1] - 1.0  # square_to_uniform_disk_concentric
    q13 = jnp.abs(x) < jnp.abs(y)
    r, rp = jnp.where(q13, y, x), jnp.where(q13, x, y)
    phi = 0.25 * jnp.pi * rp / jnp.where(r == 0, 1.0, r)
    phi = jnp.where((x == 0) & (y == 0), 0.0, jnp.where(q13, 0.5 * jnp.pi - phi, phi))
    px, py = r * jnp.cos(phi), r * jnp.sin(phi)
    py = py + (_sqrt0(1.0 - px * px) - py) * (1.0 - 0.5 * (1.0 + cos_i))
    z = _sqrt0(1.0 - px * px - py * py)
    sin_i = _sqrt0(1.0 - cos_i * cos_i)
    norm = 1.0 / (sin_i * py + cos_i * z)
    return (cos_i * py - sin_i * z) * norm, px * norm


def _visible_normal(wi, s, a):
    """GGX's ``sample(wi, s)`` for ``wi`` in the ``xz`` half-plane ``x >= 0`` (``phi = 0``): the microfacet
    normal."""
    st = jnp.stack([a * wi[0], a * wi[1], wi[2]])
    st = st / jnp.linalg.norm(st)
    sx, sy = _visible_slope(st[2], s)
    m = jnp.stack([-sx * a, -sy * a, jnp.ones_like(sx)], -1)
    return m / jnp.linalg.norm(m, axis=-1, keepdims=True)


@functools.cache
def _nodes(res: int):
    """Gauss-Legendre nodes mapped to the unit square ``(res^2, 2)`` and their weights ``(res^2,)`` (row-major
    ``meshgrid`` order, as Mitsuba's ``dr::meshgrid``)."""
    x, w = np.polynomial.legendre.leggauss(res)
    nx, ny = np.meshgrid(x, x)
    wx, wy = np.meshgrid(w, w)
    return np.stack([nx.ravel(), ny.ravel()], -1) * 0.5 + 0.5, (wx * wy).ravel()


def _quadrature(mu, a, eta, transmit: bool, res: int):
    nodes, weights = _nodes(res)
    nodes, weights = jnp.asarray(nodes, mu.dtype), jnp.asarray(weights, mu.dtype)

    def one(m_cos):
        wi = jnp.stack([jnp.sqrt(1.0 - m_cos * m_cos), jnp.zeros_like(m_cos), m_cos])
        m = _visible_normal(wi, nodes, a)
        dot = m @ wi
        f, cos_t, _, eta_ti = fresnel_dielectric(dot, eta)
        if transmit:
            wo = m * (dot * eta_ti + cos_t)[:, None] - wi * eta_ti[:, None]
            val = jnp.where(wo[:, 2] * wi[2] >= 0, 0.0, smith_g1(wo, m, a, False) * (1.0 - f))
        else:
            wo = 2.0 * dot[:, None] * m - wi
            val = jnp.where((wo[:, 2] <= 0) | (wi[2] <= 0), 0.0, smith_g1(wo, m, a, False) * f)
        return 0.25 * jnp.sum(val * weights)

    return jax.vmap(one)(mu)


def eval_reflectance(mu, a, eta, res: int):
    """Mitsuba's ``eval_reflectance(distr, wi, eta)`` at ``wi = (sqrt(1 - mu^2), 0, mu)``, ``mu (k,)``; ``res``
    nodes per axis, Mitsuba's ``32 if eta > 1 else 128`` (static: the caller knows which side ``eta`` is on)."""
    return _quadrature(mu, a, eta, False, res)


def eval_transmittance(mu, a, eta, res: int):
    """Mitsuba's ``eval_transmittance(distr, wi, eta)`` at ``wi = (sqrt(1 - mu^2), 0, mu)`` (``res`` as in
    :func:`eval_reflectance`)."""
    return _quadrature(mu, a, eta, True, res)
