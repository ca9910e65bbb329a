r"""The log-space polynomial model ``f = exp(poly) - eps``, fitted to equation (11) by a few linear solves.

A Gaussian-like lobe is a quadratic in log space, and a lobe of any width stays a low-degree function
there, where in BRDF space a narrow peak needs a very high degree. The model is

.. math::
    f(u, v) = \exp\big(P(u, v)\big) - \varepsilon,

with ``P`` the polynomial of equation (3) (or of equation (2) with ``interactions=True``) in the
principal components of the explanatory variables, and a small ``eps > 0`` (1/sr) so that values near 0
are reachable. ``P`` is linear in its coefficients; ``f`` is not, so the fit is a short sequence of
weighted linear least-squares solves, each one closed-form fit (:func:`polyjax._fit.closed_form.fit_closed_form`, the
kernel of :func:`polyjax.fit_polynomial`):

1. **log-space start**: ``P`` fitted to ``z_i = log(max(b_i, 0) + eps)`` with weights
   ``w_i cos^2(theta_u,i) (b_i + eps)^q``, ``q = start_power = 1`` by default. Near the data
   ``f - b ~ (b + eps)(P - z)``, so ``q = 2`` would be the first-order model of equation (11); but
   ``exp`` is convex and far from the data that model fails: with ``q = 2`` the dark samples weigh
   ~1e-12 of the peak and ``exp(P)`` overshoots there by orders of magnitude on sharp materials
   (chrome: 1e10 where the data is 6e-4). ``q = 0`` (the plain log-space fit) is tame but starts the
   steps too far from the peak. ``q = 1`` is both tame and close (measured on MERL materials).
2. **Gauss-Newton steps** on equation (11) itself: with ``g = f + eps = exp(P)`` of the current model,
   ``f_new - b ~ g (P_new - P) - (b - f)``, so ``P_new`` is the weighted least-squares fit of
   ``P + (b - f) / g`` with weights ``w_i cos^2(theta_u,i) g_i^2`` (iteratively reweighted least
   squares). The factors ``(b + eps)^q`` and ``g^2`` are floored at ``floor * rms`` to those powers
   (argument ``floor``). Every step keeps the best of the step lengths 1, 1/2, 1/4 and of no step, by the L2 of
   equation (11), so the L2 never increases.

The fitted model is bounded by its own largest value at the fitted samples: ``f = exp(min(P, log_top)) - eps``
with ``log_top = max_i P(u_i, v_i)`` (:attr:`polyjax.PolynomialBRDF.log_top`). At the samples nothing changes;
between and beyond them ``exp`` of a high-degree polynomial fitted to few samples otherwise reaches 1e22
(``benchmarks/bench_log_bound.py``).

``1 + steps`` solves in all (default ``steps=3``: 4 solves). Every solve uses the same samples, hence
the same principal components and basis, so the coefficients of different steps combine linearly.

When every lane (colour channel, material) keeps the same samples (directions ``(n, 3)``, and the same samples
kept by the weights, mask and cutoff in every lane), the whole sequence of solves runs in one compiled program
(:func:`_shared_kernel`) on the lanes' one design: the samples' variables and the design's rows are made once; only
the weighted factorisation is made per lane and solve (the weights of every solve depend on the lane's values). On
the design held whole (traced inputs: differentiable) each lane's solve is :func:`polyjax.fit_polynomial`'s dense
one, one lane after the other; for concrete tall inputs the preconditioned rows are made once and every solve is one
pass over them for all the lanes (:mod:`polyjax._fit.lanes`: CholeskyQR2 with one preconditioner for every lane and
solve). The polynomials are linear in their coefficients, so the values at the samples of a step of length ``t``
are ``p + t (p_step - p)``: one product with the rows per solve, none per candidate step. Otherwise (per-lane
directions, lanes that keep different samples) each solve is a :func:`polyjax.fit_polynomial` call
(:func:`_gauss_newton`). On the DiLiGenT ball (352,745 BRDF samples, 3 channels, Rusinkiewicz ``p = 8`` with
interactions) the shared program is the per-solve calls' result to 1e-14 of the largest coefficient (both split
directions), and the lanes' passes make it about four times faster than one streamed factorisation per lane and
solve (``benchmarks/RESULTS.md``).
"""

