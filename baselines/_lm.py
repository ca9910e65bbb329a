"""One Levenberg-Marquardt solve of one start with a step budget given at run time: optimistix's
:class:`optimistix.LevenbergMarquardt` (its ``init``/``step``/``terminate``) driven by our own loop, so that
the multi-start kernel traces this loop once and runs every stage of the fit through it
(see :mod:`baselines._multistart`).

optimistix and lineax are imported on first use: a fit served by its saved program (:mod:`baselines._aot`) never
traces this loop, and importing them is most of ``import baselines`` (0.2 s).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import equinox as eqx
import jax
import jax.numpy as jnp

from polyjax import RESULTS

if TYPE_CHECKING:
    import optimistix as optx


def lm_solver(rtol: float, atol: float) -> optx.LevenbergMarquardt:
    import lineax as lx  # on first use: a fit served by its saved program never needs it (module docs)
    import optimistix as optx  # likewise

    # normal equations + Cholesky for the small damped (P x P) system: cheaper than QR, and the damping keeps it SPD
    return optx.LevenbergMarquardt(rtol=rtol, atol=atol, linear_solver=lx.Normal(lx.Cholesky()))


def _all_finite(tree):
    return jnp.all(jnp.stack([jnp.all(jnp.isfinite(x)) for x in jax.tree_util.tree_leaves(tree)]))


def lm_solve(fn, raw0, args, budget, rtol, atol):
    """Minimise ``sum(fn(raw, args)**2)`` from ``raw0`` for at most ``budget`` steps (a traced integer).

    The same iteration as ``optimistix.least_squares`` (``init``, then ``step`` while not ``terminate``), with the
    step limit a run-time value: a budget of 0 returns ``raw0`` at once. Returns ``(raw, code, steps)`` with
    ``code`` a :class:`polyjax.RESULTS` (``OK`` converged, ``MAX_STEPS`` budget spent, ``NONFINITE``, ``FAILED``).
    Not differentiable (a while loop); the fit differentiates its optimum by the implicit function theorem.
    """
    import optimistix as optx  # on first use: a fit served by its saved program never traces this (module docs)

    solver = lm_solver(rtol, atol)
    r = optx.RESULTS
    fn_aux = eqx.filter_closure_convert(lambda y, a: (fn(y, a), None), raw0, args)
    f_struct, aux_struct = fn_aux.out_struct
    options, tags = {}, frozenset()
    state0 = solver.init(fn_aux, raw0, args, options, f_struct, aux_struct, tags)

    def term(y, state):
        t, res = solver.terminate(fn_aux, y, args, options, state, tags)
        return t, r.where(_all_finite(y), res, r.nonfinite)

    t0, res0 = term(raw0, state0)
    dyn0, static = eqx.partition(state0, eqx.is_array)

    def cond(c):
        _, n, _, t, res = c
        return ~t & (res == r.successful) & (n < budget)

    def body(c):
        y, n, dyn, _, _ = c
        new_y, new_state, _ = solver.step(fn_aux, y, args, options, eqx.combine(static, dyn), tags)
        t, res = term(y, new_state)
        return new_y, n + 1, eqx.partition(new_state, eqx.is_array)[0], t, res

    y, n, _, t, res = jax.lax.while_loop(cond, body, (raw0, jnp.array(0), dyn0, t0, res0))
    code = jnp.where(
        (res == r.successful) & t, RESULTS.OK,
        jnp.where(
            res == r.successful, RESULTS.MAX_STEPS, jnp.where(res == r.nonfinite, RESULTS.NONFINITE, RESULTS.FAILED)
        ),
    )
    return y, code.astype(jnp.int32), n.astype(jnp.int32)
