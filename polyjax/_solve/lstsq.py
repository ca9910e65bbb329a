r"""Closed-form weighted least squares, the solver behind every linear model in polyjax.

Minimises :math:`\sum_i w_i (y_i - D_i \beta)^2` without forming the normal equations
:math:`D^T W D` (whose condition number is the square of the design's):

1. ``A = diag(sqrt(w)) D``, columns equilibrated to unit norm;
2. Householder QR of the augmented matrix ``[A | sqrt(w) Y]`` (``R`` only, ``Q`` never formed),
   which yields ``R`` and ``Q^T sqrt(w) Y`` in one pass over the data; for very tall designs
   (MERL: a million rows) CholeskyQR2 gives the same ``R`` and ``Q^T sqrt(w) Y`` with two matrix
   products (:mod:`polyjax._solve.linalg`), falling back to Householder if the Cholesky factor fails;
3. SVD of the small ``m x m`` triangle ``R = U S V^T``, giving the rank, the 2-norm condition
   number ``s_max / s_min`` and the minimum-norm solution ``beta = V S^+ U^T Q^T sqrt(w) y``.

``method="svd"`` instead takes the SVD of ``A`` itself (slower, same answer). Columns can be
switched off with ``active`` so that several degrees share one compiled shape (``vmap`` over degrees).
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.custom_derivatives import SymbolicZero
from jaxtyping import Array, Bool, Float, Int

from .linalg import qr_r, svd, tall_qr
from .threads import one_lapack_thread

METHODS = ("qr", "svd")
#: designs with at least this many rows (and 8 times more rows than columns) take the Gram-based
#: CholeskyQR2 path of :func:`polyjax._solve.linalg.tall_qr` (one matrix product instead of ``m`` passes).
TALL_ROWS = 20_000


class LstsqSolution(eqx.Module):
    """The result of :func:`weighted_lstsq`.

    Attributes:
        coefficients: ``(m, r)`` (or ``(m,)`` for a single right-hand side); 0 for inactive columns.
        rank: numerical rank of the weighted, equilibrated design (active columns only).
        condition: 2-norm condition number of the weighted, column-equilibrated design
            (``inf`` when rank-deficient).
        singular_values: ``(m,)`` of the equilibrated design, decreasing.
        n_active: number of active columns.
    """

    coefficients: Float[Array, "m ..."]
    rank: Int[Array, ""]
    condition: Float[Array, ""]
    singular_values: Float[Array, " m"]
    n_active: Int[Array, ""]


@one_lapack_thread
def weighted_lstsq(
    design: Float[Array, "n m"],
    y: Float[Array, "n ..."],
    weights: Float[Array, " n"],
    active: Bool[Array, " m"] | None = None,
    *,
    method: str = "qr",
    rcond: float | None = None,
) -> LstsqSolution:
    r"""Solve ``min_beta sum_i w_i (y_i - design_i beta)^2`` in closed form.

    Args:
        design: ``(n, m)`` design matrix.
        y: ``(n,)`` or ``(n, r)``: one or several right-hand sides sharing the design.
        weights: ``(n,)`` non-negative weights on the squared residuals (0 drops a sample, and so does a
            negative or NaN weight).
        active: ``(m,)`` bool, columns to use (others get coefficient 0); all when None.
        method: ``"qr"`` (QR, then SVD of ``R``) or ``"svd"`` (SVD of the weighted design).
        rcond: singular values below ``rcond * s_max`` count as zero; default ``eps * max(m, sqrt(n))``.
            An exactly dependent column leaves ``s_min / s_max`` at about ``eps`` whatever ``n``; the
            ``eps * max(n, m)`` of ``numpy.linalg.lstsq`` would call a float32 MERL design (``n`` ~ 1e6,
            condition number ~40) rank-deficient (``docs/robustness.md``).

    Returns:
        :class:`LstsqSolution`, minimum-norm when the design is rank-deficient. Traceable:
        ``jit`` and ``vmap`` apply.

    Differentiation (``jvp``, ``grad``, ``jacfwd``, ``jacrev`` and ``vmap`` of them) with respect to
    ``design``, ``y`` and ``weights`` uses a rule of its own, not LAPACK's differentiation: the
    factorisation is not differentiated and no second one is made. With ``D`` the design (active
    columns), ``W = diag(w)``, ``r = y - D beta`` and ``E`` the column norms of ``W^(1/2) D``,
    differentiating the weighted normal equations ``D^T W (y - D beta) = 0`` gives

    .. math::
        d\beta = (D^T W D)^{+} \big[D^T\,dW\,r + D^T W (dy - dD\,\beta) + dD^T W r\big]
                 - 2 E^{-1} (I - P)\,dE\,\beta + E^{-1} (I - P) E^{-1} dD^T W D\,h,

    with ``(D^T W D)^+ = E^{-1} V S^{-2} V^T E^{-1}`` from the SVD ``R = U S V^T`` of the ``R`` factor already
    computed (or of the weighted design for ``method="svd"``), restricted to the ``rank`` numerically nonzero
    singular values; ``P = V_k V_k^T`` projects on the numerical row space and ``h = E^{-1} V S^{-2} V^T E
    beta``. At full rank ``P = I`` and only the first term remains. The last two terms are the
    Golub-Pereyra derivative of the pseudo-inverse (Golub and Pereyra 1973, eq. 4.12) for a rank-deficient
    design: the derivative of the minimum-norm solution (minimum norm in the equilibrated coordinates) along
    perturbations that keep the numerical rank; finite in every case. The normal equations are never solved:
    the cost is a few products with ``D`` and two ``m x m`` products, and the accuracy that of the
    seminormal equations (relative error about ``condition^2 eps``, the sensitivity the solution itself has
    when the residual is not small).

    Samples with ``w_i <= 0`` contribute exactly zero to the derivative, whatever the tangents of their
    weight, value or design row (a weight clipped at 0 is treated as a constant 0), and never NaN, even when
    their value or design row is not finite. ``rank`` and ``n_active`` have zero (``float0``) tangents;
    ``singular_values`` and ``condition`` get their derivatives ``ds_k = u_k^T dA v_k`` of the equilibrated
    weighted design ``A`` (0 for singular values at or below the rank tolerance, and for ``condition = inf``).
    First derivatives only: differentiating the rule again (``jax.hessian``) would differentiate the
    factorisation, which has no rule of its own, and is not supported.
    """
    if method not in METHODS:
        raise ValueError(f"method: expected one of {METHODS}, found {method!r}")
    single = y.ndim == 1
    y2 = y[:, None] if single else y
    m = design.shape[1]
    dtype = jnp.result_type(design, y2)
    act = jnp.ones((m,), bool) if active is None else jnp.asarray(active, bool)
    coef, rank, condition, s, n_active = _solve_compiled(
        jnp.asarray(design, dtype), jnp.asarray(y2, dtype), jnp.asarray(weights, dtype), act, method, rcond
    )
    return LstsqSolution(
        coefficients=coef[:, 0] if single else coef,
        rank=rank,
        condition=condition,
        singular_values=s,
        n_active=n_active,
    )


def _factor(design, y2, weights, act, method, rcond):
    """The solve itself: coefficients (m, r), and the factors the derivative rule reuses."""
    n, m = design.shape
    r = y2.shape[1]
    dtype = design.dtype
    pos = weights > 0
    sw = jnp.sqrt(jnp.where(pos, weights, 1.0))
    # dropped samples enter as exact zero rows (also when their value or design row is not finite)
    a = jnp.where(pos[:, None] & act[None, :], design * sw[:, None], 0.0)
    raw_scale = jnp.sqrt(jnp.sum(a * a, axis=0))
    scale = jnp.where(raw_scale > 0, raw_scale, 1.0)
    a = a / scale
    b = jnp.where(pos[:, None], y2 * sw[:, None], 0.0)
    if method == "qr" and n >= TALL_ROWS and n >= 8 * (m + r):
        rr, qtb = tall_qr(a, b, act)
        uu, s, vt = svd(rr)
        utb = uu.T @ qtb
    elif method == "qr":
        aug = jnp.concatenate([a, b], axis=1)
        rows = m + r
        if n < rows:  # zero rows leave the problem unchanged and give a square enough R
            aug = jnp.concatenate([aug, jnp.zeros((rows - n, rows), dtype)], axis=0)
        raug = qr_r(aug)
        rr = raug[:m, :m]
        qtb = raug[:m, m:]
        uu, s, vt = svd(rr)
        utb = uu.T @ qtb
    else:
        uu, s, vt = svd(a)
        utb = uu.T @ b
    out, aux = _solve_svd(uu, s, vt, utb, scale, act, n, rcond)
    aux.update(pos=pos, raw_scale=raw_scale)
    return out, aux


def _solve_svd(uu, s, vt, utb, scale, act, n, rcond):
    """Minimum-norm coefficients, rank and condition from the SVD ``U S V^T`` of ``R`` (or of ``A``) and ``U^T b``.

    Shared by the dense solve above and the streamed fit (:mod:`polyjax._fit.stream`), which builds ``R`` and
    ``Q^T b`` without ever holding the design.
    """
    m = vt.shape[0]
    dtype = vt.dtype
    eps = jnp.finfo(dtype).eps
    tol = (eps * max(m, n**0.5) if rcond is None else rcond) * s[0]
    nonzero = s > tol
    inv_s = jnp.where(nonzero, 1.0 / jnp.where(nonzero, s, 1.0), 0.0)
    coef = vt.T @ (inv_s[:, None] * utb)
    coef = coef / scale[:, None] * act[:, None]
    n_active = jnp.sum(act).astype(jnp.int32)
    rank = jnp.sum(nonzero).astype(jnp.int32)
    i_min = jnp.maximum(n_active - 1, 0)
    s_min = s[i_min]
    full = (rank >= n_active) & (s_min > 0)
    condition = jnp.where(full, s[0] / jnp.where(s_min > 0, s_min, 1.0), jnp.inf)
    out = (coef, rank, condition, s, n_active)
    aux = {"scale": scale, "vt": vt, "inv_s": inv_s, "nonzero": nonzero, "i_min": i_min, "full": full}
    return out, aux


@functools.partial(jax.custom_jvp, nondiff_argnums=(4, 5))
def _solve_weighted(design, y2, weights, act, method, rcond):
    return _factor(design, y2, weights, act, method, rcond)[0]


@functools.partial(jax.jit, static_argnums=(4, 5))
def _solve_compiled(design, y2, weights, act, method, rcond):
    """:func:`_solve_weighted` as one compiled program (and so its derivatives, under ``grad`` or ``jvp`` outside
    ``jit``: op by op, each of their operations would be compiled on its own)."""
    return _solve_weighted(design, y2, weights, act, method, rcond)


def _solve_jvp(method, rcond, primals, tangents):
    """The derivative rule documented in :func:`weighted_lstsq`; linear in the tangents (so it transposes)."""
    design, y2, weights, act = primals
    t_design, t_y, t_w, _ = tangents
    out, aux = _factor(design, y2, weights, act, method, rcond)
    coef, _, condition, s, _ = out
    pos, scale, vt, inv_s, nonzero = aux["pos"], aux["scale"], aux["vt"], aux["inv_s"], aux["nonzero"]
    keep = pos[:, None] & act[None, :]
    d = jnp.where(keep, design, 0.0)  # D, dropped rows and inactive columns zeroed
    w = jnp.where(pos, weights, 0.0)
    res = jnp.where(pos[:, None], y2 - d @ coef, 0.0)  # r = y - D beta, (n, r)
    vs = vt.T / scale[:, None]  # E^{-1} V: the right singular vectors in the design's coordinates

    def has(t):
        return not isinstance(t, SymbolicZero)

    def ginv(x):  # (A^T A)^+ = V S^-2 V^T on the numerical range
        return vt.T @ ((inv_s * inv_s)[:, None] * (vt @ x))

    def null(x):  # I - P = V_0 V_0^T, exactly 0 at full rank
        return vt.T @ ((~nonzero)[:, None] * (vt @ x))

    g = jnp.zeros_like(coef)  # D^T dW r + D^T W (dy - dD beta) + dD^T W r
    de = jnp.zeros_like(scale)  # tangent of the column norms E
    ds = jnp.zeros_like(s)  # tangent of the singular values
    q = jnp.zeros_like(coef)  # dD^T W D h (range-space term of a rank-deficient design)
    dv = d @ vs if has(t_w) or has(t_design) else None  # (n, m): D E^{-1} V, for the singular values
    if has(t_w):
        dw = jnp.where(pos, t_w, 0.0)
        g = g + d.T @ (dw[:, None] * res)
        de = de + jnp.sum(dw[:, None] * d * d, axis=0) / (2 * scale)
        ds = ds + 0.5 * jnp.sum(dw[:, None] * dv * dv, axis=0) * inv_s
    if has(t_y):
        dy = jnp.where(pos[:, None], t_y, 0.0)
        g = g + d.T @ (w[:, None] * dy)
    if has(t_design):
        dd = jnp.where(keep, t_design, 0.0)
        g = g - d.T @ (w[:, None] * (dd @ coef)) + dd.T @ (w[:, None] * res)
        de = de + jnp.sum(w[:, None] * d * dd, axis=0) / scale
        h = ginv(scale[:, None] * coef) / scale[:, None]
        q = q + dd.T @ (w[:, None] * (d @ h))
        ds = ds + jnp.sum(w[:, None] * dv * (dd @ vs), axis=0) * inv_s
    de = jnp.where(aux["raw_scale"] > 0, de, 0.0)
    dcoef = (ginv(g / scale[:, None]) - 2 * null(de[:, None] * coef) + null(q / scale[:, None])) / scale[:, None]
    dcoef = dcoef * act[:, None]
    # ds_k = u_k^T dA v_k: the part through the equilibration E is -s_k sum_j v_kj^2 de_j / e_j
    ds = ds - s * jnp.sum(vt * vt * (de / scale)[None, :], axis=1)
    ds = jnp.where(nonzero, ds, 0.0)
    s0, smin, full = s[0], s[aux["i_min"]], aux["full"]
    rel = ds[0] / jnp.where(s0 > 0, s0, 1.0) - ds[aux["i_min"]] / jnp.where(smin > 0, smin, 1.0)
    dcond = jnp.where(full, condition, 0.0) * rel  # d(s0 / smin); 0 where the condition number is inf
    int_zero = np.zeros((), jax.dtypes.float0)
    return out, (dcoef, int_zero, dcond, ds, int_zero)


_solve_weighted.defjvp(_solve_jvp, symbolic_zeros=True)


weighted_lstsq_jit = jax.jit(weighted_lstsq, static_argnames=("method", "rcond"))
