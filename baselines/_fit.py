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

import functools
import inspect

import jax
import jax.numpy as jnp
import numpy as np

import polyjax as pj
from polyjax import RESULTS, InputError
from polyjax.internal import is_concrete, one_lapack_thread, prepare_inputs, raise_on_status

from . import _jaxopt
from ._aot import fit_saved
from ._fit_joint import check_channels, fit_joint
from ._implicit import implicit_optimum
from ._models.joint import SUFFIX
from ._models.registry import get_model
from ._models.zernike import fit_zernike
from ._multistart import fit_kernel
from ._result import BaselineFit
from ._solver import SOLVER_FIELDS, MultiStart, solver_of


@one_lapack_thread
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
    nonfinite: str = "error",
    throw: bool = False,
    solver: MultiStart | None = None,
) -> BaselineFit:
    r"""Fit a baseline BRDF model to measurements, every lane (material, channel) in one batched call. (Over 80
    lines because this docstring documents every argument; the body is named steps: checks,
    :func:`polyjax.prepare_inputs`, the kernel, the result.)

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
            (``jaxopt.LevenbergMarquardt``).
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
        nonfinite: NaN/inf values where the mask is True: ``"error"`` (raise; under ``jit`` the lane is flagged
            ``NONFINITE``) or ``"mask"`` (drop those samples), as in :func:`polyjax.fit_polynomial`.
        throw: raise :class:`polyjax.FitError` naming the first lane whose status is not ``OK``; under ``jit``
            an :func:`equinox.error_if` error with that code's message.
        solver: the solver's settings as one value (:class:`baselines.MultiStart`: ``n_starts``, ``backend``,
            ``max_steps``, ``rtol``, ``atol``, ``stage_steps``, ``refine``, ``limit_steps``), instead of those
            keywords; keywords that differ from it are refused.

    Inputs follow the rules every fitter shares (:func:`polyjax.prepare_inputs`), so the input preparation also
    runs under ``jit``.

    The stages (screening, refinement, range-limit rounds) are jobs of one loop around one Levenberg-Marquardt
    solve (:mod:`baselines._multistart`): the solver is traced and compiled once per model and shapes. With JAX's
    persistent compilation cache on (:func:`polyjax.enable_compilation_cache`), a fit of concrete inputs runs as
    one saved executable of the whole fit, kept in the cache folder for later processes (:mod:`baselines._aot`).

    Differentiable (``jit``, ``grad``, ``jvp``, ``vmap``) w.r.t. ``values``, ``weights``, ``u`` and ``v``, for
    ``params``, ``raw`` and ``l2``: the kept optimum by the implicit function theorem (:mod:`baselines._implicit`);
    the solver runs on constants and is never differentiated, the choice of start is piecewise constant, samples
    cut or masked get derivative 0. ``starts`` and ``key`` are not differentiated.

    A kept start that runs out of steps with parameters close to a limit of their range (in ``sin^2``
    within ``1e-2``, and as a second candidate ``1e-1``, of 0 or 1) is put on those limits and given
    ``limit_steps`` more steps, twice at most; the best candidate is kept if its L2 is no worse than
    before. Gauss-Newton steps cannot settle on a limit by themselves (the transform's Jacobian column
    vanishes there), which on the 52 CUReT samples left 29 Ashikhmin-Shirley and 14 Cook-Torrance fits
    at the step limit; with this, 1 and 1.

    A standard material model (:data:`baselines.STANDARD_MODELS`: ``gltf-pbr``, ``principled``, ...) fits the
    R, G, B channels of each material jointly: ``values (..., 3, n)``, its shared parameters (roughness, metallic,
    ...) one per material, its colours per channel (:mod:`baselines._models.joint`); ``params`` stays per channel
    ``(..., 3, P)`` (shared values repeated), ``l2`` per channel, result codes, steps and starts those of the
    material, repeated for its channels; ``starts`` are then ``(..., S, Pj)`` in the joint layout.

    Returns:
        :class:`BaselineFit` with batch shape ``values.shape[:-1]``. A lane whose kept start did not
        converge has ``success = False`` and its :class:`polyjax.RESULTS` code; parameters are never NaN.
    """
    solver = solver_of("fit", solver, _SOLVER_DEFAULTS, n_starts=n_starts, backend=backend, max_steps=max_steps,
                       rtol=rtol, atol=atol, stage_steps=stage_steps, refine=refine, limit_steps=limit_steps)
    n_starts, backend, max_steps, rtol, atol, stage_steps, refine, limit_steps = (
        getattr(solver, k) for k in SOLVER_FIELDS)
    model = get_model(name)
    options = dict(cutoff_deg=cutoff_deg, n_starts=n_starts, backend=backend, max_steps=max_steps, rtol=rtol, atol=atol,
                   stage_steps=stage_steps, refine=refine, limit_steps=limit_steps, order=order, nonfinite=nonfinite)
    saved = fit_saved(fit, model.name, u, v, values, weights, mask, starts, key, throw, options)  # baselines/_aot.py
    if saved is not None:
        return saved
    inp, cutoff = prepare_inputs("fit", u, v, values, weights, mask, cutoff_deg=cutoff_deg, nonfinite=nonfinite)
    wl, wc2 = inp.objective_weights(cutoff)
    if model.linear:
        out = fit_zernike(inp.u, inp.v, inp.values, wl, wc2, order)
        backend = "lstsq"
    else:
        joint = bool(model.shared_across_channels)
        if joint:
            check_channels(model, tuple(inp.batch))
        raw0 = _check_starts(get_model(model.name + SUFFIX) if joint else model, starts, inp.values.dtype,
                             tuple(inp.batch[:-1]) if joint else inp.batch)
        opts = dict(
            n_starts=int(n_starts if raw0 is None else raw0.shape[1]), max_steps=int(max_steps), rtol=float(rtol),
            atol=float(atol), stage_steps=int(min(stage_steps, max_steps)),
            refine=None if refine is None else int(refine), limit_steps=int(limit_steps),
        )
        fitter = fit_joint if joint else _fit_nonlinear
        out = fitter(model, inp, wl, wc2, key, raw0, backend, opts)
    return _result(model, backend, inp, out, throw)