from __future__ import annotations

import dataclasses
import functools
import inspect

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike

from .._arrays import is_concrete, is_traced
from .._basis import n_terms, term_degrees
from .._design import fitted_design
from .._directions import cos_theta, cutoff_mask
from .._errors import InputError
from .._inputs import check_parameter_count, prepare_inputs
from .._measurements import Measurements
from .._metrics import fit_weights, l2_error, l2_from_weights
from .._model import SPEC_FIELDS, PolynomialBRDF, PolynomialSpec, spec_of, with_clamp
from .._solve.lstsq import weighted_lstsq
from .._solve.threads import one_lapack_thread
from .._variables import get_variables
from .closed_form import _lane, _raise_on_status, _residual_l2, check_fit_options, fit_closed_form
from .closed_form import _result_fields as _outputs
from .lanes import lane_rows, lanes_geometry, lanes_solve
from .stream import _scaled_components, use_stream

#: the step lengths tried after every Gauss-Newton solve (0, the current model, is always a candidate)
STEP_LENGTHS = (1.0, 0.5, 0.25)


@one_lapack_thread
def fit_log_polynomial(
    u,
    v: ArrayLike | None = None,
    values: ArrayLike | None = None,
    variables: str = "rusinkiewicz",
    degree: int = 8,
    *,
    eps: float = 1e-3,
    steps: int = 3,
    floor: float = 0.01,
    start_power: float = 1.0,
    weights: ArrayLike | None = None,
    mask: ArrayLike | None = None,
    cutoff_deg: float | None = 80.0,
    basis: str = "legendre",
    interactions: bool = True,
    method: str = "qr",
    rcond: float | None = None,
    rank_deficient: str = "flag",
    clamp: bool = False,
    spec: PolynomialSpec | None = None,
) -> PolynomialBRDF:
    """Fit ``f = exp(P) - eps`` to minimise equation (11) by ``1 + steps`` weighted linear solves (module docs).

    Args:
        u, v, values: as :func:`polyjax.fit_polynomial` (``u`` may be a :class:`polyjax.Measurements`);
            ``values (*batch, n)`` must be finite (mask out bad samples with ``mask``).
        variables: a registered variable set (default the Rusinkiewicz angles ``theta_h, theta_d``).
        degree: ``p``, one integer.
        eps: the offset ``eps > 0`` in 1/sr: the model's floor is ``-eps``; zeros in the data are fitted
            in log space as ``log(eps)``.
        steps: Gauss-Newton (reweighted) solves after the log-space start; 0 returns the start.
        floor: relative weight floor: ``b + eps`` and ``g`` are raised to at least ``floor * rms`` in the
            weights, ``rms`` the lane's root-mean-square value (eq. (11) weights), so samples far darker than
            the peak keep a small but sane weight and the weighted design keeps its rank (the steps then
            minimise a floored Gauss-Newton model of eq. (11); a step is kept only if eq. (11) decreases).
        start_power: ``q`` of the log-space start's weights ``(b + eps)^q`` (module docs).
        weights, mask, cutoff_deg, basis, method, rcond, rank_deficient: as :func:`polyjax.fit_polynomial`.
        interactions: the full response surface of equation (2) (default), or equation (3) with False.
        clamp: as :func:`polyjax.fit_polynomial` (the model's components clamped to the fitted box when evaluated).
        spec: the model's definition as one value (:class:`polyjax.PolynomialSpec` with ``link="log"``), instead
            of ``variables``, ``degree``, ``basis``, ``interactions``, ``eps`` and ``clamp``.

    Returns:
        :class:`polyjax.PolynomialBRDF` with ``link="log"``, ``eps`` and the bound ``log_top`` (module docs); its
        ``l2`` is equation (11) of ``f`` on the fitted samples, its ``rank``/``condition``/``status`` those of the
        last solve.
        Differentiable with respect to ``values``, ``weights`` and directions wherever
        :func:`polyjax.fit_polynomial` is (the step choice is piecewise constant).
    """
    if isinstance(u, Measurements) and isinstance(v, str):  # fit_log_polynomial(data, "rusinkiewicz")
        u, v, variables = u, None, v
    spec = spec_of("fit_log_polynomial", spec, _SPEC_DEFAULTS, variables=variables, degree=degree, basis=basis,
                   interactions=interactions, link="log", eps=eps, clamp=clamp)
    if spec.link != "log":
        raise InputError(f"spec: expected link='log' for fit_log_polynomial, found {spec.link!r}")
    variables, degree, basis, interactions, eps, clamp = (spec.variables, spec.degree, spec.basis, spec.interactions,
                                                          spec.eps, spec.clamp)
    u, v, values, w, mask, variables, eps, shared = _check_inputs(u, v, values, variables, degree, eps, steps,
                                                                  weights, mask)
    opts = {"variables": variables, "degree": int(degree), "mask": mask, "cutoff_deg": cutoff_deg, "basis": basis,
            "interactions": interactions, "method": method, "rcond": rcond, "rank_deficient": rank_deficient}
    gn = dict(eps=eps, steps=int(steps), floor=float(floor), start_power=float(start_power))
    if shared or _same_samples(u, v, w, mask, cutoff_deg):
        return with_clamp(_shared_gauss_newton(u, v, values, w, mask, cutoff_deg, opts, **gn), clamp)
    return with_clamp(_gauss_newton(u, v, values, w, mask, cutoff_deg, opts, **gn), clamp)


