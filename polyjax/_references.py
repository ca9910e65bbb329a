"""Independent reference fits the benchmarks and the reproduction compare against (not used by the fitters).

* :func:`numpy_design` / :func:`numpy_lstsq_l2`: the polynomial model of equation (3) built and solved with plain
  numpy (``numpy.linalg.eigh`` PCA, monomials, ``numpy.linalg.lstsq``), one lane at a time.
* :func:`scipy_best_l2`: the nonlinear baselines fitted by ``scipy.optimize.least_squares`` (MINPACK
  Levenberg-Marquardt) from the same starts and residuals as :func:`baselines.fit`, one start at a time.
"""

from __future__ import annotations

import time

import numpy as np


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
    import polyjax as pj

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


def scipy_best_l2(name: str, data, starts, idx):
    """Best-of-starts ``scipy.optimize.least_squares(method='lm')`` fits of a baseline on some materials.

    The residuals are :func:`baselines.residuals` (``sqrt(w_i cos^2) (b_i - f_i)`` with the weights normalised
    to sum 1, so the cost's square root is the L2 of equation (11)) with a ``jax.jacfwd`` Jacobian, both jitted
    and compiled before the clock starts. A start that raises or ends non-finite is skipped.

    Args:
        name: a nonlinear baseline name.
        data: measurements pytree with ``values`` of shape ``(n_materials, n)``.
        starts: ``(n_materials, n_starts, n_params)`` unconstrained starts (:func:`baselines.initial_guesses`).
        idx: the material indices to fit.

    Returns:
        ``(best_l2, seconds_per_material)``: ``(len(idx),)`` best L2 per material (inf if every start failed)
        and the mean wall time per material over all its starts.
    """
    import jax
    import jax.numpy as jnp
    from scipy.optimize import least_squares

    import baselines
    import polyjax as pj

    w, wc2 = pj.fit_weights(data.u, data.v, data.weights, data.mask, 80.0)
    sw2 = wc2 / jnp.sum(w, axis=-1, keepdims=True)
    y = jnp.asarray(data.values)
    res = jax.jit(lambda r, yb, sb: baselines.residuals(name, r, data.u, data.v, yb, sb))
    jac = jax.jit(jax.jacfwd(lambda r, yb, sb: baselines.residuals(name, r, data.u, data.v, yb, sb)))
    s0 = np.asarray(starts)
    jax.block_until_ready((res(s0[0, 0], y[0], sw2[0]), jac(s0[0, 0], y[0], sw2[0])))  # compile untimed
    best = np.full(len(idx), np.inf)
    t0 = time.perf_counter()
    for k, b in enumerate(idx):
        yb, sb = y[b], sw2[b if sw2.shape[0] > 1 else 0]
        for st in s0[b]:
            try:
                sol = least_squares(lambda r: np.asarray(res(r, yb, sb)), st,
                                    jac=lambda r: np.asarray(jac(r, yb, sb)), method="lm")
            except Exception:  # noqa: BLE001 - a failed start is skipped, as in the batched fit
                continue
            cost = float(np.sqrt(np.sum(sol.fun**2)))
            if np.isfinite(cost):
                best[k] = min(best[k], cost)
    return best, (time.perf_counter() - t0) / len(idx)
