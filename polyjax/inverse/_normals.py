r"""Per-pixel normals of a photometric capture: the robust Lambertian start and the Gauss-Newton updates.

Both work on one block of pixels at a time, vmapped over its pixels: ``obs (P, L, 3)`` are the photographs divided by
each light's intensity (``I / E``: BRDF times cosine), ``w (P, L, 3)`` the samples' weights (0: saturated, below
the noise floor where that is a shadow, or rejected by the robust steps).

**Start** (:func:`lambertian_normals`): per pixel, the grey values ``g_l`` (mean of ``obs`` over channels) are
fitted by ``g_l = b . d_l`` (``b = rho n``) in weighted least squares (QR of the weighted ``(L, 3)`` design), the
weights iteratively reweighted by a Cauchy function of the residual over its median absolute deviation, narrower
for positive residuals (highlights) than negative ones (cast shadows, inter-reflection), and zero where the fitted
``b . d_l <= 0`` (attached shadow) or the value is below the noise floor.

**Update** (:func:`gauss_newton_normals`): with the pixel's BRDF fixed (``rho / pi + sum_k m_k g_k``), damped
Gauss-Newton (Levenberg-Marquardt) steps on the two tangent coordinates ``(a, b)`` of ``n = normalise(n0 + a t1 +
b t2)``, residuals ``sqrt(w) (obs - max(n . d, 0) f(u, v))``, the Jacobian by ``jax.jacfwd``; a step is kept only
where it lowers the pixel's cost. :func:`joint_normals` takes the same steps on the normal and the pixel's linear
coefficients ``x`` (diffuse albedo, lobe weights) together, the prediction linear in ``x``, the damping scaled by
each column of the Jacobian (Marquardt) and ``x`` projected onto ``x >= 0`` after the step.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import jax.scipy.linalg
from jaxtyping import Array, Float

#: Cauchy scales of the start's reweighting (in median absolute deviations): positive residuals (highlights) are
#: cut sooner than negative ones (shadows); measured on the DiLiGenT objects (``benchmarks/bench_capture.py``)
CAUCHY_HIGH, CAUCHY_LOW = 0.5, 3.0


def small_lstsq(a: Float[Array, "n k"], b: Float[Array, " n"], ridge: float = 1e-10) -> Float[Array, " k"]:
    """``min |a x - b|^2 + ridge |a|_F^2 / k |x|^2`` by QR of ``a`` stacked on the ridge's rows (a tiny Tikhonov
    term that keeps rank-deficient designs, e.g. a dropped column, solvable); batched under ``vmap``."""
    k = a.shape[1]
    lam = jnp.sqrt(ridge * jnp.sum(a**2) / k + 1e-300)
    q, r = jnp.linalg.qr(jnp.concatenate([a, lam * jnp.eye(k, dtype=a.dtype)]))
    rhs = q.T @ jnp.concatenate([b, jnp.zeros(k, b.dtype)])
    return jax.scipy.linalg.solve_triangular(r, rhs, lower=False)


def safe_sqrt(w):
    """``sqrt(w)`` of non-negative weights whose derivative is finite at ``w = 0`` (0 there)."""
    pos = w > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, w, 1.0)), 0.0)


def _lstsq3(a: Float[Array, "n 3"], b: Float[Array, " n"], w: Float[Array, " n"]) -> Float[Array, "3"]:
    """Weighted least squares ``min sum w (a x - b)^2`` of 3 unknowns (:func:`small_lstsq`)."""
    s = safe_sqrt(w)
    return small_lstsq(a * s[:, None], b * s)


def _lambertian_pixel(g, ok, d, steps: int):
    """One pixel's robust Lambertian fit: ``(unit normal, grey albedo rho)``; see the module notes."""
    w = ok.astype(g.dtype)
    b = _lstsq3(d, g, w)
    for _ in range(steps):
        pred = d @ b
        r = g - pred
        s = 1.4826 * jnp.median(jnp.abs(r)) + 1e-12
        z = r / s
        w = jnp.where(z > 0, 1 / (1 + (z / CAUCHY_HIGH) ** 2), 1 / (1 + (z / CAUCHY_LOW) ** 2)) * (pred > 0) * ok
        b = _lstsq3(d, g, w)
    rho = jnp.linalg.norm(b)
    n = jnp.where(rho > 0, b / jnp.where(rho > 0, rho, 1.0), jnp.array([0.0, 0.0, 1.0], b.dtype))
    return n, rho * jnp.pi


def lambertian_normals(obs, ok, directions, steps: int = 5):
    """Robust Lambertian normals ``(P, 3)`` and grey albedos ``(P,)`` of a block (module notes).

    Args:
        obs: ``(P, L, 3)`` values over irradiance; ok: ``(P, L)`` usable samples (not saturated, above the noise
        floor); directions: ``(L, 3)`` unit light directions; steps: reweighted solves after the first.
    """
    g = jnp.mean(obs, axis=-1)
    return jax.vmap(lambda gi, oi: _lambertian_pixel(gi, oi, directions, steps))(g, ok)


