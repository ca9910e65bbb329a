r"""Weighted fits of several lanes on one design's rows, each lane with weights of its own, every pass over the rows
shared by the lanes.

The log-space fit (:mod:`polyjax._fit.log`) solves, for every lane ``l`` (a colour channel) and every solve of its
Gauss-Newton sequence, the weighted least-squares problem ``min |W_l^{1/2} (y_l - D beta)|`` on one design ``D``
(``n x m``, the rows of the samples' scaled principal components ``t``): the rows are the same for every lane and
solve, the weights ``W_l = diag(w_l cos^2 theta_u)`` change with the lane and the solve. Each solve is CholeskyQR2
(Fukaya et al. 2014) with a preconditioner, as :mod:`polyjax._fit.stream` factorises one weighted design, with
``A_l = W_l^{1/2} D`` and ``b_l = W_l^{1/2} y_l``:

0. **Rows and preconditioner, once** (:func:`lane_rows`): one preconditioner serves every lane and solve, the
   equilibrated Cholesky factor ``E_1, R_1`` of the sum of the lanes' Gram matrices of a sample of the rows (every
   :data:`polyjax._fit.stream.PRECONDITION_STRIDE`-th), each divided by its trace, under the weights of the first
   solve. The preconditioned rows ``P = (E_1 R_1)^{-T} D^T`` (``m x n``) are made once, a block of
   :data:`polyjax._fit.stream.BLOCK` samples at a time, and held while they take at most :data:`HOLD_BYTES`
   (352,745 x 45 in float64: 127 MB); beyond, every pass rebuilds its blocks from ``t``, as the streamed fit does.
   The polynomials' values at the samples are ``(beta^T E_1 R_1^T) P``: one product with the held rows.
1. **One pass per solve** (:func:`lanes_geometry`), a block of rows at a time, for all the lanes at once:
   ``C_l = Q_1,l^T Q_1,l`` with ``Q_1,l = W_l^{1/2} P^T = A_l E_1^{-1} R_1^{-1}`` (the second pass of CholeskyQR2,
   whose accuracy needs only a well-conditioned ``Q_1,l``: its orthogonality error is ``O(eps cond(Q_1,l)^2)``),
   ``Q_1,l^T b_l`` and ``b_l^T b_l``. The lanes' weights differ by smooth factors (the channels of one material;
   a Gauss-Newton step's weights from the last step's), so one preconditioner keeps every ``Q_1,l`` well
   conditioned (on the DiLiGenT ball ``cond(Q_1,l)`` stays below 2.8); ``R_2,l = chol(C_l)``, and when a
   ``cond(R_2,l)`` exceeds :data:`polyjax._fit.stream.PRECONDITION_CONDITION` the pass is made again with each
   lane's own ``R_2,l R_1`` (as :func:`polyjax._fit.stream.stream_geometry` does). The column norms
   ``E_l = diag(A_l^T A_l)^{1/2}`` come from ``C_l``: ``A_l^T A_l = (R_1 E_1)^T C_l (R_1 E_1)``, accurate to
   ``O(eps)`` since ``C_l`` is near the identity. ``R_l = R_2,l R_1 E_1 E_l^{-1}`` and its SVD give the rank and
   condition of :func:`polyjax.weighted_lstsq`.
2. **The solution** (:func:`lanes_solve`): ``Q_l^T b_l = R_2,l^{-T} Q_1,l^T b_l`` and ``beta_l = E_l^{-1} R_l^+
   Q_l^T b_l`` by the SVD ``R_l = U S V^T`` (the minimum-norm solution of :func:`polyjax.weighted_lstsq`):
   ``Q_1,l^T b_l`` is summed from the rows of ``Q_1,l`` themselves, so no residual pass is needed for accuracy (the
   semi-normal equations of the streamed fit, ``Q^T b`` from ``A^T b``, need one). The L2 of equation (11) from
   ``|b - A beta|^2 = b^T b - |U_r^T Q^T b|^2`` (``U_r`` the kept singular vectors; absolute error
   ``O(eps b^T b)``: the log-space fit scores its steps with the model's own residuals).

Per solve the rows are read once: ``2 n m^2`` flops per lane for ``C_l`` (one product for the ``L`` lanes), the
rows of ``Q_1`` made once for every solve; the polynomials' values at the samples are one product with the held rows
(:meth:`Rows.values`). Not differentiable (loops without derivative rules): :func:`polyjax.fit_log_polynomial`
takes this path only for concrete inputs.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .._basis import n_terms
from .._solve.linalg import svd
from .._solve.lstsq import _solve_svd
from .stream import (
    BLOCK,
    PRECONDITION_CONDITION,
    PRECONDITION_STRIDE,
    _active_inverse,
    _checked_cholesky,
    _condition_upper,
    _design_t,
    _equilibrated_cholesky,
    _root_weights,
    _stream_map,
    _stream_sum,
)

#: the preconditioned rows are held (made once) while they take at most this many bytes; beyond, each pass rebuilds
#: them block by block
HOLD_BYTES = 1 << 29

_HI = jax.lax.Precision.HIGHEST


class Rows:
    """The design's rows as the passes read them (made by :func:`lane_rows`).

    Attributes:
        spec, n, block: ``(max_degree, basis, interactions)``, the number of samples, rows per block.
        held: whether ``P`` is held (:data:`HOLD_BYTES`).
        source: the preconditioned rows ``P = (E_1 R_1)^{-T} D^T`` ``(m, n)`` when :attr:`held`, else the scaled
            components ``t (k, n)`` the rows are rebuilt from, block by block.
        scale, r1, ok: the shared preconditioner ``E_1 (m,)``, ``R_1 (m, m)`` and whether its factor succeeded.
        factor: ``(E_1 R_1)^{-T}`` ``(m, m)``.
    """

    def __init__(self, spec, n, block, held, source, scale, r1, ok, factor):
        self.spec, self.n, self.block, self.held = spec, n, block, held
        self.source, self.scale, self.r1, self.ok, self.factor = source, scale, r1, ok, factor

    def design(self, block):
        """The rows ``D_b^T (m, B)`` of a block of :attr:`source` (held: ``E_1 R_1^T P_b``, for the passes that do not
        use the shared preconditioner: a lane it serves badly, or a factor that failed)."""
        if self.held:
            return jnp.matmul(self.r1.T * self.scale[:, None], block, precision=_HI)
        return _design_t(block, *self.spec)

    def pre(self, block):
        """The preconditioned rows ``P_b (m, B)`` of a block of :attr:`source`."""
        return block if self.held else jnp.matmul(self.factor, _design_t(block, *self.spec), precision=_HI)

    def values(self, coef):
        """``coef (L, m)`` times the rows: the polynomials' values ``(L, n)`` at every sample (held: ``(coef E_1
        R_1^T) P``)."""
        if self.held:
            return jnp.matmul(jnp.matmul(coef * self.scale, self.r1.T, precision=_HI), self.source, precision=_HI)

        def block(t_b):
            return (jnp.matmul(coef, _design_t(t_b.T, *self.spec), precision=_HI),), ()

        return _stream_map(block, self.n, self.block, (self.source.T,))[0][0]

    def sum(self, fn, *arrays, pre: bool = False):
        """``sum_b fn(rows_b (m, B), *arrays_b)`` over the blocks (``arrays`` with the samples along their last axis),
        the rows ``P_b`` with ``pre``, else ``D_b``."""
        rows = self.pre if pre else self.design
        return _stream_sum(lambda src, *rest: fn(rows(src), *rest), self.n, self.block, (self.source,) + arrays,
                           (1,) + tuple(a.ndim - 1 for a in arrays))


def _factor_rows(r1inv, scale):
    """``(E R)^{-T}`` from ``R^{-1}`` and ``E`` (batched over leading axes): ``Q_1^T = (E R)^{-T} D^T W^{1/2}``."""
    return jnp.swapaxes(r1inv / scale[..., :, None], -1, -2)


def _gram(a, sw):
    """The lanes' Gram matrices ``sum_b w_l d_b d_b^T`` of rows ``a (m, B)``, ``w_l = sw_l^2`` (``sw (L, B)``)."""
    return jnp.einsum("mb,lb,kb->lmk", a, sw * sw, a, precision=_HI)


