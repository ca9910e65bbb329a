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
backend keeps its own staged kernel (:mod:`baselines._jaxopt.staged`).
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from polyjax import RESULTS

from ._lm import lm_solve
from ._models.registry import get_model
from ._starts import starts as make_starts

_A, _B, _C = 0, 1, 2  # job kinds: stage 1, stage 2, range-limit round


def _solve_block(model, u, v, y, sw, scale, raw0, budget, rtol, atol):
    """``raw0 (B, R, P)``, ``budget (B, R)`` -> raw, code, steps, L2 ``(B, R, ...)`` (L2 ``inf`` if not finite)."""
    fn = residual_fn(model, u, v)

    def one(r0, b, yb, swb):
        raw, code, steps = lm_solve(fn, r0, (yb, swb), b, rtol, atol)
        res = fn(raw, (yb, swb))
        loss = jnp.sum(res * res)
        finite = jnp.isfinite(loss) & jnp.all(jnp.isfinite(raw))
        return raw, jnp.where(finite, code, RESULTS.NONFINITE), steps, jnp.where(finite, jnp.sqrt(loss), jnp.inf)

    if raw0.shape[1] == 1:  # one start per lane and job (refine=1, the default): one vmap level traces in half
        raw, code, steps, l2 = (a[:, None] for a in jax.vmap(one)(raw0[:, 0], budget[:, 0], y, sw))
    else:
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


class _Plan(NamedTuple):
    """The static numbers of a job schedule: ``r`` starts per lane and job, ``ns`` starts per lane, ``n_a`` stage-1
    jobs, ``per_round`` jobs per range-limit round, ``n_jobs`` in all, and the options they run with."""

    r: int
    ns: int
    n_a: int
    per_round: int
    n_jobs: int
    max_steps: int
    stage_steps: int
    limit_steps: int
    rtol: float
    atol: float

    @property
    def one_stage(self) -> bool:  # every start runs to the end in stage 1 (no stage 2)
        return self.r == self.ns

    @property
    def n_cand(self) -> int:  # range-limit candidates per lane and round, padded to whole jobs
        return self.per_round * self.r


@functools.partial(
    jax.jit,
    static_argnames=("name", "n_starts", "max_steps", "rtol", "atol", "stage_steps", "refine", "limit_steps"),
)
def fit_kernel(name, u, v, y, wl, wc2, key, raw0, *, n_starts, max_steps, rtol, atol, stage_steps, refine, limit_steps):
    """Every start of every lane ``y (B, n)`` through the job schedule of the module docs; a dict of ``(B, ...)``
    arrays (see :class:`baselines.BaselineFit`). Not differentiable itself: :func:`baselines.fit` attaches the
    derivative of the kept optimum (:mod:`baselines._implicit`)."""
    model = get_model(name)
    sw, scale, raw0 = prepare_lanes(model, u, v, y, wl, wc2, key, raw0, n_starts)
    r, kinds, n_a, per_round = _schedule(raw0.shape[1], refine, limit_steps)
    plan = _Plan(r, raw0.shape[1], n_a, per_round, len(kinds), max_steps, stage_steps, limit_steps, rtol, atol)
    preps = (functools.partial(_prep_a, plan), functools.partial(_prep_b, plan),
             functools.partial(_prep_c, plan, model))
    stores = (functools.partial(_store_a, plan), _store_b, functools.partial(_store_c, plan, scale))

    def job(j, c):
        kind = jnp.asarray(kinds)[j]
        c, block, budget = jax.lax.switch(kind, preps, j, c)
        res = _solve_block(model, u, v, y, sw, scale, block, budget, rtol, atol)  # the one solver loop
        return jax.lax.switch(kind, stores, j, c, res)

    c = jax.lax.fori_loop(0, len(kinds), job, _initial_carry(raw0, plan))
    return finish(model, wc2, raw0, c)


def _initial_carry(raw0, plan: _Plan) -> dict:
    """The loop's state: every start (``raw``, ``code``, ``steps``, ``sl2``), stage 2's ``order``, the kept start
    (``*_b``), and the range-limit candidates (``cand``) and their results (``c*``)."""
    nb, ns, npar = raw0.shape
    i32, f, ncand = jnp.int32, raw0.dtype, plan.n_cand
    return dict(
        raw=raw0, code=jnp.full((nb, ns), RESULTS.MAX_STEPS, i32), steps=jnp.zeros((nb, ns), i32),
        sl2=jnp.full((nb, ns), jnp.inf, f), order=jnp.zeros((nb, plan.r), i32),
        best=jnp.zeros((nb,), i32), raw_b=raw0[:, 0], code_b=jnp.zeros((nb,), i32), l2_b=jnp.zeros((nb,), f),
        steps_b=jnp.zeros((nb,), i32), retry=jnp.zeros((nb,), bool), cand=jnp.zeros((nb, ncand, npar), f),
        craw=jnp.zeros((nb, ncand, npar), f), ccode=jnp.zeros((nb, ncand), i32), csteps=jnp.zeros((nb, ncand), i32),
        cl2=jnp.full((nb, ncand), jnp.inf, f),
    )


