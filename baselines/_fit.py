r"""Fitting the baselines: batched multi-start Levenberg-Marquardt (and closed form for Zernike).

Objective (the same as the polynomial fit, paper equation (11)): with ``w_i`` the solid-angle
weights and only samples with ``theta_u, theta_v <= cutoff_deg`` kept (the solver sees these
residuals divided by the data's own L2, ``||r(f = 0)||``, so that ``rtol``/``atol`` are relative),

.. math:: r_i(\tau) = \sqrt{w_i / \textstyle\sum_j w_j}\; \cos\theta_{u,i}\,(b_i - f(u_i, v_i; \tau)),
          \qquad \|r\|_2 = \text{L2 of equation (11)} .

``tau`` are unconstrained parameters mapped to the physical ones by smooth transforms.

Starts: the model's deterministic guesses of its nonlinear parameters (exponents, roughnesses,
Fresnel, lobe shape) first, then random ones drawn from ``key``; for each, the parameters that
enter linearly (albedos, lobe scale) are seeded by a small non-negative linear least-squares
solve on the same objective. All starts of all lanes (materials x channels) are solved in one
``vmap``-ped Levenberg-Marquardt (``optimistix.LevenbergMarquardt``, or ``jaxopt``), and per
lane the converged, finite start of lowest L2 is kept.

Under ``vmap`` the while loop runs until the slowest start ends; to keep that short, every start
first runs ``stage_steps`` iterations, then only the ``refine`` best starts of each lane are
continued to convergence (``refine=None`` runs every start to the end). The default ``refine=1``
continues the single best start: on the 52 CUReT samples x 7 models it changes the mean L2 by
-1.5% to +0.8% against ``refine=2`` and removes the slowest lanes' extra steps
(``benchmarks/bench_baselines.py --refine``).
"""

from __future__ import annotations

import enum
import functools
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import lineax as lx
import optimistix as optx
from jaxtyping import Array, Bool, Float, Int

from polyjax import InputError, Measurements, check_samples, fit_weights, l2_error, safe_normalize, weighted_lstsq

from ._common import BaselineModel
from ._registry import get_model
from ._zernike import n_zernike_terms, zernike, zernike_design

BACKENDS = ("optimistix", "jaxopt")


class BaselineStatus(enum.IntEnum):
    """Per-fit result code.

    ``OK``: converged; ``MAX_STEPS``: the step limit was reached before the tolerances (also after
    the kept start was put on the range limits it was close to, see :func:`fit`);
    ``NONFINITE``: the solver ended on a non-finite loss (that start is never selected);
    ``FAILED``: any other solver failure; ``NO_SAMPLES``: nothing to fit (L2 = inf).
    """

    OK = 0
    MAX_STEPS = 1
    NONFINITE = 2
    FAILED = 3
    NO_SAMPLES = 4


