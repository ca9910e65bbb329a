r"""Streamed fits of tall data (a MERL material: a million samples): the design is never held in memory.

The dense fit builds the ``n x m`` design ``D``, weights it, and factorises it by CholeskyQR2
(:func:`polyjax._solve.linalg.tall_qr`). For a million rows that design, and the ``Q_1`` of CholeskyQR2, are each
``8 n m`` bytes written and read again several times. Here every pass rebuilds the rows it needs, a block of
:data:`BLOCK` rows at a time inside one compiled loop, from the scaled principal components ``t``
(``k <= 3`` numbers per sample, held as ``(k, n)``: every column of a block is a contiguous, vectorised run),
and keeps only ``m x m`` (or ``m x r``) sums. With ``A = W^{1/2} D``
(``W = diag(w cos^2 theta_u)``) and ``b = W^{1/2} y``:

Geometry (the directions and weights only, not the values; :func:`stream_geometry`, kept for every material on
the same grid):

0. the PCA of the explanatory variables and the scaling of its components (as :func:`polyjax.fitted_design`),
   computed on the ``(k, n)`` layout: reductions over contiguous rows, then ``t``;
1. a preconditioner from a sample of the rows (every :data:`PRECONDITION_STRIDE`-th one): its Gram matrix
   ``G_s``, column norms ``E_1 = diag(G_s)^{1/2}`` and ``R_1 = chol(E_1^{-1} G_s E_1^{-1})``; from every row
   (the first pass of CholeskyQR2) when that Cholesky factor fails;
2. one pass over every row: ``C = Q_1^T Q_1`` with ``Q_1 = A E_1^{-1} R_1^{-1}`` built block by block, and the
   exact column norms ``E = diag(A^T A)^{1/2}``; ``R_2 = chol(C)``, and ``A E^{-1} = Q R`` with
   ``R = R_2 R_1 E_1 E^{-1}``. This is the second pass of CholeskyQR2 (Fukaya et al. 2014), whose accuracy
   needs only a well-conditioned ``Q_1`` (its orthogonality error is ``O(eps cond(Q_1)^2)``), not an exact
   ``R_1``: when ``cond(R_2) = cond(Q_1)`` exceeds :data:`PRECONDITION_CONDITION` (a sample unlike the whole),
   the pass is made again with ``R_2 R_1`` as the preconditioner. Then the SVD ``R = U S V^T``, which gives the
   rank and condition as in :func:`polyjax.weighted_lstsq`, and ``G = A^T A = E R^T R E``. (The first pass of
   CholeskyQR2 over every row, which this sample replaces, cost about two thirds of this one.)

Values (:func:`streamed_lane`, two passes that read ``t``, the weights and the values):

3. ``A^T b``: then ``Q^T b = R^{-T} E^{-1} A^T b`` and the minimum-norm solution ``beta_0`` from the SVD
   (the semi-normal equations: ``R`` from the QR of ``A``, ``A`` itself only through ``A^T b``);
4. the residuals ``r_0 = b - A beta_0``: ``|r_0|^2`` and ``A^T r_0``; one step of refinement
   ``delta = R^{-1} R^{-T} A^T r_0`` (in the equilibrated columns), ``beta = beta_0 + delta`` (the corrected
   semi-normal equations, as accurate as a QR solve; Bjorck, *Numerical methods for least squares problems*,
   section 2.5.3), and the L2 of equation (11) from
   ``|b - A beta|^2 = |r_0|^2 - 2 delta^T A^T r_0 + delta^T G delta``, whose last two terms are of second order in
   the correction (no cancellation: the residual itself is accumulated, never ``|b|^2 - |Q^T b|^2``).

Every degree of a batched fit shares the passes (columns are switched off per degree). When a Cholesky factor
fails (a rank-deficient or badly conditioned design), the fit is done by the dense path instead, inside the same
program, as :func:`~polyjax._solve.linalg.tall_qr` falls back to Householder QR.

Not differentiable: the loops have no derivative rule. :func:`polyjax.fit_polynomial` takes this path only for
concrete inputs (a call outside ``jit``/``grad``/``vmap``); traced inputs take the dense, differentiable path.
"""