#: the keyword defaults of :func:`fit_log_polynomial` that :class:`polyjax.PolynomialSpec` groups
_SPEC_DEFAULTS = {k: inspect.signature(fit_log_polynomial).parameters[k].default if k != "link" else "log"
                  for k in SPEC_FIELDS}


def _check_inputs(u, v, values, variables, degree, eps, steps, weights, mask):
    """The arguments of :func:`fit_log_polynomial` checked (before any work) and converted: ``(u, v, values,
    weights (*batch, n), mask, variables, eps, shared)``, the arrays in the float type of ``values``; ``shared``:
    every lane has the same samples by the shapes alone (directions ``(n, 3)``, weights and mask ``(n,)`` or
    None)."""
    if isinstance(u, Measurements):
        data = u
        if values is not None or (v is not None and not isinstance(v, str)):
            raise InputError("fit_log_polynomial(measurements, ...): pass the other arguments by keyword")
        if isinstance(v, str):
            variables = v
        u, v, values = data.u, data.v, data.values
        weights = data.weights if weights is None else weights
        mask = data.mask if mask is None else mask
    if v is None or values is None:
        raise InputError("fit_log_polynomial: expected u, v and values (or a Measurements)")
    if np.ndim(degree) != 0:
        raise InputError(f"degree: expected one integer for the log-space fit, found {degree!r}")
    if not (isinstance(eps, (int, float, np.floating)) and float(eps) > 0 and np.isfinite(eps)):
        raise InputError(f"eps: expected a positive offset in 1/sr, found {eps!r}")
    if not isinstance(steps, (int, np.integer)) or steps < 0:
        raise InputError(f"steps: expected a non-negative number of Gauss-Newton solves, found {steps!r}")
    values = jnp.asarray(values)
    if not jnp.issubdtype(values.dtype, jnp.floating):
        values = values.astype(jnp.result_type(float))
    if not is_traced(values):
        finite = np.isfinite(np.asarray(values)) | (False if mask is None else ~np.asarray(mask, bool))
        if not finite.all():
            raise InputError(
                f"values: expected finite numbers where mask is True, found {int((~finite).sum())} NaN/inf")
    u = jnp.asarray(u, values.dtype)
    v = jnp.asarray(v, values.dtype)
    w = jnp.ones(values.shape[-1:], values.dtype) if weights is None else jnp.asarray(weights, values.dtype)
    shared = u.ndim == 2 and w.ndim == 1 and (mask is None or np.ndim(mask) == 1)
    return u, v, values, jnp.broadcast_to(w, values.shape), mask, variables, float(eps), shared


