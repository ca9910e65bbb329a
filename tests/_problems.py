"""Shared problem definitions for the core tests: datasets and generated data (the reference solvers are in
``benchmarks.paper.references``, shared with the benchmarks)."""

from __future__ import annotations

import functools

import numpy as np

import polyjax as pj

VARIABLE_SETS = ("ward", "ashikhmin-shirley", "lafortune")
SYMMETRIC_SETS = ("ward", "ashikhmin-shirley", "lafortune", "lafortune-anisotropic")


@functools.lru_cache(maxsize=None)
def curet(samples: tuple[int, ...]) -> pj.Measurements:
    return pj.data.load_curet(None, list(samples))


def random_hemisphere(n: int, seed: int = 0, min_cos: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """``n`` random (u, v) pairs above the horizon."""
    rng = np.random.default_rng(seed)

    def draw():
        ct = rng.uniform(min_cos, 1.0, n)
        ph = rng.uniform(-np.pi, np.pi, n)
        st = np.sqrt(1 - ct**2)
        return np.stack([st * np.cos(ph), st * np.sin(ph), ct], -1)

    return draw(), draw()


def polynomial_data(variables: str, degree: int, n: int = 400, seed: int = 1):
    """Data generated exactly by a polynomial of the model's own form (equation (3)).

    Returns ``(u, v, values, beta)`` where ``values = beta_0 + sum beta Z^d`` on the PCA of the
    explanatory variables over all samples (no cutoff needed: directions stay below 80 degrees).
    """
    u, v = random_hemisphere(n, seed, min_cos=np.cos(np.deg2rad(79.0)))
    x = np.asarray(pj.explanatory_variables(variables, u, v))
    pca = pj.fit_pca(x)
    z = np.asarray(pca(x))
    k = x.shape[1]
    rng = np.random.default_rng(seed + 100)
    beta = rng.normal(size=k * degree + 1)
    values = np.asarray(pj.evaluate_paper_form(beta, z, degree))
    return u, v, values, beta
