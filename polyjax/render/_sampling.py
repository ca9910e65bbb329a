r"""Importance sampling of any BRDF: a bilinear table of ``max(f, 0) cos`` per view elevation, sampled exactly,
mixed with cosine sampling.

Strategy (works for every BRDF polyjax evaluates: polynomial fits that go negative or have no analytic
lobe, baselines, neural and tabulated data):

1. **Hemisphere map.** The upper hemisphere is the image of the unit square under the area-preserving
   map ``M`` (Shirley-Chiu concentric square-to-disk, then disk-to-hemisphere ``z = 1 - r^2``,
   ``(x, y) *= sqrt(2 - r^2)``; the same map as Mitsuba 3's ``warp.square_to_uniform_hemisphere``). Its
   Jacobian is constant, ``d omega = 2 pi dA`` on ``[0, 1]^2``, so a density ``q`` on the square is the
   solid-angle density ``q / (2 pi)``, and ``M`` is continuous, so a continuous ``q`` gives a continuous
   density on the hemisphere.
2. **Tables.** For view elevations ``theta_j = j theta_max / (n_v - 1)`` (view ``(sin theta_j, 0,
   cos theta_j)``), the ``(N + 1)^2`` nodes ``(a / N, b / N)`` of an ``N x N`` grid of the square get
   ``g_jab = mean_RGB(max(f(u, v_j), 0)) cos theta_u`` averaged over ``S x S`` points of the node's cell-sized
   neighbourhood (non-finite values count as 0). ``q_j`` is the bilinear interpolant of ``g_j``, divided by its
   integral (the trapezoid sum, exact for a bilinear function): a continuous, piecewise-bilinear density on
   the square (uniform when the integral is 0 or not finite).
3. **Exact sampling of ``q_j``** (inversion, no rejection): the marginal of ``y`` is piecewise linear
   (``R_a = int q_j(x, y_a) dx`` at the row nodes, linear in between), so its CDF is piecewise quadratic: a
   binary search picks the row interval, a quadratic solve the point in it. Given ``y`` (a fraction ``s``
   into row interval ``a``), the conditional of ``x`` is piecewise linear with node values
   ``(1 - s) q_{a,b} + s q_{a+1,b}``, its CDF the same blend of the two rows' prefix sums: again a binary
   search and a quadratic solve.
4. **Sampling for a view ``v``** (``theta_v``, azimuth ``phi_v``): with probability ``alpha`` draw ``u``
   cosine-weighted; otherwise pick node ``j`` or ``j + 1`` (``theta_v`` between them, with probabilities
   ``1 - t`` and ``t``, ``t`` the linear position), draw a point of the square from ``q_j``, map it by ``M``
   and rotate it by ``phi_v`` about the normal. The density is

   .. math::
       \mathrm{pdf}(u \mid v) = \alpha \frac{\cos^+\theta_u}{\pi}
           + \frac{1 - \alpha}{2\pi}\big[(1 - t)\, q_j(M^{-1}(u')) + t\, q_{j+1}(M^{-1}(u'))\big],

   ``u' = R_z(-phi_v) u``; 0 below the horizon. It is continuous in ``u`` (the mixture of continuous
   densities), so histogram tests that integrate it numerically (Mitsuba's ``ChiSquareTest``, trapezoids in
   float32) see no jumps at cell edges.

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
from .._solve.threads import one_lapack_thread
from ._brdf import evaluate_rgb, rgb_brdf

_QUARTER_PI = 0.25 * np.pi


# --------------------------------------------------------------------------- the area-preserving map


@jax.jit
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


@jax.jit
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


# --------------------------------------------------------------------------- exact sampling of a bilinear table


def _last_at_most(value_at, n: int, x):
    """Per lane, the largest ``i`` in ``[0, n - 1]`` with ``value_at(i) <= x``, for ``value_at`` non-decreasing
    with ``value_at(0) <= x``: a branch-free binary search of ``ceil(log2 n)`` steps."""
    lo = jnp.zeros(jnp.shape(x), jnp.int32)
    hi = jnp.full(jnp.shape(x), n, jnp.int32)
    for _ in range(int(np.ceil(np.log2(max(n, 1))))):
        mid = (lo + hi) // 2
        go = value_at(mid) <= x
        lo = jnp.where(go, mid, lo)
        hi = jnp.where(go, hi, mid)
    return lo


def _invert_linear(d0, d1, t):
    """The ``s`` in ``[0, 1]`` with ``d0 s + (d1 - d0) s^2 / 2 = t``: the inverse of the (unnormalised) CDF of the
    linear density ``(1 - s) d0 + s d1`` on ``[0, 1]``, by the cancellation-free root ``2 t / (d0 + sqrt(d0^2 +
    2 (d1 - d0) t))`` (0 for an interval of no mass)."""
    den = d0 + jnp.sqrt(jnp.maximum(d0 * d0 + 2.0 * (d1 - d0) * t, 0.0))
    s = jnp.where(den > 0, 2.0 * t / jnp.where(den > 0, den, 1.0), 0.0)
    return jnp.clip(s, 0.0, 1.0)


def bilinear_tables(g: Float[Array, "n1 n1"]
                    ) -> tuple[Float[Array, "n1 n1"], Float[Array, "n1 n1"], Float[Array, " n1"]]:
    """The sampling tables of the bilinear density through node values ``g`` (``(N + 1, N + 1)``, rows ``y``).

    Returns:
        ``(q, prefix, row_cdf)``: ``q = g / Z`` (``Z`` the integral of the bilinear interpolant over the unit
        square, the trapezoid sum, exact; ``q = 1`` when ``Z`` is 0 or not finite); ``prefix[a, b] = int_0^{b/N}
        q(x, a/N) dx`` (so ``prefix[a, N]`` is the ``y``-marginal at row node ``a``); ``row_cdf[a] =
        int_0^{a/N}`` of that marginal (``row_cdf[N] = 1`` up to rounding). All exact for the bilinear ``q``.
    """
    n = g.shape[-1] - 1
    h = 1.0 / n
    w = jnp.ones(n + 1, g.dtype).at[0].set(0.5).at[-1].set(0.5)
    total = h * h * jnp.einsum("a,ab,b->", w, g, w)
    good = jnp.isfinite(total) & (total > 0)
    q = jnp.where(good, g / jnp.where(good, total, 1.0), 1.0)
    zero = jnp.zeros((n + 1, 1), g.dtype)
    prefix = jnp.concatenate([zero, jnp.cumsum(0.5 * h * (q[:, 1:] + q[:, :-1]), axis=1)], axis=1)
    rows = prefix[:, -1]
    row_cdf = jnp.concatenate([zero[0], jnp.cumsum(0.5 * h * (rows[1:] + rows[:-1]))])
    return q, prefix, row_cdf


# --------------------------------------------------------------------------- the sampler


class ImportanceSampler(eqx.Module):
    """Tabulated importance sampler of one BRDF (module docstring: strategy, density and unbiasedness).

    Build with :func:`importance_sampler`. ``u, pdf = s.sample(key, v, n)`` draws ``n`` light directions
    for a view ``v``; ``s.pdf(u, v)`` is their density (solid angle); ``s.warp(xi, v)`` maps uniforms
    ``xi (..., 5)`` to directions, broadcasting over ``v``. All are jittable and vmappable.

    Attributes:
        density: ``(n_v, N + 1, N + 1)`` the density ``q_j`` on the unit square at the grid nodes
            (``[j, a, b]`` at ``x = b / N``, ``y = a / N``), bilinear in between, integral 1.
        prefix: ``(n_v, N + 1, N + 1)`` its integrals along rows, ``int_0^{b/N} q_j(x, a/N) dx``.
        row_cdf: ``(n_v, N + 1)`` the CDF of the ``y``-marginal at the row nodes.
        theta_max: elevation of the last view node (radians); views beyond use its table.
        alpha: probability of the cosine-weighted component.
        resolution: ``N``.
    """

    density: Float[Array, "nv n1 n1"]
    prefix: Float[Array, "nv n1 n1"]
    row_cdf: Float[Array, "nv n1"]
    theta_max: float = eqx.field(static=True)
    alpha: float = eqx.field(static=True)
    resolution: int = eqx.field(static=True)

    @property
    def n_views(self) -> int:
        return int(self.density.shape[0])

    def _node(self, v):
        """Lower view node ``j`` and the weight ``t`` of node ``j + 1`` for views ``v``."""
        nv = self.n_views
        theta = jnp.arccos(jnp.clip(v[..., 2], -1.0, 1.0))
        s = jnp.clip(theta / self.theta_max, 0.0, 1.0) * (nv - 1)
        j = jnp.clip(jnp.floor(s), 0, max(nv - 2, 0)).astype(jnp.int32)
        t = jnp.clip(s - j, 0.0, 1.0) if nv > 1 else jnp.zeros_like(s)
        return j, t

    def _arrays(self, dtype):
        return tuple(jax.lax.stop_gradient(a).astype(dtype) for a in (self.density, self.prefix, self.row_cdf))

    def _square_density(self, j, sq):
        """``q_j`` at points ``sq`` of the unit square (bilinear interpolation of the node values)."""
        n = self.resolution
        q, _, _ = self._arrays(sq.dtype)
        f = sq * n
        i = jnp.clip(jnp.floor(f), 0, n - 1).astype(jnp.int32)
        s = jnp.clip(f - i, 0.0, 1.0)
        ix, iy, sx, sy = i[..., 0], i[..., 1], s[..., 0], s[..., 1]
        lower = (1.0 - sx) * q[j, iy, ix] + sx * q[j, iy, ix + 1]
        upper = (1.0 - sx) * q[j, iy + 1, ix] + sx * q[j, iy + 1, ix + 1]
        return (1.0 - sy) * lower + sy * upper

    def _draw_square(self, j, xi_y, xi_x):
        """A point of the unit square drawn from ``q_j`` by inversion: ``y`` from its piecewise-linear marginal
        (``xi_y``), then ``x`` from the piecewise-linear conditional (``xi_x``); module docstring, step 3."""
        n = self.resolution
        h = 1.0 / n
        q, prefix, row_cdf = self._arrays(xi_y.dtype)
        target = xi_y * row_cdf[j, n]
        a = _last_at_most(lambda i: row_cdf[j, i], n, target)
        r0, r1 = prefix[j, a, n], prefix[j, a + 1, n]
        sy = _invert_linear(r0, r1, (target - row_cdf[j, a]) / h)

        def blend(table, b):
            return (1.0 - sy) * table[j, a, b] + sy * table[j, a + 1, b]

        target = xi_x * ((1.0 - sy) * r0 + sy * r1)
        b = _last_at_most(lambda i: blend(prefix, i), n, target)
        sx = _invert_linear(blend(q, b), blend(q, b + 1), (target - blend(prefix, b)) / h)
        return jnp.stack([(b + sx) * h, (a + sy) * h], axis=-1)

    def pdf(self, u: Float[ArrayLike, "... 3"], v: Float[ArrayLike, "... 3"]) -> Float[Array, "..."]:
        """Solid-angle density of :meth:`warp`'s directions ``u`` for views ``v`` (0 below the horizon); one compiled
        program per shape."""
        return _pdf(self, jnp.asarray(u), jnp.asarray(v))

    def _pdf(self, u, v):
        u, v = jnp.broadcast_arrays(u, v)
        c, s = _azimuth(v)
        sq = hemisphere_to_square(_rotate_z(u, c, -s))
        j, t = self._node(v)
        j1 = jnp.minimum(j + 1, self.n_views - 1)
        tab = (1.0 - t) * self._square_density(j, sq) + t * self._square_density(j1, sq)
        p = self.alpha * cosine_pdf(u) + (1.0 - self.alpha) / (2.0 * jnp.pi) * tab
        return jnp.where(u[..., 2] > 0, p, 0.0)

    def warp(self, xi: Float[ArrayLike, "... 5"], v: Float[ArrayLike, "... 3"]
             ) -> tuple[Float[Array, "... 3"], Float[Array, "..."]]:
        """Map uniforms ``xi`` in ``[0, 1)^5`` to light directions for views ``v``.

        ``xi[0]`` picks the component (cosine if ``< alpha``), ``xi[1]`` the view node, ``xi[3]`` and ``xi[4]``
        the point (``y`` then ``x`` of the square for the table, or the cosine sample); ``xi[2]`` is not used.

        Returns:
            ``(u, pdf)``: ``(..., 3)`` unit directions and their density :meth:`pdf`; one compiled program per
            shape.
        """
        xi = jnp.asarray(xi)
        return _warp(self, xi, jnp.asarray(v, xi.dtype))

    def _warp(self, xi, v):
        shape = jnp.broadcast_shapes(xi.shape[:-1], v.shape[:-1])
        xi = jnp.broadcast_to(xi, shape + (5,))
        v = jnp.broadcast_to(v, shape + (3,))
        j, t = self._node(v)
        jj = jnp.where(xi[..., 1] < t, jnp.minimum(j + 1, self.n_views - 1), j)
        sq = self._draw_square(jj, xi[..., 3], xi[..., 4])
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


@jax.jit
def _pdf(sampler, u, v):
    return sampler._pdf(u, v)


@jax.jit
def _warp(sampler, xi, v):
    return sampler._warp(xi, v)


@eqx.filter_jit
def _sample(sampler, key, v, n):
    return sampler.warp(jax.random.uniform(key, (n, 5), v.dtype), v)


@eqx.filter_jit
def _tables(brdf, theta_max, n_views, resolution, supersample, dtype):
    """Node values ``g_j`` (module docstring, step 2) and their :func:`bilinear_tables`, for every view node."""
    n, s = resolution, supersample
    offsets = ((jnp.arange(s, dtype=dtype) + 0.5) / s - 0.5) / n  # a cell-sized neighbourhood of each node
    g = jnp.clip((jnp.arange(n + 1, dtype=dtype)[:, None] / n + offsets[None, :]).reshape(-1), 0.0, 1.0)
    X, Y = jnp.meshgrid(g, g)  # rows: y
    u = square_to_hemisphere(jnp.stack([X, Y], -1))  # ((n + 1) s, (n + 1) s, 3)
    thetas = jnp.linspace(0.0, theta_max, n_views, dtype=dtype) if n_views > 1 else jnp.zeros((1,), dtype)
    views = jnp.stack([jnp.sin(thetas), jnp.zeros_like(thetas), jnp.cos(thetas)], -1)

    def one(v):
        f = evaluate_rgb(brdf, u, jnp.broadcast_to(v, u.shape))  # max(f, 0), the transported BRDF
        f = jnp.where(jnp.isfinite(f), f, 0.0)
        nodes = (jnp.mean(f, axis=-1) * jnp.maximum(u[..., 2], 0.0)).reshape(n + 1, s, n + 1, s).mean(axis=(1, 3))
        return bilinear_tables(nodes)

    return jax.tree.map(jax.lax.stop_gradient, jax.lax.map(one, views))


@one_lapack_thread
def importance_sampler(brdf, *, resolution: int = 64, n_views: int = 16, theta_max_deg: float = 88.0,
                       alpha: float = 0.1, supersample: int = 2, dtype=None) -> ImportanceSampler:
    """Build the :class:`ImportanceSampler` of any BRDF polyjax evaluates.

    Args:
        brdf: a :class:`polyjax.PolynomialBRDF` (batch shape ``()``, ``(1,)`` or ``(3,)``) or any callable
            ``f(u, v) -> (..., 3)`` or ``(...)`` (baselines via a closure, ``NeuralBRDF``, ``TabulatedBRDF``).
        resolution: ``N``, cells per side of the square (``(N + 1)^2`` nodes, cells of ``2 pi / N^2`` sr).
        n_views: view-elevation nodes from 0 to ``theta_max_deg``.
        theta_max_deg: elevation of the last node (views beyond use it), in ``(0, 90)``.
        alpha: probability of cosine sampling, in ``(0, 1]``; keeps ``pdf > 0`` wherever ``cos theta_u > 0``.
        supersample: ``S``, points per side of each node's neighbourhood averaged into its value.
        dtype: table dtype (default: JAX's default float).

    Returns:
        The sampler; building it costs ``n_views ((N + 1) S)^2`` BRDF evaluations.
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
    density, prefix, row_cdf = _tables(brdf, theta_max, int(n_views), int(resolution), int(supersample), dtype)
    return ImportanceSampler(density, prefix, row_cdf, theta_max, float(alpha), int(resolution))


__all__ = ["ImportanceSampler", "bilinear_tables", "cosine_pdf", "cosine_sample", "hemisphere_to_square",
           "importance_sampler", "square_to_hemisphere"]
