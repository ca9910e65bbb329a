r"""Closed-form weighted least squares, the solver behind every linear model in polyjax.

Minimises :math:`\sum_i w_i (y_i - D_i \beta)^2` without forming the normal equations
:math:`D^T W D` (whose condition number is the square of the design's):

1. ``A = diag(sqrt(w)) D``, columns equilibrated to unit norm;
2. Householder QR of the augmented matrix ``[A | sqrt(w) Y]`` (``R`` only, ``Q`` never formed),
   which yields ``R`` and ``Q^T sqrt(w) Y`` in one pass over the data; for very tall designs
   (MERL: a million rows) CholeskyQR2 gives the same ``R`` and ``Q^T sqrt(w) Y`` with two matrix
   products (:mod:`polyjax._linalg`), falling back to Householder if the Cholesky factor fails;
3. SVD of the small ``m x m`` triangle ``R = U S V^T``, giving the rank, the 2-norm condition
   number ``s_max / s_min`` and the minimum-norm solution ``beta = V S^+ U^T Q^T sqrt(w) y``.

``method="svd"`` instead takes the SVD of ``A`` itself (slower, same answer). Columns can be
switched off with ``active`` so that several degrees share one compiled shape (``vmap`` over degrees).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from ._linalg import qr_r, svd, tall_qr

METHODS = ("qr", "svd")
#: designs with at least this many rows (and 8 times more rows than columns) take the Gram-based
#: CholeskyQR2 path of :func:`polyjax._linalg.tall_qr` (one matrix product instead of ``m`` passes).
TALL_ROWS = 20_000


class LstsqSolution(eqx.Module):
    """Result of :func:`weighted_lstsq`.

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


def weighted_lstsq(
    design: Float[Array, "n m"],
    y: Float[Array, "n ..."],
    weights: Float[Array, " n"],
    active: Bool[Array, " m"] | None = None,
    *,
    method: str = "qr",
    rcond: float | None = None,
) -> LstsqSolution:
    """Solve ``min_beta sum_i w_i (y_i - design_i beta)^2`` in closed form.

    Args:
        design: ``(n, m)`` design matrix.
        y: ``(n,)`` or ``(n, r)``: one or several right-hand sides sharing the design.
        weights: ``(n,)`` non-negative weights on the squared residuals (0 drops a sample).
        active: ``(m,)`` bool, columns to use (others get coefficient 0); all when None.
        method: ``"qr"`` (QR, then SVD of ``R``) or ``"svd"`` (SVD of the weighted design).
        rcond: singular values below ``rcond * s_max`` count as zero; default ``eps * max(m, sqrt(n))``.
            An exactly dependent column leaves ``s_min / s_max`` at about ``eps`` whatever ``n``; the
            ``eps * max(n, m)`` of ``numpy.linalg.lstsq`` would call a float32 MERL design (``n`` ~ 1e6,
            condition number ~40) rank-deficient (``docs/robustness.md``).

    Returns:
        :class:`LstsqSolution`, minimum-norm when the design is rank-deficient. Traceable:
        ``jit`` and ``vmap`` apply.
    """
    if method not in METHODS:
        raise ValueError(f"method: expected one of {METHODS}, found {method!r}")
    single = y.ndim == 1
    y2 = y[:, None] if single else y
    n, m = design.shape
    r = y2.shape[1]
    dtype = design.dtype
    act = jnp.ones((m,), bool) if active is None else active
    sw = jnp.sqrt(jnp.maximum(weights, 0.0)).astype(dtype)
    a = design * sw[:, None] * act[None, :]
    scale = jnp.sqrt(jnp.sum(a * a, axis=0))
    scale = jnp.where(scale > 0, scale, 1.0)
    a = a / scale
    b = y2 * sw[:, None]
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
    eps = jnp.finfo(dtype).eps
    tol = (eps * max(m, n**0.5) if rcond is None else rcond) * s[0]
    nonzero = s > tol
    coef = vt.T @ (jnp.where(nonzero, 1.0 / jnp.where(nonzero, s, 1.0), 0.0)[:, None] * utb)
    coef = coef / scale[:, None] * act[:, None]
    n_active = jnp.sum(act).astype(jnp.int32)
    rank = jnp.sum(nonzero).astype(jnp.int32)
    s_min = s[jnp.maximum(n_active - 1, 0)]
    condition = jnp.where((rank >= n_active) & (s_min > 0), s[0] / jnp.where(s_min > 0, s_min, 1.0), jnp.inf)
    return LstsqSolution(
        coefficients=coef[:, 0] if single else coef,
        rank=rank,
        condition=condition,
        singular_values=s,
        n_active=n_active,
    )


weighted_lstsq_jit = jax.jit(weighted_lstsq, static_argnames=("method", "rcond"))
