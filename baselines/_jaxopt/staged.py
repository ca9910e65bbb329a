"""The jaxopt backend of the multi-start fit (``backend="jaxopt"``), alone: jaxopt's Levenberg-Marquardt on every
start of every lane (:func:`run_starts`), in the staged kernel: every start for ``stage_steps`` steps, the
``refine`` best of each lane to convergence, the best converged start kept, and a kept start that ran out of steps
next to its parameters' range limits put on them and finished (see :func:`baselines.fit`). Each stage is a separate
solve (a separate traced loop); the optimistix backend runs the same schedule through one loop
(:mod:`baselines._multistart`, which also holds the pieces both share)."""

from __future__ import annotations

import functools
import warnings

import jax
import jax.numpy as jnp
import lineax as lx
import optimistix as optx

from polyjax import RESULTS

from .._models.registry import get_model
from .._multistart import _LIMIT_ROUNDS, _LIMIT_TOLS, _at, _pick, finish, prepare_lanes, residual_fn

with warnings.catch_warnings():  # jaxopt warns on import that it is unmaintained: it is the alternative backend named
    warnings.filterwarnings("ignore", message="JAXopt is no longer maintained", category=DeprecationWarning)
    import jaxopt


def optimistix_solve(fn, raw0, args, max_steps, rtol, atol):
    """``optimistix.least_squares`` run to ``max_steps`` on one start: the staged kernel's solve with
    ``backend="optimistix"`` (the default backend runs :func:`baselines._lm.lm_solve` in one loop instead)."""
    # normal equations + Cholesky for the small damped (P x P) system: cheaper than QR, and the damping keeps it SPD
    solver = optx.LevenbergMarquardt(rtol=rtol, atol=atol, linear_solver=lx.Normal(lx.Cholesky()))
    sol = optx.least_squares(fn, solver, raw0, args=args, max_steps=max_steps, throw=False)
    r = optx.RESULTS
    max_steps_hit = (sol.result == r.max_steps_reached) | (sol.result == r.nonlinear_max_steps_reached)
    code = jnp.where(
        sol.result == r.successful,
        RESULTS.OK,
        jnp.where(
            max_steps_hit, RESULTS.MAX_STEPS,
            jnp.where(sol.result == r.nonfinite, RESULTS.NONFINITE, RESULTS.FAILED),
        ),
    )
    return sol.value, code.astype(jnp.int32), sol.stats["num_steps"].astype(jnp.int32)


def _jaxopt_solve(fn, raw0, args, max_steps, rtol, atol):
    solver = jaxopt.LevenbergMarquardt(
        residual_fun=lambda r, a: fn(r, a), maxiter=max_steps, stop_criterion="madsen-nielsen", xtol=rtol,
        gtol=atol, tol=atol, solver="cholesky", materialize_jac=True, implicit_diff=False, jit=True,
    )
    value, state = solver.run(raw0, args)
    steps = state.iter_num.astype(jnp.int32)
    code = jnp.where(steps < max_steps, RESULTS.OK, RESULTS.MAX_STEPS).astype(jnp.int32)
    return value, code, steps


def run_starts(model, backend, u, v, y, sw, scale, raw0, max_steps, rtol, atol):
    """Solve every start of every lane by ``backend``'s Levenberg-Marquardt (jaxopt's; optimistix's, one solve per
    stage, as a comparison): raw0 (B, S, P) -> raw, code, steps, loss (B, S ...)."""
    fn = residual_fn(model, u, v)
    solve = {"optimistix": optimistix_solve, "jaxopt": _jaxopt_solve}[backend]

    def one(r0, yb, swb):
        raw, code, steps = solve(fn, r0, (yb, swb), max_steps, rtol, atol)
        res = fn(raw, (yb, swb))
        loss = jnp.sum(res * res)
        finite = jnp.isfinite(loss) & jnp.all(jnp.isfinite(raw))
        code = jnp.where(finite, code, RESULTS.NONFINITE)
        return raw, code, steps, jnp.where(finite, jnp.sqrt(loss), jnp.inf)

    raw, code, steps, l2 = jax.vmap(jax.vmap(one, in_axes=(0, None, None)))(raw0, y, sw)
    return raw, code, steps, l2 * scale



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
        done = code1 == RESULTS.OK
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
        retry = (code_b == RESULTS.MAX_STEPS) & jnp.any(snapped[-1][1], axis=-1)
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
        return jnp.any((code_b == RESULTS.MAX_STEPS) & jnp.any(near, axis=-1))

    state = (raw_b, code_b, l2_b, steps_b)
    for _ in range(_LIMIT_ROUNDS if limit_steps > 0 else 0):  # skipped at run time when no lane needs it
        state = jax.lax.cond(needs_round(state), limit_round, lambda s: s, state)
    raw_b, code_b, l2_b, steps_b = state
    return finish(model, wc2, raw0, dict(
        code=code, sl2=sl2, best=best, raw_b=raw_b, code_b=code_b, l2_b=l2_b, steps_b=steps_b))