class BaselineFit(eqx.Module):
    """Result of :func:`baselines.fit` for a batch of lanes (materials, channels).

    Attributes:
        params: ``(*batch, P)`` constrained (physical) parameters, see ``param_names``.
        raw: ``(*batch, P)`` the unconstrained parameters the optimiser worked on.
        l2: ``(*batch,)`` L2 of equation (11) (:func:`polyjax.l2_error`) of the kept start.
        status: ``(*batch,)`` :class:`BaselineStatus` code of the kept start.
        steps: ``(*batch,)`` solver steps of the kept start (both stages).
        success: ``(*batch,)`` True when the kept start converged to a finite L2.
        start_l2: ``(*batch, S)`` final L2 of every start (``inf`` for non-finite ones).
        start_status: ``(*batch, S)`` code of every start.
        best_start: ``(*batch,)`` index of the kept start.
        at_limit: ``(*batch, P)`` True for a parameter on (within 0.01 in ``sin^2`` of) a limit of its
            range (e.g. ``F0 = 1``, an exponent at its lower bound): the data asks for a value the
            model's valid range excludes.
        name: model name; ``backend``: solver used.
    """

    params: Float[Array, "*batch P"]
    raw: Float[Array, "*batch P"]
    l2: Float[Array, "*batch"]
    status: Int[Array, "*batch"]
    steps: Int[Array, "*batch"]
    success: Bool[Array, "*batch"]
    start_l2: Float[Array, "*batch S"]
    start_status: Int[Array, "*batch S"]
    best_start: Int[Array, "*batch"]
    at_limit: Bool[Array, "*batch P"]
    name: str = eqx.field(static=True)
    backend: str = eqx.field(static=True, default="optimistix")

    @property
    def model(self) -> BaselineModel:
        return get_model(self.name)

    @property
    def param_names(self) -> tuple[str, ...]:
        if self.name == "zernike":
            return tuple(f"c{j}" for j in range(self.params.shape[-1]))
        return self.model.param_names

    @property
    def batch_shape(self) -> tuple[int, ...]:
        return tuple(self.l2.shape)

    def __call__(self, u, v) -> Float[Array, "*batch n"]:
        """Evaluate every fitted lane at directions ``u, v`` ``(n, 3)``: returns ``(*batch, n)``.

        Directions are renormalised, as :func:`fit` does with its inputs (so a non-unit ``u`` gives
        the same value as ``u / |u|``); a zero vector has no direction and gives 0.
        """
        u = jnp.asarray(u, self.params.dtype)
        v = jnp.asarray(v, self.params.dtype)
        if u.ndim != 2 or u.shape[-1] != 3 or u.shape != v.shape:
            raise InputError(f"u, v: expected two (n, 3) arrays of directions, found {u.shape} and {v.shape}")
        return _evaluate_batch(self.name, self.params, u, v)


@functools.partial(jax.jit, static_argnames=("name",))
def _evaluate_batch(name, params, u, v):
    model = get_model(name)
    u, ok_u = safe_normalize(u)
    v, ok_v = safe_normalize(v)
    flat = params.reshape(-1, params.shape[-1])
    out = jax.vmap(lambda p: jnp.where(ok_u & ok_v, model.evaluate(p, u, v), 0.0))(flat)
    return out.reshape(params.shape[:-1] + (u.shape[0],))


# ---------------------------------------------------------------------------------------------
# input handling


def _prepare(u, v, values, weights, mask, cutoff_deg):
    """Validated flat arrays: u, v (n, 3); y (B, n); w, wc2 (B, n); batch shape."""
    if isinstance(u, Measurements):
        data = u
        if v is not None or values is not None:
            raise InputError("fit(name, measurements, ...): pass the other arguments by keyword")
        u, v, values = data.u, data.v, data.values
        weights = data.weights if weights is None else weights
        mask = data.mask if mask is None else mask
    if v is None or values is None:
        raise InputError("fit: expected u, v and values (or a polyjax.Measurements)")
    if cutoff_deg is not None and not (0.0 < float(cutoff_deg) <= 90.0):
        raise InputError(f"cutoff_deg: expected an angle in (0, 90] degrees or None, found {cutoff_deg}")
    values = np.asarray(values)
    if np.issubdtype(values.dtype, np.complexfloating):
        raise InputError(f"values: expected real BRDF values, found dtype {values.dtype}")
    if not np.issubdtype(values.dtype, np.floating):
        values = values.astype(float)
    dtype = jnp.result_type(float)
    uu = np.asarray(u, dtype=float)
    vv = np.asarray(v, dtype=float)
    n = check_samples(uu, vv, values)
    batch = values.shape[:-1]
    m = np.ones(values.shape, bool) if mask is None else np.broadcast_to(np.asarray(mask, bool), values.shape)
    bad = m & ~np.isfinite(values)
    if bad.any():
        first = tuple(int(i) for i in np.argwhere(bad)[0])
        raise InputError(
            f"values: expected finite numbers where mask is True, found {int(bad.sum())} NaN/inf (first at {first}); "
            "mask them out"
        )
    w = np.ones(n) if weights is None else np.asarray(weights, dtype=float)
    if w.shape[-1] != n or (w.ndim > 1 and w.shape != values.shape):
        raise InputError(f"weights: expected shape ({n},) or {values.shape}, found {w.shape}")
    if not np.all(np.isfinite(w)) or np.any(w < 0):
        raise InputError("weights: expected finite, non-negative solid-angle weights")
    u_j, ok_u = safe_normalize(jnp.asarray(uu, dtype))
    v_j, ok_v = safe_normalize(jnp.asarray(vv, dtype))
    m = m & np.asarray(ok_u & ok_v)
    nb = int(np.prod(batch)) if batch else 1
    y = jnp.asarray(np.where(m, values, 0.0).reshape(nb, n), dtype)
    wb = jnp.asarray(np.broadcast_to(w, values.shape).reshape(nb, n), dtype)
    wl, wc2 = fit_weights(u_j, v_j, wb, jnp.asarray(m.reshape(nb, n)), cutoff_deg)
    return u_j, v_j, y, wl, wc2, batch