def tangent_frame(n: Float[Array, "3"]):
    """Two unit tangents ``t1, t2`` orthogonal to the unit ``n`` (smooth away from ``n = +-x``)."""
    a = jnp.where(jnp.abs(n[0]) < 0.9, jnp.array([1.0, 0.0, 0.0], n.dtype), jnp.array([0.0, 1.0, 0.0], n.dtype))
    t2 = jnp.cross(n, a)
    t2 = t2 / jnp.linalg.norm(t2)
    return jnp.cross(t2, n), t2


def local_directions(n, directions):
    """Light ``u (L, 3)`` and view ``v (L, 3)`` in the local frame of the unit normal ``n`` (view ``(0, 0, 1)``)."""
    t1, t2 = tangent_frame(n)
    frame = jnp.stack([t1, t2, n])
    view = jnp.array([0.0, 0.0, 1.0], n.dtype)
    u = directions @ frame.T
    v = jnp.broadcast_to(frame @ view, u.shape)
    return u, v


def _pixel_step(n0, obs, w, shade, damping):
    """One Levenberg-Marquardt step of one pixel's normal (module notes); ``shade(n) -> (L, 3)`` its prediction."""
    t1, t2 = tangent_frame(n0)

    def normal(ab):
        n = n0 + ab[0] * t1 + ab[1] * t2
        return n / jnp.linalg.norm(n)

    sw = safe_sqrt(w)

    def residual(ab):
        return ((obs - shade(normal(ab))) * sw).reshape(-1)

    zero = jnp.zeros(2, obs.dtype)
    r0 = residual(zero)
    jac = jax.jacfwd(residual)(zero)
    a = jnp.concatenate([jac, jnp.sqrt(damping) * jnp.eye(2, dtype=obs.dtype)])
    step = small_lstsq(a, jnp.concatenate([-r0, zero]), ridge=0.0)
    step = jnp.clip(step, -0.3, 0.3)
    r1 = residual(step)
    better = jnp.sum(r1**2) < jnp.sum(r0**2)
    return jnp.where(better, normal(step), n0), jnp.where(better, jnp.sum(r1**2), jnp.sum(r0**2))


def _joint_step(n0, x0, obs, w, shade, damping):
    """One Levenberg-Marquardt step of one pixel's normal and its non-negative linear coefficients ``x`` together
    (module notes); ``shade(n, x) -> (L, 3)``. The coefficients are projected onto ``x >= 0`` after the step."""
    t1, t2 = tangent_frame(n0)

    def normal(ab):
        n = n0 + ab[0] * t1 + ab[1] * t2
        return n / jnp.linalg.norm(n)

    sw = safe_sqrt(w)
    k = x0.shape[0]

    def residual(p):
        return ((obs - shade(normal(p[:2]), x0 + p[2:])) * sw).reshape(-1)

    zero = jnp.zeros(2 + k, obs.dtype)
    r0 = residual(zero)
    jac = jax.jacfwd(residual)(zero)
    scale = jnp.sqrt(jnp.sum(jac**2, 0) + 1e-30)  # Marquardt's scaling: damping relative to each column
    a = jnp.concatenate([jac, jnp.sqrt(damping) * jnp.diag(scale)])
    step = small_lstsq(a, jnp.concatenate([-r0, zero]), ridge=0.0)
    step = jnp.concatenate([jnp.clip(step[:2], -0.3, 0.3), jnp.maximum(x0 + step[2:], 0.0) - x0])
    c0, c1 = jnp.sum(r0**2), jnp.sum(residual(step) ** 2)
    better = c1 < c0
    return (jnp.where(better, normal(step[:2]), n0), jnp.where(better, x0 + step[2:], x0),
            jnp.where(better, c1, c0))


def joint_normals(normals, coefs, obs, w, shade_fn, steps: int = 3, damping: float = 1e-3):
    """``steps`` Levenberg-Marquardt steps of every pixel's normal and linear coefficients ``coefs (P, k)`` together
    (``shade_fn(n, x) -> (L, 3)``, linear in ``x >= 0``), vmapped over the block; returns ``(normals, coefs, cost)``.
    """
    def one(n, x, o, wi):
        cost = jnp.zeros((), o.dtype)
        for _ in range(steps):
            n, x, cost = _joint_step(n, x, o, wi, shade_fn, damping)
        return n, x, cost

    return jax.vmap(one)(normals, coefs, obs, w)


def gauss_newton_normals(normals, obs, w, shade_fn, params, steps: int = 2, damping: float = 1e-3):
    """``steps`` damped Gauss-Newton steps of every pixel's normal (module notes), vmapped over the block.

    Args:
        normals: ``(P, 3)`` unit normals; obs, w: ``(P, L, 3)``; shade_fn: ``shade_fn(n, param) -> (L, 3)``, the
        pixel's prediction ``max(n . d, 0) f(u, v)``; params: a pytree of per-pixel leaves (leading axis ``P``).

    Returns:
        ``(normals (P, 3), cost (P,))`` after the steps.
    """
    def one(n, o, wi, p):
        cost = jnp.zeros((), o.dtype)
        for _ in range(steps):
            n, cost = _pixel_step(n, o, wi, lambda m: shade_fn(m, p), damping)
        return n, cost

    return jax.vmap(one)(normals, obs, w, params)


__all__ = ["gauss_newton_normals", "joint_normals", "lambertian_normals", "local_directions", "safe_sqrt",
           "small_lstsq", "tangent_frame"]