from __future__ import annotations

import os

import jax
import jax.numpy as jnp

from .._basis import exponents
from .._design import range_scaling
from .._errors import InputError
from .._pca import pca_from_covariance
from .._solve.linalg import cholesky_upper, svd
from .._solve.lstsq import _solve_svd

#: shared-design fits with at least this many samples (and 8 times more than columns plus right-hand sides)
#: are streamed, unless :data:`STREAM_ROWS_ENV` says otherwise (:func:`stream_threshold`)
STREAM_ROWS = 100_000
#: environment variable: the number of samples from which a shared design is streamed (default
#: :data:`STREAM_ROWS`); a machine short of memory streams from fewer, a large number never streams
STREAM_ROWS_ENV = "POLYJAX_STREAM_ROWS"
#: rows per block: the block's design (``m x BLOCK``) and its products stay in the CPU's cache (a core's 1 MB
#: level-2 cache on the machine measured: 4096 rows made the rows' and the values' passes 10-30% faster than 8192)
BLOCK = 4096
#: the preconditioning factor ``R_1`` of CholeskyQR2 is taken from every this many-th row (its Gram matrix costs
#: this fraction of a pass; at least 1024 rows are sampled)
PRECONDITION_STRIDE = 16
#: ... and a further orthogonalising pass is made when ``Q_1 = A E_1^{-1} R_1^{-1}`` is further from orthogonal
#: than this (the condition number of ``R_2 = chol(Q_1^T Q_1)``; 1 for an orthogonal ``Q_1``)
PRECONDITION_CONDITION = 4.0
#: the one-pass solution (semi-normal equations, step 3) is kept when the equilibrated design's condition number
#: is at most this (its error bound ``kappa^2 eps`` is then within this factor of a QR solve's ``kappa eps``,
#: below 1e-13 in float64) ...
SNE_CONDITION = 30.0
#: ... and the residual is at least this fraction of ``b^T b`` (``b^T b - 2 beta^T A^T b + beta^T G beta`` loses
#: at most a factor ``1 / CANCELLATION`` of relative accuracy); otherwise the residual pass refines both
CANCELLATION = 1e-3


def stream_threshold() -> int:
    """The number of samples from which a shared design is streamed: ``$POLYJAX_STREAM_ROWS``, read at every fit,
    else :data:`STREAM_ROWS`.

    Raises:
        InputError: the variable is set but is not a positive integer.
    """
    text = os.environ.get(STREAM_ROWS_ENV, "").strip()
    if not text:
        return STREAM_ROWS
    if not text.isdigit() or int(text) < 1:
        raise InputError(f"${STREAM_ROWS_ENV}: expected a positive number of samples, found {text!r}")
    return int(text)


def use_stream(n: int, m: int, r: int, method: str, shared: bool, concrete: bool) -> bool:
    """Whether :func:`polyjax.fit_polynomial` streams (see the module docstring): concrete inputs, ``method="qr"``,
    a shared design of at least :func:`stream_threshold` samples and 8 times more than columns plus right-hand sides."""
    return method == "qr" and shared and concrete and n >= 8 * (m + r) and n >= stream_threshold()


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


def _stream_map(fn, n: int, block: int, arrays):
    """``fn(*blocks) -> (rows, sums)`` over the row blocks of ``arrays`` (rows first): the per-row outputs ``rows``
    (a tuple of arrays, rows last) written into whole ``(..., n)`` arrays (in place, inside one loop) and the
    ``sums`` added; a loop over full blocks, then the remainder."""

    def take(start, size):
        return [jax.lax.dynamic_slice_in_dim(a, start, size, axis=0) for a in arrays]

    def put(carry, start, size):
        rows, sums = fn(*take(start, size))
        whole, acc = carry
        whole = tuple(jax.lax.dynamic_update_slice_in_dim(w, r, start, axis=-1) for w, r in zip(whole, rows))
        return whole, jax.tree.map(jnp.add, acc, sums)

    rows, sums = jax.eval_shape(fn, *take(0, min(block, n)))
    carry = (tuple(jnp.zeros(r.shape[:-1] + (n,), r.dtype) for r in rows),
             jax.tree.map(lambda s: jnp.zeros(s.shape, s.dtype), sums))
    n_full, rem = divmod(n, block)
    if n_full:
        carry = jax.lax.fori_loop(0, n_full, lambda i, c: put(c, i * block, block), carry)
    if rem:
        carry = put(carry, n_full * block, rem)
    return carry