def _gauss_newton(u, v, values, w, mask, cutoff_deg, opts, *, eps, steps, floor, start_power):
    """The log-space start and the ``steps`` Gauss-Newton solves of the module docs, each a closed-form fit
    (:func:`polyjax._fit.closed_form.fit_closed_form`) with ``opts``; every step keeps the best of
    :data:`STEP_LENGTHS` and no step by the L2 of equation (11)."""
    keep = fit_weights(u, v, w, mask, cutoff_deg)[0] > 0  # the fitted samples; the model may overflow elsewhere

    def solve(target, wt):
        ok = keep & jnp.isfinite(target) & jnp.isfinite(wt)
        return fit_closed_form(u, v, jnp.where(ok, target, 0.0), weights=jnp.where(ok, wt, 0.0), **opts)

    def score(model):
        return l2_error(values, model(u, v), u, v, w, cutoff_deg, mask)

    b = jnp.maximum(values, 0.0) + eps
    wc2 = fit_weights(u, v, w, mask, cutoff_deg)[1]
    rms = jnp.sqrt(jnp.sum(wc2 * b * b, -1, keepdims=True) / jnp.maximum(jnp.sum(wc2, -1, keepdims=True), 1e-300))
    fl2 = (floor * rms) ** 2  # weight floor: keeps the log-space polynomial tame where the data is dark
    model = _as_log(solve(jnp.log(b), w * jnp.maximum(b * b, fl2) ** (0.5 * start_power)), eps)
    l2 = score(model)
    for _ in range(steps):
        f = model(u, v)
        g = jnp.maximum(f + eps, jnp.finfo(values.dtype).tiny)  # = exp(P) where P is finite
        step = _as_log(solve(jnp.log(g) + (values - f) / g, w * jnp.maximum(g * g, fl2)), eps)
        for t in STEP_LENGTHS:
            cand = _blend(model, step, t)
            l2_c = score(cand)
            better = l2_c < l2
            model = _select(better, cand, model)
            l2 = jnp.where(better, l2_c, l2)
    return dataclasses.replace(_with_l2(model, l2), log_top=_log_top(model.polynomial(u, v), keep))


#: the bound of a lane without samples: ``log`` of the largest float64, past which ``exp`` overflows anyway (finite,
#: so that every store of the field, EXR's float32 pairs included, holds it)
NO_BOUND = float(np.log(np.finfo(np.float64).max))


def _log_top(p, keep):
    """:attr:`polyjax.PolynomialBRDF.log_top`: the largest of the polynomials ``p (*batch, n)`` at the fitted samples
    (``keep``), per lane; :data:`NO_BOUND` in a lane without samples."""
    top = jnp.max(jnp.where(keep, p, -jnp.inf), axis=-1)
    return jnp.where(jnp.any(keep, axis=-1), jnp.minimum(top, NO_BOUND), NO_BOUND)


def _same_samples(u, v, w, mask, cutoff_deg) -> bool:
    """Whether concrete inputs keep the same samples in every lane (per-lane weights or masks with the same zeros,
    e.g. radiance-space weights of coloured lights): then the lanes share one design."""
    if u.ndim != 2 or not is_concrete(u, v, w, mask):
        return False
    keep = np.asarray(fit_weights(u, v, w, mask, cutoff_deg)[0] > 0).reshape(-1, u.shape[0])
    return bool(np.all(keep == keep[:1]))


