r"""The BRDF solves of :func:`polyjax.fit_capture`, with the normals fixed.

**Per pixel** (:func:`solve_mix`): the pixel's prediction ``max(n . d_l, 0) (rho_c / pi + sum_k m_k g_{k,c}(u_l,
v))`` is linear in its diffuse albedo ``rho (3,)`` and lobe weights ``m (K,)``: a weighted least-squares solve of the
``(3 L, 3 + K)`` design by QR, then the columns of negative coefficients dropped and the solve repeated (an
active-set pass of non-negative least squares, ``K + 1`` rounds), vmapped over the block's pixels; ``rho`` is at most
``pi max_l obs_l / 0.2`` (:data:`MIN_BRIGHTEST_COS`) and ``m_k`` at most ``max_l obs_l / (0.2 max g_k)`` (grey):
no term predicts more than its pixel's brightest value seen at a cosine of 0.2.

**Shared lobes** (:func:`fit_lobes`): each pixel belongs to the lobe of its largest weight; lobe ``k``'s polynomial
BRDF (per channel, Rusinkiewicz ``theta_h, theta_d``, clamped to the fitted box so it stays bounded) is fitted in
closed form by :func:`polyjax.fit_polynomial` to its pixels' specular samples ``(obs / cos - rho / pi) / m_k``
(weights ``w m_k^2``: the same residual as the pixel's own), on a fixed sample of the object's pixels.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .._fit.polynomial import fit_polynomial
from .._model import PolynomialBRDF
from ._normals import local_directions, safe_sqrt, small_lstsq

#: the shared lobes' polynomial: Rusinkiewicz variables (``theta_h``, ``theta_d``; isotropic, frame-free), degree,
#: clamped to the fitted box (bounded under unseen lights); measured in ``benchmarks/bench_capture.py``
LOBE_VARIABLES, LOBE_DEGREE = "rusinkiewicz", 4


def lobe_values(lobes: PolynomialBRDF, u, v):
    """``(K, n, 3)`` values of the lobes (batch ``(K, 3)``) at local directions ``u, v (n, 3)``."""
    return jnp.moveaxis(lobes(u, v), -1, -2)


def pixel_shading(n, directions, lobes: PolynomialBRDF):
    """``(cos (L,), g (K, L, 3))`` of one pixel of unit normal ``n``: ``max(n . d, 0)`` and the lobes there."""
    u, v = local_directions(n, directions)
    return jnp.maximum(u[:, 2], 0.0), lobe_values(lobes, u, v)


def shade(n, rho, mix, directions, lobes: PolynomialBRDF):
    """``(L, 3)`` prediction ``max(n . d, 0) (rho / pi + sum_k m_k g_k)`` of one pixel (over irradiance)."""
    cos, g = pixel_shading(n, directions, lobes)
    return cos[:, None] * (rho / jnp.pi + jnp.einsum("k,klc->lc", mix, g))


#: nodes per axis of the lobes' table in ``(theta_h, theta_d)`` over ``[0, pi/2]^2`` (the fit's inner loops read
#: the table, bilinear; the fitted :class:`CaptureFit` evaluates the polynomials themselves)
TABLE_SIZE = 91


def lobe_table(lobes: PolynomialBRDF, size: int = TABLE_SIZE):
    """``(K, size, size, 3)`` values of the lobes at nodes of ``(theta_h, theta_d)`` (any ``phi_d``: the
    Rusinkiewicz variables do not depend on it)."""
    t = jnp.linspace(0.0, jnp.pi / 2, size)
    th, td = jnp.meshgrid(t, t, indexing="ij")
    th, td = th.reshape(-1), td.reshape(-1)
    zero = jnp.zeros_like(th)
    half_u = jnp.stack([zero, jnp.sin(td), jnp.cos(td)], -1)  # phi_d = 90 degrees, in the half vector's frame
    half_v = jnp.stack([zero, -jnp.sin(td), jnp.cos(td)], -1)

    def tilt(a):  # the half vector tilted by theta_h about y
        return jnp.stack([a[:, 0] * jnp.cos(th) + a[:, 2] * jnp.sin(th), a[:, 1],
                          -a[:, 0] * jnp.sin(th) + a[:, 2] * jnp.cos(th)], -1)

    g = lobe_values(lobes, tilt(half_u), tilt(half_v))  # (K, size^2, 3)
    return g.reshape(g.shape[0], size, size, 3)


def table_shading(n, directions, table):
    """``(cos (L,), g (K, L, 3))`` of one pixel from the lobes' table (bilinear in ``theta_h, theta_d``)."""
    view = jnp.array([0.0, 0.0, 1.0], n.dtype)
    h = directions + view
    h = h / jnp.linalg.norm(h, axis=-1, keepdims=True)
    size = table.shape[1]
    scale = (size - 1) / (jnp.pi / 2)
    x = jnp.clip(jnp.arccos(jnp.clip(h @ n, -1.0, 1.0 - 1e-12)) * scale, 0.0, size - 1.0 - 1e-9)
    y = jnp.clip(jnp.arccos(jnp.clip(jnp.sum(directions * h, -1), -1.0, 1.0 - 1e-12)) * scale, 0.0, size - 1 - 1e-9)
    i, j = jnp.floor(x).astype(int), jnp.floor(y).astype(int)
    fx, fy = (x - i)[None, :, None], (y - j)[None, :, None]
    g = (table[:, i, j] * (1 - fx) * (1 - fy) + table[:, i + 1, j] * fx * (1 - fy)
         + table[:, i, j + 1] * (1 - fx) * fy + table[:, i + 1, j + 1] * fx * fy)
    return jnp.maximum(directions @ n, 0.0), g