def _check_common(name, backend, n_starts):
    model = get_model(name)
    if backend not in BACKENDS:
        raise InputError(f"backend: expected one of {BACKENDS}, found {backend!r}")
    if not isinstance(n_starts, (int, np.integer)) or n_starts < 1:
        raise InputError(f"n_starts: expected a positive integer, found {n_starts!r}")
    return model


# ---------------------------------------------------------------------------------------------
# starting points


def _linear_seed(cols, y, wc2):
    """Non-negative weighted LSQ of ``y ~ cols @ c`` for 1 or 2 columns; tiny positive floor."""
    sw = jnp.sqrt(wc2)
    a = cols * sw[:, None]
    b = y * sw
    norm_b = jnp.sqrt(jnp.sum(b * b))
    aa = jnp.sum(a * a, axis=0)
    aa_safe = jnp.where(aa > 0, aa, 1.0)
    floor = 1e-3 * jnp.maximum(norm_b, 1e-12) / jnp.sqrt(aa_safe)
    single = jnp.maximum(a.T @ b / aa_safe, 0.0)  # each column alone
    L = cols.shape[1]
    if L == 1:
        return jnp.maximum(single, floor)
    g = a.T @ a + 1e-12 * jnp.trace(a.T @ a) * jnp.eye(L, dtype=a.dtype)
    full = jnp.linalg.solve(g, a.T @ b)
    cands = [full] + [jnp.zeros(L, a.dtype).at[j].set(single[j]) for j in range(L)]
    ok = [jnp.all(full >= 0) & jnp.all(jnp.isfinite(full))] + [jnp.bool_(True)] * L
    res = jnp.stack([jnp.where(o, jnp.sum((b - a @ c) ** 2), jnp.inf) for c, o in zip(cands, ok)])
    best = jnp.stack(cands)[jnp.argmin(res)]
    return jnp.maximum(jnp.where(jnp.isfinite(best), best, 0.0), floor)


def _nonlinear_starts(model: BaselineModel, n_starts: int, key):
    det = jnp.asarray(model.guesses[: min(n_starts, len(model.guesses))])
    n_rand = n_starts - det.shape[0]
    if n_rand > 0:
        det = jnp.concatenate([det, model.sample(key, n_rand).astype(det.dtype)], axis=0)
    return det


def _starts(model: BaselineModel, u, v, y, wc2, key, n_starts):
    """Raw starting parameters ``(B, S, P)``."""
    nl = _nonlinear_starts(model, n_starts, key).astype(y.dtype)  # (S, Pnl)
    cols = jax.vmap(lambda q: model.columns(q, u, v))(nl)  # (S, n, L)
    lin = jax.vmap(lambda yb, wb: jax.vmap(lambda c: _linear_seed(c, yb, wb))(cols))(y, wc2)  # (B, S, L)
    params = jax.vmap(jax.vmap(model.combine), in_axes=(0, None))(lin, nl)
    return model.to_raw(params)