def _stage1_idx(plan: _Plan, j):
    """The starts of stage-1 job ``j`` (the padding of the last job repeats the last start)."""
    return jnp.minimum(j * plan.r + jnp.arange(plan.r), plan.ns - 1)


def _round_job(plan: _Plan, j):
    """The index of range-limit job ``j`` within its round."""
    return (j - (plan.n_jobs - plan.per_round * _LIMIT_ROUNDS)) % plan.per_round


def _pick_best(c):
    best = _pick(c["sl2"], c["code"]).astype(jnp.int32)
    return dict(c, best=best, raw_b=_at(c["raw"], best), code_b=_at(c["code"], best).astype(jnp.int32),
                steps_b=_at(c["steps"], best), l2_b=_at(c["sl2"], best))


def _prep_a(plan: _Plan, j, c):
    budget = plan.max_steps if plan.one_stage else plan.stage_steps
    return c, c["raw"][:, _stage1_idx(plan, j)], jnp.full((c["raw"].shape[0], plan.r), budget, jnp.int32)


def _prep_b(plan: _Plan, j, c):
    order = jnp.argsort(c["sl2"], axis=1)[:, :plan.r].astype(jnp.int32)
    done = jnp.take_along_axis(c["code"], order, axis=1) == RESULTS.OK
    block = jnp.take_along_axis(c["raw"], order[..., None], axis=1)
    return dict(c, order=order), block, jnp.where(done, 0, max(plan.max_steps - plan.stage_steps, 1)).astype(jnp.int32)


def _prep_c(plan: _Plan, model, j, c):
    sub = _round_job(plan, j)
    snapped = [model.snap_to_limits(c["raw_b"], tol) for tol in _LIMIT_TOLS]  # candidates, tightest first
    retry = (c["code_b"] == RESULTS.MAX_STEPS) & jnp.any(snapped[-1][1], axis=-1)
    cand = jnp.stack([jnp.where(retry[:, None], s, c["raw_b"]) for s, _ in snapped], axis=1)
    cand = jnp.concatenate([cand, jnp.repeat(cand[:, -1:], plan.n_cand - cand.shape[1], axis=1)], axis=1)
    first = sub == 0  # a round's candidates are made by its first job
    c = dict(c, cand=jnp.where(first, cand, c["cand"]), retry=jnp.where(first, retry, c["retry"]))
    block = jax.lax.dynamic_slice_in_dim(c["cand"], sub * plan.r, plan.r, axis=1)
    budget = jnp.where(c["retry"][:, None], plan.limit_steps, 0).astype(jnp.int32) * jnp.ones((1, plan.r), jnp.int32)
    return c, block, budget


def _store_a(plan: _Plan, j, c, res):
    idx = _stage1_idx(plan, j)
    c = dict(c, **{k: c[k].at[:, idx].set(a) for k, a in zip(("raw", "code", "steps", "sl2"), res)})
    return jax.lax.cond(j == plan.n_a - 1, _pick_best, lambda c: c, c) if plan.one_stage else c


def _store_b(j, c, res):
    raw2, code2, steps2, sl22 = res
    order = c["order"]
    rows = jnp.arange(order.shape[0])[:, None]
    take = lambda a: jnp.take_along_axis(a, order.reshape(order.shape + (1,) * (a.ndim - 2)), axis=1)  # noqa
    d = take(c["code"]) == RESULTS.OK  # converged in stage 1: keep its stage-1 state
    c = dict(
        c, raw=c["raw"].at[rows, order].set(jnp.where(d[..., None], take(c["raw"]), raw2)),
        code=c["code"].at[rows, order].set(jnp.where(d, take(c["code"]), code2)),
        steps=c["steps"].at[rows, order].set(take(c["steps"]) + jnp.where(d, 0, steps2)),
        sl2=c["sl2"].at[rows, order].set(jnp.where(d, take(c["sl2"]), sl22)),
    )
    return _pick_best(c)


def _store_c(plan: _Plan, scale, j, c, res):
    sub = _round_job(plan, j)
    c = dict(c, **{k: jax.lax.dynamic_update_slice_in_dim(c[k], a, sub * plan.r, axis=1)
                   for k, a in zip(("craw", "ccode", "csteps", "cl2"), res)})
    ncand_real = len(_LIMIT_TOLS)
    raw_p, code_p = c["craw"][:, :ncand_real], c["ccode"][:, :ncand_real]
    steps_p, l2_p = c["csteps"][:, :ncand_real], c["cl2"][:, :ncand_real]
    # the best candidate is kept if its L2 is no worse than before; its own status is reported
    better = jnp.isfinite(l2_p) & (l2_p <= (c["l2_b"] * (1.0 + plan.rtol) + plan.atol * scale[:, 0])[:, None])
    k = _pick(jnp.where(better, l2_p, jnp.inf), code_p)
    at = functools.partial(_at, idx=k)
    last = sub == plan.per_round - 1  # a round is decided by its last job
    take_p = c["retry"] & at(better) & last
    spent = c["retry"] & last
    return dict(
        c, raw_b=jnp.where(take_p[:, None], at(raw_p), c["raw_b"]),
        code_b=jnp.where(take_p, at(code_p), c["code_b"]),
        l2_b=jnp.where(take_p, at(l2_p), c["l2_b"]), steps_b=c["steps_b"] + jnp.where(spent, at(steps_p), 0),
    )


