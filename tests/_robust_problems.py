"""Shared problem definitions for the robustness tests: hard geometry, measured data at high degree,
and hand-built baseline fits for evaluating every model."""

from __future__ import annotations

import functools

import jax.numpy as jnp
import numpy as np
from _mitsuba_rough_problems import ROUGH_PARAMS
from _standard_problems import STANDARD_PARAMS as OPENPBR_USD_PARAMS

import baselines as bl
import polyjax as pj

from _baseline_problems import STANDARD_PARAMS, TRUE_PARAMS
from _problems import curet, random_hemisphere  # noqa: F401 - re-exported for the robustness modules

#: Stated bound on L2(float32) / L2(float64) for the default Legendre basis up to p = 15
#: (measured worst over every variable set: 1.000001, benchmarks/bench_robustness.py; a wide margin).
F32_L2_FACTOR = 1.01
#: Worst condition numbers of the default (Legendre) design up to p = 15 on Quarry tile (measured:
#: lafortune 63, ward 693, ashikhmin-shirley 3.6e3, lafortune-anisotropic 8.7e3), with margin.
QUARRY_COND_BOUND = {"lafortune": 200.0, "ward": 2e3, "ashikhmin-shirley": 1e4, "lafortune-anisotropic": 3e4}
QUARRY = 25  # CUReT sample 25, "Quarry tile"


@functools.lru_cache(maxsize=None)
def green_latex(subsample: int = 4000) -> pj.Measurements:
    """Neural MERL green-latex on a reproducible random subset of the MERL grid."""
    return pj.data.load("merl-nbrdf:green-latex", subsample=subsample, seed=0)


def as_dtype(d: pj.Measurements, dtype):
    return dict(u=jnp.asarray(d.u, dtype), v=jnp.asarray(d.v, dtype), values=jnp.asarray(d.values, dtype),
                weights=jnp.asarray(d.weights, dtype))


def hard_directions() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Degenerate (u, v) pairs and whether each is above the horizon.

    Rows: normal incidence u = v = n; u = v at 89.9999 degrees; both exactly at 90 degrees;
    mirror pairs (v = reflect(u)) at 60 and 89.9999 degrees; u = -v (half vector undefined);
    u below the horizon; v below the horizon; both just above the horizon (cos = 1e-9).
    """
    th = np.deg2rad
    s = lambda t, p: np.asarray(pj.spherical_to_cartesian(th(t), p))  # noqa: E731
    u = np.stack([s(0, 0), s(89.9999, 0.3), s(90, 0.0), s(60, 1.0), s(89.9999, 2.0), s(45, 0.5), s(120, 0.2),
                  s(30, 0.1), [1.0, 0.0, 1e-9]])
    v = np.stack([s(0, 0), s(89.9999, 0.3), s(90, np.pi), np.asarray(pj.reflect(s(60, 1.0))),
                  np.asarray(pj.reflect(s(89.9999, 2.0))), -s(45, 0.5), s(20, 0.0), s(100, 2.0), [0.0, 1.0, 1e-9]])
    above = (u[:, 2] > 0) & (v[:, 2] > 0)
    return u, v, above


def baseline_params(name: str):
    """Known constrained parameters of a baseline model (a 55-term ramp for Zernike)."""
    if name == "zernike":
        return jnp.linspace(-1.0, 1.0, bl.n_zernike_terms(8))
    return jnp.asarray({**TRUE_PARAMS, **STANDARD_PARAMS, **OPENPBR_USD_PARAMS, **PUBLISHED_LIKE, **ROUGH_PARAMS}[name])


#: Parameters of the published compact models, typical of their MERL fits (``kap`` folded into ``rho_s``).
PUBLISHED_LIKE = {
    "sgd": [0.2, 3.0, 0.02, 0.45, 0.06, -0.02, 3.0, 1e-5, 25.0, 0.25],
    "abc": [0.1, 20.0, 5e4, 1.2, 1.8],
}


def baseline_fit_at(name: str, params) -> bl.BaselineFit:
    """A :class:`baselines.BaselineFit` holding ``params`` (one lane), to evaluate through the fit's own call."""
    p = jnp.asarray(params)[None]
    z = jnp.zeros((1,), jnp.int32)
    return bl.BaselineFit(params=p, raw=p, l2=jnp.zeros((1,)), status=z, steps=z, success=z == 0,
                          start_l2=jnp.zeros((1, 1)), start_status=z[:, None], best_start=z,
                          at_limit=jnp.zeros(p.shape, bool), name=name)