def _checked_cholesky(g):
    """:func:`polyjax._solve.linalg.cholesky_upper` of ``g`` and whether it succeeded (finite, positive diagonal)."""
    r = cholesky_upper(g)
    return r, jnp.all(jnp.isfinite(r)) & jnp.all(jnp.diagonal(r) > 0)


_HI = jax.lax.Precision.HIGHEST


def _design_t(t_b, max_degree, basis, interactions):
    """The design's rows transposed, ``(m, B)``, of the scaled components ``t_b (k, B)``: the columns of
    :func:`polyjax._basis.design_matrix` (same order, same recurrence), each a contiguous run of samples, so the
    arithmetic is vectorised along the samples and the sums below are matrix products."""
    k = t_b.shape[0]
    table = [jnp.ones_like(t_b), t_b][: max_degree + 1]  # table[d][j] = P_d(t_j) (or t_j^d)
    for d in range(2, max_degree + 1):
        if basis == "monomial":
            table.append(table[-1] * t_b)
        else:  # d P_d = (2d - 1) t P_{d-1} - (d - 1) P_{d-2}, by multiplications (a division costs several)
            table.append(((2 * d - 1) / d) * t_b * table[-1] - ((d - 1) / d) * table[-2])
    if not interactions:  # [1, Z_1..Z_k, Z_1^2..Z_k^2, ...]
        return jnp.concatenate([jnp.ones_like(t_b[:1])] + table[1:], axis=0)
    rows = []
    for e in exponents(k, max_degree, interactions):
        row = jnp.ones_like(t_b[0])
        for j in range(k):
            row = row * table[int(e[j])][j]
        rows.append(row)
    return jnp.stack(rows)


def _rows(t_b, sw_b, max_degree, basis, interactions):
    """``A^T = (W^{1/2} D)^T`` of a block, ``(m, B)``: dropped samples are exact zeros (their ``t`` is 0)."""
    return _design_t(t_b, max_degree, basis, interactions) * sw_b[None]


def _scaled_components(x, keep, pos, basis):
    """The PCA and affine scaling of :func:`polyjax.fitted_design` computed on the ``(k, n)`` layout (each
    component's samples contiguous): ``(pca, centre, halfwidth, t (k, n))``, ``t`` zero where ``pos`` is False.

    Two reductions over ``x`` (the mean, then the centred covariance, as :func:`polyjax.fit_pca`: no raw second
    moments), one over the components (their range) and the pass writing ``t``; on the ``(n, k)`` layout every
    such step ran at a fraction of the memory's speed."""
    xt = x.T  # (k, n)
    kf = keep.astype(x.dtype)
    cnt = jnp.sum(kf)
    mean = jnp.sum(xt * kf[None], axis=1) / jnp.maximum(cnt, 1.0)
    xc = (xt - mean[:, None]) * kf[None]
    k = xt.shape[0]
    # sums of products row by row (XLA's dot of a (k, n) by an (n, k) array ran at a tenth of this speed)
    cov = jnp.stack([jnp.stack([jnp.sum(xc[i] * xc[j]) for j in range(k)]) for i in range(k)])
    pca = pca_from_covariance(mean, cov / jnp.maximum(cnt - 1.0, 1.0))
    z = _rotate(xt, pca.mean, pca.rotation)
    big = jnp.finfo(x.dtype).max
    lo = jnp.min(jnp.where(keep[None], z, big), axis=1)
    hi = jnp.max(jnp.where(keep[None], z, -big), axis=1)
    x_mag = jnp.max(jnp.where(keep[None], jnp.abs(xt), 0.0))
    centre, hw = range_scaling(lo, hi, jnp.any(keep), x_mag, basis)
    return pca, centre, hw, _scale(z, centre, hw, pos)


