"""One way in: the input preparation every fitter uses (polynomial, Zernike, nonlinear baselines).

Rules, the same for every fitter and with the same messages:

* ``u``, ``v``: ``(n, 3)`` directions, renormalised; a zero (or non-finite) vector has no direction and its sample
  is dropped. ``values``: ``(*batch, n)``, samples last, ``n >= 1``.
* Per-lane directions (only for fitters that ask for them, ``lane_directions=True``): ``u``, ``v`` of shape
  ``(*dbatch, n, 3)`` with ``dbatch`` a leading part of ``batch`` (``values (H, W, 3, n)`` with ``u (H, W, n, 3)``:
  each texel its own directions, shared by its colour channels). The lanes then form ``G = prod(dbatch)`` groups
  of ``r = prod(batch[len(dbatch):])`` right-hand sides; ``weights`` and ``mask`` are ``(n,)``, ``(*dbatch, n)``
  or, when ``dbatch == batch``, ``(*batch, n)``.
* dtype: the fit runs in the dtype of ``values``; integers and booleans become the default float, float16 and
  bfloat16 float32 (LAPACK has no half precision); complex values are rejected.
* ``weights``: ``(n,)`` (shared by every lane) or ``(*batch, n)``; finite and non-negative. ``mask``: ``(n,)``
  (shared) or ``(*batch, n)``.
* ``cutoff_deg`` in ``(0, 90]`` or None.
* non-finite values where the mask is True: ``nonfinite="error"`` raises on concrete input (an eager
  ``jax.grad`` too: the check needs no host copy of the values) and, where nothing can be raised (under ``jit``),
  flags the lane (:attr:`PreparedInputs.lane_bad`, reported as ``NONFINITE``); ``nonfinite="mask"`` drops those
  samples.
* negative or non-finite weights: the same rule, eager and traced: an :class:`InputError` wherever the weights are
  concrete, else (under ``jit``) every lane using them flagged ``NONFINITE`` with L2 ``inf``, never clipped.
* One set of samples for every lane (the shared-design path, one factorisation for all lanes) is chosen from the
  shapes alone: ``weights`` and ``mask`` absent or ``(n,)``, and ``nonfinite="error"``. The loaders return
  ``(n,)`` masks whenever every lane has the same valid samples, so their data take that path without any
  inspection of the mask.

Decisions use shapes and dtypes only; value checks (NaN, negative weights) run only on concrete arrays, so traced
inputs (``jit``, ``grad``, ``vmap``) pass through and are never copied to the host.
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from ._arrays import is_concrete
from ._cache import memo
from ._directions import safe_normalize
from ._errors import InputError
from ._measurements import Measurements
from ._metrics import fit_weights

NONFINITE = ("error", "mask")


class PreparedInputs(eqx.Module):
    """Validated, flattened inputs of a fit.

    Attributes:
        u, v: ``(n, 3)`` unit directions, or ``(G, n, 3)`` per group of lanes (``lane_directions``).
        values: ``(B, n)`` values, ``B = prod(batch)``; non-finite entries replaced by 0 (they are masked or
            their lane is flagged).
        weights: ``(L, n)`` solid-angle weights, ``L = 1`` when shared by every lane, else ``G``: the number of
            groups of lanes with their own samples (``G = B`` without per-lane directions; lanes ``g r .. g r + r``
            form group ``g``, ``r = B / G``). With per-lane directions ``weights`` and ``mask`` may be ``(1, n)``
            or ``(G, n)`` independently (nothing is broadcast to every lane).
        mask: ``(L, n)`` samples to fit (directions valid, mask, finite values with ``nonfinite="mask"``).
        lane_bad: ``(B,)`` lanes with NaN/inf values where the mask is True (only traced input gets here).
        batch: the batch shape ``values.shape[:-1]``.
        shared: True when every lane has the same samples (one design, ``L = 1``, directions ``(n, 3)``).
        lane_directions: True when ``u``, ``v`` are ``(G, n, 3)``.
    """

    u: Float[Array, "*G n 3"]
    v: Float[Array, "*G n 3"]
    values: Float[Array, "B n"]
    weights: Float[Array, "L n"]
    mask: Bool[Array, "L n"]
    lane_bad: Bool[Array, " B"]
    batch: tuple[int, ...] = eqx.field(static=True)
    shared: bool = eqx.field(static=True)
    lane_directions: bool = eqx.field(static=True, default=False)

    @property
    def n(self) -> int:
        return self.values.shape[-1]

    @property
    def groups(self) -> int:
        """``G``, the number of groups of lanes with their own samples (1 when shared)."""
        if self.lane_directions:
            return self.u.shape[0]
        return 1 if self.shared else self.values.shape[0]

    def per_lane(self) -> tuple[Float[Array, "B n"], Bool[Array, "B n"]]:
        """``weights`` and ``mask`` broadcast to one row per lane."""
        shape = self.values.shape
        r = shape[0] // max(self.weights.shape[0], 1)
        w, m = (jnp.repeat(a, r, axis=0) if a.shape[0] > 1 else a for a in (self.weights, self.mask))
        return jnp.broadcast_to(w, shape), jnp.broadcast_to(m, shape)

    def objective_weights(self, cutoff_deg) -> tuple[Float[Array, "B n"], Float[Array, "B n"]]:
        """Per lane ``(w, w cos^2 theta_u)`` of equation (11) (:func:`polyjax.fit_weights`), 0 where not fitted."""
        w, m = self.per_lane()
        u, v = self.u, self.v
        if self.lane_directions:
            r = self.values.shape[0] // self.groups
            u, v = jnp.repeat(u, r, axis=0), jnp.repeat(v, r, axis=0)
        return fit_weights(u, v, w, m, cutoff_deg)


def unpack(caller: str, u, v, values, weights, mask):
    """``(u, v, values, weights, mask)`` from arrays or a :class:`polyjax.Measurements` in ``u``."""
    if isinstance(u, Measurements):
        data = u
        if v is not None or values is not None:
            raise InputError(f"{caller}(measurements, ...): pass the other arguments by keyword")
        u, v, values = data.u, data.v, data.values
        weights = data.weights if weights is None else weights
        mask = data.mask if mask is None else mask
    if v is None or values is None:
        raise InputError(f"{caller}: expected u, v and values (or a polyjax.Measurements)")
    return tuple(_as_array(name, a) for name, a in
                 (("u", u), ("v", v), ("values", values), ("weights", weights), ("mask", mask)))


def _as_array(name: str, a):
    """Python lists and tuples (of numbers, nested) as numpy arrays; arrays and scalars unchanged."""
    if not isinstance(a, (list, tuple)):
        return a
    try:
        return np.asarray(a)
    except ValueError as e:  # ragged nesting
        raise InputError(f"{name}: expected an array or a nested list of numbers of one shape, found a ragged "
                         f"list ({e})") from None


def fit_dtype(values) -> jnp.dtype:
    """The dtype a fit of ``values`` runs in (see the module's rules)."""
    dt = jnp.result_type(values)
    if jnp.issubdtype(dt, jnp.complexfloating):
        raise InputError(f"values: expected real BRDF values, found dtype {dt}")
    if not jnp.issubdtype(dt, jnp.floating):
        return jnp.result_type(float)
    if jnp.finfo(dt).bits < 32:
        return jnp.dtype(jnp.float32)
    return dt


def check_cutoff(cutoff_deg) -> float | None:
    if cutoff_deg is not None and not (0.0 < float(cutoff_deg) <= 90.0):
        raise InputError(f"cutoff_deg: expected an angle in (0, 90] degrees or None, found {cutoff_deg}")
    return None if cutoff_deg is None else float(cutoff_deg)


def _lane_shape_error(name: str, found, n: int, batch) -> InputError:
    want = f"({n},)" if not batch else f"({n},) or {tuple(batch) + (n,)}"
    return InputError(f"{name}: expected shape {want} (samples last, n = len(u) = {n}), found {tuple(found)}")


def _holds(flag, default: bool = False) -> bool:
    """``bool(flag)`` when it is concrete, else ``default``: concrete arrays closed over inside a trace (``jit``)
    give traced results, on which nothing can be decided."""
    return bool(flag) if is_concrete(flag) else default


def _check_directions(u, v, concrete: bool, lane_directions: bool = False) -> int:
    for name, w in (("u", u), ("v", v)):
        if (w.ndim != 2 and not (lane_directions and w.ndim > 2)) or w.shape[-1] != 3:
            want = "(n, 3) or (*batch, n, 3)" if lane_directions else "(n, 3)"
            raise InputError(f"{name}: expected directions of shape {want}, found {w.shape}")
        # a reduction on the device(s): a sharded input is never gathered to the host
        # (inside a trace, where the reduction of a closed-over concrete array is traced: on the host)
        if concrete:
            finite = _all_finite(w)
            finite = bool(finite) if is_concrete(finite) else bool(np.all(np.isfinite(np.asarray(w))))
        if concrete and not finite:
            raise InputError(f"{name}: expected finite direction vectors, found NaN or inf")
    if u.shape != v.shape:
        raise InputError(f"u and v: expected the same shape, found {u.shape} and {v.shape}")
    return u.shape[-2]


@jax.jit
def _all_finite(w):
    return jnp.all(jnp.isfinite(w))


def _lane_array(name, a, n, batch, dtype, dbatch=None):
    """``weights``/``mask`` as ``(1, n)`` (shared) or ``(G, n)``; the shape rule of the module."""
    a = jnp.asarray(a, dtype)
    if dbatch is None:  # one set of directions: flattened to (1, n) / (B, n) inside the compiled _prepare_core
        if a.shape == (n,) or tuple(a.shape) == tuple(batch) + (n,):
            return a
        raise _lane_shape_error(name, a.shape, n, batch)
    if a.shape == (n,):
        return a[None]
    group = tuple(dbatch)
    if tuple(a.shape) == group + (n,):
        return a.reshape(-1, n)
    if group != tuple(batch):
        raise InputError(f"{name}: expected shape ({n},) or {group + (n,)} (one row per set of directions; samples "
                         f"last, n = {n}), found {tuple(a.shape)}")
    raise _lane_shape_error(name, a.shape, n, batch)


@jax.jit
def _normalize_pair(u, v):
    u, ok_u = safe_normalize(u)
    v, ok_v = safe_normalize(v)
    return u, v, ok_u & ok_v


def _unit_directions(u, v):
    """Unit ``u``, ``v`` and where both have a direction. The last concrete pair is remembered by identity
    (:mod:`polyjax._cache.memo`): the loaders hand out the same device arrays for a shared grid (every MERL
    ``.binary`` file), whose million directions are then normalised once, not once per fit."""
    if not is_concrete(u, v):
        return _normalize_pair(u, v)
    known = memo.known_unit_directions(u, v)
    if known is not None:
        return known
    out = _normalize_pair(u, v)
    if not is_concrete(out):  # concrete arrays closed over inside a trace give traced results: never kept
        return out
    memo.remember_unit_directions(u, v, out)
    return out


def _known_pair(u, v) -> bool:
    """Whether ``u``, ``v`` are the pair :func:`_unit_directions` remembers (already checked and normalised)."""
    return memo.known_unit_directions(u, v) is not None


@functools.partial(jax.jit, static_argnames=("nonfinite", "shared"))
def _prepare_core(ok, values, w, m, *, nonfinite, shared):
    """The array work of :func:`prepare_inputs`: masks and flags for the concrete checks (the directions are not
    passed through: the same arrays go on, so work kept for them, e.g. a streamed fit's geometry, is found again)."""
    n = values.shape[-1]
    y = values.reshape(-1, n)
    nb = y.shape[0]
    w = jnp.ones((1, n), y.dtype) if w is None else w.reshape(-1, n)
    m = jnp.ones((1, n), bool) if m is None else m.reshape(-1, n)
    lane_w_bad = jnp.broadcast_to(jnp.any(~jnp.isfinite(w) | (w < 0), axis=-1), (nb,))
    w_bad = jnp.any(lane_w_bad)
    m = m & ok[None]
    finite = jnp.isfinite(y)
    bad = m & ~finite  # (B, n)
    any_bad = jnp.any(bad)
    if nonfinite == "mask":
        m = m & finite
        lane_bad = lane_w_bad
    else:
        lane_bad = jnp.any(bad, axis=-1) | lane_w_bad
    # first bad sample (flat index into (B, n)) for the eager message: computed here, so that a caller holding
    # tracers (an eager jax.grad) needs no host copy of the values
    first_bad = jnp.argmax(bad.reshape(-1))
    n_bad = jnp.sum(bad)
    if not shared:
        w = jnp.broadcast_to(w, (nb, n))
        m = jnp.broadcast_to(m, (nb, n))
    return w, m, lane_bad, w_bad, any_bad, jnp.all(finite), (first_bad, n_bad)


@jax.jit
def _finite_values(values):
    y = values.reshape(-1, values.shape[-1])
    return jnp.where(jnp.isfinite(y), y, 0.0)


def prepare_inputs(
    caller: str, u, v, values, weights=None, mask=None, *, cutoff_deg=80.0, nonfinite: str = "error",
    lane_directions: bool = False,
) -> tuple[PreparedInputs, float | None]:
    """Check and flatten a fit's inputs (see the module's rules); returns ``(PreparedInputs, cutoff_deg)``.

    ``lane_directions=True`` (for fitters that handle it) also accepts directions ``(*dbatch, n, 3)``, one set per
    group of lanes (see the module's rules).

    Raises :class:`polyjax.InputError` naming the argument, what was expected and what was found, before any
    work is done.
    """
    u, v, values, weights, mask = unpack(caller, u, v, values, weights, mask)
    if nonfinite not in NONFINITE:
        raise InputError(f"nonfinite: expected one of {NONFINITE}, found {nonfinite!r}")
    cutoff = check_cutoff(cutoff_deg)
    dtype = fit_dtype(values)
    values = jnp.asarray(values, dtype)
    u = jnp.asarray(u, dtype)
    v = jnp.asarray(v, dtype)
    n = _check_directions(u, v, is_concrete(u, v) and not _known_pair(u, v), lane_directions)
    if values.ndim < 1 or values.shape[-1] != n:
        raise InputError(f"values: expected shape (..., {n}) with samples last (n = len(u)), found {values.shape}")
    if n == 0 or values.size == 0:
        raise InputError(f"{caller}: empty input: expected at least one sample and one lane, found values of shape "
                         f"{values.shape}")
    batch = tuple(values.shape[:-1])
    nb = int(np.prod(batch)) if batch else 1
    if u.ndim > 2:  # per-lane directions: groups of lanes, each with its own samples (never the shared design)
        return _prepare_lane_directions(u, v, values, weights, mask, batch, n, dtype, nonfinite), cutoff
    w = None if weights is None else _lane_array("weights", weights, n, batch, dtype)
    m = None if mask is None else _lane_array("mask", mask, n, batch, bool)
    shared = (w is None or w.ndim == 1) and (m is None or m.ndim == 1) and (nonfinite == "error" or nb == 1)
    # one compiled program for the array work (op by op it was a dozen programs, each traced and lowered anew
    # in every process: most of a warm `polyjax fit`)
    u, v, ok = _unit_directions(u, v)
    w, m, lane_bad, w_bad, any_bad, all_finite, first = _prepare_core(ok, values, w, m, nonfinite=nonfinite,
                                                                      shared=shared)
    # the values go on as they are when they are all finite (no copy of a million-sample table), else with 0 for
    # NaN/inf (masked or flagged)
    y = values.reshape(nb, n) if _holds(all_finite) else _finite_values(values)
    if is_concrete(w_bad) and bool(w_bad):
        raise InputError("weights: expected finite, non-negative solid-angle weights")
    if nonfinite == "error" and is_concrete(any_bad, *first) and bool(any_bad):
        _raise_nonfinite_at(int(first[0]), int(first[1]), values.shape)
    return PreparedInputs(u, v, y, w, m, lane_bad, batch, shared), cutoff


def _raise_nonfinite(bad, values):
    where = np.argwhere(np.asarray(bad).reshape(values.shape))
    _raise_nonfinite_at(int(np.ravel_multi_index(where[0], values.shape)), len(where), values.shape)


def _raise_nonfinite_at(flat: int, count: int, shape):
    """The eager error for NaN/inf values: ``count`` of them, the first at C-order index ``flat`` of ``shape``."""
    index = tuple(int(i) for i in np.unravel_index(flat, shape))
    raise InputError(
        f"values: expected finite numbers, found {count} NaN/inf (first at index {index}) where mask is True; pass "
        "nonfinite='mask' to drop them"
    )


@jax.jit
def _bad_weights(w):
    return ~jnp.all(jnp.isfinite(w)) | jnp.any(w < 0)


@functools.partial(jax.jit, static_argnames=("n_groups", "nonfinite"))
def _lane_core(u, v, y, m, w, *, n_groups, nonfinite):
    """The array work of :func:`_prepare_lane_directions` in one compiled program: unit directions per group, the
    mask, the per-lane flags and the values with 0 for NaN/inf (plus what its check needs: the bad samples and
    whether there is any)."""
    nb, n = y.shape
    u, ok_u = safe_normalize(u.reshape(n_groups, n, 3))
    v, ok_v = safe_normalize(v.reshape(n_groups, n, 3))
    m = m & (ok_u & ok_v)
    finite = jnp.isfinite(y)
    r = nb // n_groups
    m_lanes = jnp.repeat(m, r, axis=0) if m.shape[0] > 1 and r > 1 else m
    bad = m_lanes & ~finite  # (B, n)
    if nonfinite == "mask":
        finite_group = jnp.all(finite.reshape(n_groups, -1, n), axis=1)
        m = m & (finite if n_groups == nb else finite_group)
        lane_bad = jnp.zeros((nb,), bool)
    else:
        lane_bad = jnp.any(bad, axis=-1)
    w_bad = jnp.any(~jnp.isfinite(w) | (w < 0), axis=-1)  # (1,) or (G,): flags the lanes where nothing is raised
    lane_bad = lane_bad | (jnp.repeat(w_bad, r) if w_bad.shape[0] > 1 and r > 1 else jnp.broadcast_to(w_bad, (nb,)))
    return u, v, jnp.where(finite, y, 0.0), m, lane_bad, bad, jnp.any(bad)


@functools.partial(jax.jit, static_argnames=("n_groups",))
def _same_nonfinite(y, n_groups):
    """Whether every lane of each of ``n_groups`` groups of rows of ``y`` has NaN/inf at the same samples."""
    finite = jnp.isfinite(y).reshape(n_groups, -1, y.shape[-1])
    return jnp.all(jnp.all(finite, axis=1) == jnp.any(finite, axis=1))


def _prepare_lane_directions(u, v, values, weights, mask, batch, n, dtype, nonfinite) -> PreparedInputs:
    """:func:`prepare_inputs` for directions ``(*dbatch, n, 3)``: ``G = prod(dbatch)`` groups of lanes."""
    nb = int(np.prod(batch)) if batch else 1
    dbatch = tuple(u.shape[:-2])
    if batch[: len(dbatch)] != dbatch:
        raise InputError(f"u, v: expected per-lane directions of shape (*batch, n, 3) with batch a leading part of "
                         f"values' batch shape {batch} (values {values.shape}), found {u.shape}")
    n_groups = int(np.prod(dbatch))
    y = values.reshape(nb, n)
    w = jnp.ones((1, n), dtype) if weights is None else _lane_array("weights", weights, n, batch, dtype, dbatch)
    m = jnp.ones((1, n), bool) if mask is None else _lane_array("mask", mask, n, batch, bool, dbatch)
    if is_concrete(w) and _holds(_bad_weights(w)):
        raise InputError("weights: expected finite, non-negative solid-angle weights")
    u, v, y_zeroed, m, lane_bad, bad, any_bad = _lane_core(u, v, y, m, w, n_groups=n_groups, nonfinite=nonfinite)
    if nonfinite == "error" and is_concrete(any_bad, bad) and _holds(any_bad):
        _raise_nonfinite(bad, values)
    if nonfinite == "mask" and n_groups != nb and is_concrete(y) and not _holds(_same_nonfinite(y, n_groups)):
        raise InputError("values: nonfinite='mask' with directions shared by several lanes (u of shape "
                         f"{tuple(dbatch) + (n, 3)}) needs NaN/inf at the same samples in every lane of a group")
    return PreparedInputs(u, v, y_zeroed, w, m, lane_bad, batch, False, True)


#: a design of more than this many bytes is refused up front (it would not fit in memory on common machines)
MAX_DESIGN_BYTES = 4 * 2**30


#: parameters per sample above which a model is refused up front (below it, more parameters than samples is a
#: minimum-norm interpolation flagged ``RANK_DEFICIENT``; the command line refuses any more than the samples used)
MAX_PARAMS_PER_SAMPLE = 4


def check_parameter_count(what: str, n_params: int, n: int, itemsize: int = 8) -> None:
    """Refuse absurd models before any work: more than ``max(4 n, 64)`` parameters for ``n`` samples, or a
    design (``n x n_params``) over :data:`MAX_DESIGN_BYTES`. ``what`` names the arguments that set the count."""
    limit = max(MAX_PARAMS_PER_SAMPLE * n, 64)
    size = n * n_params * itemsize
    if n_params > limit or size > MAX_DESIGN_BYTES:
        raise InputError(
            f"{what}: expected at most {limit} parameters for {n} samples ({MAX_PARAMS_PER_SAMPLE} per sample, at "
            f"least 64) and a "
            f"design under {MAX_DESIGN_BYTES / 2**30:.0f} GiB, found {n_params} parameters ({size / 2**30:.3g} GiB)"
        )
