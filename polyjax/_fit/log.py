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

``1 + steps`` solves in all (default ``steps=3``: 4 solves). Every solve uses the same samples, hence
the same principal components and basis, so the coefficients of different steps combine linearly.

When every lane (colour channel, material) keeps the same samples (directions ``(n, 3)``, and the same samples
kept by the weights, mask and cutoff in every lane), the whole sequence of solves runs in one compiled program
(:func:`_shared_kernel`) on the lanes' one design: the samples' variables and the model's values at the samples are
made for every lane at once; only the weighted factorisation is made per lane and solve
(the weights of every solve depend on the lane's values), one lane after the other, each as
:func:`polyjax.fit_polynomial` makes it: on the design held whole (differentiable), or, for concrete tall inputs,
streamed a block of rows at a time as ``fit_polynomial`` streams a shared design (:mod:`polyjax._fit.stream`). Otherwise
(per-lane directions, lanes that keep different samples) each solve is a :func:`polyjax.fit_polynomial` call
(:func:`_gauss_newton`). On the DiLiGenT ball (352,745 BRDF samples, 3 channels, Rusinkiewicz ``p = 8`` with
interactions) the shared program is the per-solve calls' result to 3e-14 (coefficients) and several times faster
(``benchmarks/RESULTS.md``).
"""

from __future__ import annotations

import functools
import inspect

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike

from .._arrays import is_concrete, is_traced
from .._basis import n_terms, term_degrees
from .._design import fitted_design
from .._errors import InputError
from .._inputs import check_parameter_count, prepare_inputs
from .._measurements import Measurements
from .._metrics import fit_weights, l2_error
from .._model import SPEC_FIELDS, PolynomialBRDF, PolynomialSpec, spec_of
from .._solve.lstsq import weighted_lstsq
from .._solve.threads import one_lapack_thread
from .._variables import get_variables
from .closed_form import _lane, _raise_on_status, _residual_l2, check_fit_options, fit_closed_form
from .closed_form import _result_fields as _outputs
from .stream import BLOCK, _design_t, _scaled_components, _stream_map, stream_geometry, streamed_lane, use_stream

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
        spec: the model's definition as one value (:class:`polyjax.PolynomialSpec` with ``link="log"``), instead
            of ``variables``, ``degree``, ``basis``, ``interactions`` and ``eps``.

    Returns:
        :class:`polyjax.PolynomialBRDF` with ``link="log"`` and ``eps``; its ``l2`` is equation (11) of
        ``f`` on the fitted samples, its ``rank``/``condition``/``status`` those of the last solve.
        Differentiable with respect to ``values``, ``weights`` and directions wherever
        :func:`polyjax.fit_polynomial` is (the step choice is piecewise constant).
    """
    if isinstance(u, Measurements) and isinstance(v, str):  # fit_log_polynomial(data, "rusinkiewicz")
        u, v, variables = u, None, v
    spec = spec_of("fit_log_polynomial", spec, _SPEC_DEFAULTS, variables=variables, degree=degree, basis=basis,
                   interactions=interactions, link="log", eps=eps)
    if spec.link != "log":
        raise InputError(f"spec: expected link='log' for fit_log_polynomial, found {spec.link!r}")
    variables, degree, basis, interactions, eps = spec.variables, spec.degree, spec.basis, spec.interactions, spec.eps
    u, v, values, w, mask, variables, eps, shared = _check_inputs(u, v, values, variables, degree, eps, steps,
                                                                  weights, mask)
    opts = {"variables": variables, "degree": int(degree), "mask": mask, "cutoff_deg": cutoff_deg, "basis": basis,
            "interactions": interactions, "method": method, "rcond": rcond, "rank_deficient": rank_deficient}
    gn = dict(eps=eps, steps=int(steps), floor=float(floor), start_power=float(start_power))
    if shared or _same_samples(u, v, w, mask, cutoff_deg):
        return _shared_gauss_newton(u, v, values, w, mask, cutoff_deg, opts, **gn)
    return _gauss_newton(u, v, values, w, mask, cutoff_deg, opts, **gn)


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
    return _with_l2(model, l2)


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


def _dense_design(x, keep, active, *, degree, basis, interactions, method, rcond):
    """The shared design held whole (differentiable): ``(fit, values_at)``, ``fit(y, w, w cos^2)`` one lane's
    solve as :func:`polyjax.fit_polynomial` makes it (its outputs as ``polyjax._fit._lane``'s, without the degree
    axis) and ``values_at(coef (B, m))`` the polynomial at every sample, ``(B, n)``."""
    pca, centre, hw, d = fitted_design(x, keep, degree, basis, interactions)

    def fit(y, wl, wc2l):
        sol = weighted_lstsq(d, y[:, None], wc2l, active, method=method, rcond=rcond)
        c = sol.coefficients[:, 0]
        l2 = _residual_l2(d, c, y, wl, wc2l)
        return (pca.mean, pca.rotation, centre, hw), c, l2, sol.rank, sol.condition, sol.n_active, jnp.sum(wl > 0)

    return fit, lambda coef: (d @ coef.T).T


def _streamed_design(x, keep, active, *, degree, basis, interactions, method, rcond):
    """:func:`_dense_design` streamed: every solve :func:`polyjax.fit_polynomial`'s streamed fit of one lane
    (:func:`polyjax._stream.stream_geometry`, :func:`polyjax._stream.streamed_lane`; the dense solve where a
    Cholesky factor fails), and the polynomial's values made a block of rows at a time, the design never held."""
    lane = functools.partial(_lane, active=active[None], max_degree=degree, basis=basis, interactions=interactions,
                             method=method, rcond=rcond)
    opts = dict(max_degree=degree, basis=basis, interactions=interactions)

    def fit(y, wl, wc2l):
        geo = stream_geometry(x, wl, wc2l, active[None], **opts)
        out = streamed_lane(geo, y[None], active[None], rcond=rcond, dense=lambda: lane(y[None], wl, wc2l, x), **opts)
        tr, coef, l2, rank, cond, n_act, n_used = out
        return tr, coef[0, 0], l2[0, 0], rank[0], cond[0], n_act[0], n_used

    t = _scaled_components(x, keep, keep, basis)[3]

    def values_at(coef):
        def block(t_b):
            return (jnp.matmul(coef, _design_t(t_b.T, degree, basis, interactions), precision="highest"),), ()

        return _stream_map(block, t.shape[1], BLOCK, (t.T,))[0][0]

    return fit, values_at


@functools.partial(jax.jit, static_argnames=("variables", "degree", "basis", "interactions", "method", "rcond",
                                             "cutoff_deg", "eps", "steps", "floor", "start_power", "stream"))
def _shared_kernel(inp, u, v, w, mask, *, variables, degree, basis, interactions, method, rcond, cutoff_deg, eps,
                   steps, floor, start_power, stream) -> dict:
    """The solves of :func:`_gauss_newton` on one design shared by the ``B`` lanes of ``inp`` (the same arithmetic:
    each solve that of :func:`polyjax.fit_polynomial`, lane by lane, ``jax.lax.map``: under ``vmap`` the streamed
    solve's conditionals would run both branches, its dense fallback included); ``u, v, w (B, n), mask`` as
    :func:`_gauss_newton` has them;
    ``stream``: :func:`_streamed_design`, else :func:`_dense_design`. Returns the fields of
    :class:`polyjax.PolynomialBRDF` as ``(B, ...)`` arrays."""
    values = inp.values
    keep, wc2 = fit_weights(u, v, w, mask, cutoff_deg)
    keep = keep > 0  # the fitted samples; the model may overflow elsewhere
    x = get_variables(variables).fn(inp.u, inp.v)
    active = jnp.asarray(term_degrees(x.shape[-1], degree, interactions)) <= degree
    fit, values_at = (_streamed_design if stream else _dense_design)(
        x, fit_weights(inp.u, inp.v, inp.weights[0], inp.mask[0], cutoff_deg)[0] > 0, active, degree=degree,
        basis=basis, interactions=interactions, method=method, rcond=rcond)

    def solve(target, wt):
        ok = keep & jnp.isfinite(target) & jnp.isfinite(wt)
        wl, wc2l = fit_weights(inp.u, inp.v, jnp.where(ok, wt, 0.0), inp.mask, cutoff_deg)
        tr, *fitted = jax.lax.map(lambda a: fit(*a), (jnp.where(ok, target, 0.0), wl, wc2l))
        out = _outputs(inp, jnp.asarray([degree], jnp.int32), tuple(a[None] for a in tr), *(a[None] for a in fitted))
        return {k: a[0] for k, a in out.items()}

    def predict(coef):  # the model at the samples, 0 off the fitted ones (where it may overflow)
        p = jnp.where(keep, values_at(coef), 0.0)
        return jnp.where(keep, jnp.exp(p) - eps, 0.0)

    def score(coef):
        return l2_error(values, predict(coef), u, v, w, cutoff_deg, mask)

    b = jnp.maximum(values, 0.0) + eps
    rms = jnp.sqrt(jnp.sum(wc2 * b * b, -1, keepdims=True) / jnp.maximum(jnp.sum(wc2, -1, keepdims=True), 1e-300))
    fl2 = (floor * rms) ** 2
    start = (jnp.log(b), w * jnp.maximum(b * b, fl2) ** (0.5 * start_power))

    def solve_step(i, carry):  # i = 0: the log-space start; then the Gauss-Newton steps (one solve, compiled once)
        model, l2 = carry
        f = predict(model["coefficients"])
        g = jnp.maximum(f + eps, jnp.finfo(values.dtype).tiny)
        first = i == 0
        step = solve(jnp.where(first, start[0], jnp.log(g) + (values - f) / g),
                     jnp.where(first, start[1], w * jnp.maximum(g * g, fl2)))
        return jax.lax.cond(first, lambda: (step, score(step["coefficients"])),
                            lambda: _line_search(model, step, l2, score))

    blank = jax.tree.map(lambda a: jnp.zeros(a.shape, a.dtype), jax.eval_shape(solve, *start))
    model, l2 = jax.lax.fori_loop(0, steps + 1, solve_step, (blank, jnp.zeros(values.shape[:1], values.dtype)))
    return dict(model, l2=l2)


def _line_search(model: dict, step: dict, l2, score):
    """Lane-wise the best of ``model`` (L2 ``l2``) and the steps towards ``step`` of :data:`STEP_LENGTHS` by
    ``score`` (each candidate compared with the best so far, as :func:`_gauss_newton` does): ``(model, l2)``."""
    for t in STEP_LENGTHS:
        cand = dict(step, coefficients=model["coefficients"] + t * (step["coefficients"] - model["coefficients"]))
        l2_c = score(cand["coefficients"])
        better = l2_c < l2
        model = _select(better, cand, model)
        l2 = jnp.where(better, l2_c, l2)
    return model, l2

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