def _rotate(xt, mean, rotation):
    """The principal components ``Z^T = rotation^T (X^T - mean)``, ``(k, n)``, by rows."""
    xm = xt - mean[:, None]
    k = xt.shape[0]
    return jnp.stack([sum(rotation[j, i] * xm[j] for j in range(k)) for i in range(k)])


def _scale(z, centre, hw, pos):
    return jnp.where(pos[None], (z - centre[:, None]) / hw[:, None], 0.0)


def _root_weights(wc2l):
    pos = wc2l > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, wc2l, 1.0)), 0.0)


def stream_rows(x, wl, wc2l, mean, rotation, centre, halfwidth):
    """The per-sample part of :func:`stream_geometry` given its transform (a geometry kept on disk,
    :mod:`polyjax._cache.geometry`), of the samples ``x`` (a block of them in :func:`kept_rows`): ``t (k, n)``,
    ``sqrt(w cos^2 theta_u)`` and its square, and the samples used and their weight (checked against the kept
    geometry's)."""
    pos = wc2l > 0
    t = _scale(_rotate(x.T, mean, rotation), centre, halfwidth, pos)
    sw = _root_weights(wc2l)
    return dict(t=t, sw=sw, wc2=sw * sw, den=jnp.sum(wl), n_used=jnp.sum(wl > 0))


def sampled_rows(sample, arrays, *, block=None):
    """The explanatory variables transposed, ``(k, n)``, and the weights ``w``, ``w cos^2 theta_u`` ``(n,)`` of every
    sample, a block of :data:`BLOCK` rows at a time inside one loop (``sample`` and ``arrays`` as in
    :func:`kept_rows`): the inputs of :func:`stream_geometry` in one pass over the directions, the variables already
    in the ``(k, n)`` layout its reductions read."""
    block = BLOCK if block is None else int(block)

    def one(*blocks):
        x, wl, wc2l = sample(*blocks)
        return (x.T, wl, wc2l), ()

    return _stream_map(one, arrays[0].shape[0], block, arrays)[0]


def kept_rows(sample, arrays, mean, rotation, centre, halfwidth, *, block=None):
    """:func:`stream_rows` of every sample, a block of :data:`BLOCK` rows at a time inside one loop (over the whole
    arrays at once, XLA read the directions several times, at half the speed): the rows a geometry kept on disk
    (:mod:`polyjax._cache.geometry`) needs, from its transform.

    Args:
        sample: ``(*blocks) -> (x (B, k), w (B,), w cos^2 theta_u (B,))``, the explanatory variables and weights of
            a block of rows of ``arrays``.
        arrays: arrays with the samples first (the directions, weights and mask).
        mean, rotation, centre, halfwidth: the kept transform.
        block: rows per block (default :data:`BLOCK`).

    Returns:
        dict of ``t (k, n)``, ``wc2 (n,)`` (``w cos^2 theta_u``, rounded as ``sqrt(.)^2`` like the geometry's), and
        the samples used and their total weight, ``den`` (checked against the kept geometry's).
    """
    block = BLOCK if block is None else int(block)

    def one(*blocks):
        r = stream_rows(*sample(*blocks), mean, rotation, centre, halfwidth)
        return (r["t"], r["wc2"]), (r["den"], r["n_used"])

    (t, wc2), (den, n_used) = _stream_map(one, arrays[0].shape[0], block, arrays)
    return dict(t=t, wc2=wc2, den=den, n_used=n_used)


def _equilibrated_cholesky(g, act):
    """Column norms ``E`` (from the diagonal of the Gram matrix ``g``) and ``R_1 = chol(E^{-1} g E^{-1})`` over the
    active columns (a unit diagonal elsewhere), with whether the factor succeeded."""
    dtype = g.dtype
    m = g.shape[0]
    raw = jnp.sqrt(jnp.where(act, jnp.diagonal(g), 0.0))
    scale = jnp.where(raw > 0, raw, 1.0)
    pad = jnp.diag(jnp.where(act, 0.0, 1.0).astype(dtype))
    r1, ok = _checked_cholesky(jnp.where(act[:, None] & act[None, :], g / (scale[:, None] * scale[None, :]), 0.0) + pad)
    return scale, jnp.where(ok, r1, jnp.eye(m, dtype=dtype)), ok


