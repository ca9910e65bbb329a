"""Independent reference fits that tests and benchmarks compare polyjax and baselines with (never used by them).

* :func:`numpy_design` / :func:`numpy_lstsq_l2`: the polynomial model of equation (3) built and solved with plain
  numpy (``numpy.linalg.eigh`` PCA, monomials, ``numpy.linalg.lstsq``), one lane at a time.
* :func:`numpy_reference_fit`: the same in one call, returning the L2 and the predictions.
* :func:`scipy_best_l2`: the nonlinear baselines fitted by ``scipy.optimize.least_squares`` (MINPACK
  Levenberg-Marquardt) from given starts on the residuals :func:`baselines.residuals`, one start at a time.

Only public APIs of ``polyjax`` and ``baselines`` are used.
"""

from __future__ import annotations

import time

import jax
import jax.numpy as jnp
import numpy as np

import baselines
import polyjax as pj


def numpy_design(u, v, w, variables: str, p: int, cutoff_deg: float = 80.0):
    """Equation (13) with numpy: PCA of the kept samples, monomials of the scaled components, rows scaled by
    ``sqrt(w_i) cos(theta_u,i)`` (equation (11)).

    Args:
        u, v: ``(n, 3)`` unit light and view directions (numpy).
        w: ``(n,)`` sample weights.
        variables: a registered variable set.
        p: the polynomial degree.
        cutoff_deg: samples with ``theta_u`` or ``theta_v`` above it are dropped (same tolerance as polyjax).

    Returns:
        ``(A, keep, row_scale)``: the row-scaled ``(n_kept, k p + 1)`` design, the ``(n,)`` kept-sample mask and
        the ``(n_kept,)`` row scale ``sqrt(w) cos(theta_u)``.
    """
    c = np.cos(np.deg2rad(cutoff_deg)) - 1e-9
    keep = (u[:, 2] >= c) & (v[:, 2] >= c) & (w > 0)
    x = np.asarray(pj.explanatory_variables(variables, u[keep], v[keep]))
    xm = x.mean(0)
    _, vec = np.linalg.eigh(np.cov((x - xm).T))
    z = (x - xm) @ vec
    z = z / np.maximum(np.abs(z).max(0), 1e-300)
    sw = np.sqrt(w[keep]) * u[keep, 2]
    a = np.concatenate([np.ones((len(z), 1))] + [z**k for k in range(1, p + 1)], axis=1) * sw[:, None]
    return a, keep, sw


def numpy_lstsq_l2(a, keep, sw, y, w) -> float:
    """``numpy.linalg.lstsq`` of one lane ``y (n,)`` on the design of :func:`numpy_design`; the L2 of equation (11)."""
    b = y[keep] * sw
    beta = np.linalg.lstsq(a, b, rcond=None)[0]
    r = b - a @ beta
    return float(np.sqrt(np.sum(r * r) / np.sum(w[keep])))


def numpy_reference_fit(u, v, b, variables: str, degree: int, cutoff_deg: float = 80.0):
    """The paper's fit with numpy (unit weights): PCA, monomial design (equation (13)), ``lstsq``.

    Returns:
        ``(l2, predictions)``: the L2 of equation (11) and the model at all ``n`` samples.
    """
    u, v, b = np.asarray(u), np.asarray(v), np.asarray(b)
    x = np.asarray(pj.explanatory_variables(variables, u, v))
    c = np.cos(np.deg2rad(cutoff_deg))
    keep = (u[:, 2] >= c - 1e-9) & (v[:, 2] >= c - 1e-9)
    xm = x[keep].mean(0)
    _, evecs = np.linalg.eigh(np.cov((x[keep] - xm).T))
    z = (x - xm) @ evecs
    design = np.concatenate([np.ones((len(z), 1))] + [z**d for d in range(1, degree + 1)], axis=1)
    cu = u[:, 2]
    beta = np.linalg.lstsq(design[keep] * cu[keep, None], b[keep] * cu[keep], rcond=None)[0]
    pred = design @ beta
    l2 = np.sqrt(np.mean((cu[keep] * (b[keep] - pred[keep])) ** 2))
    return l2, pred


def scipy_best_l2(name: str, u, v, values, starts, *, weights=None, mask=None, cutoff_deg=80.0, lanes=None):
    """Best-of-starts ``scipy.optimize.least_squares(method='lm')`` fits of a baseline.

    The residuals are :func:`baselines.residuals` (``sqrt(w_i cos^2) (b_i - f_i)`` with the weights normalised
    to sum 1, so the cost's square root is the L2 of equation (11)) with a ``jax.jacfwd`` Jacobian, both jitted
    and compiled before the clock starts: only the solver differs from :func:`baselines.fit`. A start that
    raises or ends non-finite is skipped.

    Args:
        name: a nonlinear baseline name.
        u, v: ``(n, 3)`` unit directions.
        values: ``(B, n)`` BRDF values.
        starts: ``(B, S, P)`` unconstrained starts (:func:`baselines.initial_guesses`).
        weights, mask, cutoff_deg: as for :func:`baselines.fit`.
        lanes: the lane indices to fit (all by default).

    Returns:
        ``(best_l2, seconds_per_lane)``: ``(len(lanes),)`` best L2 per lane (inf if every start failed) and the
        mean wall time per lane over all its starts.
    """
    from scipy.optimize import least_squares

    u, v = jnp.asarray(u), jnp.asarray(v)
    y = jnp.asarray(values)
    w, wc2 = pj.internal.fit_weights(u, v, weights, mask, cutoff_deg)
    w, wc2 = jnp.broadcast_to(w, y.shape), jnp.broadcast_to(wc2, y.shape)
    den = jnp.sum(w, axis=-1, keepdims=True)
    sw2 = wc2 / jnp.where(den > 0, den, 1.0)
    y = jnp.where(wc2 > 0, y, 0.0)
    lanes = np.arange(y.shape[0]) if lanes is None else np.asarray(lanes)

    def fn(r, yb, sb):
        return baselines.residuals(name, r, u, v, yb, sb)

    res, jac = jax.jit(fn), jax.jit(jax.jacfwd(fn))
    s0 = np.asarray(starts)
    jax.block_until_ready((res(s0[0, 0], y[0], sw2[0]), jac(s0[0, 0], y[0], sw2[0])))  # compile untimed
    best = np.full(len(lanes), np.inf)
    t0 = time.perf_counter()
    for k, b in enumerate(lanes):
        yb, sb = y[b], sw2[b]
        for st in s0[b]:
            try:
                sol = least_squares(lambda r, yb=yb, sb=sb: np.asarray(res(r, yb, sb)), st,
                                    jac=lambda r, yb=yb, sb=sb: np.asarray(jac(r, yb, sb)), method="lm")
            except Exception:  # noqa: BLE001 - a failed start is skipped, as in the batched fit
                continue
            cost = float(np.sqrt(np.sum(sol.fun**2)))
            if np.isfinite(cost):
                best[k] = min(best[k], cost)
    return best, (time.perf_counter() - t0) / max(len(lanes), 1)
