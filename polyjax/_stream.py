r"""Streamed fits of tall data (a MERL material: a million samples): the design is never held in memory.

The dense fit builds the ``n x m`` design ``D``, weights it, and factorises it by CholeskyQR2
(:func:`polyjax._linalg.tall_qr`). For a million rows that design, and the ``Q_1`` of CholeskyQR2, are each
``8 n m`` bytes written and read again several times. Here every pass rebuilds the rows it needs, a block of
:data:`BLOCK` rows at a time inside one compiled loop, from the scaled principal components ``t (n, k)``
(``k <= 3`` numbers per sample), and keeps only ``m x m`` sums:

1. ``G = A^T A`` with ``A = W^{1/2} D`` (``W = diag(w cos^2 theta_u)``): the column norms ``E = diag(G)^{1/2}``
   equilibrate it, ``R_1 = chol(E^{-1} G E^{-1})``;
2. ``Q_1 = A E^{-1} R_1^{-1}`` block by block: ``C = Q_1^T Q_1`` and ``Q_1^T W^{1/2} y``; ``R_2 = chol(C)``,
   ``R = R_2 R_1``, ``Q^T W^{1/2} y = R_2^{-T} Q_1^T W^{1/2} y`` (CholeskyQR2, exactly the sums of
   :func:`polyjax._linalg.tall_qr`, accumulated in blocks);
3. the residuals of the fitted coefficients, for the L2 of equation (11).

Then the SVD of the ``m x m`` ``R`` as in :func:`polyjax.weighted_lstsq`. Pass 1 reads ``t`` and the weights,
passes 2 and 3 also the values. Every degree of a batched fit shares pass 1 (columns are switched off in ``G``).
When a Cholesky factor fails (a rank-deficient or badly conditioned design), the fit is done by the dense path
instead, inside the same program, as :func:`~polyjax._linalg.tall_qr` falls back to Householder QR.

Pass 1 and ``R_1`` depend on the directions and weights only, not on the values: :func:`stream_geometry`
computes them in a program of their own, which :func:`polyjax.fit_polynomial` keeps for the next fit on the same
samples (every MERL material shares the grid of directions, so a second material pays for passes 2 and 3 only).

Not differentiable: the loops have no derivative rule. :func:`polyjax.fit_polynomial` takes this path only for
concrete inputs (a call outside ``jit``/``grad``/``vmap``); traced inputs take the dense, differentiable path.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ._basis import design_matrix
from ._design import fitted_scaling
from ._linalg import svd
from ._lstsq import _solve_svd

#: shared-design fits with at least this many samples (and 8 times more than columns plus right-hand sides)
#: are streamed
STREAM_ROWS = 100_000
#: rows per block: the block's design (``BLOCK x m``) stays in the CPU's cache
BLOCK = 4096


def use_stream(n: int, m: int, r: int, method: str, shared: bool, concrete: bool) -> bool:
    """Whether :func:`polyjax.fit_polynomial` streams (see the module docstring)."""
    return method == "qr" and shared and concrete and n >= STREAM_ROWS and n >= 8 * (m + r)


def _stream_sum(fn, n: int, block: int, arrays, axes):
    """``sum_b fn(*block_b)`` over the row blocks of ``arrays`` (rows along ``axes``): a loop over full blocks,
    then the remainder; nothing is padded or copied."""

    def take(start, size):
        return [jax.lax.dynamic_slice_in_dim(a, start, size, axis=ax) for a, ax in zip(arrays, axes)]

    n_full, rem = divmod(n, block)
    acc = None
    if n_full:
        shapes = jax.eval_shape(fn, *take(0, block))
        zero = jax.tree.map(lambda s: jnp.zeros(s.shape, s.dtype), shapes)
        body = lambda i, acc: jax.tree.map(jnp.add, acc, fn(*take(i * block, block)))  # noqa: E731
        acc = jax.lax.fori_loop(0, n_full, body, zero)
    if rem:
        tail = fn(*[jax.lax.slice_in_dim(a, n_full * block, n, axis=ax) for a, ax in zip(arrays, axes)])
        acc = tail if acc is None else jax.tree.map(jnp.add, acc, tail)
    return acc


def _chol_upper(g):
    r = jnp.linalg.cholesky(g).T
    return r, jnp.all(jnp.isfinite(r)) & jnp.all(jnp.diagonal(r) > 0)


def stream_geometry(x, wl, wc2l, active, *, max_degree, basis, interactions, block=None):
    """What a streamed fit needs of the samples alone (not of the values): pass 1 and ``R_1``.

    Args:
        x: ``(n, k)`` explanatory variables; ``wl``, ``wc2l``: ``(n,)`` the weights ``w`` and ``w cos^2 theta_u``
            (0 for dropped samples); ``active``: ``(D, m)`` columns per degree.
        max_degree, basis, interactions: as in :func:`polyjax.fit_polynomial`.
        block: rows per block (default :data:`BLOCK`).

    Returns:
        A dict of arrays: the PCA and scaling, ``t (n, k)``, the weights, and per degree the column norms
        ``E``, ``R_1``, ``R_1^{-1}`` and whether the Cholesky factor succeeded. The same for every material on
        one grid: :func:`polyjax.fit_polynomial` keeps the last one.
    """
    block = BLOCK if block is None else int(block)
    n = x.shape[0]
    dtype = x.dtype
    keep = wl > 0
    pca, centre, hw, t = fitted_scaling(x, keep, basis)
    pos = wc2l > 0
    sw = jnp.where(pos, jnp.sqrt(jnp.where(pos, wc2l, 1.0)), 0.0)

    def gram(t_b, sw_b):
        a = _rows(t_b, sw_b, max_degree, basis, interactions)
        return jnp.matmul(a.T, a, precision=_HI)

    g = _stream_sum(gram, n, block, (t, sw), (0, 0))
    m = g.shape[0]
    eye = jnp.eye(m, dtype=dtype)

    def first(act):
        both = act[:, None] & act[None, :]
        raw = jnp.sqrt(jnp.where(act, jnp.diagonal(g), 0.0))
        scale = jnp.where(raw > 0, raw, 1.0)
        pad = jnp.diag(jnp.where(act, 0.0, 1.0).astype(dtype))
        r1, ok1 = _chol_upper(jnp.where(both, g / (scale[:, None] * scale[None, :]), 0.0) + pad)
        r1 = jnp.where(ok1, r1, eye)
        r1inv = jax.scipy.linalg.solve_triangular(r1, eye, lower=False)
        return scale, r1, r1inv * act[:, None], pad, ok1

    scale, r1, r1inv, pad, ok1 = jax.vmap(first)(active)
    return dict(mean=pca.mean, rotation=pca.rotation, centre=centre, halfwidth=hw, t=t, sw=sw, wc2=wc2l,
                den=jnp.sum(wl), n_used=jnp.sum(keep), scale=scale, r1=r1, r1inv=r1inv, pad=pad, ok1=ok1)


_HI = jax.lax.Precision.HIGHEST


def _rows(t_b, sw_b, max_degree, basis, interactions):
    """Rows of ``A = W^{1/2} D``: dropped samples are exact zero rows, also where their design is not finite."""
    d = design_matrix(t_b, max_degree, basis, interactions)
    return jnp.where(sw_b[:, None] > 0, d * sw_b[:, None], 0.0)


def streamed_lane(geo, y, active, *, max_degree, basis, interactions, rcond, dense, block=None):
    """The shared-design fit of every right-hand side of ``y (r, n)`` for every degree, streamed.

    Args:
        geo: :func:`stream_geometry` of the samples.
        y: ``(r, n)`` values; ``active``: ``(D, m)`` columns per degree.
        max_degree, basis, interactions, rcond: as in :func:`polyjax.fit_polynomial`.
        dense: ``() -> outputs``, the dense fit, run instead when a Cholesky factor fails.
        block: rows per block (default :data:`BLOCK`).

    Returns:
        The outputs of the dense fit of ``polyjax._fit``: ``((mean, rotation, centre, halfwidth), coef (D, r, m),
        l2 (D, r), rank (D,), condition (D,), n_active (D,), n_used)``.
    """
    block = BLOCK if block is None else int(block)
    t, sw, wc2l = geo["t"], geo["sw"], geo["wc2"]
    n = t.shape[0]
    eye = jnp.eye(geo["r1"].shape[-1], dtype=t.dtype)

    def second(t_b, y_b, sw_b):
        a = _rows(t_b, sw_b, max_degree, basis, interactions)
        b = jnp.where(sw_b[:, None] > 0, y_b.T * sw_b[:, None], 0.0)  # (B, r)
        q1 = jnp.einsum("bm,dm,dmj->dbj", a, 1.0 / geo["scale"], geo["r1inv"], precision=_HI)  # (D, B, m)
        return jnp.einsum("dbi,dbj->dij", q1, q1, precision=_HI), jnp.einsum("dbi,br->dir", q1, b, precision=_HI)

    c, q1tb = _stream_sum(second, n, block, (t, y, sw), (0, 1, 0))

    def finish(act, scale, r1, c, q1tb, pad):
        both = act[:, None] & act[None, :]
        r2, ok2 = _chol_upper(c + pad)
        r2 = jnp.where(ok2, r2, eye)
        qtb = jax.scipy.linalg.solve_triangular(r2, q1tb, lower=False, trans="T") * act[:, None]
        rr = jnp.where(both, r2 @ r1, 0.0)
        uu, s, vt = svd(rr)
        (coef, rank, cond, _, n_act), _ = _solve_svd(uu, s, vt, uu.T @ qtb, scale, act, n, rcond)
        return coef.T, rank, cond, n_act, ok2  # coef (r, m)

    coef, rank, cond, n_act, ok2 = jax.vmap(finish)(active, geo["scale"], geo["r1"], c, q1tb, geo["pad"])
    ok = jnp.all(geo["ok1"]) & jnp.all(ok2)

    def streamed():
        def residuals(t_b, y_b, wc2_b):
            d = design_matrix(t_b, max_degree, basis, interactions)
            res = jnp.where(wc2_b > 0, y_b[None] - jnp.einsum("bm,drm->drb", d, coef, precision=_HI), 0.0)
            return jnp.sum(wc2_b * res * res, axis=-1)  # (D, r)

        num = _stream_sum(residuals, n, block, (t, y, wc2l), (0, 1, 0))
        den = geo["den"]
        nz = (den > 0) & (num != 0)
        l2 = jnp.where(nz, jnp.sqrt(jnp.where(nz, num, 1.0) / jnp.where(nz, den, 1.0)), 0.0)
        l2 = jnp.where(den > 0, l2, jnp.inf)
        tr = (geo["mean"], geo["rotation"], geo["centre"], geo["halfwidth"])
        return tr, coef, l2, rank, cond, n_act, geo["n_used"]

    return jax.lax.cond(ok, streamed, dense)
