"""The staged multi-start kernel of the jaxopt backend: every start for ``stage_steps`` steps, the ``refine`` best of
each lane to convergence, the best converged start kept, and a kept start that ran out of steps next to its
parameters' range limits put on them and finished (see :func:`baselines.fit`). Each stage is a separate solve (a
separate traced loop); the optimistix backend runs the same schedule through one loop (:mod:`baselines._multistart`).
Also the shared pieces of both: the lanes' weights and starts (:func:`prepare_lanes`), the pick of the best start
and the packaging of the kept one (:func:`finish`)."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

from polyjax import Result

from ._registry import get_model
from ._solvers import run_starts
from ._starts import starts as make_starts


def _at(a, idx):
    """``a[b, idx[b]]`` for every lane ``b``: ``a`` is ``(B, S, ...)``, ``idx`` is ``(B,)``."""
    return jnp.take_along_axis(a, idx.reshape(idx.shape + (1,) * (a.ndim - 1)), axis=1)[:, 0]


def _pick(score_l2, code):
    """Index of the best start per lane: converged and finite first, then any finite one."""
    conv = jnp.where(code == Result.OK, score_l2, jnp.inf)
    any_conv = jnp.any(jnp.isfinite(conv), axis=-1)
    return jnp.where(any_conv, jnp.argmin(conv, axis=-1), jnp.argmin(score_l2, axis=-1))


# a kept start that ran out of steps with parameters close to their range limits (in the unit
# coordinate sin^2: one candidate per tolerance) is put on them and gets `limit_steps` more steps, up to
# _LIMIT_ROUNDS times; _LIMIT_TOL flags the parameters reported as on a limit
_LIMIT_TOLS = (1e-2, 1e-1)
_LIMIT_TOL = _LIMIT_TOLS[0]
_LIMIT_ROUNDS = 2


@functools.partial(
    jax.jit,
    static_argnames=(
        "name", "backend", "n_starts", "max_steps", "rtol", "atol", "stage_steps", "refine", "limit_steps",
    ),
)
def staged_kernel(
    name, u, v, y, wl, wc2, key, raw0, *, backend, n_starts, max_steps, rtol, atol, stage_steps, refine, limit_steps
):
    """Every start of every lane ``y (B, n)``: stage 1 (``stage_steps``), stage 2 (the ``refine`` best to
    convergence), the pick of the best start, and up to two range-limit rounds; a dict of ``(B, ...)`` arrays.

    One jitted function so that the stages, the pick and the range-limit rounds compile into one program; each
    stage is a call of :func:`run_starts`.
    """
    model = get_model(name)
    sw, scale, raw0 = prepare_lanes(model, u, v, y, wl, wc2, key, raw0, n_starts)
    nb, ns, _ = raw0.shape
    take = lambda a, idx: jnp.take_along_axis(a, idx, axis=1)  # noqa: E731
    if refine is None or refine >= ns:
        raw, code, steps, sl2 = run_starts(model, backend, u, v, y, sw, scale, raw0, max_steps, rtol, atol)
    else:
        # stage 1: every start for a few steps; stage 2: the `refine` best of each lane to convergence
        raw1, code1, steps1, sl21 = run_starts(model, backend, u, v, y, sw, scale, raw0, stage_steps, rtol, atol)
        order = jnp.argsort(sl21, axis=1)[:, :refine]  # (B, K)
        raw2, code2, steps2, sl22 = run_starts(
            model, backend, u, v, y, sw, scale, take(raw1, order[..., None]), max(max_steps - stage_steps, 1), rtol,
            atol,
        )
        done = code1 == Result.OK
        raw, code, steps, sl2 = raw1, code1, steps1, sl21
        # starts not continued: keep stage-1 state (those not converged are MAX_STEPS)
        d = take(done, order)
        upd = lambda a, b: jnp.where(  # noqa: E731
            d.reshape(d.shape + (1,) * (b.ndim - 2)), take(a, order.reshape(order.shape + (1,) * (a.ndim - 2))), b
        )
        raw_sel = upd(raw1, raw2)
        code_sel = jnp.where(d, take(code1, order), code2)
        steps_sel = take(steps1, order) + jnp.where(d, 0, steps2)
        sl2_sel = jnp.where(d, take(sl21, order), sl22)
        rows = jnp.arange(nb)[:, None]
        raw = raw.at[rows, order].set(raw_sel)
        code = code.at[rows, order].set(code_sel)
        steps = steps.at[rows, order].set(steps_sel)
        sl2 = sl2.at[rows, order].set(sl2_sel)
    best = _pick(sl2, code)
    raw_b, code_b, steps_b, l2_b = _at(raw, best), _at(code, best), _at(steps, best), _at(sl2, best)
    # a kept start that ran out of steps next to a range limit: put it on the limit and finish from there
    # (the best candidate is kept if its L2 is no worse than before; its own status is reported)
    def limit_round(state):
        raw_b, code_b, l2_b, steps_b = state
        snapped = [model.snap_to_limits(raw_b, tol) for tol in _LIMIT_TOLS]  # candidates, tightest first
        retry = (code_b == Result.MAX_STEPS) & jnp.any(snapped[-1][1], axis=-1)
        cand = jnp.stack([jnp.where(retry[:, None], r, raw_b) for r, _ in snapped], axis=1)  # (B, C, P)
        raw_p, code_p, steps_p, l2_p = run_starts(model, backend, u, v, y, sw, scale, cand, limit_steps, rtol, atol)
        better = jnp.isfinite(l2_p) & (l2_p <= (l2_b * (1.0 + rtol) + atol * scale[:, 0])[:, None])
        c = _pick(jnp.where(better, l2_p, jnp.inf), code_p)
        at = functools.partial(_at, idx=c)
        take_p = retry & at(better)
        return (
            jnp.where(take_p[:, None], at(raw_p), raw_b), jnp.where(take_p, at(code_p), code_b),
            jnp.where(take_p, at(l2_p), l2_b), steps_b + jnp.where(retry, at(steps_p), 0),
        )

    def needs_round(state):
        raw_b, code_b = state[0], state[1]
        near = model.snap_to_limits(raw_b, _LIMIT_TOLS[-1])[1]
        return jnp.any((code_b == Result.MAX_STEPS) & jnp.any(near, axis=-1))

    state = (raw_b, code_b, l2_b, steps_b)
    for _ in range(_LIMIT_ROUNDS if limit_steps > 0 else 0):  # skipped at run time when no lane needs it
        state = jax.lax.cond(needs_round(state), limit_round, lambda s: s, state)
    raw_b, code_b, l2_b, steps_b = state
    return finish(model, wc2, raw0, dict(
        code=code, sl2=sl2, best=best, raw_b=raw_b, code_b=code_b, l2_b=l2_b, steps_b=steps_b))


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
    code_b = jnp.where(ok, code_b, Result.NONFINITE)
    no_samples = jnp.sum(wc2 > 0, axis=-1) == 0
    code_b = jnp.where(no_samples, Result.NO_SAMPLES, code_b).astype(jnp.int32)
    return dict(
        raw=raw_b, status=code_b, steps=steps_b, start_l2=sl2, start_status=code.astype(jnp.int32),
        best_start=best.astype(jnp.int32), at_limit=model.snap_to_limits(raw_b, _LIMIT_TOL)[1],
    )
