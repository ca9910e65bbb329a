"""Shared problem definitions for the core tests: datasets and generated data (the reference solvers are in
``benchmarks.paper.references``, shared with the benchmarks)."""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping

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


def band_directions(n: int, lo_deg: float, hi_deg: float, seed: int) -> np.ndarray:
    """``n`` unit directions with polar angles in ``[lo_deg, hi_deg]`` and all azimuths."""
    rng = np.random.default_rng(seed)
    ct = rng.uniform(np.cos(np.deg2rad(hi_deg)), np.cos(np.deg2rad(lo_deg)), n)
    ph = rng.uniform(-np.pi, np.pi, n)
    st = np.sqrt(1 - ct**2)
    return np.stack([st * np.cos(ph), st * np.sin(ph), ct], -1)


def narrow_lobe(u, v) -> np.ndarray:
    """A diffuse level plus a narrow Beckmann-like lobe in the half vector: ``0.1 + 2 exp(-tan^2(theta_h) / 0.05)``."""
    h = u + v
    h = h / np.linalg.norm(h, axis=-1, keepdims=True)
    return 0.1 + 2.0 * np.exp(-(1.0 / h[:, 2] ** 2 - 1.0) / 0.05)


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


class LazyModels(Mapping):
    """Fitted models by name, fitted on first use rather than when the test module is imported.

    Every pytest-xdist worker imports every test module to collect it; fits made at import would be compiled and
    run by every worker (and by runs that deselect the module's tests). The names are known at import (for
    ``parametrize``); ``make()`` returns the dict of models and must have exactly these names.
    """

    def __init__(self, names, make: Callable[[], dict]):
        self._names, self._make, self._models = tuple(names), make, None

    def _get(self) -> dict:
        if self._models is None:
            models = self._make()
            assert tuple(models) == self._names, (tuple(models), self._names)
            self._models = models
        return self._models

    def __getitem__(self, name):
        return self._get()[name]

    def __iter__(self):
        return iter(self._names)

    def __len__(self):
        return len(self._names)