def _shared_gauss_newton(u, v, values, w, mask, cutoff_deg, opts, **gn) -> PolynomialBRDF:
    """:func:`_gauss_newton` for lanes with the same samples: the checks of :func:`polyjax.fit_polynomial` once,
    then every solve in one compiled program (:func:`_shared_kernel`), streamed where ``fit_polynomial`` would
    stream a shared design (:func:`polyjax._stream.use_stream`: concrete inputs, ``method="qr"``, tall data)."""
    vs = get_variables(opts["variables"])
    degree, interactions = opts["degree"], bool(opts["interactions"])
    check_fit_options(opts["basis"], opts["method"], opts["rank_deficient"], degree, 1)
    inp, cutoff = prepare_inputs("fit_log_polynomial", u, v, values, w, mask, cutoff_deg=cutoff_deg)
    m = n_terms(vs.k, degree, interactions)
    check_parameter_count(f"degree={degree}, interactions={interactions}, variables={vs.name!r}", m, inp.n,
                          inp.values.dtype.itemsize)
    n = inp.n
    stream = use_stream(n, m, 1, opts["method"], True, is_concrete(inp, u, v, w, mask))
    mk = None if mask is None or np.ndim(mask) == 1 else jnp.asarray(mask).reshape(-1, n)
    out = _shared_kernel(inp, u, v, w.reshape(-1, n), mask if mk is None else mk, variables=vs.name, degree=degree,
                         basis=opts["basis"], interactions=interactions, method=opts["method"], rcond=opts["rcond"],
                         cutoff_deg=cutoff, stream=stream, **gn)
    model = PolynomialBRDF(**{k: a.reshape(inp.batch + a.shape[1:]) for k, a in out.items()}, variables=vs.name,
                           basis=opts["basis"], interactions=interactions, max_degree=degree, link="log",
                           eps=gn["eps"])
    return _raise_on_status(model) if opts["rank_deficient"] == "error" else model


def _dense_design(x, keep, active, first_wc2, *, degree, basis, interactions, method, rcond):
    """The shared design held whole (differentiable): ``(fit, values_at)``, ``fit(y, w, w cos^2)`` the lanes' solves
    (``(L, n)`` each), each as :func:`polyjax.fit_polynomial` makes it (its outputs as ``polyjax._fit._lane``'s,
    without the degree axis, with a lane axis; ``jax.lax.map`` over the lanes: under ``vmap`` a solve's conditionals
    would run both branches), and ``values_at(coef (L, m))`` the polynomials at every sample, ``(L, n)``
    (``first_wc2``, the first solve's weights, is not used here)."""
    pca, centre, hw, d = fitted_design(x, keep, degree, basis, interactions)

    def fit_lane(y, wl, wc2l):
        sol = weighted_lstsq(d, y[:, None], wc2l, active, method=method, rcond=rcond)
        c = sol.coefficients[:, 0]
        l2 = _residual_l2(d, c, y, wl, wc2l)
        return (pca.mean, pca.rotation, centre, hw), c, l2, sol.rank, sol.condition, sol.n_active, jnp.sum(wl > 0)

    return (lambda y, wl, wc2l: jax.lax.map(lambda a: fit_lane(*a), (y, wl, wc2l))), lambda coef: (d @ coef.T).T


def _streamed_design(x, keep, active, first_wc2, *, degree, basis, interactions, method, rcond):
    """:func:`_dense_design` for concrete tall inputs (:mod:`polyjax._fit.lanes`): the rows made once with one
    preconditioner for every lane and solve (from the first solve's weights ``first_wc2 (L, n)``), one pass over them
    per solve for all the lanes (the dense solve for a lane whose Cholesky factor fails, as
    :func:`polyjax.fit_polynomial` falls back), and the polynomials' values one product with the rows."""
    lane = functools.partial(_lane, active=active[None], max_degree=degree, basis=basis, interactions=interactions,
                             method=method, rcond=rcond)
    pca, centre, hw, t = _scaled_components(x, keep, keep, basis)
    rows = lane_rows(t, degree, basis, interactions, first_wc2, active)
    tr = (pca.mean, pca.rotation, centre, hw)

    def fit(y, wl, wc2l):
        geo = lanes_geometry(rows, wl, wc2l, y, active)
        coef, l2, rank, cond, n_act = lanes_solve(geo, rows.n, active, rcond=rcond)
        lanes = jax.tree.map(lambda a: jnp.broadcast_to(a, y.shape[:1] + a.shape), tr)
        streamed = (lanes, coef, l2, rank, cond, n_act, geo["n_used"])

        def one(args):  # a lane whose factor failed: the dense solve
            ok, y_l, wl_l, wc2_l, out = args

            def dense():
                tr_d, c, l2_d, rank_d, cond_d, n_act_d, n_used_d = lane(y_l[None], wl_l, wc2_l, x)
                return tr_d, c[0, 0], l2_d[0, 0], rank_d[0], cond_d[0], n_act_d[0], n_used_d.astype(out[-1].dtype)

            return jax.lax.cond(ok, lambda: out, dense)

        return jax.lax.cond(jnp.all(geo["ok"]), lambda: streamed,
                            lambda: jax.lax.map(one, (geo["ok"], y, wl, wc2l, streamed)))

    return fit, rows.values