def _preconditioner(t, sw, active, rows, block, stride):
    """``(E_1, R_1, ok)`` per degree and whether every row was read: the equilibration and Cholesky factor of the
    Gram matrix of every ``stride``-th row (a sample of the rows, ``1 / stride`` of the work); of every row when
    that factor fails (or ``stride`` is 1). Only a preconditioner: :func:`_orthogonal_pass` then factors
    ``A E_1^{-1} R_1^{-1}`` over every row."""
    n = t.shape[1]

    def gram(t_b, sw_b):
        a = rows(t_b, sw_b)  # (m, B)
        return jnp.matmul(a, a.T, precision=_HI)

    def full():
        return _stream_sum(gram, n, block, (t, sw), (1, 0))

    def factors(g):
        return jax.vmap(_equilibrated_cholesky, in_axes=(None, 0))(g, active)

    if stride <= 1:
        return factors(full()) + (jnp.asarray(True),)
    scale, r1, ok = factors(gram(t[:, ::stride], sw[::stride]) * stride)
    return jax.lax.cond(jnp.all(ok), lambda: (scale, r1, ok, jnp.asarray(False)),
                        lambda: factors(full()) + (jnp.asarray(True),))


def _orthogonal_pass(t, sw, scale, r1inv, rows, block):
    """One pass over the rows: ``C = Q_1^T Q_1`` per degree, ``Q_1 = A E_1^{-1} R_1^{-1}`` built block by block,
    and the squared column norms ``diag(A^T A)``."""

    def body(t_b, sw_b):
        a = rows(t_b, sw_b)  # (m, B)
        q1 = jnp.einsum("mb,dm,dmj->djb", a, 1.0 / scale, r1inv, precision=_HI)  # (D, m, B)
        return jnp.einsum("dib,djb->dij", q1, q1, precision=_HI), jnp.sum(a * a, axis=1)

    return _stream_sum(body, t.shape[1], block, (t, sw), (1, 0))


