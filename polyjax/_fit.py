"""Fitting the polynomial model (paper, section 4): one jitted, batched weighted least-squares solve."""

from __future__ import annotations

import functools
from typing import Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike

from ._basis import BASES, design_matrix, n_terms, term_degrees
from ._errors import FitError, InputError
from ._geometry import safe_normalize
from ._lstsq import METHODS, weighted_lstsq
from ._measurements import Measurements, check_samples
from ._metrics import fit_weights
from ._model import FitStatus, PolynomialBRDF
from ._pca import fit_pca
from ._variables import get_variables


def _is_tracer(x) -> bool:
    return isinstance(x, jax.core.Tracer)


def _design_for(x, keep, max_degree, basis, interactions):
    """PCA of the kept samples, affine scaling, and the design matrix (equation (13)).

    A component whose range over the kept samples is within rounding of ``x`` (``1e3 eps max|x|``;
    e.g. Lafortune's ``X_1 + X_2 = 1`` when every sample has ``u = v``) carries no information,
    only rounding noise that column equilibration would blow up into huge coefficients. Its
    half-width is set to ``inf``: ``t = 0`` here and wherever the model is evaluated, so its
    columns are constants and the fit is flagged rank-deficient (minimum-norm solution).
    """
    pca = fit_pca(x, keep)
    z = pca(x)
    k = x.shape[-1]
    big = jnp.finfo(x.dtype).max
    lo = jnp.min(jnp.where(keep[:, None], z, big), axis=0)
    hi = jnp.max(jnp.where(keep[:, None], z, -big), axis=0)
    any_kept = jnp.any(keep)
    lo = jnp.where(any_kept, lo, -1.0)
    hi = jnp.where(any_kept, hi, 1.0)
    hw = 0.5 * (hi - lo)
    x_mag = jnp.max(jnp.where(keep[:, None], jnp.abs(x), 0.0))
    flat = ~(hw > 1e3 * jnp.finfo(x.dtype).eps * x_mag)
    if basis == "legendre":
        centre = 0.5 * (lo + hi)
    else:
        centre = jnp.zeros((k,), x.dtype)
        hw = jnp.ones((k,), x.dtype)
    hw = jnp.where(flat, jnp.inf, hw)
    d = design_matrix((z - centre) / hw, max_degree, basis, interactions)
    return pca, centre, hw, d


