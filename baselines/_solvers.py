"""Solver backends of the multi-start fit: Levenberg-Marquardt from optimistix (default) or jaxopt, on the
residuals ``sqrt(w_i cos^2) (b_i - f_i)`` of paper equation (11), every start of every lane in one ``vmap``."""

from __future__ import annotations

import warnings

import jax
import jax.numpy as jnp

from polyjax import Result

from ._registry import get_model

BACKENDS = ("optimistix", "jaxopt")


def residual_fn(model, u, v):
    def fn(raw, args):
        y, sw = args
        f = model.evaluate(model.to_params(raw), u, v)
        return jnp.where(sw > 0, sw * (y - f), 0.0)

    return fn


def _optimistix_solve(fn, raw0, args, max_steps, rtol, atol):
    import lineax as lx  # on first use, as in baselines/_lm.py
    import optimistix as optx

    # normal equations + Cholesky for the small damped (P x P) system: cheaper than QR, and the damping keeps it SPD
    solver = optx.LevenbergMarquardt(rtol=rtol, atol=atol, linear_solver=lx.Normal(lx.Cholesky()))
    sol = optx.least_squares(fn, solver, raw0, args=args, max_steps=max_steps, throw=False)
    r = optx.RESULTS
    max_steps_hit = (sol.result == r.max_steps_reached) | (sol.result == r.nonlinear_max_steps_reached)
    code = jnp.where(
        sol.result == r.successful,
        Result.OK,
        jnp.where(
            max_steps_hit, Result.MAX_STEPS,
            jnp.where(sol.result == r.nonfinite, Result.NONFINITE, Result.FAILED),
        ),
    )
    return sol.value, code.astype(jnp.int32), sol.stats["num_steps"].astype(jnp.int32)


def _import_jaxopt():
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="JAXopt is no longer maintained", category=DeprecationWarning)
        import jaxopt
    return jaxopt


def _jaxopt_solve(fn, raw0, args, max_steps, rtol, atol):
    jaxopt = _import_jaxopt()
    solver = jaxopt.LevenbergMarquardt(
        residual_fun=lambda r, a: fn(r, a), maxiter=max_steps, stop_criterion="madsen-nielsen", xtol=rtol,
        gtol=atol, tol=atol, solver="cholesky", materialize_jac=True, implicit_diff=False, jit=True,
    )
    value, state = solver.run(raw0, args)
    steps = state.iter_num.astype(jnp.int32)
    code = jnp.where(steps < max_steps, Result.OK, Result.MAX_STEPS).astype(jnp.int32)
    return value, code, steps


_SOLVERS = {"optimistix": _optimistix_solve, "jaxopt": _jaxopt_solve}


def run_starts(model, backend, u, v, y, sw, scale, raw0, max_steps, rtol, atol):
    """Solve every start of every lane: raw0 (B, S, P) -> raw, code, steps, loss (B, S ...)."""
    fn = residual_fn(model, u, v)
    solve = _SOLVERS[backend]

    def one(r0, yb, swb):
        raw, code, steps = solve(fn, r0, (yb, swb), max_steps, rtol, atol)
        res = fn(raw, (yb, swb))
        loss = jnp.sum(res * res)
        finite = jnp.isfinite(loss) & jnp.all(jnp.isfinite(raw))
        code = jnp.where(finite, code, Result.NONFINITE)
        return raw, code, steps, jnp.where(finite, jnp.sqrt(loss), jnp.inf)

    raw, code, steps, l2 = jax.vmap(jax.vmap(one, in_axes=(0, None, None)))(raw0, y, sw)
    return raw, code, steps, l2 * scale


def residuals(name: str, raw, u, v, values, weights_c2):
    """The residual vector ``sqrt(w_i cos^2) (b_i - f_i)`` of one lane at unconstrained ``raw`` (for other solvers)."""
    model = get_model(name)
    return residual_fn(model, u, v)(raw, (values, jnp.sqrt(weights_c2)))
