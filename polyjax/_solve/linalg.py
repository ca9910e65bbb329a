r"""Dense factorisations that stay one matrix at a time under ``vmap``, and a Gram-based QR for tall designs.

Why one matrix at a time: on the CPU, jaxlib runs a *batched* LAPACK call (QR, SVD, eigh, ...)
by scheduling chunks of the batch onto XLA's intra-op thread pool and blocking until they end.
When one compiled program holds two such calls that XLA runs concurrently (for instance several
fits inside one ``jit``), each can occupy a pool worker while waiting for chunks queued behind the
other; on a small pool (2 cores) the program then never finishes. A single, unbatched call runs
inline on the calling thread, so polyjax maps its factorisations over batch axes with
:func:`jax.lax.map` (a loop inside the compiled program) instead of letting ``vmap`` batch them.
The matrices here are small (``m x m`` triangles, ``k x k`` covariances, designs of a few hundred
rows), so the loop costs little; see ``benchmarks/bench_fit.py``.

Why Gram-based for tall designs: Householder QR of an ``n x m`` design with ``n`` around a million
(a MERL material) makes ``m`` passes over the data. CholeskyQR2 (Fukaya et al. 2014,
"CholeskyQR2: a simple and communication-avoiding algorithm for computing a tall-skinny QR
factorization") forms the Gram matrix ``G = A^T A`` with one matrix product, ``R_1 = chol(G)``,
``Q_1 = A R_1^{-1}``, then repeats once: ``R = chol(Q_1^T Q_1) R_1``. The second pass restores
orthogonality to machine precision provided ``cond(A) < ~ eps^{-1/2}`` (about ``1e8`` in float64);
polyjax's designs are column-equilibrated Legendre bases with condition numbers of a few hundred
at most (``docs/robustness.md``), and :func:`tall_qr` falls back to Householder QR when the
Cholesky factor shows trouble.

Derivatives: :func:`eigh` has a rule of its own (first-order perturbation theory). :func:`qr_r`,
:func:`svd` and :func:`tall_qr` have none and cannot be differentiated (``custom_vmap`` has no reverse
mode); :func:`polyjax.weighted_lstsq` differentiates through its own rule, which reuses their factors.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jax.custom_batching import custom_vmap


def _sequential_under_vmap(fn):
    """Wrap ``fn`` (arrays -> pytree of arrays) so that ``vmap`` runs it once per batch element."""
    wrapped = custom_vmap(fn)

    @wrapped.def_vmap
    def _rule(axis_size, in_batched, *args):
        args = [a if b else jnp.broadcast_to(a, (axis_size,) + a.shape) for a, b in zip(args, in_batched)]
        out = jax.lax.map(lambda xs: wrapped(*xs), tuple(args))
        return out, jax.tree_util.tree_map(lambda _: True, out)

    return functools.wraps(fn)(wrapped)


@_sequential_under_vmap
def qr_r(a):
    """``R`` of the Householder QR of ``a`` (``mode="r"``)."""
    return jnp.linalg.qr(a, mode="r")


@_sequential_under_vmap
def svd(a):
    """Thin SVD ``(U, S, V^T)`` of ``a``."""
    return tuple(jnp.linalg.svd(a, full_matrices=False))


@_sequential_under_vmap
def _eigh(a):
    return tuple(jnp.linalg.eigh(a))


@jax.custom_jvp
def eigh(a):
    r"""Eigenvalues (ascending) and eigenvectors of the symmetric ``a``, with a derivative rule.

    Derivative (first-order perturbation theory, ``A = V diag(w) V^T``, ``dA`` symmetrised):
    ``dw_i = v_i^T dA v_i`` and ``dV = V (F * (V^T dA V))`` with ``F_ij = 1 / (w_j - w_i)`` for
    ``i != j``. Tied eigenvalues (``|w_i - w_j| <= sqrt(eps) max|w|``, e.g. two explanatory variables with
    equal variance and no correlation) have no unique eigenvectors: ``F_ij = 0`` there, i.e. the basis of a
    tied eigenspace is held fixed and only its mixing with the other eigenspaces moves. The derivative
    stays finite; the eigenspace (its projector ``V_T V_T^T``) and the sum of its eigenvalues are
    differentiated exactly, the individual tied eigenvalues and eigenvectors only when ``V_T^T dA V_T``
    is diagonal. The rule is linear in ``dA``, so ``grad`` and ``jacrev`` work (the factorisation
    itself, :func:`jax.custom_batching.custom_vmap`, has no reverse mode of its own). First derivatives only.
    """
    return _eigh(a)


@eigh.defjvp
def _eigh_jvp(primals, tangents):
    (a,), (da,) = primals, tangents
    w, v = _eigh(a)
    da = 0.5 * (da + jnp.swapaxes(da, -1, -2))
    vdv = v.T @ da @ v
    gap = w[None, :] - w[:, None]
    tol = jnp.sqrt(jnp.finfo(w.dtype).eps) * jnp.max(jnp.abs(w))
    tied = jnp.abs(gap) <= tol  # includes the diagonal
    f = jnp.where(tied, 0.0, 1.0 / jnp.where(tied, 1.0, gap))
    return (w, v), (jnp.diagonal(vdv), v @ (f * vdv))


def cholesky_upper(g):
    """Upper Cholesky factor of the symmetric positive definite ``g`` (NaN where it fails)."""
    return jnp.linalg.cholesky(g).T


@_sequential_under_vmap
def tall_qr(a, b, active):
    r"""``R`` and ``Q^T b`` of a QR of the tall ``a`` by CholeskyQR2; Householder where Cholesky breaks down.

    ``R_1 = chol(A^T A)``, ``Q_1 = A R_1^{-1}``, ``R_2 = chol(Q_1^T Q_1)``; then ``R = R_2 R_1`` and
    ``Q^T b = R_2^{-T} (Q_1^T b)`` (``Q_1`` is orthogonal to ``O(eps cond(A)^2)``, so no accuracy is
    lost forming ``Q_1^T b``). Inactive (all-zero) columns get a unit diagonal during the
    factorisation and a zero row and column in the returned ``R``, as Householder QR would give.

    Args:
        a: ``(n, m)`` equilibrated, square-root-weighted design.
        b: ``(n, r)`` square-root-weighted right-hand sides.
        active: ``(m,)`` bool, the columns in use.

    Returns:
        ``(R (m, m), Q^T b (m, r))``, ``R`` upper triangular: the same triangle as Householder QR up
        to the signs of its rows, so the least-squares solution built on it is the same.
    """
    n, m = a.shape
    hi = jax.lax.Precision.HIGHEST
    pad = jnp.diag(jnp.where(active, 0.0, 1.0).astype(a.dtype))
    r1 = cholesky_upper(jnp.matmul(a.T, a, precision=hi) + pad)
    ok1 = jnp.all(jnp.isfinite(r1)) & jnp.all(jnp.diagonal(r1) > 0)
    r1 = jnp.where(ok1, r1, jnp.eye(m, dtype=a.dtype))
    # Q1 = A R1^{-1} through the explicit m x m inverse: one matrix product over the n rows (a triangular
    # solve with n right-hand sides ran 3x slower on the CPU); the second pass absorbs its rounding.
    q1 = jnp.matmul(a, jax.scipy.linalg.solve_triangular(r1, jnp.eye(m, dtype=a.dtype), lower=False), precision=hi)
    r2 = cholesky_upper(jnp.matmul(q1.T, q1, precision=hi) + pad)
    ok = ok1 & jnp.all(jnp.isfinite(r2)) & jnp.all(jnp.diagonal(r2) > 0)
    r2 = jnp.where(ok, r2, jnp.eye(m, dtype=a.dtype))
    both = active[:, None] & active[None, :]

    def cholesky_qr2():
        qtb = jax.scipy.linalg.solve_triangular(r2, jnp.matmul(q1.T, b, precision=hi), lower=False, trans="T")
        return jnp.where(both, r2 @ r1, 0.0), qtb * active[:, None]

    def householder():  # a poorly conditioned or rank-deficient design; computed only in that case
        raug = jnp.linalg.qr(jnp.concatenate([a, b], axis=1), mode="r")
        return raug[:m, :m], raug[:m, m:]

    return jax.lax.cond(ok, cholesky_qr2, householder)
