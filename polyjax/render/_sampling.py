r"""Importance sampling of any BRDF: tabulated ``max(f, 0) cos`` per view elevation, mixed with cosine sampling.

Strategy (works for every BRDF polyjax evaluates: polynomial fits that go negative or have no analytic
lobe, baselines, neural and tabulated data):

1. **Hemisphere grid.** The upper hemisphere is the image of the unit square under the area-preserving
   map ``M`` (Shirley-Chiu concentric square-to-disk, then disk-to-hemisphere ``z = 1 - r^2``,
   ``(x, y) *= sqrt(2 - r^2)``; the same map as Mitsuba 3's ``warp.square_to_uniform_hemisphere``). Its
   Jacobian is constant, ``d omega = (pi / 2) dA`` on ``[-1, 1]^2``, i.e. ``2 pi`` per unit area of
   ``[0, 1]^2``, so an ``N x N`` grid of the square gives ``N^2`` cells of equal solid angle
   ``2 pi / N^2`` and well-shaped everywhere (no pole singularity).
2. **Tables.** For view elevations ``theta_j = j theta_max / (n_v - 1)`` (view ``(sin theta_j, 0,
   cos theta_j)``), cell ``c`` gets ``g_jc = mean over S x S points of the cell of
   mean_RGB(max(f(u, v_j), 0)) cos theta_u``; ``p_jc = g_jc / sum_c g_jc`` (a uniform table when the sum is
   0 or not finite; non-finite values count as 0).
3. **Sampling for a view ``v``** (``theta_v``, azimuth ``phi_v``): with probability ``alpha`` draw ``u``
   cosine-weighted; otherwise pick node ``j`` or ``j + 1`` (``theta_v`` between them, with probabilities
   ``1 - t`` and ``t``, ``t`` the linear position), a cell with probability ``p_jc`` and a uniform point in
   it, mapped by ``M`` and rotated by ``phi_v`` about the normal. The density is

   .. math::
       \mathrm{pdf}(u \mid v) = \alpha \frac{\cos^+\theta_u}{\pi}
           + (1 - \alpha) \frac{N^2}{2\pi}\big[(1 - t)\, p_{j, c(u')} + t\, p_{j+1, c(u')}\big],

   ``u' = R_z(-phi_v) u`` and ``c(u')`` the cell of ``M^{-1}(u')``; 0 below the horizon.

**Why it is unbiased.** A Monte Carlo estimate ``f(u, v) L(u) cos / pdf(u | v)`` is unbiased whenever
``pdf > 0`` wherever the integrand is non-zero, and ``pdf`` is the density the samples are actually drawn
from. The cosine term makes ``pdf >= alpha cos theta_u / pi > 0`` on the whole open upper hemisphere, so
negative lobes, lobes narrower than a cell, regions the grid missed and anisotropy the
azimuthal rotation ignores cost variance, never bias; and :meth:`ImportanceSampler.pdf` evaluates exactly
the mixture :meth:`ImportanceSampler.warp` draws from (checked by chi-square tests). Isotropic BRDFs
(``f`` invariant under a common rotation of ``u`` and ``v`` about the normal) are matched best; for
anisotropic ones the tables are those of view azimuth 0, still unbiased.

The tables are built under ``stop_gradient``: the density is a sampling choice, so gradients of a render
w.r.t. BRDF parameters flow through ``f`` only (the expectation does not depend on the density), and
:meth:`warp` / :meth:`pdf` are differentiable w.r.t. ``u`` and ``v``.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, PRNGKeyArray

from .._errors import InputError
from ._brdf import evaluate_rgb, rgb_brdf

_QUARTER_PI = 0.25 * np.pi


# --------------------------------------------------------------------------- the area-preserving map


def square_to_hemisphere(s: Float[Array, "... 2"]) -> Float[Array, "... 3"]:
    """The map ``M``: ``[0, 1]^2`` to the upper hemisphere, area-preserving (``d omega = 2 pi dA``)."""
    x = 2.0 * s[..., 0] - 1.0
    y = 2.0 * s[..., 1] - 1.0
    q13 = jnp.abs(x) < jnp.abs(y)
    r = jnp.where(q13, y, x)
    rp = jnp.where(q13, x, y)
    safe_r = jnp.where(r == 0, 1.0, r)
    phi = _QUARTER_PI * rp / safe_r
    phi = jnp.where(q13, 0.5 * jnp.pi - phi, phi)
    phi = jnp.where(r == 0, 0.0, phi)
    dx, dy = r * jnp.cos(phi), r * jnp.sin(phi)
    r2 = dx * dx + dy * dy
    z = 1.0 - r2
    scale = jnp.sqrt(jnp.maximum(2.0 - r2, 0.0))
    return jnp.stack([dx * scale, dy * scale, z], axis=-1)


def hemisphere_to_square(w: Float[Array, "... 3"]) -> Float[Array, "... 2"]:
    """The inverse of :func:`square_to_hemisphere` for ``w_z >= 0`` (unit vectors)."""
    z = jnp.clip(w[..., 2], 0.0, 1.0)
    inv = 1.0 / jnp.sqrt(1.0 + z)
    px, py = w[..., 0] * inv, w[..., 1] * inv
    q02 = jnp.abs(px) > jnp.abs(py)
    r_sign = jnp.where(q02, px, py)
    sgn = jnp.where(r_sign < 0, -1.0, 1.0)
    nrm2 = px * px + py * py
    nrm = jnp.sqrt(jnp.where(nrm2 > 0, nrm2, 1.0)) * (nrm2 > 0)
    r = nrm * sgn
    phi = jnp.arctan2(py * sgn, px * sgn)
    t = 4.0 / jnp.pi * phi
    t = jnp.where(q02, t, 2.0 - t) * r
    a = jnp.where(q02, r, t)
    b = jnp.where(q02, t, r)
    return jnp.stack([(a + 1.0) * 0.5, (b + 1.0) * 0.5], axis=-1)


def _rotate_z(w, c, s):
    """Rotate ``w`` about ``+z`` by the angle with cosine ``c`` and sine ``s``."""
    return jnp.stack([c * w[..., 0] - s * w[..., 1], s * w[..., 0] + c * w[..., 1], w[..., 2]], axis=-1)


def _azimuth(v):
    """``(cos phi_v, sin phi_v)`` of view directions (``(1, 0)`` at the normal), gradient-safe."""
    r2 = v[..., 0] ** 2 + v[..., 1] ** 2
    ok = r2 > 1e-30
    r = jnp.sqrt(jnp.where(ok, r2, 1.0))
    return jnp.where(ok, v[..., 0] / r, 1.0), jnp.where(ok, v[..., 1] / r, 0.0)


def cosine_pdf(u: Float[Array, "... 3"]) -> Float[Array, "..."]:
    """Density of cosine-weighted hemisphere sampling, ``max(cos theta_u, 0) / pi``."""
    return jnp.maximum(u[..., 2], 0.0) / jnp.pi


def cosine_sample(xi: Float[Array, "... 2"]) -> Float[Array, "... 3"]:
    """Cosine-weighted directions (Malley's method on :func:`square_to_hemisphere`'s disk)."""
    h = square_to_hemisphere(xi)
    # the disk point of M is h_xy / sqrt(1 + h_z); lift it with z = sqrt(1 - r^2)
    d = h[..., :2] / jnp.sqrt(1.0 + h[..., 2:3])
    z = jnp.sqrt(jnp.maximum(1.0 - jnp.sum(d * d, axis=-1), 0.0))
    return jnp.concatenate([d, z[..., None]], axis=-1)


# --------------------------------------------------------------------------- the sampler


class ImportanceSampler(eqx.Module):
    """Tabulated importance sampler of one BRDF (module docstring: strategy and unbiasedness).

    Build with :func:`importance_sampler`. ``u, pdf = s.sample(key, v, n)`` draws ``n`` light directions
    for a view ``v``; ``s.pdf(u, v)`` is their density (solid angle); ``s.warp(xi, v)`` maps uniforms
    ``xi (..., 5)`` to directions, broadcasting over ``v``. All are jittable and vmappable.

    Attributes:
        pmf: ``(n_v, N^2)`` cell probabilities per view node (row-major: cell ``iy N + ix``).
        cdf: ``(n_v, N^2)`` their running sums (last entry 1).
        theta_max: elevation of the last view node (radians); views beyond use its table.
        alpha: probability of the cosine-weighted component.
        resolution: ``N``.
    """

    pmf: Float[Array, "nv cells"]
    cdf: Float[Array, "nv cells"]
    theta_max: float = eqx.field(static=True)
    alpha: float = eqx.field(static=True)
    resolution: int = eqx.field(static=True)

    @property
    def n_views(self) -> int:
        return int(self.pmf.shape[0])

    def _node(self, v):
        """Lower view node ``j`` and the weight ``t`` of node ``j + 1`` for views ``v``."""
        nv = self.n_views
        theta = jnp.arccos(jnp.clip(v[..., 2], -1.0, 1.0))
        s = jnp.clip(theta / self.theta_max, 0.0, 1.0) * (nv - 1)
        j = jnp.clip(jnp.floor(s), 0, max(nv - 2, 0)).astype(jnp.int32)
        t = jnp.clip(s - j, 0.0, 1.0) if nv > 1 else jnp.zeros_like(s)
        return j, t

    def _table_pdf(self, u_local, j, t):
        """Tabulated density (solid angle) of local directions ``u_local`` at node ``j`` blended with ``j + 1``."""
        n = self.resolution
        sq = hemisphere_to_square(u_local)
        ix = jnp.clip(jnp.floor(sq[..., 0] * n), 0, n - 1).astype(jnp.int32)
        iy = jnp.clip(jnp.floor(sq[..., 1] * n), 0, n - 1).astype(jnp.int32)
        c = iy * n + ix
        pmf = jax.lax.stop_gradient(self.pmf).astype(u_local.dtype)
        j1 = jnp.minimum(j + 1, self.n_views - 1)
        p = (1.0 - t) * pmf[j, c] + t * pmf[j1, c]
        return p * (n * n / (2.0 * jnp.pi))

    def pdf(self, u: Float[ArrayLike, "... 3"], v: Float[ArrayLike, "... 3"]) -> Float[Array, "..."]:
        """Solid-angle density of :meth:`warp`'s directions ``u`` for views ``v`` (0 below the horizon)."""
        u, v = jnp.broadcast_arrays(jnp.asarray(u), jnp.asarray(v))
        c, s = _azimuth(v)
        ul = _rotate_z(u, c, -s)
        j, t = self._node(v)
        tab = self._table_pdf(ul, j, t)
        p = self.alpha * cosine_pdf(u) + (1.0 - self.alpha) * tab
        return jnp.where(u[..., 2] > 0, p, 0.0)

    def warp(self, xi: Float[ArrayLike, "... 5"], v: Float[ArrayLike, "... 3"]
             ) -> tuple[Float[Array, "... 3"], Float[Array, "..."]]:
        """Map uniforms ``xi`` in ``[0, 1)^5`` to light directions for views ``v``.

        ``xi[0]`` picks the component (cosine if ``< alpha``), ``xi[1]`` the view node, ``xi[2]`` the
        cell, ``xi[3:5]`` the point in the cell (or the cosine sample).

        Returns:
            ``(u, pdf)``: ``(..., 3)`` unit directions and their density :meth:`pdf`.
        """
        xi = jnp.asarray(xi)
        v = jnp.asarray(v, xi.dtype)
        shape = jnp.broadcast_shapes(xi.shape[:-1], v.shape[:-1])
        xi = jnp.broadcast_to(xi, shape + (5,))
        v = jnp.broadcast_to(v, shape + (3,))
        n = self.resolution
        j, t = self._node(v)
        jj = jnp.where(xi[..., 1] < t, jnp.minimum(j + 1, self.n_views - 1), j)
        # row j of the stacked table holds j + cdf_j, in (j, j + 1]: one search over all rows
        cdf = jax.lax.stop_gradient(self.cdf).astype(xi.dtype)
        stacked = (cdf + jnp.arange(self.n_views, dtype=xi.dtype)[:, None]).reshape(-1)
        flat = jnp.searchsorted(stacked, jj.astype(xi.dtype) + xi[..., 2], side="right")
        cell = jnp.clip(flat - jj * (n * n), 0, n * n - 1)
        sq = jnp.stack([(cell % n + xi[..., 3]) / n, (cell // n + xi[..., 4]) / n], axis=-1)
        c, s = _azimuth(v)
        u_tab = _rotate_z(square_to_hemisphere(sq), c, s)
        u_cos = cosine_sample(xi[..., 3:5])
        u = jnp.where((xi[..., 0] < self.alpha)[..., None], u_cos, u_tab)
        return u, self.pdf(u, v)

    def sample(self, key: PRNGKeyArray, v: Float[ArrayLike, "3"], n: int
               ) -> tuple[Float[Array, "n 3"], Float[Array, " n"]]:
        """Draw ``n`` light directions for one view ``v`` (``(3,)``): ``(u (n, 3), pdf (n,))``, compiled once per
        ``n`` and dtype."""
        v = jnp.asarray(v)
        dtype = v.dtype if jnp.issubdtype(v.dtype, jnp.floating) else jnp.dtype(jnp.result_type(float))
        return _sample(self, key, v.astype(dtype), int(n))


@eqx.filter_jit
def _sample(sampler, key, v, n):
    return sampler.warp(jax.random.uniform(key, (n, 5), v.dtype), v)


@eqx.filter_jit
def _tables(brdf, theta_max, n_views, resolution, supersample, dtype):
    n, s = resolution, supersample
    sub = (jnp.arange(s, dtype=dtype) + 0.5) / s
    cells = jnp.arange(n, dtype=dtype)
    gx = (cells[:, None] + sub[None, :]).reshape(-1) / n  # (n s,)
    X, Y = jnp.meshgrid(gx, gx)  # rows: y
    u = square_to_hemisphere(jnp.stack([X, Y], -1))  # (n s, n s, 3)
    thetas = jnp.linspace(0.0, theta_max, n_views, dtype=dtype) if n_views > 1 else jnp.zeros((1,), dtype)
    views = jnp.stack([jnp.sin(thetas), jnp.zeros_like(thetas), jnp.cos(thetas)], -1)

    def one(v):
        f = evaluate_rgb(brdf, u, jnp.broadcast_to(v, u.shape))
        f = jnp.where(jnp.isfinite(f), jnp.maximum(f, 0.0), 0.0)
        g = jnp.mean(f, axis=-1) * jnp.maximum(u[..., 2], 0.0)
        g = g.reshape(n, s, n, s).mean(axis=(1, 3)).reshape(-1)
        total = jnp.sum(g)
        good = jnp.isfinite(total) & (total > 0)
        pmf = jnp.where(good, g / jnp.where(good, total, 1.0), 1.0 / (n * n))
        cdf = jnp.cumsum(pmf)
        return pmf, cdf.at[-1].set(1.0)

    pmf, cdf = jax.lax.map(one, views)
    return jax.lax.stop_gradient(pmf), jax.lax.stop_gradient(cdf)


def importance_sampler(brdf, *, resolution: int = 64, n_views: int = 16, theta_max_deg: float = 88.0,
                       alpha: float = 0.1, supersample: int = 2, dtype=None) -> ImportanceSampler:
    """Build the :class:`ImportanceSampler` of any BRDF polyjax evaluates.

    Args:
        brdf: a :class:`polyjax.PolynomialBRDF` (batch shape ``()``, ``(1,)`` or ``(3,)``) or any callable
            ``f(u, v) -> (..., 3)`` or ``(...)`` (baselines via a closure, ``NeuralBRDF``, ``TabulatedBRDF``).
        resolution: ``N``, cells per side of the square (``N^2`` cells of ``2 pi / N^2`` sr).
        n_views: view-elevation nodes from 0 to ``theta_max_deg``.
        theta_max_deg: elevation of the last node (views beyond use it), in ``(0, 90)``.
        alpha: probability of cosine sampling, in ``(0, 1]``; keeps ``pdf > 0`` wherever ``cos theta_u > 0``.
        supersample: ``S``, points per cell side averaged into each table entry.
        dtype: table dtype (default: JAX's default float).

    Returns:
        The sampler; building it costs ``n_views (N S)^2`` BRDF evaluations.
    """
    if int(resolution) < 1 or int(n_views) < 1 or int(supersample) < 1:
        raise InputError(f"resolution, n_views, supersample: expected positive integers, found {resolution}, "
                         f"{n_views}, {supersample}")
    if not 0.0 < float(alpha) <= 1.0:
        raise InputError(f"alpha: expected a cosine-sampling probability in (0, 1], found {alpha}")
    if not 0.0 < float(theta_max_deg) < 90.0:
        raise InputError(f"theta_max_deg: expected an elevation in (0, 90) degrees, found {theta_max_deg}")
    brdf = rgb_brdf(brdf)
    dtype = jnp.dtype(dtype) if dtype is not None else jnp.dtype(jnp.result_type(float))
    theta_max = float(np.deg2rad(theta_max_deg))
    pmf, cdf = _tables(brdf, theta_max, int(n_views), int(resolution), int(supersample), dtype)
    return ImportanceSampler(pmf, cdf, theta_max, float(alpha), int(resolution))


__all__ = ["ImportanceSampler", "cosine_pdf", "cosine_sample", "hemisphere_to_square", "importance_sampler",
           "square_to_hemisphere"]