@functools.partial(
    jax.jit,
    static_argnames=(
        "variables", "max_degree", "basis", "interactions", "method", "rcond", "cutoff_deg", "shared", "flag_nonfinite",
    ),
)
def _fit_kernel(u, v, values, weights, mask, degrees, *, variables, max_degree, basis, interactions, method, rcond,
                cutoff_deg, shared, flag_nonfinite=True):
    """values (B, n); weights, mask (B or 1, n); degrees (D,) -> dict of (D, B, ...) arrays."""
    x = get_variables(variables).fn(u, v)
    k = x.shape[-1]
    dtype = values.dtype
    finite = jnp.isfinite(values)
    if shared:  # one mask for every lane: a lane with NaN/inf cannot be masked alone, it is flagged
        lane_bad = ~jnp.all(finite, axis=-1)
    else:  # nonfinite="error" under an outer jit flags the lane whatever the mask; "mask" drops the samples
        lane_bad = ~jnp.all(finite, axis=-1) & flag_nonfinite
        mask = mask & finite
    values = jnp.where(finite, values, 0.0)
    w, wc2 = fit_weights(u, v, weights, mask, cutoff_deg)  # (B or 1, n)
    tdeg = jnp.asarray(term_degrees(k, max_degree, interactions))
    active = tdeg[None, :] <= degrees[:, None]  # (D, m)
    n_deg = degrees.shape[0]

    def residual_l2(d, coef, y, wl, wc2l):  # coef (m,) ; y (n,)
        r = y - d @ coef
        den = jnp.sum(wl)
        return jnp.where(den > 0, jnp.sqrt(jnp.sum(wc2l * r * r) / jnp.where(den > 0, den, 1.0)), jnp.inf)

    def lane(y, wl, wc2l):
        """One set of samples (B_l right-hand sides sharing it) fitted for all degrees."""
        keep = wl > 0
        pca, centre, hw, d = _design_for(x, keep, max_degree, basis, interactions)
        sol = jax.vmap(lambda a: weighted_lstsq(d, y.T, wc2l, a, method=method, rcond=rcond))(active)
        coef = jnp.swapaxes(sol.coefficients, 1, 2)  # (D, r, m)
        l2 = jax.vmap(jax.vmap(lambda c, yy: residual_l2(d, c, yy, wl, wc2l), in_axes=(0, 0)), in_axes=(0, None))(coef, y)
        return pca, centre, hw, coef, l2, sol.rank, sol.condition, sol.n_active, jnp.sum(keep)

    if shared:
        pca, centre, hw, coef, l2, rank, cond, n_act, n_used = lane(values, w[0], wc2[0])
        nb = values.shape[0]
        bc = lambda a: jnp.broadcast_to(a, (n_deg, nb) + a.shape)  # noqa: E731
        out_pca = (bc(pca.mean), bc(pca.rotation), bc(centre), bc(hw))
        rank = jnp.broadcast_to(rank[:, None], (n_deg, nb))
        cond = jnp.broadcast_to(cond[:, None], (n_deg, nb))
        n_act = jnp.broadcast_to(n_act[:, None], (n_deg, nb))
        n_used = jnp.broadcast_to(n_used, (n_deg, nb))
    else:
        res = jax.vmap(lambda y, wl, wc2l: lane(y[None], wl, wc2l))(values, w, wc2)
        pca, centre, hw, coef, l2, rank, cond, n_act, n_used = res
        # lane returns (D, 1, ...) for coefficients / l2; move D first
        coef = jnp.swapaxes(coef[:, :, 0], 0, 1)
        l2 = jnp.swapaxes(l2[:, :, 0], 0, 1)
        rank, cond, n_act = (jnp.swapaxes(a, 0, 1) for a in (rank, cond, n_act))
        bc = lambda a: jnp.broadcast_to(a[None], (n_deg,) + a.shape)  # noqa: E731
        out_pca = (bc(pca.mean), bc(pca.rotation), bc(centre), bc(hw))
        n_used = jnp.broadcast_to(n_used[None], (n_deg,) + n_used.shape)
    bad = jnp.broadcast_to(lane_bad[None, :], (n_deg, values.shape[0]))
    status = jnp.where(
        bad, FitStatus.NONFINITE_VALUES,
        jnp.where(n_used == 0, FitStatus.NO_SAMPLES, jnp.where(rank < n_act, FitStatus.RANK_DEFICIENT, FitStatus.OK)),
    ).astype(jnp.int32)
    failed = bad | (n_used == 0)
    coef = jnp.where(failed[..., None], 0.0, coef)
    l2 = jnp.where(failed, jnp.inf, l2)
    degs = jnp.broadcast_to(degrees[:, None], status.shape)
    return dict(
        coefficients=coef.astype(dtype), degree=degs.astype(jnp.int32), mean=out_pca[0], rotation=out_pca[1],
        centre=out_pca[2], halfwidth=out_pca[3], l2=l2, rank=rank, condition=cond, n_used=n_used.astype(jnp.int32),
        status=status,
    )


