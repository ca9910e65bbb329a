"""The seven nonlinear models of the paper in plain numpy, fitted by ``scipy.optimize.least_squares``: the
alternative a user has without JAX, the comparison of ``bench_latency.py``'s plain row (it imports no JAX).

The same models as :mod:`baselines` (the same formulas, the same clamped cosines ``max(cos, 1e-6)`` and half
vector, ``+z`` where ``u = -v``), the same unconstrained parameters (the same transforms ``r^2``, ``sin^2 r``,
``exp(log lo + (log hi - log lo) sin^2 r)``, ``hi |sin r|``) and the same objective, paper equation (11):
``r_i = sqrt(w_i / sum_j w_j) cos theta_u,i (b_i - f_i)`` over the samples with ``theta_u, theta_v <= 80``
degrees, so ``sqrt(2 cost)`` of a solution is its L2. ``tests/test_baseline_saved_programs.py`` checks the
models against :mod:`baselines`.
"""

from __future__ import annotations

import numpy as np

EPS_COS = 1e-6


def _positive(r):
    return r * r


def _unit(r):
    return np.sin(r) ** 2


def _log_bounded(lo, hi):
    a, b = np.log(lo), np.log(hi)
    return lambda r: np.exp(a + (b - a) * np.sin(r) ** 2)


def _bounded(hi):
    return lambda r: hi * np.abs(np.sin(r))


def _real(r):
    return r


class Geometry:
    """Clamped cosines and the half vector of ``(n, 3)`` directions, as ``baselines._models.common.Geometry``."""

    def __init__(self, u, v):
        self.u, self.v = u, v
        self.cu_raw, self.cv_raw = u[:, 2], v[:, 2]
        self.above = (self.cu_raw > 0) & (self.cv_raw > 0)
        self.cu = np.maximum(self.cu_raw, EPS_COS)
        self.cv = np.maximum(self.cv_raw, EPS_COS)
        s = u + v
        m = np.max(np.abs(s), axis=1, keepdims=True)
        length = m * np.linalg.norm(s / np.where(m > 0, m, 1.0), axis=1, keepdims=True)
        ok = length > 1e-12
        self.h = np.where(ok, s / np.where(ok, length, 1.0), np.array([0.0, 0.0, 1.0]))
        self.nh = np.maximum(self.h[:, 2], EPS_COS)
        self.vh = np.maximum(np.sum(v * self.h, axis=1), EPS_COS)
        self.tan2_h = np.maximum(1.0 / (self.nh * self.nh) - 1.0, 0.0)
        self.dot_xy = u[:, 0] * v[:, 0] + u[:, 1] * v[:, 1]


def _pow(base, exponent):
    pos = base > 0
    return np.where(pos, np.exp(np.minimum(exponent * np.log(np.where(pos, base, 1.0)), 600.0)), 0.0)


def _schlick(f0, c):
    return f0 + (1.0 - f0) * (1.0 - c) ** 5


def _ward(p, g):
    a2 = p[2] * p[2]
    return p[0] / np.pi + p[1] * np.where(g.above, np.exp(-g.tan2_h / a2) / (4 * np.pi * a2 * np.sqrt(g.cu * g.cv)), 0)


def _ward_duer(p, g):
    a2 = p[2] * p[2]
    return p[0] / np.pi + p[1] * np.where(g.above, np.exp(-g.tan2_h / a2) / (4 * np.pi * a2 * g.cu * g.cv), 0)


def _blinn_phong(p, g):
    return p[0] / np.pi + p[1] * np.where(g.above, (p[2] + 2) / (2 * np.pi) * _pow(g.nh, p[2]), 0)


def _cook_torrance(p, g):
    m2 = p[2] * p[2]
    d = np.exp(-g.tan2_h / m2) / (m2 * g.nh**4)
    shadow = np.minimum(1.0, np.minimum(2 * g.nh * g.cv / g.vh, 2 * g.nh * g.cu / g.vh))
    return p[0] / np.pi + p[1] * np.where(g.above, _schlick(p[3], g.vh) * d * shadow / (np.pi * g.cu * g.cv), 0)


def _ashikhmin_shirley(p, g):
    spec = (p[2] + 1) / (8 * np.pi) * _pow(g.nh, p[2]) / (g.vh * np.maximum(g.cu, g.cv)) * _schlick(p[3], g.vh)
    return p[0] / np.pi + p[1] * np.where(g.above, spec, 0)


def _lafortune(p, g):
    base = p[1] * g.dot_xy + p[2] * g.cu_raw * g.cv_raw
    return p[0] / np.pi + np.where(g.above, _pow(base, p[3]), 0)


def _oren_nayar(p, g):
    s2 = p[1] * p[1]
    a, b = 1 - 0.5 * s2 / (s2 + 0.33), 0.45 * s2 / (s2 + 0.09)
    return p[0] * (a + b * np.maximum(g.dot_xy, 0) / np.maximum(g.cu, g.cv)) / np.pi


#: name -> (model f(params, geometry), transforms raw -> params)
MODELS = {
    "ward": (_ward, (_positive, _positive, _log_bounded(1e-3, 3.0))),
    "ward-duer": (_ward_duer, (_positive, _positive, _log_bounded(1e-3, 3.0))),
    "blinn-phong": (_blinn_phong, (_positive, _positive, _log_bounded(0.1, 1e5))),
    "cook-torrance": (_cook_torrance, (_positive, _positive, _log_bounded(1e-3, 3.0), _unit)),
    "ashikhmin-shirley": (_ashikhmin_shirley, (_positive, _positive, _log_bounded(0.1, 1e5), _unit)),
    "lafortune": (_lafortune, (_positive, _real, _real, _log_bounded(0.1, 1e4))),
    "oren-nayar": (_oren_nayar, (_positive, _bounded(2.0))),
}


def evaluate(name: str, raw, u, v):
    """The model ``name`` at unconstrained parameters ``raw (P,)`` and directions ``u, v (n, 3)``."""
    f, transforms = MODELS[name]
    return f([t(r) for t, r in zip(transforms, raw)], Geometry(u, v))


def fit_best_l2(name: str, u, v, values, weights, starts, cutoff_deg: float = 80.0):
    """The lowest L2 over ``starts (S, P)`` of ``least_squares(method="lm")`` (finite-difference Jacobian) of one
    lane ``values (n,)``; a start that raises is skipped (inf when all do)."""
    from scipy.optimize import least_squares

    c = np.cos(np.deg2rad(cutoff_deg)) - 1e-9
    keep = (u[:, 2] > 0) & (v[:, 2] > 0) & (u[:, 2] >= c) & (v[:, 2] >= c)
    w = np.where(keep, weights, 0.0)
    sw = np.sqrt(w / np.sum(w)) * np.where(keep, u[:, 2], 0.0)
    f, transforms = MODELS[name]
    g = Geometry(u, v)

    def residuals(raw):
        return sw * (values - f([t(r) for t, r in zip(transforms, raw)], g))

    best = np.inf
    for s in starts:
        try:
            sol = least_squares(residuals, s, method="lm")
        except (ValueError, np.linalg.LinAlgError):
            continue
        if np.isfinite(sol.cost):
            best = min(best, float(np.sqrt(2 * sol.cost)))
    return best