def shade_table(n, rho, mix, directions, table):
    """:func:`shade` from the lobes' table."""
    cos, g = table_shading(n, directions, table)
    return cos[:, None] * (rho / jnp.pi + jnp.einsum("k,klc->lc", mix, g))


#: the diffuse albedo is at most what the pixel's brightest value gives at this cosine: a pixel whose normal turns
#: away from every fitted light (a dark pixel on the mask's edge) cannot take an albedo that explodes under new lights
MIN_BRIGHTEST_COS = 0.2


def _mix_pixel(n, obs, w, directions, table):
    """One pixel's ``(rho (3,), mix (K,))`` by the active-set solve of the module notes."""
    cos, g = table_shading(n, directions, table)
    n_l, k = cos.shape[0], g.shape[0]
    diffuse = cos[:, None, None] / jnp.pi * jnp.eye(3, dtype=obs.dtype)[None]  # (L, 3, 3): rows (l, c), cols rho_c
    design = jnp.concatenate([diffuse, cos[:, None, None] * jnp.moveaxis(g, 0, -1)], -1).reshape(3 * n_l, 3 + k)
    sw = safe_sqrt(w.reshape(-1))
    keep = jnp.ones(3 + k, bool)
    x = jnp.zeros(3 + k, obs.dtype)
    for _ in range(k + 1):
        a = design * sw[:, None] * keep[None]
        x = small_lstsq(a, obs.reshape(-1) * sw) * keep
        keep = keep & (x >= 0)
    x = jnp.maximum(x, 0.0)
    bound = jnp.pi * jnp.max(obs, axis=0) / MIN_BRIGHTEST_COS
    peak = jnp.max(jnp.mean(table, -1), axis=(1, 2))  # (K,) each lobe's largest grey value
    lobe_bound = jnp.max(jnp.mean(obs, -1)) / (MIN_BRIGHTEST_COS * jnp.maximum(peak, 1e-12))
    return jnp.minimum(x[:3], bound), jnp.minimum(x[3:], lobe_bound)


def solve_mix(normals, obs, w, directions, table):
    """``(rho (P, 3), mix (P, K))`` of a block of pixels (module notes), vmapped; ``table``: :func:`lobe_table`."""
    return jax.vmap(lambda n, o, wi: _mix_pixel(n, o, wi, directions, table))(normals, obs, w)


def _lobe_samples(normals, obs, w, rho, directions):
    """Local ``u, v (S, L, 3)``, specular samples ``(S, L, 3)`` over ``m``-free units, their usable mask."""
    u, v = jax.vmap(lambda n: local_directions(n, directions))(normals)
    cos = u[..., 2]
    lit = cos > 0.05
    spec = obs / jnp.where(lit, cos, 1.0)[..., None] - rho[:, None, :] / jnp.pi
    return u, v, spec, lit[..., None] & (w > 0)


def fit_lobes(normals, obs, w, rho, mix, directions, degree: int = LOBE_DEGREE) -> PolynomialBRDF:
    """The ``K`` shared lobes (batch ``(K, 3)``) refitted to the sample pixels given (module notes)."""
    k = mix.shape[1]
    u, v, spec, ok = _lobe_samples(normals, obs, w, rho, directions)
    owner = jnp.argmax(mix, axis=1)
    m = jnp.take_along_axis(mix, owner[:, None], 1)[:, 0]
    s, n_l = u.shape[:2]
    lanes = (owner[None, :] == jnp.arange(k)[:, None]) & (m[None, :] > 1e-6)  # (K, S)
    mask = lanes[:, :, None, None] & ok[None]  # (K, S, L, 3)
    values = jnp.broadcast_to(spec[None], mask.shape) / jnp.where(m > 1e-6, m, 1.0)[None, :, None, None]
    weights = jnp.broadcast_to(w[None] * (m**2)[None, :, None, None], mask.shape)

    def to_lanes(a):  # (K, S, L, 3) -> (K, 3, S L)
        return jnp.moveaxis(a.reshape(k, s * n_l, 3), -1, 1)

    mask_l = to_lanes(mask)
    return fit_polynomial(u.reshape(-1, 3), v.reshape(-1, 3), to_lanes(jnp.where(mask, values, 0.0)),
                          LOBE_VARIABLES, degree, weights=to_lanes(weights), mask=mask_l,
                          cutoff_deg=None, interactions=True, clamp=True)


__all__ = ["LOBE_DEGREE", "LOBE_VARIABLES", "MIN_BRIGHTEST_COS", "TABLE_SIZE", "fit_lobes", "lobe_table", "lobe_values",
           "pixel_shading", "shade", "shade_table", "solve_mix", "table_shading"]