def _rows_equal(a: np.ndarray) -> bool:
    flat = a.reshape(-1, a.shape[-1])
    return bool(np.all(flat == flat[:1]))


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
        mask: ``(*batch, n)`` validity mask; False samples are not fitted.
        cutoff_deg: grazing cutoff in degrees (80 in the paper); None keeps all samples above the horizon.
        basis: ``"legendre"`` (default, well conditioned) or ``"monomial"`` (the paper's literal powers);
           both span the same space and give the same fit.
        interactions: fit the full response surface of equation (2) instead of equation (3).
        method: ``"qr"`` (default) or ``"svd"``.
        rcond: relative singular-value cutoff for the rank; default ``eps * max(m, sqrt(n))``.
        rank_deficient: ``"flag"`` (minimum-norm solution, ``status = RANK_DEFICIENT``) or ``"error"``
           (raise :class:`polyjax.FitError`). Lanes with no samples are always flagged ``NO_SAMPLES``
           (L2 = inf) and raise under ``"error"``. Under an outer ``jit`` nothing can be raised: read ``status``.
        nonfinite: ``"error"`` (raise on NaN/inf in ``values``; under an outer ``jit``, where nothing can be
           raised, such a lane is flagged ``NONFINITE_VALUES`` with or without ``mask``) or ``"mask"``
           (drop those samples).
        link, eps, steps: ``link="log"`` fits ``f = exp(poly) - eps`` to equation (11) by ``1 + steps``
           weighted solves (:func:`polyjax.fit_log_polynomial`, one integer ``degree``); ``"identity"`` (default)
           is equation (3) itself.

    Returns:
        :class:`polyjax.PolynomialBRDF` with batch shape ``values.shape[:-1]`` (preceded by the
        degree axis when ``degree`` is a sequence).
    """
    if link != "identity":  # log-space model f = exp(poly) - eps: polyjax/_logfit.py
        if link != "log" or nonfinite != "error":
            raise InputError(f"link: expected 'identity' or 'log' (with nonfinite='error'), found {link!r}")
        from ._logfit import fit_log_polynomial

        return fit_log_polynomial(u, v, values, variables, degree, eps=eps, steps=steps, weights=weights, mask=mask,
                                  cutoff_deg=cutoff_deg, basis=basis, interactions=interactions, method=method,
                                  rcond=rcond, rank_deficient=rank_deficient)
    if isinstance(u, Measurements):
        data = u
        if values is not None or (v is not None and not isinstance(v, str)):
            raise InputError("fit_polynomial(measurements, ...): pass the other arguments by keyword")
        if isinstance(v, str):
            variables = v
        u, v, values = data.u, data.v, data.values
        weights = data.weights if weights is None else weights
        mask = data.mask if mask is None else mask
    if v is None or values is None:
        raise InputError("fit_polynomial: expected u, v and values (or a Measurements)")
    vs = get_variables(variables)
    if basis not in BASES:
        raise InputError(f"basis: expected one of {BASES}, found {basis!r}")
    if method not in METHODS:
        raise InputError(f"method: expected one of {METHODS}, found {method!r}")
    if rank_deficient not in ("flag", "error"):
        raise InputError(f"rank_deficient: expected 'flag' or 'error', found {rank_deficient!r}")
    if nonfinite not in ("error", "mask"):
        raise InputError(f"nonfinite: expected 'error' or 'mask', found {nonfinite!r}")
    if cutoff_deg is not None and not (0.0 < float(cutoff_deg) <= 90.0):
        raise InputError(f"cutoff_deg: expected an angle in (0, 90] degrees or None, found {cutoff_deg}")
    scalar_degree = np.ndim(degree) == 0
    degrees = np.atleast_1d(np.asarray(degree))
    if degrees.ndim != 1 or degrees.size == 0 or not np.issubdtype(degrees.dtype, np.integer) or np.any(degrees < 0):
        raise InputError(f"degree: expected a non-negative integer or a sequence of them, found {degree!r}")
    max_degree = int(degrees.max())

    values = jnp.asarray(values)
    if jnp.issubdtype(values.dtype, jnp.complexfloating):
        raise InputError(f"values: expected real BRDF values, found dtype {values.dtype}")
    if not jnp.issubdtype(values.dtype, jnp.floating):
        values = values.astype(jnp.result_type(float))
    elif jnp.finfo(values.dtype).bits < 32:  # LAPACK has no half precision: float16/bfloat16 are fitted in float32
        values = values.astype(jnp.float32)
    dtype = values.dtype
    u = jnp.asarray(u, dtype)
    v = jnp.asarray(v, dtype)
    batch = values.shape[:-1]
    concrete = not any(_is_tracer(a) for a in (u, v, values, weights, mask))
    n = check_samples(u, v, values, concrete=not (_is_tracer(u) or _is_tracer(v)))
    u, ok_u = safe_normalize(u)
    v, ok_v = safe_normalize(v)
    dir_ok = ok_u & ok_v
    m = jnp.broadcast_to(dir_ok, values.shape) if mask is None else jnp.broadcast_to(jnp.asarray(mask, bool) & dir_ok, values.shape)
    if concrete:
        finite = np.isfinite(np.asarray(values))
        if not finite.all():
            if nonfinite == "error":
                bad = np.argwhere(~finite)[0]
                raise InputError(
                    f"values: expected finite numbers, found {int((~finite).sum())} NaN/inf "
                    f"(first at index {tuple(int(i) for i in bad)}); pass nonfinite='mask' to drop them"
                )
    w = jnp.ones((n,), dtype) if weights is None else jnp.asarray(weights, dtype)
    if w.shape[-1] != n or (w.ndim > 1 and w.shape != values.shape):
        raise InputError(f"weights: expected shape ({n},) or {values.shape}, found {w.shape}")
    if concrete and (not bool(jnp.all(jnp.isfinite(w))) or bool(jnp.any(w < 0))):
        raise InputError("weights: expected finite, non-negative solid-angle weights")

    nb = int(np.prod(batch)) if batch else 1
    values2 = values.reshape(nb, n)
    w2 = w.reshape(-1, n)
    if mask is None and w2.shape[0] == 1 and (nonfinite == "error" or concrete):
        # one set of samples for every lane: one design, one factorisation, nb right-hand sides
        shared = True
        m2 = dir_ok[None, :]
    else:
        m2 = m.reshape(nb, n)
        if nonfinite == "mask":
            m2 = m2 & jnp.isfinite(values2)
        shared = False
        if concrete and _rows_equal(np.asarray(m2)) and _rows_equal(np.asarray(w2)):
            shared = True
            m2, w2 = m2[:1], w2[:1]
    if not shared:
        w2 = jnp.broadcast_to(w2, (nb, n))
    if shared and concrete and nonfinite == "mask" and not bool(jnp.all(jnp.isfinite(values2))):
        shared = False
        m2 = jnp.broadcast_to(m2, (nb, n)) & jnp.isfinite(values2)
        w2 = jnp.broadcast_to(w2, (nb, n))

    out = _fit_kernel(
        u, v, values2, w2, m2, jnp.asarray(degrees, jnp.int32), variables=vs.name, max_degree=max_degree, basis=basis,
        interactions=bool(interactions), method=method, rcond=rcond,
        cutoff_deg=None if cutoff_deg is None else float(cutoff_deg), shared=shared, flag_nonfinite=nonfinite == "error",
    )
    lead = (degrees.size,) if not scalar_degree else ()

    def shape(a):
        a = a.reshape((degrees.size,) + batch + a.shape[2:])
        return a[0] if scalar_degree else a.reshape(lead + batch + a.shape[len(batch) + 1 :])

    model = PolynomialBRDF(
        **{key: shape(a) for key, a in out.items()}, variables=vs.name, basis=basis, interactions=bool(interactions),
        max_degree=max_degree,
    )
    if rank_deficient == "error" and concrete:
        status = np.asarray(model.status)
        if np.any(status != FitStatus.OK):
            bad = np.argwhere(status != FitStatus.OK)
            first = tuple(int(i) for i in bad[0])
            code = FitStatus(int(status[first] if status.ndim else status))
            at = lambda a: int(np.asarray(a)[first] if np.ndim(a) else a)  # noqa: E731
            what = {
                FitStatus.NO_SAMPLES: "have no samples left to fit",
                FitStatus.RANK_DEFICIENT: "are rank-deficient",
                FitStatus.NONFINITE_VALUES: "have non-finite values",
            }.get(code, f"ended with status {code.name}")
            where = f"first at batch index {first}" if first else "the fit"
            raise FitError(
                f"fit_polynomial: {len(bad)} of {status.size} fits {what} ({where}: rank {at(model.rank)} of "
                f"{at(model.n_params)} parameters, {at(model.n_used)} samples used after the cutoff and mask); "
                "pass rank_deficient='flag' to get a minimum-norm solution and read model.status instead"
            )
    return model


def n_parameters(variables: str, degree: int, interactions: bool = False) -> int:
    """``k p + 1`` for a variable set (equation (3)); ``C(k + p, p)`` with interactions (equation (2))."""
    return n_terms(get_variables(variables).k, degree, interactions)
