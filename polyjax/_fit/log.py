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
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike

from .._arrays import is_traced
from .._errors import InputError
from .._measurements import Measurements
from .._metrics import fit_weights, l2_error
from .._model import PolynomialBRDF
from .._solve.threads import one_lapack_thread
from .closed_form import fit_closed_form

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

    Returns:
        :class:`polyjax.PolynomialBRDF` with ``link="log"`` and ``eps``; its ``l2`` is equation (11) of
        ``f`` on the fitted samples, its ``rank``/``condition``/``status`` those of the last solve.
        Differentiable with respect to ``values``, ``weights`` and directions wherever
        :func:`polyjax.fit_polynomial` is (the step choice is piecewise constant).
    """
    u, v, values, w, mask, variables, eps = _check_inputs(u, v, values, variables, degree, eps, steps, weights, mask)
    opts = {"variables": variables, "degree": int(degree), "mask": mask, "cutoff_deg": cutoff_deg, "basis": basis,
            "interactions": interactions, "method": method, "rcond": rcond, "rank_deficient": rank_deficient}
    return _gauss_newton(u, v, values, w, mask, cutoff_deg, opts, eps=eps, steps=int(steps), floor=floor,
                         start_power=start_power)


def _check_inputs(u, v, values, variables, degree, eps, steps, weights, mask):
    """The arguments of :func:`fit_log_polynomial` checked (before any work) and converted: ``(u, v, values,
    weights (*batch, n), mask, variables, eps)``, the arrays in the float type of ``values``."""
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
    return u, v, values, jnp.broadcast_to(w, values.shape), mask, variables, float(eps)


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
    """Lane-wise ``a`` where ``better`` else ``b``."""
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