@functools.partial(jax.jit, static_argnames=("name", "n_starts"))
def _starts_kernel(name, u, v, y, wc2, key, n_starts):
    return _starts(get_model(name), u, v, y, wc2, key, n_starts)


def initial_guesses(
    name: str, u, v=None, values=None, *, weights=None, mask=None, cutoff_deg: float | None = 80.0,
    n_starts: int = 16, key=None,
) -> Float[Array, "*batch S P"]:
    """The unconstrained starting parameters :func:`fit` uses, ``(*batch, n_starts, P)``.

    Map them with ``get_model(name).to_params``; useful to start another solver from the same points.
    """
    model = _check_common(name, "optimistix", n_starts)
    if model.linear:
        raise InputError(f"{model.name} is linear and fitted in closed form: it has no starting points")
    u, v, y, _, wc2, batch = _prepare(u, v, values, weights, mask, cutoff_deg)
    key = jax.random.PRNGKey(0) if key is None else key
    raw = _starts_kernel(model.name, u, v, y, wc2, key, int(n_starts))
    return raw.reshape(batch + raw.shape[1:])


# ---------------------------------------------------------------------------------------------
# solvers


def _residual_fn(model, u, v):
    def fn(raw, args):
        y, sw = args
        f = model.evaluate(model.to_params(raw), u, v)
        return jnp.where(sw > 0, sw * (y - f), 0.0)

    return fn