#: the solver backends of :func:`baselines.fit`
BACKENDS = ("optimistix", "jaxopt")


def residual_fn(model, u, v):
    def fn(raw, args):
        y, sw = args
        f = model.evaluate(model.to_params(raw), u, v)
        return jnp.where(sw > 0, sw * (y - f), 0.0)

    return fn


def residuals(name: str, raw, u, v, values, weights_c2):
    """The residual vector ``sqrt(w_i cos^2) (b_i - f_i)`` of one lane at unconstrained ``raw`` (for other solvers)."""
    model = get_model(name)
    return residual_fn(model, u, v)(raw, (values, jnp.sqrt(weights_c2)))


def _at(a, idx):
    """``a[b, idx[b]]`` for every lane ``b``: ``a`` is ``(B, S, ...)``, ``idx`` is ``(B,)``."""
    return jnp.take_along_axis(a, idx.reshape(idx.shape + (1,) * (a.ndim - 1)), axis=1)[:, 0]


def _pick(score_l2, code):
    """Index of the best start per lane: converged and finite first, then any finite one."""
    conv = jnp.where(code == RESULTS.OK, score_l2, jnp.inf)
    any_conv = jnp.any(jnp.isfinite(conv), axis=-1)
    return jnp.where(any_conv, jnp.argmin(conv, axis=-1), jnp.argmin(score_l2, axis=-1))


# a kept start that ran out of steps with parameters close to their range limits (in the unit
# coordinate sin^2: one candidate per tolerance) is put on them and gets `limit_steps` more steps, up to
# _LIMIT_ROUNDS times; _LIMIT_TOL flags the parameters reported as on a limit
_LIMIT_TOLS = (1e-2, 1e-1)
_LIMIT_TOL = _LIMIT_TOLS[0]
_LIMIT_ROUNDS = 2


def prepare_lanes(model, u, v, y, wl, wc2, key, raw0, n_starts):
    """What both kernels solve with: ``(sw, scale, raw0)``, the residuals' square-root weights ``sw (B, n)``
    (``sqrt(w cos^2 / sum w)`` of equation (11)) divided by the data's own L2 ``scale (B, 1)`` (the L2 of
    ``f = 0``; 1 where that is 0), so that the solver's tolerances are relative, and the starts ``raw0 (B, S, P)``
    (``n_starts`` made by :func:`baselines._starts.starts` when ``raw0`` is None)."""
    den = jnp.sum(wl, axis=-1, keepdims=True)
    sw = jnp.sqrt(wc2 / jnp.where(den > 0, den, 1.0))
    scale = jnp.sqrt(jnp.sum(sw * sw * y * y, axis=-1, keepdims=True))
    scale = jnp.where(scale > 0, scale, 1.0)
    if raw0 is None:
        raw0 = make_starts(model, u, v, y, wc2, key, n_starts)
    return sw / scale, scale, raw0


def finish(model, wc2, raw0, c):
    """The kept start's result (its L2 and code written back into the per-start arrays): a dict of ``(B, ...)``
    arrays, the fields of :class:`baselines.BaselineFit` but ``params``, ``l2`` and ``success`` (which
    :func:`baselines.fit` computes from ``raw``, differentiably)."""
    best, raw_b, code_b, l2_b, steps_b = (c[k] for k in ("best", "raw_b", "code_b", "l2_b", "steps_b"))
    rows = jnp.arange(raw_b.shape[0])
    sl2 = c["sl2"].at[rows, best].set(l2_b)
    code = c["code"].at[rows, best].set(code_b)
    ok = jnp.all(jnp.isfinite(raw_b), axis=-1)
    raw_b = jnp.where(ok[:, None], raw_b, raw0[:, 0])  # never hand back NaN parameters
    code_b = jnp.where(ok, code_b, RESULTS.NONFINITE)
    no_samples = jnp.sum(wc2 > 0, axis=-1) == 0
    code_b = jnp.where(no_samples, RESULTS.NO_SAMPLES, code_b).astype(jnp.int32)
    return dict(
        raw=raw_b, status=code_b, steps=steps_b, start_l2=sl2, start_status=code.astype(jnp.int32),
        best_start=best.astype(jnp.int32), at_limit=model.snap_to_limits(raw_b, _LIMIT_TOL)[1],
    )