def stream_geometry(x, wl, wc2l, active, *, max_degree, basis, interactions, block=None, stride=None):
    """What a streamed fit needs of the samples alone (not of the values): steps 1 and 2 of the module docstring.

    Args:
        x: ``(n, k)`` explanatory variables; ``wl``, ``wc2l``: ``(n,)`` the weights ``w`` and ``w cos^2 theta_u``
            (0 for dropped samples); ``active``: ``(D, m)`` columns per degree.
        max_degree, basis, interactions: as in :func:`polyjax.fit_polynomial`.
        block: rows per block (default :data:`BLOCK`); stride: the preconditioner's sample of the rows (default
            :data:`PRECONDITION_STRIDE`).

    Returns:
        A dict of arrays: the PCA and scaling, ``t`` transposed ``(k, n)``, ``w cos^2 theta_u``, ``G``, and
        per degree the column norms ``E``, ``R_1^{-1}``, ``R_2`` (``R = R_2 R_1``), the SVD of ``R``, whether
        the Cholesky factors succeeded, the number of passes over the rows (1 to 3) and whether the preconditioner
        came from the sample of the rows. The same for every material on one grid: :func:`polyjax.fit_polynomial`
        keeps the last one (and :mod:`polyjax._cache.geometry` all but the per-sample arrays, on disk).
    """
    block = BLOCK if block is None else int(block)
    stride = PRECONDITION_STRIDE if stride is None else int(stride)
    dtype = x.dtype
    keep = wl > 0
    pos = wc2l > 0
    pca, centre, hw, t = _scaled_components(x, keep, pos, basis)
    sw = _root_weights(wc2l)
    rows = lambda t_b, sw_b: _rows(t_b, sw_b, max_degree, basis, interactions)  # noqa: E731
    scale1, r1, ok1, read_all = _preconditioner(t, sw, active, rows, block, max(1, min(stride, t.shape[1] // 1024)))
    eye = jnp.eye(r1.shape[-1], dtype=dtype)
    r1inv = _active_inverse(r1, active)
    c, colsq = _orthogonal_pass(t, sw, scale1, r1inv, rows, block)

    def second(act, c):
        r2, ok = _checked_cholesky(c + jnp.diag(jnp.where(act, 0.0, 1.0).astype(dtype)))
        return jnp.where(ok, r2, eye), ok

    r2, ok2 = jax.vmap(second)(active, c)
    # a sample that preconditions badly (Q_1 far from orthogonal) gets one more pass, with R = R_2 R_1 as the
    # preconditioner: the factor is then a CholeskyQR2 of the already well-conditioned A E_1^{-1} R^{-1}
    again = ~jnp.all(_condition_upper(r2) <= PRECONDITION_CONDITION)

    def refine():
        r = jnp.einsum("dij,djk->dik", r2, r1, precision=_HI)
        rinv = _active_inverse(r, active)
        c3, _ = _orthogonal_pass(t, sw, scale1, rinv, rows, block)
        r3, ok3 = jax.vmap(second)(active, c3)
        return r, r3, ok3

    again = again & jnp.all(ok2)
    r1, r2, ok2 = jax.lax.cond(again, refine, lambda: (r1, r2, ok2))
    passes = 1 + read_all.astype(jnp.int32) + again.astype(jnp.int32)
    # the same factor in the exact column norms E of A (those of the dense fit): A E^{-1} = Q R_2 R_1 E_1 E^{-1}
    scale = jax.vmap(lambda act: jnp.where(act & (colsq > 0), jnp.sqrt(jnp.where(act, colsq, 1.0)), 1.0))(active)
    r1 = r1 * (scale1 / scale)[:, None, :]
    r1inv = _active_inverse(r1, active)

    def finish(act, r1, r2, e):
        r = jnp.where(act[:, None] & act[None, :], r2 @ r1, 0.0)
        uu, s, vt = svd(r)
        return uu, s, vt, (r.T @ r) * e[:, None] * e[None, :]  # G = A^T A = E R^T R E

    uu, s, vt, g = jax.vmap(finish)(active, r1, r2, scale)
    g = g[jnp.argmax(jnp.sum(active, axis=1))]  # every column active: the degree p itself
    return dict(mean=pca.mean, rotation=pca.rotation, centre=centre, halfwidth=hw, t=t, wc2=sw * sw,
                g=g, den=jnp.sum(wl), n_used=jnp.sum(keep), scale=scale, r1inv=r1inv, r2=r2, u=uu, s=s, vt=vt,
                ok=jnp.all(ok1) & jnp.all(ok2), passes=passes, sampled=~read_all)


def _active_inverse(r, active):
    """``R^{-1}`` of the upper triangular factors ``r (D, m, m)``, rows of inactive columns (``active (D, m)``)
    zeroed."""
    eye = jnp.eye(r.shape[-1], dtype=r.dtype)
    return jax.vmap(lambda r, a: jax.scipy.linalg.solve_triangular(r, eye, lower=False) * a[:, None])(r, active)


def _condition_upper(r):
    """The condition numbers of the triangular factors ``r (D, m, m)`` (1 for the factor of an orthogonal
    ``Q_1``)."""
    s = jax.vmap(lambda a: svd(a)[1])(r)
    return s[:, 0] / s[:, -1]


def _solve_from_geometry(geo, act_all, atb, n, rcond):
    """``beta`` (D, r, m) minimising ``|b - A beta|`` given ``A^T b`` (D, m, r), per degree, from the geometry's
    ``E``, ``R_1^{-1}``, ``R_2`` and SVD of ``R`` (step 3 of the module docstring); also rank, condition and the
    number of active columns."""

    def one(act, scale, r1inv, r2, uu, s, vt, atb):
        q1tb = r1inv.T @ (atb / scale[:, None])  # (E R_1)^{-T} A^T b
        qtb = jax.scipy.linalg.solve_triangular(r2, q1tb, lower=False, trans="T") * act[:, None]
        (coef, rank, cond, _, n_act), _ = _solve_svd(uu, s, vt, uu.T @ qtb, scale, act, n, rcond)
        return coef.T, rank, cond, n_act

    return jax.vmap(one)(act_all, geo["scale"], geo["r1inv"], geo["r2"], geo["u"], geo["s"], geo["vt"], atb)


def streamed_lane(geo, y, active, *, max_degree, basis, interactions, rcond, dense, block=None):
    """The shared-design fit of every right-hand side of ``y (r, n)`` for every degree, streamed.

    Args:
        geo: :func:`stream_geometry` of the samples.
        y: ``(r, n)`` values; ``active``: ``(D, m)`` columns per degree.
        max_degree, basis, interactions, rcond: as in :func:`polyjax.fit_polynomial`.
        dense: ``() -> outputs``, the dense fit, run instead when a Cholesky factor fails.
        block: rows per block (default :data:`BLOCK`).

    Returns:
        The outputs of the dense fit of ``polyjax._fit.closed_form``: ``((mean, rotation, centre, halfwidth),
        coef (D, r, m), l2 (D, r), rank (D,), condition (D,), n_active (D,), n_used)``.
    """
    block = BLOCK if block is None else int(block)
    t, wc2 = geo["t"], geo["wc2"]
    n = t.shape[1]
    design = lambda t_b: _design_t(t_b, max_degree, basis, interactions)  # noqa: E731
    g = geo["g"]
    n_deg = active.shape[0]

    def streamed():
        def rhs(t_b, y_b, wc2_b):  # step 3: A^T b = D^T W y, and b^T b = y^T W y
            wy = y_b * wc2_b[None]  # (r, B)
            return jnp.einsum("mb,rb->mr", design(t_b), wy, precision=_HI), jnp.sum(wy * y_b, axis=-1)

        atb, bb = _stream_sum(rhs, n, block, (t, y, wc2), (1, 1, 0))
        coef0, rank, cond, n_act = _solve_from_geometry(geo, active, jnp.broadcast_to(atb, (n_deg,) + atb.shape), n,
                                                        rcond)
        num0 = _residual_norm(bb, coef0, atb, g)  # (D, r)
        one_pass = jnp.all(cond <= SNE_CONDITION) & jnp.all(num0 >= CANCELLATION * bb)

        def refined():
            def residuals(t_b, y_b, wc2_b):  # step 4: |r_0|^2 and A^T r_0 per degree
                d = design(t_b)  # (m, B)
                e = y_b[None] - jnp.einsum("drm,mb->drb", coef0, d, precision=_HI)  # (D, r, B)
                we = e * wc2_b[None, None]
                return jnp.sum(we * e, axis=-1), jnp.einsum("mb,drb->dmr", d, we, precision=_HI)

            r0, atr = _stream_sum(residuals, n, block, (t, y, wc2), (1, 1, 0))
            delta = _solve_from_geometry(geo, active, atr, n, rcond)[0]  # (D, r, m)
            num = r0 - 2.0 * jnp.einsum("drm,dmr->dr", delta, atr) + jnp.einsum("drm,mk,drk->dr", delta, g, delta)
            return coef0 + delta, num

        coef, num = jax.lax.cond(one_pass, lambda: (coef0, num0), refined)
        num = jnp.maximum(num, 0.0)
        den = geo["den"]
        nz = (den > 0) & (num != 0)
        l2 = jnp.where(nz, jnp.sqrt(jnp.where(nz, num, 1.0) / jnp.where(nz, den, 1.0)), 0.0)
        l2 = jnp.where(den > 0, l2, jnp.inf)
        tr = (geo["mean"], geo["rotation"], geo["centre"], geo["halfwidth"])
        return tr, coef, l2, rank, cond, n_act, geo["n_used"]

    return jax.lax.cond(geo["ok"], streamed, dense)


def _residual_norm(bb, coef, atb, g):
    """``|b - A beta|^2 = b^T b - 2 beta^T A^T b + beta^T G beta`` per degree and right-hand side."""
    return bb - 2.0 * jnp.einsum("drm,mr->dr", coef, atb) + jnp.einsum("drm,mk,drk->dr", coef, g, coef)