def _optimistix_solve(fn, raw0, args, max_steps, rtol, atol):
    # normal equations + Cholesky for the small damped (P x P) system: cheaper than QR, and the damping keeps it SPD
    solver = optx.LevenbergMarquardt(rtol=rtol, atol=atol, linear_solver=lx.Normal(lx.Cholesky()))
    sol = optx.least_squares(fn, solver, raw0, args=args, max_steps=max_steps, throw=False)
    r = optx.RESULTS
    max_steps_hit = (sol.result == r.max_steps_reached) | (sol.result == r.nonlinear_max_steps_reached)
    code = jnp.where(
        sol.result == r.successful,
        BaselineStatus.OK,
        jnp.where(
            max_steps_hit, BaselineStatus.MAX_STEPS,
            jnp.where(sol.result == r.nonfinite, BaselineStatus.NONFINITE, BaselineStatus.FAILED),
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
    code = jnp.where(steps < max_steps, BaselineStatus.OK, BaselineStatus.MAX_STEPS).astype(jnp.int32)
    return value, code, steps


_SOLVERS = {"optimistix": _optimistix_solve, "jaxopt": _jaxopt_solve}


def _run_starts(model, backend, u, v, y, sw, scale, raw0, max_steps, rtol, atol):
    """Solve every start of every lane: raw0 (B, S, P) -> raw, code, steps, loss (B, S ...)."""
    fn = _residual_fn(model, u, v)
    solve = _SOLVERS[backend]

    def one(r0, yb, swb):
        raw, code, steps = solve(fn, r0, (yb, swb), max_steps, rtol, atol)
        res = fn(raw, (yb, swb))
        loss = jnp.sum(res * res)
        finite = jnp.isfinite(loss) & jnp.all(jnp.isfinite(raw))
        code = jnp.where(finite, code, BaselineStatus.NONFINITE)
        return raw, code, steps, jnp.where(finite, jnp.sqrt(loss), jnp.inf)

    raw, code, steps, l2 = jax.vmap(jax.vmap(one, in_axes=(0, None, None)))(raw0, y, sw)
    return raw, code, steps, l2 * scale


def _at(a, idx):
    """``a[b, idx[b]]`` for every lane ``b``: ``a`` is ``(B, S, ...)``, ``idx`` is ``(B,)``."""
    return jnp.take_along_axis(a, idx.reshape(idx.shape + (1,) * (a.ndim - 1)), axis=1)[:, 0]


def _pick(score_l2, code):
    """Index of the best start per lane: converged and finite first, then any finite one."""
    conv = jnp.where(code == BaselineStatus.OK, score_l2, jnp.inf)
    any_conv = jnp.any(jnp.isfinite(conv), axis=-1)
    return jnp.where(any_conv, jnp.argmin(conv, axis=-1), jnp.argmin(score_l2, axis=-1))


# a kept start that ran out of steps with parameters close to their range limits (in the unit
# coordinate sin^2: one candidate per tolerance) is put on them and gets `limit_steps` more steps, up to
# _LIMIT_ROUNDS times; _LIMIT_TOL flags the parameters reported as on a limit
_LIMIT_TOLS = (1e-2, 1e-1)
_LIMIT_TOL = _LIMIT_TOLS[0]
_LIMIT_ROUNDS = 2


@functools.partial(
    jax.jit, static_argnames=("name", "backend", "n_starts", "max_steps", "rtol", "atol", "stage_steps", "refine", "limit_steps")
)
def _fit_kernel(
    name, u, v, y, wl, wc2, key, raw0, *, backend, n_starts, max_steps, rtol, atol, stage_steps, refine, limit_steps
):
    model = get_model(name)
    den = jnp.sum(wl, axis=-1, keepdims=True)
    sw = jnp.sqrt(wc2 / jnp.where(den > 0, den, 1.0))
    # residuals in units of the data's own L2 (the L2 of f = 0), so the tolerances are relative
    scale = jnp.sqrt(jnp.sum(sw * sw * y * y, axis=-1, keepdims=True))
    scale = jnp.where(scale > 0, scale, 1.0)
    sw = sw / scale
    if raw0 is None:
        raw0 = _starts(model, u, v, y, wc2, key, n_starts)
    nb, ns, _ = raw0.shape
    take = lambda a, idx: jnp.take_along_axis(a, idx, axis=1)  # noqa: E731
    if refine is None or refine >= ns:
        raw, code, steps, sl2 = _run_starts(model, backend, u, v, y, sw, scale, raw0, max_steps, rtol, atol)
    else:
        # stage 1: every start for a few steps; stage 2: the `refine` best of each lane to convergence
        raw1, code1, steps1, sl21 = _run_starts(model, backend, u, v, y, sw, scale, raw0, stage_steps, rtol, atol)
        order = jnp.argsort(sl21, axis=1)[:, :refine]  # (B, K)
        raw2, code2, steps2, sl22 = _run_starts(
            model, backend, u, v, y, sw, scale, take(raw1, order[..., None]), max(max_steps - stage_steps, 1), rtol, atol
        )
        done = code1 == BaselineStatus.OK
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
        retry = (code_b == BaselineStatus.MAX_STEPS) & jnp.any(snapped[-1][1], axis=-1)
        cand = jnp.stack([jnp.where(retry[:, None], r, raw_b) for r, _ in snapped], axis=1)  # (B, C, P)
        raw_p, code_p, steps_p, l2_p = _run_starts(model, backend, u, v, y, sw, scale, cand, limit_steps, rtol, atol)
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
        return jnp.any((code_b == BaselineStatus.MAX_STEPS) & jnp.any(near, axis=-1))

    state = (raw_b, code_b, l2_b, steps_b)
    for _ in range(_LIMIT_ROUNDS if limit_steps > 0 else 0):  # skipped at run time when no lane needs it
        state = jax.lax.cond(needs_round(state), limit_round, lambda s: s, state)
    raw_b, code_b, l2_b, steps_b = state
    rows = jnp.arange(nb)
    sl2 = sl2.at[rows, best].set(l2_b)
    code = code.at[rows, best].set(code_b)
    ok = jnp.all(jnp.isfinite(raw_b), axis=-1)
    raw_b = jnp.where(ok[:, None], raw_b, raw0[:, 0])  # never hand back NaN parameters
    code_b = jnp.where(ok, code_b, BaselineStatus.NONFINITE)
    params = model.to_params(raw_b)
    pred = jax.vmap(lambda p: model.evaluate(p, u, v))(params)
    l2 = l2_error(y, pred, u, v, weights=wl, cutoff_deg=None, mask=wc2 > 0)
    no_samples = jnp.sum(wc2 > 0, axis=-1) == 0
    code_b = jnp.where(no_samples, BaselineStatus.NO_SAMPLES, code_b).astype(jnp.int32)
    return dict(
        params=params, raw=raw_b, l2=l2, status=code_b, steps=steps_b, success=(code_b == BaselineStatus.OK) & jnp.isfinite(l2),
        start_l2=sl2, start_status=code.astype(jnp.int32), best_start=best.astype(jnp.int32),
        at_limit=model.snap_to_limits(raw_b, _LIMIT_TOL)[1],
    )


@functools.partial(jax.jit, static_argnames=("order",))
def _zernike_kernel(u, v, y, wl, wc2, *, order):
    d = zernike_design(u, v, order)
    sol = jax.vmap(lambda yb, wb: weighted_lstsq(d, yb, wb))(y, wc2)
    coef = sol.coefficients
    l2 = l2_error(y, coef @ d.T, u, v, weights=wl, cutoff_deg=None, mask=wc2 > 0)
    no_samples = jnp.sum(wc2 > 0, axis=-1) == 0
    code = jnp.where(no_samples, BaselineStatus.NO_SAMPLES, BaselineStatus.OK).astype(jnp.int32)
    coef = jnp.where(no_samples[:, None], 0.0, coef)
    zero = jnp.zeros(code.shape, jnp.int32)
    return dict(
        params=coef, raw=coef, l2=l2, status=code, steps=zero, success=code == BaselineStatus.OK, start_l2=l2[:, None],
        start_status=code[:, None], best_start=zero, at_limit=jnp.zeros(coef.shape, bool),
    )


def fit(
    name: str,
    u,
    v=None,
    values=None,
    *,
    weights=None,
    mask=None,
    cutoff_deg: float | None = 80.0,
    n_starts: int = 16,
    key=None,
    backend: str = "optimistix",
    max_steps: int = 100,
    rtol: float = 1e-6,
    atol: float = 1e-8,
    stage_steps: int = 6,
    refine: int | None = 1,
    limit_steps: int = 20,
    starts=None,
    order: int = 8,
) -> BaselineFit:
    r"""Fit a baseline BRDF model to measurements, every lane (material, channel) in one batched call.

    Minimises ``sum_i w_i cos^2(theta_u,i) (b_i - f(u_i, v_i))^2`` over the samples with
    ``theta_u, theta_v <= cutoff_deg`` (the polynomial fit's objective, paper equation (11)) by
    Levenberg-Marquardt from ``n_starts`` starting points (see the module docs), vmapped over
    starts and lanes; Zernike is linear and solved in closed form (:func:`polyjax.weighted_lstsq`).

    Args:
        name: a model of :data:`baselines.MODELS`, e.g. ``"cook-torrance"``.
        u: ``(n, 3)`` light directions, or a :class:`polyjax.Measurements` (``v``, ``values``,
            ``weights`` and ``mask`` then come from it).
        v: ``(n, 3)`` view directions.
        values: ``(*batch, n)`` BRDF values, samples last.
        weights: solid-angle weights ``(n,)`` or ``(*batch, n)``; ones by default.
        mask: ``(*batch, n)`` validity mask (False samples are ignored).
        cutoff_deg: grazing cutoff in degrees (80 in the paper); None keeps all samples above the horizon.
        n_starts: number of starting points per lane (deterministic guesses first, then random).
        key: ``jax.random.PRNGKey`` for the random starts (``PRNGKey(0)`` when None).
        backend: ``"optimistix"`` (``optimistix.LevenbergMarquardt``) or ``"jaxopt"``
            (``jaxopt.LevenbergMarquardt``, imported only when asked for).
        max_steps: step limit per start (both stages together).
        limit_steps: steps given to a kept start that ran out of steps next to its range limits,
            once put on them (at most twice, so up to ``2 * limit_steps`` beyond ``max_steps``);
            0 turns this off.
        rtol, atol: the solver's relative and absolute tolerances (for jaxopt: ``xtol`` and ``gtol``).
        stage_steps, refine: every start runs ``stage_steps`` steps, then the ``refine`` best per
            lane run to convergence (default: the best one only); ``refine=None`` runs all starts
            to the end.
        starts: optional ``(*batch, S, P)`` or ``(S, P)`` unconstrained starting points, used instead of the
            generated ones (``n_starts`` is then ``S``).
        order: Zernike order (8 gives 55 terms, 2 gives 5); ignored by the other models.

    A kept start that runs out of steps with parameters close to a limit of their range (in ``sin^2``
    within ``1e-2``, and as a second candidate ``1e-1``, of 0 or 1) is put on those limits and given
    ``limit_steps`` more steps, twice at most; the best candidate is kept if its L2 is no worse than
    before. Gauss-Newton steps cannot settle on a limit by themselves (the transform's Jacobian column
    vanishes there), which on the 52 CUReT samples left 29 Ashikhmin-Shirley and 14 Cook-Torrance fits
    at the step limit; with this, 1 and 1.

    Returns:
        :class:`BaselineFit` with batch shape ``values.shape[:-1]``. A lane whose kept start did not
        converge has ``success = False`` and its :class:`BaselineStatus`; parameters are never NaN.
    """
    model = _check_common(name, backend, n_starts)
    u, v, y, wl, wc2, batch = _prepare(u, v, values, weights, mask, cutoff_deg)
    nb = y.shape[0]
    if model.linear:
        if not isinstance(order, (int, np.integer)) or order < 0:
            raise InputError(f"order: expected a non-negative integer, found {order!r}")
        out = _zernike_kernel(u, v, y, wl, wc2, order=int(order))
        return BaselineFit(**{k: a.reshape(batch + a.shape[1:]) for k, a in out.items()}, name=model.name, backend="lstsq")
    if not isinstance(max_steps, (int, np.integer)) or max_steps < 1:
        raise InputError(f"max_steps: expected a positive integer, found {max_steps!r}")
    if not isinstance(limit_steps, (int, np.integer)) or limit_steps < 0:
        raise InputError(f"limit_steps: expected a non-negative integer, found {limit_steps!r}")
    raw0 = None
    if starts is not None:
        raw0 = jnp.asarray(starts, y.dtype)
        if raw0.ndim < 2 or raw0.shape[-1] != model.n_params:
            raise InputError(f"starts: expected shape (..., S, {model.n_params}), found {raw0.shape}")
        raw0 = jnp.broadcast_to(raw0, batch + raw0.shape[-2:]).reshape((nb,) + raw0.shape[-2:])
        if not bool(jnp.all(jnp.isfinite(raw0))):
            raise InputError("starts: expected finite unconstrained parameters")
        n_starts = raw0.shape[1]
    key = jax.random.PRNGKey(0) if key is None else key
    stage = int(min(stage_steps, max_steps))
    out = _fit_kernel(
        model.name, u, v, y, wl, wc2, key, raw0, backend=backend, n_starts=int(n_starts), max_steps=int(max_steps),
        rtol=float(rtol), atol=float(atol), stage_steps=stage, refine=None if refine is None else int(refine),
        limit_steps=int(limit_steps),
    )
    shaped = {k: a.reshape(batch + a.shape[1:]) for k, a in out.items()}
    return BaselineFit(**shaped, name=model.name, backend=backend)


def residuals(name: str, raw, u, v, values, weights_c2):
    """The residual vector ``sqrt(w_i cos^2) (b_i - f_i)`` of one lane at unconstrained ``raw`` (for other solvers)."""
    model = get_model(name)
    return _residual_fn(model, u, v)(raw, (values, jnp.sqrt(weights_c2)))


