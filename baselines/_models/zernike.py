r"""Zernike-polynomial BRDF (Koenderink, van Doorn, Stavridi 1996), isotropic and reciprocal, linear.

**Hemisphere to disk.** Each direction ``w = (x, y, z)`` (``z = cos theta``) goes to the unit disk
by the equal-area (Lambert azimuthal) map ``rho = sqrt(2) sin(theta / 2)``, ``phi`` unchanged, i.e.
the disk point ``p = (x, y) / sqrt(1 + z)`` with ``rho^2 = 1 - z``: no angles and no division
by ``sin theta`` are needed.

**Basis.** Disk Zernike functions are ``Z_n^{+-m}(rho, phi) = R_n^m(rho) {cos, sin}(m phi)`` with
``n - m`` even and ``0 <= m <= n``. A BRDF expanded in products ``Z_n^m(u) Z_{n'}^{m'}(v)`` is
isotropic (depends on ``phi_u - phi_v`` only) exactly when ``m = m'`` and the cos/sin parts pair
up as ``cos(m phi_u) cos(m phi_v) + sin(m phi_u) sin(m phi_v) = cos(m (phi_u - phi_v))``, and it is
reciprocal when the coefficient of ``(n, n')`` equals that of ``(n', n)``. The isotropic, reciprocal
basis of order ``N`` is therefore

.. math::
    B_{m,n,n'}(u, v) = \tfrac12\big[R_n^m(\rho_u) R_{n'}^m(\rho_v) + R_{n'}^m(\rho_u) R_n^m(\rho_v)\big]
                       \cos(m(\phi_u - \phi_v)), \qquad m \le n \le n' \le N,\ n \equiv n' \equiv m \pmod 2 .

**Counting.** For each ``m`` there are ``k_m = floor((N - m)/2) + 1`` radial orders, hence
``k_m (k_m + 1) / 2`` unordered pairs; the total over ``m = 0..N`` is 5 for ``N = 2``
(3 + 1 + 1) and 55 for ``N = 8`` (15 + 10 + 10 + 6 + 6 + 3 + 3 + 1 + 1): the parameter counts the
paper gives (its Fig. 7) for orders 2 and 8.

It is evaluated without angles as ``Q_n^m(rho_u^2) Q_{n'}^m(rho_v^2) Re[(p_u conj(p_v))^m]``, where
``R_n^m(rho) = rho^m Q_n^m(rho^2)`` and ``p`` is the complex disk point. The model ``f = sum c_j B_j``
is fitted to the BRDF values themselves, by the closed-form weighted solve of polyjax
(:func:`polyjax.weighted_lstsq`) on the same objective as every other model.
"""

from __future__ import annotations

import functools
from math import factorial

import jax
import jax.numpy as jnp
import numpy as np

from polyjax import RESULTS, InputError, l2_error, weighted_lstsq
from polyjax.internal import check_parameter_count


@functools.lru_cache(maxsize=None)
def zernike_terms(order: int) -> tuple[tuple[int, int, int], ...]:
    """The ``(m, n, n')`` index triples of the isotropic reciprocal basis of ``order`` (see module docs)."""
    if not isinstance(order, (int, np.integer)) or order < 0:
        raise InputError(f"order: expected a non-negative integer, found {order!r}")
    out = []
    for m in range(order + 1):
        ns = list(range(m, order + 1, 2))
        for i, n in enumerate(ns):
            for n2 in ns[i:]:
                out.append((m, n, n2))
    return tuple(out)


def n_zernike_terms(order: int) -> int:
    """Number of basis functions: 5 at order 2, 55 at order 8."""
    return len(zernike_terms(order))


@functools.lru_cache(maxsize=None)
def _order_of(n_params: int) -> int:
    for order in range(0, 41):
        if n_zernike_terms(order) == n_params:
            return order
    raise InputError(f"zernike: {n_params} coefficients is not the size of any order's basis")


