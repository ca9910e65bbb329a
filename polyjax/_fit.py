"""Fitting the polynomial model (paper, section 4): one jitted, batched weighted least-squares solve."""

from __future__ import annotations

import functools
import weakref
from typing import Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike

from ._basis import BASES, n_terms, term_degrees
from ._design import fitted_design
from ._errors import InputError
from ._inputs import PreparedInputs, check_parameter_count, is_concrete, prepare_inputs
from ._lstsq import METHODS, weighted_lstsq
from ._measurements import Measurements
from ._metrics import fit_weights
from ._model import PolynomialBRDF
from ._results import Result, raise_on_status
from ._stream import stream_geometry, streamed_lane, use_stream
from ._variables import get_variables


@functools.partial(
    jax.jit, static_argnames=("variables", "max_degree", "basis", "interactions", "method", "rcond", "cutoff_deg",
                              "batch", "scalar", "stream"),
)
def _fit_kernel(inp: PreparedInputs, degrees, *, variables, max_degree, basis, interactions, method, rcond, cutoff_deg,
                batch, scalar, stream=False, geometry=None):
    """Every lane of ``inp`` for every degree of ``degrees (D,)`` -> dict of ``(D, *batch, ...)`` arrays
    (``(*batch, ...)`` when ``scalar``); ``stream``: the shared design is streamed (:mod:`polyjax._stream`),
    from ``geometry`` (:func:`_geometry_kernel`) when given."""
    u, v, values = inp.u, inp.v, inp.values
    k = get_variables(variables).k

    def samples():  # computed where used: a streamed fit from a given geometry never needs them
        x = get_variables(variables).fn(u, v)
        w, wc2 = fit_weights(u, v, inp.weights, inp.mask, cutoff_deg)  # (L, n)
        return x, w, wc2

    tdeg = jnp.asarray(term_degrees(k, max_degree, interactions))
    active = tdeg[None, :] <= degrees[:, None]  # (D, m)
    n_deg, nb = degrees.shape[0], values.shape[0]

    def residual_l2(d, coef, y, wl, wc2l):  # coef (m,) ; y (n,)
        r = y - d @ coef
        den = jnp.sum(wl)
        num = jnp.sum(wc2l * r * r)
        nz = (den > 0) & (num != 0)  # sqrt has no derivative at 0: an empty lane or a perfect fit gets 0, not NaN
        l2 = jnp.where(nz, jnp.sqrt(jnp.where(nz, num, 1.0) / jnp.where(nz, den, 1.0)), 0.0)
        return jnp.where(den > 0, l2, jnp.inf)

    def lane(y, wl, wc2l, x):
        """One set of samples (the right-hand sides ``y (r, n)`` sharing it) fitted for all degrees."""
        keep = wl > 0
        pca, centre, hw, d = fitted_design(x, keep, max_degree, basis, interactions)
        sol = jax.vmap(lambda a: weighted_lstsq(d, y.T, wc2l, a, method=method, rcond=rcond))(active)
        coef = jnp.swapaxes(sol.coefficients, 1, 2)  # (D, r, m)
        l2 = jax.vmap(jax.vmap(lambda c, yy: residual_l2(d, c, yy, wl, wc2l)), in_axes=(0, None))(coef, y)
        return (pca.mean, pca.rotation, centre, hw), coef, l2, sol.rank, sol.condition, sol.n_active, jnp.sum(keep)

    def dense_shared():
        x, w, wc2 = samples()
        return lane(values, w[0], wc2[0], x)

    if inp.shared and stream:  # the same, the design built block by block and never held
        geo = _geometry(inp, active, variables, max_degree, basis, interactions, cutoff_deg) if geometry is None \
            else geometry
        tr, coef, l2, rank, cond, n_act, n_used = streamed_lane(
            geo, values, active, max_degree=max_degree, basis=basis, interactions=interactions, rcond=rcond,
            dense=dense_shared,
        )
    if inp.shared and not stream:  # one design, one factorisation, nb right-hand sides
        tr, coef, l2, rank, cond, n_act, n_used = dense_shared()
    if inp.shared:
        tr = tuple(jnp.broadcast_to(a, (n_deg, nb) + a.shape) for a in tr)
        rank, cond, n_act = (jnp.broadcast_to(a[:, None], (n_deg, nb)) for a in (rank, cond, n_act))
        n_used = jnp.broadcast_to(n_used, (n_deg, nb))
    else:
        x, w, wc2 = samples()
        per_lane = jax.vmap(lambda y, wl, wc2l: lane(y[None], wl, wc2l, x))
        tr, coef, l2, rank, cond, n_act, n_used = per_lane(values, w, wc2)
        coef, l2 = jnp.swapaxes(coef[:, :, 0], 0, 1), jnp.swapaxes(l2[:, :, 0], 0, 1)  # lane axis after degrees
        rank, cond, n_act = (jnp.swapaxes(a, 0, 1) for a in (rank, cond, n_act))
        tr = tuple(jnp.broadcast_to(a[None], (n_deg,) + a.shape) for a in tr)
        n_used = jnp.broadcast_to(n_used[None], (n_deg, nb))
    bad = jnp.broadcast_to(inp.lane_bad[None, :], (n_deg, nb))
    status = jnp.where(jnp.isfinite(l2), Result.OK, Result.NONFINITE)  # an overflowing L2 is not OK
    status = jnp.where(rank < n_act, Result.RANK_DEFICIENT, status)
    status = jnp.where(n_used == 0, Result.NO_SAMPLES, status)
    status = jnp.where(bad, Result.NONFINITE, status).astype(jnp.int32)
    failed = bad | (n_used == 0)
    coef = jnp.where(failed[..., None], 0.0, coef)
    l2 = jnp.where(failed, jnp.inf, l2)
    out = dict(
        coefficients=coef.astype(values.dtype),
        degree=jnp.broadcast_to(degrees[:, None], status.shape).astype(jnp.int32),
        mean=tr[0], rotation=tr[1], centre=tr[2], halfwidth=tr[3], l2=l2, rank=rank, condition=cond,
        n_used=n_used.astype(jnp.int32), status=status,
    )
    lead = () if scalar else (n_deg,)  # (D, B, ...) -> (D?, *batch, ...) inside the program: no eager reshapes
    return {key: (a[0] if scalar else a).reshape(lead + tuple(batch) + a.shape[2:]) for key, a in out.items()}