def _start(values, w, wc2, *, eps, floor, start_power):
    """The log-space start's target and weights (module docs, step 1) and the squared weight floor ``fl2 (B, 1)``."""
    b = jnp.maximum(values, 0.0) + eps
    rms = jnp.sqrt(jnp.sum(wc2 * b * b, -1, keepdims=True) / jnp.maximum(jnp.sum(wc2, -1, keepdims=True), 1e-300))
    fl2 = (floor * rms) ** 2
    return (jnp.log(b), w * jnp.maximum(b * b, fl2) ** (0.5 * start_power)), fl2


@functools.partial(jax.jit, static_argnames=("variables", "degree", "basis", "interactions", "method", "rcond",
                                             "cutoff_deg", "eps", "steps", "floor", "start_power", "stream"))
def _shared_kernel(inp, u, v, w, mask, *, variables, degree, basis, interactions, method, rcond, cutoff_deg, eps,
                   steps, floor, start_power, stream) -> dict:
    """The solves of :func:`_gauss_newton` on one design shared by the ``B`` lanes of ``inp`` (each lane's solve as
    :func:`polyjax.fit_polynomial` makes it); ``u, v, w (B, n), mask`` as :func:`_gauss_newton` has them; ``stream``:
    :func:`_streamed_design`, else :func:`_dense_design`. The polynomials' values at the samples are carried from
    solve to solve (one product with the rows per solve: the line search blends them linearly). Returns the fields of
    :class:`polyjax.PolynomialBRDF` as ``(B, ...)`` arrays."""
    values = inp.values
    w_fit, wc2 = fit_weights(u, v, w, mask, cutoff_deg)  # equation (11)'s weights, made once for every score
    keep = w_fit > 0  # the fitted samples; the model may overflow elsewhere
    inside = cutoff_mask(inp.u, inp.v, cutoff_deg)
    kept = inside & inp.mask  # fit_weights of the solves' weights, made once
    cos_u = jnp.where(inside, cos_theta(inp.u), 0.0)

    def weights(target, wt):  # (w, w cos^2) of a solve: fit_weights' arithmetic, 0 off the fitted samples
        wl = jnp.where(kept, jnp.where(keep & jnp.isfinite(target) & jnp.isfinite(wt), wt, 0.0), 0.0)
        return wl, wl * cos_u * cos_u

    start, fl2 = _start(values, w, wc2, eps=eps, floor=floor, start_power=start_power)
    x = get_variables(variables).fn(inp.u, inp.v)
    active = jnp.asarray(term_degrees(x.shape[-1], degree, interactions)) <= degree
    fit, values_at = (_streamed_design if stream else _dense_design)(
        x, fit_weights(inp.u, inp.v, inp.weights[0], inp.mask[0], cutoff_deg)[0] > 0, active, weights(*start)[1],
        degree=degree, basis=basis, interactions=interactions, method=method, rcond=rcond)

    def solve(target, wt):
        tr, *fitted = fit(jnp.where(keep & jnp.isfinite(target) & jnp.isfinite(wt), target, 0.0),
                          *weights(target, wt))
        out = _outputs(inp, jnp.asarray([degree], jnp.int32), tuple(a[None] for a in tr), *(a[None] for a in fitted))
        return {k: a[0] for k, a in out.items()}

    def score(p):  # the L2 of equation (11) of the model whose polynomials at the samples are p
        return l2_from_weights(values, jnp.where(keep, jnp.exp(p) - eps, 0.0), w_fit, wc2)

    def solve_step(i, carry):  # i = 0: the log-space start; then the Gauss-Newton steps (one solve, compiled once)
        model, l2, p = carry
        f = jnp.where(keep, jnp.exp(p) - eps, 0.0)
        g = jnp.maximum(f + eps, jnp.finfo(values.dtype).tiny)
        first = i == 0
        step = solve(jnp.where(first, start[0], jnp.log(g) + (values - f) / g),
                     jnp.where(first, start[1], w * jnp.maximum(g * g, fl2)))
        p_step = jnp.where(keep, values_at(step["coefficients"]), 0.0)  # 0 off the fitted samples (may overflow)
        return jax.lax.cond(first, lambda: (step, score(p_step), p_step),
                            lambda: _line_search(model, step, l2, p, p_step, score))

    blank = jax.tree.map(lambda a: jnp.zeros(a.shape, a.dtype), jax.eval_shape(solve, *start))
    carry = (blank, jnp.zeros(values.shape[:1], values.dtype), jnp.zeros(values.shape, values.dtype))
    model, l2, p = jax.lax.fori_loop(0, steps + 1, solve_step, carry)
    return dict(model, l2=l2, log_top=_log_top(p, keep))