#: the keyword defaults of :func:`fit` that :class:`MultiStart` groups
_SOLVER_DEFAULTS = {k: inspect.signature(fit).parameters[k].default for k in SOLVER_FIELDS}


def _fit_nonlinear(model, inp, wl, wc2, key, raw0, backend: str, opts: dict) -> dict:
    """The multi-start kernel of ``backend`` on constants, then the kept optimum with its implicit derivative:
    a dict of ``(B, ...)`` arrays, the fields of :class:`BaselineFit`."""
    sg = jax.lax.stop_gradient  # the solver loops see constants; the optimum differentiates implicitly
    args = (model.name, sg(inp.u), sg(inp.v), sg(inp.values), sg(wl), sg(wc2),
            jax.random.PRNGKey(0) if key is None else key, None if raw0 is None else sg(raw0))
    if backend == "optimistix":
        out = fit_kernel(*args, **opts)
    else:  # loaded on first use (baselines/_jaxopt/__init__.py)
        out = _jaxopt.staged_kernel(*args, backend=backend, **opts)
    out["raw"], out["params"], out["l2"] = _package(model.name, out["raw"], inp.u, inp.v, inp.values, wl, wc2)
    out["success"] = (out["status"] == RESULTS.OK) & jnp.isfinite(out["l2"])
    return out


def _result(model, backend: str, inp, out: dict, throw: bool) -> BaselineFit:
    """The :class:`BaselineFit` of the kernel's ``out`` in the batch shape of the inputs, with its result codes
    (raised with ``throw``)."""
    fitted = BaselineFit(**_shaped(out, inp.lane_bad, batch=tuple(inp.batch)), name=model.name, backend=backend)
    return raise_on_status("fit", fitted.status, fitted) if throw else fitted


@functools.partial(jax.jit, static_argnames=("batch",))
def _shaped(out: dict, lane_bad, *, batch: tuple) -> dict:
    """The kernel's ``(B, ...)`` fields with their result codes, in the batch shape ``batch`` (one compiled call).

    One result code for every fitter: NaN/inf values in a lane (flagged under jit) and an overflowing L2 are
    NONFINITE, as in the polynomial fit; a NONFINITE lane's L2 is inf."""
    status = jnp.where(lane_bad, RESULTS.NONFINITE, out["status"])
    status = jnp.where((status == RESULTS.OK) & ~jnp.isfinite(out["l2"]), RESULTS.NONFINITE, status).astype(jnp.int32)
    out = dict(out, status=status, success=out["success"] & (status == RESULTS.OK),
               l2=jnp.where(lane_bad, jnp.inf, out["l2"]))
    return {k: a.reshape(batch + a.shape[1:]) for k, a in out.items()}


@functools.partial(jax.jit, static_argnames=("name",))
def _package(name, raw, u, v, y, wl, wc2):
    """The kept optimum with its implicit derivative, its physical parameters and L2 (one compiled call)."""
    model = get_model(name)
    raw = implicit_optimum(model, raw, u, v, y, wl, wc2)
    params = model.to_params(raw)
    pred = jax.vmap(lambda p: model.evaluate(p, u, v))(params)
    return raw, params, pj.l2_error(y, pred, u, v, weights=wl, cutoff_deg=None, mask=wc2 > 0)


def _check_starts(model, starts, dtype, batch):
    """``starts`` of a nonlinear fit as ``(B, S, P)`` (or None); the step limits are checked by
    :class:`baselines.MultiStart`."""
    if starts is None:
        return None
    raw0 = jnp.asarray(starts, dtype)
    if raw0.ndim < 2 or raw0.shape[-1] != model.n_params:
        raise InputError(f"starts: expected shape (..., S, {model.n_params}), found {raw0.shape}")
    nb = int(np.prod(batch)) if batch else 1
    raw0 = jnp.broadcast_to(raw0, batch + raw0.shape[-2:]).reshape((nb,) + raw0.shape[-2:])
    if is_concrete(raw0) and not bool(jnp.all(jnp.isfinite(raw0))):
        raise InputError("starts: expected finite unconstrained parameters")
    return raw0