def _geometry(inp, active, variables, max_degree, basis, interactions, cutoff_deg):
    x = get_variables(variables).fn(inp.u, inp.v)
    w, wc2 = fit_weights(inp.u, inp.v, inp.weights, inp.mask, cutoff_deg)
    return stream_geometry(x, w[0], wc2[0], active, max_degree=max_degree, basis=basis, interactions=interactions)


@functools.partial(jax.jit, static_argnames=("variables", "max_degree", "basis", "interactions", "cutoff_deg"))
def _geometry_kernel(inp, degrees, *, variables, max_degree, basis, interactions, cutoff_deg):
    """The values-independent half of a streamed fit (:func:`polyjax._stream.stream_geometry`), compiled alone."""
    k = get_variables(variables).k
    active = jnp.asarray(term_degrees(k, max_degree, interactions))[None, :] <= degrees[:, None]
    return _geometry(inp, active, variables, max_degree, basis, interactions, cutoff_deg)


_GEOMETRY_MEMO: dict = {}


def _streamed_geometry(inp, degrees, **static):
    """The geometry of a streamed fit, remembered for the next fit on the same samples (the same direction arrays
    by identity, equal weights and mask, the same options): one entry, the last one."""
    key = (tuple(int(d) for d in degrees), tuple(sorted(static.items())))
    hit = _GEOMETRY_MEMO.get("last")
    w, m = np.asarray(inp.weights), np.asarray(inp.mask)
    if (hit is not None and hit["key"] == key and hit["u"]() is inp.u and hit["v"]() is inp.v
            and np.array_equal(hit["w"], w) and np.array_equal(hit["m"], m)):
        return hit["geo"]
    geo = _geometry_kernel(inp, np.asarray(degrees, np.int32), **static)
    if not is_concrete(geo):
        return geo
    try:
        _GEOMETRY_MEMO["last"] = dict(key=key, u=weakref.ref(inp.u), v=weakref.ref(inp.v), w=w.copy(), m=m.copy(),
                                      geo=geo)
    except TypeError:  # arrays without weak references: not remembered
        _GEOMETRY_MEMO.pop("last", None)
    return geo