def _line_search(model: dict, step: dict, l2, p, p_step, score):
    """Lane-wise the best of ``model`` (L2 ``l2``, polynomials ``p (L, n)`` at the samples) and the steps towards
    ``step`` (``p_step``) of :data:`STEP_LENGTHS` by ``score`` (each candidate compared with the best so far, as
    :func:`_gauss_newton` does): ``(model, l2, p)``. The polynomials are linear in the coefficients, so a
    candidate's are ``p + t (p_step - p)``: no pass over the rows per candidate."""
    for t in STEP_LENGTHS:
        cand = dict(step, coefficients=model["coefficients"] + t * (step["coefficients"] - model["coefficients"]))
        p_c = p + t * (p_step - p)
        l2_c = score(p_c)
        better = l2_c < l2
        model = _select(better, cand, model)
        p = _select(better, p_c, p)
        l2 = jnp.where(better, l2_c, l2)
    return model, l2, p


def _as_log(model: PolynomialBRDF, eps: float) -> PolynomialBRDF:
    return PolynomialBRDF(**{k: getattr(model, k) for k in _FIELDS}, variables=model.variables, basis=model.basis,
                          interactions=model.interactions, max_degree=model.max_degree, link="log", eps=eps)


_FIELDS = ("coefficients", "degree", "mean", "rotation", "centre", "halfwidth", "l2", "rank", "condition", "n_used",
           "status")


def _blend(a: PolynomialBRDF, b: PolynomialBRDF, t: float) -> PolynomialBRDF:
    """``b`` with coefficients ``a + t (b - a)`` (same samples, hence same components and basis)."""
    coef = a.coefficients + t * (b.coefficients - a.coefficients)
    return _replace(b, coefficients=coef)


def _select(better, a: PolynomialBRDF, b: PolynomialBRDF) -> PolynomialBRDF:
    """Lane-wise ``a`` where ``better`` else ``b`` (models, or dicts of their fields)."""
    def pick(x, y):
        cond = jnp.reshape(better, better.shape + (1,) * (x.ndim - better.ndim))
        return jnp.where(cond, x, y)

    return jax.tree.map(pick, a, b)


def _with_l2(model: PolynomialBRDF, l2) -> PolynomialBRDF:
    return _replace(model, l2=l2)


def _replace(model: PolynomialBRDF, **arrays) -> PolynomialBRDF:
    return PolynomialBRDF(**{k: arrays.get(k, getattr(model, k)) for k in _FIELDS}, variables=model.variables,
                          basis=model.basis, interactions=model.interactions, max_degree=model.max_degree,
                          link=model.link, eps=model.eps)
