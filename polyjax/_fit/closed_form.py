"""Fitting the polynomial model (paper, section 4): one jitted, batched weighted least-squares solve."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from .._arrays import is_concrete
from .._basis import BASES, n_terms, term_degrees
from .._cache import geometry as store
from .._cache import memo
from .._cache.keys import geometry_key
from .._design import fitted_design
from .._errors import InputError
from .._inputs import PreparedInputs, check_parameter_count, prepare_inputs
from .._measurements import Measurements
from .._metrics import fit_weights
from .._model import PolynomialBRDF
from .._results import RESULTS, raise_on_status
from .._solve.lstsq import METHODS, weighted_lstsq
from .._variables import get_variables
from . import stream as streaming
from .sharding import lane_sharding, shard_lanes
from .stream import (
    kept_rows,
    sampled_rows,
    stream_geometry,
    streamed_lane,
    use_stream,
)

#: lanes fitted at once (``vmap``) inside the loop over blocks of lanes (``lax.map``) of the per-lane path
LANE_BLOCK = 1024


@functools.partial(
    jax.jit, static_argnames=("variables", "max_degree", "basis", "interactions", "method", "rcond", "cutoff_deg",
                              "batch", "scalar", "stream", "lane_block"),
)
def _fit_kernel(inp: PreparedInputs, degrees, *, variables, max_degree, basis, interactions, method, rcond, cutoff_deg,
                batch, scalar, stream=False, geometry=None, lane_block=LANE_BLOCK):
    """Every lane of ``inp`` for every degree of ``degrees (D,)`` -> dict of ``(D, *batch, ...)`` arrays
    (``(*batch, ...)`` when ``scalar``; ``(D, B, ...)``, the lanes flat, when ``batch`` is None: a sharded fit's
    block of lanes); ``stream``: the shared design is streamed (:mod:`polyjax._fit.stream`), from ``geometry``
    (:func:`_geometry_kernel`) when given.

    Lanes with samples of their own (per-lane weights, masks or directions) are fitted group by group (a group:
    the lanes sharing one set of samples, e.g. a texel's colour channels), ``lane_block`` lanes at a time:
    :func:`jax.lax.map` over blocks, ``vmap`` inside a block, so memory is bounded by the block, not the batch.
    Only the shared-design path is ever streamed.
    """
    k = get_variables(variables).k
    active = jnp.asarray(term_degrees(k, max_degree, interactions))[None, :] <= degrees[:, None]  # (D, m)
    lane = functools.partial(_lane, active=active, max_degree=max_degree, basis=basis, interactions=interactions,
                             method=method, rcond=rcond)
    if inp.shared:
        fitted = _fit_shared(inp, active, lane, variables=variables, max_degree=max_degree, basis=basis,
                             interactions=interactions, rcond=rcond, cutoff_deg=cutoff_deg, stream=stream,
                             geometry=geometry)
    else:
        fitted = _fit_groups(inp, active.shape[0], lane, variables=variables, cutoff_deg=cutoff_deg,
                             lane_block=lane_block)
    out = _result_fields(inp, degrees, *fitted)
    if batch is None:  # a sharded fit's block of lanes: (D, B_local, ...), reshaped outside the shard_map
        return out
    lead = () if scalar else (degrees.shape[0],)  # (D, B, ...) -> (D?, *batch, ...) inside the program
    return {key: (a[0] if scalar else a).reshape(lead + tuple(batch) + a.shape[2:]) for key, a in out.items()}


def _residual_l2(d, coef, y, wl, wc2l):
    """The L2 of equation (11) of one right-hand side ``y (n,)`` fitted by ``coef (m,)`` on the design ``d``; 0 for
    a perfect fit (not NaN: ``sqrt`` has no derivative at 0), ``inf`` for a lane with no samples."""
    r = y - d @ coef
    den = jnp.sum(wl)
    num = jnp.sum(wc2l * r * r)
    nz = (den > 0) & (num != 0)
    l2 = jnp.where(nz, jnp.sqrt(jnp.where(nz, num, 1.0) / jnp.where(nz, den, 1.0)), 0.0)
    return jnp.where(den > 0, l2, jnp.inf)


def _lane(y, wl, wc2l, x, *, active, max_degree, basis, interactions, method, rcond):
    """One set of samples (the right-hand sides ``y (r, n)`` sharing it) fitted for all degrees (``active (D, m)``
    terms): the transform ``(mean, rotation, centre, halfwidth)``, ``coef (D, r, m)``, ``l2 (D, r)``, rank,
    condition and active terms ``(D,)``, samples used."""
    keep = wl > 0
    pca, centre, hw, d = fitted_design(x, keep, max_degree, basis, interactions)
    sol = jax.vmap(lambda a: weighted_lstsq(d, y.T, wc2l, a, method=method, rcond=rcond))(active)
    coef = jnp.swapaxes(sol.coefficients, 1, 2)  # (D, r, m)
    l2 = jax.vmap(jax.vmap(lambda c, yy: _residual_l2(d, c, yy, wl, wc2l)), in_axes=(0, None))(coef, y)
    return (pca.mean, pca.rotation, centre, hw), coef, l2, sol.rank, sol.condition, sol.n_active, jnp.sum(keep)


def _fit_shared(inp, active, lane, *, variables, max_degree, basis, interactions, rcond, cutoff_deg, stream,
                geometry):
    """Every lane on the one shared design: one factorisation, ``B`` right-hand sides; streamed (the design built
    block by block and never held, from ``geometry`` when given) when ``stream``. :func:`_lane`'s outputs
    broadcast to ``(D, B, ...)``."""
    n_deg, nb = active.shape[0], inp.values.shape[0]

    def dense_shared():
        x = get_variables(variables).fn(inp.u, inp.v)
        w, wc2 = fit_weights(inp.u, inp.v, inp.weights, inp.mask, cutoff_deg)  # (L, n)
        return lane(inp.values, w[0], wc2[0], x)

    if stream:
        geo = _geometry(inp, active, variables, max_degree, basis, interactions, cutoff_deg) if geometry is None \
            else geometry
        tr, coef, l2, rank, cond, n_act, n_used = streamed_lane(
            geo, inp.values, active, max_degree=max_degree, basis=basis, interactions=interactions, rcond=rcond,
            dense=dense_shared,
        )
    else:
        tr, coef, l2, rank, cond, n_act, n_used = dense_shared()
    tr = tuple(jnp.broadcast_to(a, (n_deg, nb) + a.shape) for a in tr)
    rank, cond, n_act = (jnp.broadcast_to(a[:, None], (n_deg, nb)) for a in (rank, cond, n_act))
    return tr, coef, l2, rank, cond, n_act, jnp.broadcast_to(n_used, (n_deg, nb))


def _fit_groups(inp, n_deg, lane, *, variables, cutoff_deg, lane_block):
    """Groups of ``r`` lanes, each group with its own samples (weights, masks or directions), ``lane_block`` lanes
    at a time; :func:`_lane`'s outputs with the lane axis ``(G r)`` after the degree axis: ``(D, B, ...)``."""
    u, v, values = inp.u, inp.v, inp.values
    var_fn = get_variables(variables).fn
    nb, n_groups = values.shape[0], inp.groups
    r = nb // n_groups
    x_shared = None if inp.lane_directions else var_fn(u, v)

    # per-group arrays are mapped over; (1, n) weights or masks (per-lane directions only) are shared
    mapped = {"y": values.reshape(n_groups, r, -1)}
    for name, a in (("w", inp.weights), ("m", inp.mask)):
        if a.shape[0] > 1:
            mapped[name] = a
    if inp.lane_directions:
        mapped.update(u=inp.u, v=inp.v)

    def group(a):
        ul, vl = (a["u"], a["v"]) if inp.lane_directions else (u, v)
        x = var_fn(ul, vl) if inp.lane_directions else x_shared
        wg, wc2g = fit_weights(ul, vl, a.get("w", inp.weights[0]), a.get("m", inp.mask[0]), cutoff_deg)
        return lane(a["y"], wg, wc2g, x)

    tr, coef, l2, rank, cond, n_act, n_used = jax.lax.map(group, mapped, batch_size=max(1, lane_block // r))
    # (G, D, r, ...) -> lane axis (G r) after the degree axis
    coef = jnp.swapaxes(coef, 0, 1).reshape((n_deg, nb) + coef.shape[3:])
    l2 = jnp.swapaxes(l2, 0, 1).reshape(n_deg, nb)
    rank, cond, n_act = (jnp.repeat(jnp.swapaxes(a, 0, 1), r, axis=1) for a in (rank, cond, n_act))
    tr = tuple(jnp.broadcast_to(jnp.repeat(a, r, axis=0)[None], (n_deg, nb) + a.shape[1:]) for a in tr)
    n_used = jnp.broadcast_to(jnp.repeat(n_used, r)[None], (n_deg, nb))
    return tr, coef, l2, rank, cond, n_act, n_used


def _result_fields(inp, degrees, tr, coef, l2, rank, cond, n_act, n_used) -> dict:
    """The fields of :class:`polyjax.PolynomialBRDF` as ``(D, B, ...)`` arrays, with the :class:`polyjax.RESULTS`
    code of every lane; a failed lane (no samples, non-finite values) has zero coefficients and L2 ``inf``."""
    n_deg, nb = l2.shape
    bad = jnp.broadcast_to(inp.lane_bad[None, :], (n_deg, nb))
    status = jnp.where(jnp.isfinite(l2), RESULTS.OK, RESULTS.NONFINITE)  # an overflowing L2 is not OK
    status = jnp.where(rank < n_act, RESULTS.RANK_DEFICIENT, status)
    status = jnp.where(n_used == 0, RESULTS.NO_SAMPLES, status)
    status = jnp.where(bad, RESULTS.NONFINITE, status).astype(jnp.int32)
    failed = bad | (n_used == 0)
    coef = jnp.where(failed[..., None], 0.0, coef)
    l2 = jnp.where(failed, jnp.inf, l2)
    return dict(
        coefficients=coef.astype(inp.values.dtype),
        degree=jnp.broadcast_to(degrees[:, None], status.shape).astype(jnp.int32),
        mean=tr[0], rotation=tr[1], centre=tr[2], halfwidth=tr[3], l2=l2, rank=rank, condition=cond,
        n_used=n_used.astype(jnp.int32), status=status,
    )


def _geometry(inp, active, variables, max_degree, basis, interactions, cutoff_deg):
    """:func:`polyjax._fit.stream.stream_geometry` of the shared samples of ``inp``, their variables and weights made in
    one loop over the directions (:func:`polyjax._fit.stream.sampled_rows`)."""
    xt, w, wc2 = sampled_rows(_sample_rows(variables, cutoff_deg), (inp.u, inp.v, inp.weights[0], inp.mask[0]))
    return stream_geometry(xt.T, w, wc2, active, max_degree=max_degree, basis=basis, interactions=interactions)


@functools.partial(jax.jit, static_argnames=("variables", "max_degree", "basis", "interactions", "cutoff_deg"))
def _geometry_kernel(inp, degrees, *, variables, max_degree, basis, interactions, cutoff_deg):
    """The values-independent half of a streamed fit (:func:`polyjax._fit.stream.stream_geometry`), compiled alone."""
    k = get_variables(variables).k
    active = jnp.asarray(term_degrees(k, max_degree, interactions))[None, :] <= degrees[:, None]
    return _geometry(inp, active, variables, max_degree, basis, interactions, cutoff_deg)


def _sample_rows(variables, cutoff_deg):
    """``(u, v, w, mask) -> (x, w, w cos^2 theta_u)`` of a block of samples (:func:`polyjax._fit.stream.kept_rows`)."""
    var_fn = get_variables(variables).fn

    def sample(u, v, w, m):
        wl, wc2l = fit_weights(u, v, w, m, cutoff_deg)
        return var_fn(u, v), wl, wc2l

    return sample


@functools.partial(jax.jit, static_argnames=("variables", "max_degree", "basis", "interactions", "method", "rcond",
                                             "cutoff_deg", "batch", "scalar", "lane_block"))
def _kept_fit_kernel(inp: PreparedInputs, degrees, kept: dict, *, variables, cutoff_deg, **static):
    """The first streamed fit on a geometry kept on disk (its small fields ``kept``), in one program: the per-sample
    rows from the kept transform (:func:`polyjax._fit.stream.kept_rows`), then :func:`_fit_kernel` on the completed
    geometry. Returns ``(outputs, rows)``; the caller uses the outputs only if the rows' samples used and total
    weight are the kept geometry's (:func:`_streamed_fit`)."""
    rows = kept_rows(_sample_rows(variables, cutoff_deg), (inp.u, inp.v, inp.weights[0], inp.mask[0]),
                     *(kept[f] for f in ("mean", "rotation", "centre", "halfwidth")))
    geo = {**kept, "t": rows["t"], "wc2": rows["wc2"]}
    out = _fit_kernel(inp, degrees, variables=variables, cutoff_deg=cutoff_deg, stream=True, geometry=geo, **static)
    return out, rows


def _kept_rows_match(rows, kept) -> bool:
    """Whether the rows of a kept geometry have its samples used and total weight (to rounding: ``1e-12``)."""
    return int(rows["n_used"]) == int(kept["n_used"]) and np.allclose(rows["den"], kept["den"], rtol=1e-12, atol=0)


def _stream_constants() -> tuple:
    """The streaming constants a kept geometry depends on (part of its key), read when the key is made."""
    return (streaming.BLOCK, streaming.PRECONDITION_STRIDE, streaming.PRECONDITION_CONDITION)


def _streamed_fit(inp, degrees, *, static, **options) -> dict:
    """:func:`_fit_kernel` streamed, on the geometry of these samples and options: the one this process made last
    (:func:`polyjax._cache.memo.remembered_geometry`), else the one kept on disk when the compilation cache is on
    (``polyjax/_cache/geometry.py``: found by a hash of everything it depends on, checked, never trusted
    otherwise; its per-sample rows are made inside the fit's program, :func:`_kept_fit_kernel`, and the fit is kept
    only if they have the samples used and total weight of the kept geometry), else a new one (written there)."""
    degrees = np.asarray(degrees, np.int32)
    kernel = functools.partial(_fit_kernel, method=options["method"], rcond=options["rcond"], batch=inp.batch,
                               scalar=options["scalar"], lane_block=options["lane_block"], **static)
    geo = memo.remembered_geometry(inp, degrees, static)
    if geo is not None:
        return kernel(inp, degrees, stream=True, geometry=geo)
    folder = store.store_folder()
    key = None if folder is None else geometry_key(inp, degrees, static, _stream_constants())
    if key is not None:
        k = get_variables(static["variables"]).k
        m = n_terms(k, static["max_degree"], static["interactions"])
        kept = store.load(folder, key, store.template(k, m, len(degrees), inp.u.dtype))
        if kept is not None:
            kept = {f: jnp.asarray(a) for f, a in kept.items()}
            out, rows = _kept_fit_kernel(inp, degrees, kept, batch=inp.batch, **options, **static)
            if _kept_rows_match(rows, kept):
                memo.remember_geometry(inp, degrees, static, {**kept, "t": rows["t"], "wc2": rows["wc2"]})
                return out
    geo = _geometry_kernel(inp, degrees, **static)
    memo.remember_geometry(inp, degrees, static, geo)
    out = kernel(inp, degrees, stream=True, geometry=geo)
    if key is not None:  # written while the fit runs (the kernel returns before its result is ready)
        store.save(folder, key, geo)
    return out


def check_fit_options(basis, method, rank_deficient, degree, lane_block):
    """The options of :func:`polyjax.fit_polynomial` checked; the degrees as a ``(D,)`` integer array."""
    if basis not in BASES:
        raise InputError(f"basis: expected one of {BASES}, found {basis!r}")
    if method not in METHODS:
        raise InputError(f"method: expected one of {METHODS}, found {method!r}")
    if rank_deficient not in ("flag", "error"):
        raise InputError(f"rank_deficient: expected 'flag' or 'error', found {rank_deficient!r}")
    degrees = np.atleast_1d(np.asarray(degree))
    if degrees.ndim != 1 or degrees.size == 0 or not np.issubdtype(degrees.dtype, np.integer) or np.any(degrees < 0):
        raise InputError(f"degree: expected a non-negative integer or a sequence of them, found {degree!r}")
    if not isinstance(lane_block, (int, np.integer)) or isinstance(lane_block, bool) or lane_block < 1:
        raise InputError(f"lane_block: expected a positive integer, found {lane_block!r}")
    return degrees


def fit_closed_form(u, v, values, variables: str, degree, *, weights, mask, cutoff_deg, basis: str, interactions: bool,
                    method: str, rcond, rank_deficient: str, nonfinite: str = "error", throw: bool = False,
                    lane_block: int = LANE_BLOCK) -> PolynomialBRDF:
    """The closed-form fit of equation (3) (:func:`polyjax.fit_polynomial` with ``link="identity"``, its arguments):
    the options checked, :func:`polyjax.internal.prepare_inputs`, the compiled kernel (dense, streamed or sharded:
    :func:`_run_kernel`), the result; the building block of every polynomial fit (the log-space fit's solves too)."""
    if isinstance(u, Measurements) and isinstance(v, str):
        u, v, variables = u, None, v
    vs = get_variables(variables)
    degrees = check_fit_options(basis, method, rank_deficient, degree, lane_block)
    sharded = _input_sharding(u, v, values, weights, mask)
    inp, cutoff = prepare_inputs("fit_polynomial", u, v, values, weights, mask, cutoff_deg=cutoff_deg,
                                 nonfinite=nonfinite, lane_directions=True)
    max_degree = int(degrees.max())
    m = n_terms(vs.k, max_degree, bool(interactions))
    check_parameter_count(f"degree={max_degree}, interactions={bool(interactions)}, variables={vs.name!r}", m, inp.n,
                          inp.values.dtype.itemsize)
    static = dict(variables=vs.name, max_degree=max_degree, basis=basis, interactions=bool(interactions),
                  cutoff_deg=cutoff)
    out = _run_kernel(inp, degrees, sharded, m, scalar=np.ndim(degree) == 0, method=method, rcond=rcond,
                      lane_block=int(lane_block), static=static)
    model = PolynomialBRDF(**out, variables=vs.name, basis=basis, interactions=bool(interactions),
                           max_degree=max_degree)
    return _raise_on_status(model) if throw or rank_deficient == "error" else model


def _run_kernel(inp: PreparedInputs, degrees, sharded, m: int, *, scalar, method, rcond, lane_block, static) -> dict:
    """:func:`_fit_kernel` on prepared inputs: on the devices the inputs are sharded over (each its own lanes,
    dense; the result stays sharded, ``polyjax/_fit/sharding.py``), or in one program, streamed when the shared design
    is tall (``polyjax/_fit/stream.py``); the fields of the result, shaped ``(D?, *batch, ...)``."""
    if sharded is None:
        # streamed only on the shared design (one set of samples for every lane, never per-lane directions)
        stream = use_stream(inp.n, m, int(np.prod(inp.batch, dtype=int)), method, inp.shared,
                            is_concrete(inp.u, inp.v, inp.values, inp.weights, inp.mask))
        if stream:
            return _streamed_fit(inp, degrees, static=static, method=method, rcond=rcond, scalar=scalar,
                                 lane_block=lane_block)
        return _fit_kernel(inp, np.asarray(degrees, np.int32), method=method, rcond=rcond, batch=inp.batch,
                           scalar=scalar, stream=False, lane_block=lane_block, **static)
    kernel = functools.partial(_fit_kernel, method=method, rcond=rcond, batch=None, scalar=False, stream=False,
                               lane_block=lane_block, **static)
    out = shard_lanes(kernel, *sharded, inp, jnp.asarray(degrees, jnp.int32))
    lead = () if scalar else (degrees.size,)
    return {key: (a[0] if scalar else a).reshape(lead + inp.batch + a.shape[2:]) for key, a in out.items()}


def _raise_on_status(model: PolynomialBRDF) -> PolynomialBRDF:
    """``throw=True``: :func:`polyjax.raise_on_status` naming the first lane that is not ``OK`` with its rank and
    samples used."""
    def describe(i):
        at = lambda a: int(np.asarray(a)[i] if np.ndim(a) else a)  # noqa: E731
        return (f"rank {at(model.rank)} of {at(model.n_params)} parameters, {at(model.n_used)} samples used after "
                "the cutoff and mask")

    return raise_on_status("fit_polynomial", model.status, model, describe)


def _input_sharding(u, v, values, weights, mask):
    """The mesh and lane axes of inputs sharded over their leading batch axis (``polyjax/_fit/sharding.py``)."""
    if isinstance(u, Measurements):
        u, v, values = u.u, u.v, u.values
    if values is None or not hasattr(values, "shape"):
        return None
    nb = np.ndim(values) - 1
    return lane_sharding(nb, {"values": (values, 1), "u": (u, 2), "v": (v, 2), "weights": (weights, 1),
                              "mask": (mask, 1)})