def _check_options(basis, method, rank_deficient, degree):
    if basis not in BASES:
        raise InputError(f"basis: expected one of {BASES}, found {basis!r}")
    if method not in METHODS:
        raise InputError(f"method: expected one of {METHODS}, found {method!r}")
    if rank_deficient not in ("flag", "error"):
        raise InputError(f"rank_deficient: expected 'flag' or 'error', found {rank_deficient!r}")
    degrees = np.atleast_1d(np.asarray(degree))
    if degrees.ndim != 1 or degrees.size == 0 or not np.issubdtype(degrees.dtype, np.integer) or np.any(degrees < 0):
        raise InputError(f"degree: expected a non-negative integer or a sequence of them, found {degree!r}")
    return degrees


def fit_polynomial(
    u,
    v: ArrayLike | None = None,
    values: ArrayLike | None = None,
    variables: str = "lafortune",
    degree: int | Sequence[int] = 5,
    *,
    weights: ArrayLike | None = None,
    mask: ArrayLike | None = None,
    cutoff_deg: float | None = 80.0,
    basis: str = "legendre",
    interactions: bool = False,
    method: str = "qr",
    rcond: float | None = None,
    rank_deficient: str = "flag",
    nonfinite: str = "error",
    throw: bool = False,
    link: str = "identity",
    eps: float = 1e-3,
    steps: int = 3,
) -> PolynomialBRDF:
    r"""Fit the polynomial BRDF of equation (3) by weighted least squares, in closed form.

    Minimises the Ngan et al. objective of equation (11),
    ``sum_i w_i cos^2(theta_u,i) (b_i - f(u_i, v_i))^2``, over the samples with ``theta_u`` and
    ``theta_v`` at most ``cutoff_deg``. The explanatory variables (section 3) are transformed to
    principal components over those samples, the design of equation (13) is built, and the
    solve is QR + SVD of the square-root-weighted design (:func:`polyjax.weighted_lstsq`).
    Inputs follow the rules every fitter shares (``polyjax/_inputs.py``); the fit is differentiable and
    batches under ``jit``/``vmap`` (``throw`` then raises through :func:`equinox.error_if`).

    Args:
        u: ``(n, 3)`` light directions, or a :class:`polyjax.Measurements` (then ``v``/``values``
           and its ``weights``/``mask`` are taken from it).
        v: ``(n, 3)`` view directions.
        values: ``(*batch, n)`` measured BRDF, samples last; every leading axis (materials, channels)
           is fitted independently in the same call.
           The fit runs in the dtype of ``values`` (float32 or float64; integers are converted to the
           default float, float16/bfloat16 to float32; complex values are rejected).
        variables: a registered variable set: ``"ward"``, ``"ashikhmin-shirley"``, ``"lafortune"``,
           ``"lafortune-anisotropic"`` or a user's own.
        degree: ``p``, or a sequence of degrees: the result then has a leading degree axis.
        weights: solid-angle weights ``w_i`` (``(n,)`` or ``(*batch, n)``), ones by default.
        mask: ``(n,)`` (shared by every lane) or ``(*batch, n)`` validity mask; False samples are not fitted.
        cutoff_deg: grazing cutoff in degrees (80 in the paper); None keeps all samples above the horizon.
        basis: ``"legendre"`` (default, well conditioned) or ``"monomial"`` (the paper's literal powers);
           both span the same space and give the same fit.
        interactions: fit the full response surface of equation (2) instead of equation (3).
        method: ``"qr"`` (default) or ``"svd"``.
        rcond: relative singular-value cutoff for the rank; default ``eps * max(m, sqrt(n))``.
        rank_deficient: ``"flag"`` (minimum-norm solution, ``status = RANK_DEFICIENT``) or ``"error"``
           (the same as ``throw=True``).
        nonfinite: ``"error"`` (raise on NaN/inf in ``values`` where the mask is True; under an outer ``jit``,
           where nothing can be raised before the fit, such a lane is flagged ``NONFINITE``) or ``"mask"``
           (drop those samples).
        throw: raise :class:`polyjax.FitError` naming the first lane whose status is not ``OK``
           (rank-deficient, no samples, non-finite values or L2); under ``jit`` an
           :func:`equinox.error_if` error with that code's message. Lanes with no samples are always
           ``NO_SAMPLES`` (L2 = inf); a lane whose L2 overflows is ``NONFINITE``.
        link, eps, steps: ``link="log"`` fits ``f = exp(poly) - eps`` to equation (11) by ``1 + steps``
           weighted solves (:func:`polyjax.fit_log_polynomial`, one integer ``degree``); ``"identity"`` (default)
           is equation (3) itself.

    Returns:
        :class:`polyjax.PolynomialBRDF` with batch shape ``values.shape[:-1]`` (preceded by the
        degree axis when ``degree`` is a sequence); ``status`` holds :class:`polyjax.Result` codes.
    """
    if link != "identity":  # log-space model f = exp(poly) - eps: polyjax/_logfit.py
        if link != "log" or nonfinite != "error":
            raise InputError(f"link: expected 'identity' or 'log' (with nonfinite='error'), found {link!r}")
        from ._logfit import fit_log_polynomial

        return fit_log_polynomial(u, v, values, variables, degree, eps=eps, steps=steps, weights=weights, mask=mask,
                                  cutoff_deg=cutoff_deg, basis=basis, interactions=interactions, method=method,
                                  rcond=rcond, rank_deficient=rank_deficient)
    if isinstance(u, Measurements) and isinstance(v, str):
        u, v, variables = u, None, v
    vs = get_variables(variables)
    degrees = _check_options(basis, method, rank_deficient, degree)
    inp, cutoff = prepare_inputs("fit_polynomial", u, v, values, weights, mask, cutoff_deg=cutoff_deg,
                                 nonfinite=nonfinite)
    max_degree = int(degrees.max())
    m = n_terms(vs.k, max_degree, bool(interactions))
    check_parameter_count(f"degree={max_degree}, interactions={bool(interactions)}, variables={vs.name!r}", m, inp.n,
                          inp.values.dtype.itemsize)
    scalar = np.ndim(degree) == 0
    stream = use_stream(inp.n, m, int(np.prod(inp.batch, dtype=int)), method, inp.shared,
                        is_concrete(inp.u, inp.v, inp.values, inp.weights, inp.mask))
    static = dict(variables=vs.name, max_degree=max_degree, basis=basis, interactions=bool(interactions),
                  cutoff_deg=cutoff)
    geometry = _streamed_geometry(inp, degrees, **static) if stream else None
    out = _fit_kernel(inp, np.asarray(degrees, np.int32), method=method, rcond=rcond, batch=inp.batch, scalar=scalar,
                      stream=stream, geometry=geometry, **static)
    model = PolynomialBRDF(**out, variables=vs.name, basis=basis, interactions=bool(interactions),
                           max_degree=max_degree)
    if throw or rank_deficient == "error":
        def describe(i):
            at = lambda a: int(np.asarray(a)[i] if np.ndim(a) else a)  # noqa: E731
            return (f"rank {at(model.rank)} of {at(model.n_params)} parameters, {at(model.n_used)} samples used after "
                    "the cutoff and mask")

        model = raise_on_status("fit_polynomial", model.status, model, describe)
    return model


def n_parameters(variables: str, degree: int, interactions: bool = False) -> int:
    """``k p + 1`` for a variable set (equation (3)); ``C(k + p, p)`` with interactions (equation (2))."""
    return n_terms(get_variables(variables).k, degree, interactions)
