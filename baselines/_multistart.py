"""The multi-start kernel, one solver loop: every start for ``stage_steps`` steps, the ``refine`` best of each lane
to convergence, the best converged start kept, and a kept start that ran out of steps next to its parameters' range
limits put on them and finished (see :func:`baselines.fit`).

All of it is one ``fori_loop`` over *jobs*; each job solves one block of ``(B, R)`` starts (``R = refine``, one
start per lane by default) with a step budget per start (:func:`baselines._lm.lm_solve`), so the Levenberg-Marquardt
loop is traced and compiled once per (model, shapes) whatever the stages:

- stage 1: ``ceil(S / R)`` jobs, the starts ``[j R, (j + 1) R)`` of every lane, ``stage_steps`` steps each;
- stage 2: one job, the ``R`` best starts of each lane after stage 1, ``max_steps - stage_steps`` steps (0 for those
  stage 1 already converged);
- range limits: per round (two at most), the kept start put on its limits with the two tolerances of
  :data:`_LIMIT_TOLS` (``ceil(2 / R)`` jobs), ``limit_steps`` steps for lanes that need it and 0 for the others.

A job's work is that of its block, so the stages cost what separate solves of the same sizes cost; the jaxopt
backend keeps its own staged kernel (:mod:`baselines._staged`).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from polyjax import Result

from ._lm import lm_solve
from ._registry import get_model
from ._solvers import residual_fn
from ._staged import _LIMIT_TOLS, _at, _pick, finish
from ._starts import starts as make_starts

_LIMIT_ROUNDS = 2
_A, _B, _C = 0, 1, 2  # job kinds: stage 1, stage 2, range-limit round


def _solve_block(model, u, v, y, sw, scale, raw0, budget, rtol, atol):
    """``raw0 (B, R, P)``, ``budget (B, R)`` -> raw, code, steps, L2 ``(B, R, ...)`` (L2 ``inf`` if not finite)."""
    fn = residual_fn(model, u, v)

    def one(r0, b, yb, swb):
        raw, code, steps = lm_solve(fn, r0, (yb, swb), b, rtol, atol)
        res = fn(raw, (yb, swb))
        loss = jnp.sum(res * res)
        finite = jnp.isfinite(loss) & jnp.all(jnp.isfinite(raw))
        return raw, jnp.where(finite, code, Result.NONFINITE), steps, jnp.where(finite, jnp.sqrt(loss), jnp.inf)

    raw, code, steps, l2 = jax.vmap(jax.vmap(one, in_axes=(0, 0, None, None)))(raw0, budget, y, sw)
    return raw, code, steps, l2 * scale


def _schedule(ns, refine, limit_steps):
    """Static job table: ``(R, kinds, n_stage1_jobs, jobs_per_round)``."""
    r = ns if refine is None or refine >= ns else refine
    n_a = -(-ns // r)
    kinds = [_A] * n_a + ([_B] if r < ns else [])
    per_round = -(-len(_LIMIT_TOLS) // r)
    kinds += [_C] * (per_round * (_LIMIT_ROUNDS if limit_steps > 0 else 0))
    return r, np.asarray(kinds, np.int32), n_a, per_round


@functools.partial(
    jax.jit,
    static_argnames=("name", "n_starts", "max_steps", "rtol", "atol", "stage_steps", "refine", "limit_steps"),
)
def fit_kernel(name, u, v, y, wl, wc2, key, raw0, *, n_starts, max_steps, rtol, atol, stage_steps, refine, limit_steps):
    """Every start of every lane ``y (B, n)`` through the job schedule of the module docs; a dict of ``(B, ...)``
    arrays (see :class:`baselines.BaselineFit`). Not differentiable itself: :func:`baselines.fit` attaches the
    derivative of the kept optimum (:mod:`baselines._implicit`)."""
    model = get_model(name)
    den = jnp.sum(wl, axis=-1, keepdims=True)
    sw = jnp.sqrt(wc2 / jnp.where(den > 0, den, 1.0))
    # residuals in units of the data's own L2 (the L2 of f = 0), so the tolerances are relative
    scale = jnp.sqrt(jnp.sum(sw * sw * y * y, axis=-1, keepdims=True))
    scale = jnp.where(scale > 0, scale, 1.0)
    sw = sw / scale
    if raw0 is None:
        raw0 = make_starts(model, u, v, y, wc2, key, n_starts)
    nb, ns, npar = raw0.shape
    r, kinds, n_a, per_round = _schedule(ns, refine, limit_steps)
    one_stage = r == ns
    rows = jnp.arange(nb)[:, None]
    ncand = per_round * r
    i32, f = jnp.int32, raw0.dtype
    carry0 = dict(
        raw=raw0, code=jnp.full((nb, ns), Result.MAX_STEPS, i32), steps=jnp.zeros((nb, ns), i32),
        sl2=jnp.full((nb, ns), jnp.inf, f), order=jnp.zeros((nb, r), i32),
        best=jnp.zeros((nb,), i32), raw_b=raw0[:, 0], code_b=jnp.zeros((nb,), i32), l2_b=jnp.zeros((nb,), f),
        steps_b=jnp.zeros((nb,), i32), retry=jnp.zeros((nb,), bool), cand=jnp.zeros((nb, ncand, npar), f),
        craw=jnp.zeros((nb, ncand, npar), f), ccode=jnp.zeros((nb, ncand), i32), csteps=jnp.zeros((nb, ncand), i32),
        cl2=jnp.full((nb, ncand), jnp.inf, f),
    )
    stage1_idx = lambda j: jnp.minimum(j * r + jnp.arange(r), ns - 1)  # noqa: E731  (padding repeats the last)
    full = lambda n: jnp.full((nb, r), n, i32)  # noqa: E731

    def pick_best(c):
        best = _pick(c["sl2"], c["code"]).astype(i32)
        return dict(c, best=best, raw_b=_at(c["raw"], best), code_b=_at(c["code"], best).astype(i32),
                    steps_b=_at(c["steps"], best), l2_b=_at(c["sl2"], best))

    def prep_a(j, c):
        return c, c["raw"][:, stage1_idx(j)], full(max_steps if one_stage else stage_steps)

    def prep_b(j, c):
        order = jnp.argsort(c["sl2"], axis=1)[:, :r].astype(i32)
        done = jnp.take_along_axis(c["code"], order, axis=1) == Result.OK
        block = jnp.take_along_axis(c["raw"], order[..., None], axis=1)
        return dict(c, order=order), block, jnp.where(done, 0, max(max_steps - stage_steps, 1)).astype(i32)

    def prep_c(j, c):
        sub = (j - (len(kinds) - per_round * _LIMIT_ROUNDS)) % per_round
        snapped = [model.snap_to_limits(c["raw_b"], tol) for tol in _LIMIT_TOLS]  # candidates, tightest first
        retry = (c["code_b"] == Result.MAX_STEPS) & jnp.any(snapped[-1][1], axis=-1)
        cand = jnp.stack([jnp.where(retry[:, None], s, c["raw_b"]) for s, _ in snapped], axis=1)
        cand = jnp.concatenate([cand, jnp.repeat(cand[:, -1:], ncand - cand.shape[1], axis=1)], axis=1)
        first = sub == 0  # a round's candidates are made by its first job
        c = dict(c, cand=jnp.where(first, cand, c["cand"]), retry=jnp.where(first, retry, c["retry"]))
        block = jax.lax.dynamic_slice_in_dim(c["cand"], sub * r, r, axis=1)
        return c, block, jnp.where(c["retry"][:, None], limit_steps, 0).astype(i32) * jnp.ones((1, r), i32)

    def store_a(j, c, res):
        idx = stage1_idx(j)
        c = dict(c, **{k: c[k].at[:, idx].set(a) for k, a in zip(("raw", "code", "steps", "sl2"), res)})
        return jax.lax.cond(j == n_a - 1, pick_best, lambda c: c, c) if one_stage else c

    def store_b(j, c, res):
        raw2, code2, steps2, sl22 = res
        order = c["order"]
        take = lambda a: jnp.take_along_axis(a, order.reshape(order.shape + (1,) * (a.ndim - 2)), axis=1)  # noqa
        d = take(c["code"]) == Result.OK  # converged in stage 1: keep its stage-1 state
        c = dict(
            c, raw=c["raw"].at[rows, order].set(jnp.where(d[..., None], take(c["raw"]), raw2)),
            code=c["code"].at[rows, order].set(jnp.where(d, take(c["code"]), code2)),
            steps=c["steps"].at[rows, order].set(take(c["steps"]) + jnp.where(d, 0, steps2)),
            sl2=c["sl2"].at[rows, order].set(jnp.where(d, take(c["sl2"]), sl22)),
        )
        return pick_best(c)

    def store_c(j, c, res):
        sub = (j - (len(kinds) - per_round * _LIMIT_ROUNDS)) % per_round
        c = dict(c, **{k: jax.lax.dynamic_update_slice_in_dim(c[k], a, sub * r, axis=1)
                       for k, a in zip(("craw", "ccode", "csteps", "cl2"), res)})
        ncand_real = len(_LIMIT_TOLS)
        raw_p, code_p = c["craw"][:, :ncand_real], c["ccode"][:, :ncand_real]
        steps_p, l2_p = c["csteps"][:, :ncand_real], c["cl2"][:, :ncand_real]
        # the best candidate is kept if its L2 is no worse than before; its own status is reported
        better = jnp.isfinite(l2_p) & (l2_p <= (c["l2_b"] * (1.0 + rtol) + atol * scale[:, 0])[:, None])
        k = _pick(jnp.where(better, l2_p, jnp.inf), code_p)
        at = functools.partial(_at, idx=k)
        take_p = c["retry"] & at(better) & (sub == per_round - 1)  # a round is decided by its last job
        spent = c["retry"] & (sub == per_round - 1)
        return dict(
            c, raw_b=jnp.where(take_p[:, None], at(raw_p), c["raw_b"]),
            code_b=jnp.where(take_p, at(code_p), c["code_b"]),
            l2_b=jnp.where(take_p, at(l2_p), c["l2_b"]), steps_b=c["steps_b"] + jnp.where(spent, at(steps_p), 0),
        )

    def job(j, c):
        kind = jnp.asarray(kinds)[j]
        c, block, budget = jax.lax.switch(kind, (prep_a, prep_b, prep_c), j, c)
        res = _solve_block(model, u, v, y, sw, scale, block, budget, rtol, atol)  # the one solver loop
        return jax.lax.switch(kind, (store_a, store_b, store_c), j, c, res)

    c = jax.lax.fori_loop(0, len(kinds), job, carry0)
    return finish(model, wc2, raw0, c)