def lane_rows(t, max_degree: int, basis: str, interactions: bool, wc2l, active, *, block: int | None = None,
              stride: int | None = None) -> Rows:
    """Step 0 of the module docs: the rows of the scaled components ``t (k, n)`` and the preconditioner shared by the
    lanes of weights ``wc2l (L, n)`` (``w cos^2 theta_u`` of the first solve); ``active (m,)`` the design's columns.
    ``block``: rows per block (default :data:`polyjax._fit.stream.BLOCK`); ``stride``: the sample's (default
    :data:`polyjax._fit.stream.PRECONDITION_STRIDE`; at least 1024 rows are sampled)."""
    spec = (max_degree, basis, interactions)
    n = t.shape[1]
    block = BLOCK if block is None else int(block)
    stride = PRECONDITION_STRIDE if stride is None else int(stride)
    stride = max(1, min(stride, n // 1024))
    sw = _root_weights(wc2l[:, ::stride])
    g = _gram(_design_t(t[:, ::stride], *spec), sw)
    tr = jnp.trace(g, axis1=1, axis2=2)
    scale, r1, ok = _equilibrated_cholesky(jnp.sum(g / jnp.where(tr > 0, tr, 1.0)[:, None, None], axis=0), active)
    factor = _factor_rows(_active_inverse(r1[None], active[None])[0], scale)
    held = n_terms(t.shape[0], max_degree, interactions) * n * t.dtype.itemsize <= HOLD_BYTES
    source = t
    if held:
        def one(t_b):
            return (jnp.matmul(factor, _design_t(t_b.T, *spec), precision=_HI),), ()

        source = _stream_map(one, n, block, (t.T,))[0][0]
    return Rows(spec, n, block, held, source, scale, r1, ok, factor)


def _orthogonal_pass(rows: Rows, sw, y, factors=None):
    """One pass over the rows (step 1 of the module docs): per lane ``C_l = Q_1,l^T Q_1,l``, ``Q_1,l^T b_l`` and
    ``b_l^T b_l`` for the values ``y (L, n)``; ``Q_1,l`` from the lanes' own ``(E_1,l R_1,l)^{-T}`` ``factors (L, m,
    m)`` (made block by block), or, when None, ``W_l^{1/2} P^T`` of the shared preconditioner (one product of the
    block's ``P`` with the lanes' weights)."""
    if factors is None:
        def shared(p, sw_b, y_b):
            wc2 = sw_b * sw_b
            wy = y_b * wc2
            return (jnp.einsum("jb,lb,kb->ljk", p, wc2, p, precision=_HI),
                    jnp.einsum("jb,lb->lj", p, wy, precision=_HI), jnp.sum(wy * y_b, axis=-1))

        return rows.sum(shared, sw, y, pre=True)

    def own(a, sw_b, y_b):
        q = jnp.einsum("ljm,mb->ljb", factors, a, precision=_HI) * sw_b[:, None, :]
        sy = sw_b * y_b
        return (jnp.einsum("ljb,lkb->ljk", q, q, precision=_HI), jnp.einsum("ljb,lb->lj", q, sy, precision=_HI),
                jnp.sum(sy * sy, axis=-1))

    return rows.sum(own, sw, y)


def _column_norms(c, r1, scale1):
    """``diag(A_l^T A_l)`` from ``C_l = Q_1,l^T Q_1,l`` and ``A_l = Q_1,l R_1,l E_1,l`` (``r1 (L, m, m)``,
    ``scale1 (L, m)``): ``Q_1,l`` is near orthogonal, so this is accurate to ``O(eps)`` relative without a product
    of its own in the pass."""
    re = r1 * scale1[:, None, :]
    return jnp.einsum("ljm,ljk,lkm->lm", re, c, re, precision=_HI)


def _first_pass(rows: Rows, sw, y, act):
    """Step 1's pass with the shared preconditioner, or, when its factor failed, with each lane's own factor from the
    Gram matrices of every row (an extra pass): ``(E_1, R_1, ok)`` per lane, the pass's sums and whether that extra
    pass was made."""
    nl = act.shape[0]

    def shared():
        lanes = (jnp.broadcast_to(rows.scale, act.shape), jnp.broadcast_to(rows.r1, (nl,) + rows.r1.shape),
                 jnp.broadcast_to(rows.ok, (nl,)))
        return lanes + _orthogonal_pass(rows, sw, y) + (jnp.asarray(False),)

    def own():
        scale, r1, ok = jax.vmap(_equilibrated_cholesky)(rows.sum(_gram, sw), act)
        sums = _orthogonal_pass(rows, sw, y, _factor_rows(_active_inverse(r1, act), scale))
        return (scale, r1, ok) + sums + (jnp.asarray(True),)

    return jax.lax.cond(rows.ok, shared, own)


def lanes_geometry(rows: Rows, wl, wc2l, y, active) -> dict:
    """Step 1 of the module docs for the lanes' weights ``wl`` (``w``) and ``wc2l`` (``w cos^2 theta_u``),
    ``(L, n)``, 0 for dropped samples, and values ``y (L, n)``; ``active (m,)`` the design's columns.

    Returns:
        dict of ``(L, ...)`` arrays: the column norms ``scale``, ``R_2`` ``r2``, the SVD ``u, s, vt`` of ``R`` (as
        :func:`polyjax._fit.stream.stream_geometry` makes them for one degree), ``ok`` (every Cholesky factor
        succeeded), ``Q_1^T b`` ``q1tb``, ``b^T b`` ``bb``, ``den``, ``n_used`` and
        the passes over the rows (1 to 3).
    """
    nl, m = wl.shape[0], active.shape[0]
    dtype = wc2l.dtype
    act = jnp.broadcast_to(active, (nl, m))
    sw = _root_weights(wc2l)
    scale1, r1, ok1, c, q1tb, bb, read_all = _first_pass(rows, sw, y, act)
    colsq = _column_norms(c, r1, scale1)
    eye = jnp.eye(m, dtype=dtype)

    def second(a, c):
        r2, ok = _checked_cholesky(c + jnp.diag(jnp.where(a, 0.0, 1.0).astype(dtype)))
        return jnp.where(ok, r2, eye), ok

    r2, ok2 = jax.vmap(second)(act, c)
    # a preconditioner that serves a lane badly: one more pass, R_2 R_1 each lane's own (as stream_geometry)
    again = jnp.any(ok2 & ~(_condition_upper(r2) <= PRECONDITION_CONDITION))

    def refine():
        r = jnp.einsum("lij,ljk->lik", r2, r1, precision=_HI)
        c3, q1tb3 = _orthogonal_pass(rows, sw, y, _factor_rows(_active_inverse(r, act), scale1))[:2]
        r3, ok3 = jax.vmap(second)(act, c3)
        return r, r3, ok3, q1tb3

    r1, r2, ok2, q1tb = jax.lax.cond(again, refine, lambda: (r1, r2, ok2, q1tb))
    # the factor in the exact column norms E of A: A E^{-1} = Q R_2 R_1 E_1 E^{-1}
    scale = jnp.where(act & (colsq > 0), jnp.sqrt(jnp.where(act, colsq, 1.0)), 1.0)
    r1 = r1 * (scale1 / scale)[:, None, :]

    uu, s, vt = jax.vmap(lambda a, r1, r2: svd(jnp.where(a[:, None] & a[None, :], r2 @ r1, 0.0)))(act, r1, r2)
    return dict(scale=scale, r2=r2, u=uu, s=s, vt=vt, ok=ok1 & ok2, q1tb=q1tb, bb=bb,
                den=jnp.sum(wl, axis=-1), n_used=jnp.sum(wl > 0, axis=-1),
                passes=1 + read_all.astype(jnp.int32) + again.astype(jnp.int32))


def lanes_solve(geo: dict, n: int, active, *, rcond):
    """Step 2 of the module docs for every lane of :func:`lanes_geometry` ``geo`` (``n`` samples):
    ``(coef (L, m), l2 (L,), rank, condition, active terms)``."""

    def one(a, scale, r2, uu, s, vt, q1tb, bb):
        qtb = jax.scipy.linalg.solve_triangular(r2, q1tb[:, None], lower=False, trans="T") * a[:, None]
        utb = uu.T @ qtb
        (coef, rank, cond, _, n_act), aux = _solve_svd(uu, s, vt, utb, scale, a, n, rcond)
        return coef[:, 0], rank, cond, n_act, bb - jnp.sum(jnp.where(aux["nonzero"], utb[:, 0], 0.0) ** 2)

    act = jnp.broadcast_to(active, geo["q1tb"].shape)
    coef, rank, cond, n_act, num = jax.vmap(one)(act, geo["scale"], geo["r2"], geo["u"], geo["s"], geo["vt"],
                                                 geo["q1tb"], geo["bb"])
    num = jnp.maximum(num, 0.0)
    den = geo["den"]
    nz = (den > 0) & (num != 0)
    l2 = jnp.where(nz, jnp.sqrt(jnp.where(nz, num, 1.0) / jnp.where(nz, den, 1.0)), 0.0)
    return coef, jnp.where(den > 0, l2, jnp.inf), rank, cond, n_act