@functools.lru_cache(maxsize=None)
def _radial_table(order: int):
    """The radial polynomials of ``order``'s terms as one table: ``(coef, first, second, m)``, with
    ``coef (P + 1, J)`` over the ``J`` distinct pairs ``(n, m)`` the terms use,
    ``Q_n^m(rho^2) = R_n^m(rho) / rho^m = sum_p coef[p, j] rho^(2p)``, and for every term ``(m, n, n2)`` the
    columns ``first`` of ``(n, m)`` and ``second`` of ``(n2, m)``, and its ``m``. Evaluated as one product with the
    powers of ``rho^2``, not one polynomial at a time (at order 20, 121 polynomials: a program that took seconds
    to compile)."""
    terms = zernike_terms(order)
    pairs = sorted({(n, m) for (m, n, _) in terms} | {(n2, m) for (m, _, n2) in terms})
    col = {pair: j for j, pair in enumerate(pairs)}
    coef = np.zeros((max((n - m) // 2 for n, m in pairs) + 1, len(pairs)))
    for j, (n, m) in enumerate(pairs):
        for k in range((n - m) // 2 + 1):
            coef[(n - m) // 2 - k, j] = (-1) ** k * factorial(n - k) / (
                factorial(k) * factorial((n + m) // 2 - k) * factorial((n - m) // 2 - k))
    first = np.array([col[(n, m)] for (m, n, _) in terms])
    second = np.array([col[(n2, m)] for (m, _, n2) in terms])
    return coef, first, second, np.array([m for (m, _, _) in terms])


def _radial(coef, r2):
    """``(..., J)``: every ``Q_n^m(r2)`` of :func:`_radial_table`'s ``coef``."""
    powers = jnp.stack([jnp.ones_like(r2)] + [r2 ** p for p in range(1, coef.shape[0])], axis=-1)
    return powers @ jnp.asarray(coef, r2.dtype)


def disk_point(w):
    """Equal-area map of the upper hemisphere to the unit disk: ``(p_x, p_y, rho^2)`` (below the horizon: the rim)."""
    w = jnp.asarray(w)
    z = jnp.clip(w[..., 2], 0.0, 1.0)
    s = 1.0 / jnp.sqrt(1.0 + z)
    return w[..., 0] * s, w[..., 1] * s, 1.0 - z


def zernike_design(u, v, order: int = 8):
    """The ``(..., n_terms)`` basis values ``B_j(u, v)`` (see module docs)."""
    ux, uy, ru = disk_point(u)
    vx, vy, rv = disk_point(v)
    # z = p_u conj(p_v) = rho_u rho_v exp(i (phi_u - phi_v))
    a = ux * vx + uy * vy
    b = uy * vx - ux * vy
    powers = [jnp.ones_like(a)]
    re, im = jnp.ones_like(a), jnp.zeros_like(a)
    for _ in range(order):
        re, im = re * a - im * b, re * b + im * a
        powers.append(re)
    coef, first, second, m = _radial_table(order)
    qu, qv = _radial(coef, ru), _radial(coef, rv)
    sym = 0.5 * (qu[..., first] * qv[..., second] + qu[..., second] * qv[..., first])
    return sym * jnp.stack(powers, axis=-1)[..., m]


def zernike(params, u, v):
    r"""Isotropic, reciprocal Zernike BRDF ``f(u, v) = sum_j c_j B_j(u, v)`` (see module docs).

    Reference: J. J. Koenderink, A. J. van Doorn, M. Stavridi, "Bidirectional reflection
    distribution function expressed in terms of surface scattering modes", ECCV 1996.

    Args:
        params: ``(n_terms,)`` coefficients; the order is inferred from the count (55 -> order 8, 5 -> order 2).
        u, v: ``(..., 3)`` light and view directions.

    Returns:
        ``f`` with the shape of ``u[..., 0]``.
    """
    order = _order_of(int(params.shape[-1]))
    return zernike_design(u, v, order) @ params


@functools.partial(jax.jit, static_argnames=("order",))
def _zernike_kernel(u, v, y, wl, wc2, *, order):
    d = zernike_design(u, v, order)
    sol = jax.vmap(lambda yb, wb: weighted_lstsq(d, yb, wb))(y, wc2)
    coef = sol.coefficients
    l2 = l2_error(y, coef @ d.T, u, v, weights=wl, cutoff_deg=None, mask=wc2 > 0)
    no_samples = jnp.sum(wc2 > 0, axis=-1) == 0
    code = jnp.where(sol.rank < sol.n_active, RESULTS.RANK_DEFICIENT, RESULTS.OK)  # as in the polynomial fit
    code = jnp.where(no_samples, RESULTS.NO_SAMPLES, code).astype(jnp.int32)
    coef = jnp.where(no_samples[:, None], 0.0, coef)
    zero = jnp.zeros(code.shape, jnp.int32)
    return dict(
        params=coef, raw=coef, l2=l2, status=code, steps=zero, success=code == RESULTS.OK, start_l2=l2[:, None],
        start_status=code[:, None], best_start=zero, at_limit=jnp.zeros(coef.shape, bool),
    )


def fit_zernike(u, v, y, wl, wc2, order) -> dict:
    """Closed-form weighted least squares of the Zernike basis of ``order`` on every lane ``y (B, n)`` with the
    weights ``wl``, ``wc2 (B, n)`` of equation (11); the fields of :class:`baselines.BaselineFit` as ``(B, ...)``
    arrays. A lane whose weighted design has lower rank than its term count is ``RANK_DEFICIENT`` (minimum-norm
    coefficients), as in the polynomial fit; a term count absurd for the data is refused up front
    (:func:`polyjax.check_parameter_count`)."""
    if not isinstance(order, (int, np.integer)) or order < 0:
        raise InputError(f"order: expected a non-negative integer, found {order!r}")
    check_parameter_count(f"order={int(order)} (Zernike)", n_zernike_terms(int(order)), y.shape[-1], y.dtype.itemsize)
    return _zernike_kernel(u, v, y, wl, wc2, order=int(order))
