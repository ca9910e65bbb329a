"""Shared BRDFs and a chi-square test of a sampler against its density, for the sampling and export tests."""

import functools
from typing import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import polyjax as pj
import polyjax.render as pr

NORMAL = np.array([0.0, 0.0, 1.0])
GRAZING = np.array([np.sin(np.deg2rad(80.0)), 0.0, np.cos(np.deg2rad(80.0))])
OBLIQUE = np.array([np.sin(np.deg2rad(45.0)) * np.cos(1.0), np.sin(np.deg2rad(45.0)) * np.sin(1.0),
                    np.cos(np.deg2rad(45.0))])
GLOSSY = "gold-metallic-paint"


class Baseline(eqx.Module):
    """A baselines model with fixed parameters as a BRDF callable ``f(u, v)`` (a pytree: every instance of one model
    shares the compiled programs it is passed to)."""

    fn: Callable = eqx.field(static=True)
    params: jax.Array

    def __init__(self, name, params):
        import baselines

        self.fn = baselines.get_model(name).evaluate
        self.params = jnp.asarray(params, dtype=float)

    def __call__(self, u, v):
        return _evaluate(self, u, v)


@eqx.filter_jit
def _evaluate(brdf: Baseline, u, v):  # one compiled program per model and shapes (op by op: one per operation)
    return brdf.fn(brdf.params, u, v)


def cook_torrance():
    return Baseline("cook-torrance", [0.3, 0.6, 0.15, 0.1])


def ward():
    return Baseline("ward", [0.2, 0.3, 0.08])


@functools.lru_cache(maxsize=1)
def glossy_polynomial():
    """The p = 5 Lafortune-variable polynomial fitted to the neural MERL fit of a glossy material."""
    data = pj.data.load_merl_nbrdf(GLOSSY, subsample=60000, seed=0)
    return pj.fit_polynomial(data, variables="lafortune", degree=5)


@functools.lru_cache(maxsize=1)
def neural():
    return pj.data.load_nbrdf(GLOSSY)


TABLE = 48  # table resolution of the samplers under test
BINS = 20  # histogram bins per side of the square of the hemisphere map, not aligned with the table cells
SUB = 48  # quadrature points per bin side: the quadrature grid (BINS * SUB = TABLE * 20) is aligned with both


def expected_frequencies(pdf):
    """Integral of ``pdf(w)`` over each bin, bins ``BINS x BINS`` cells of the square of the equal-area
    hemisphere map (``d omega = 2 pi dA``), by the midpoint rule on a grid aligned with the table cells
    (exact for the tabulated part, which is bilinear on each sub-cell: the midpoint rule integrates it exactly)."""
    m = BINS * SUB
    g = (np.arange(m) + 0.5) / m
    X, Y = np.meshgrid(g, g)
    vals = np.asarray(pdf(pr.square_to_hemisphere(jnp.asarray(np.stack([X, Y], -1)))))
    return (vals * 2 * np.pi / m**2).reshape(BINS, SUB, BINS, SUB).sum(axis=(1, 3))


def observed_frequencies(u):
    u = np.asarray(u)
    s = np.asarray(pr.hemisphere_to_square(jnp.asarray(u[u[:, 2] > 0])))
    h, _, _ = np.histogram2d(s[:, 1], s[:, 0], bins=[np.linspace(0, 1, BINS + 1)] * 2)
    return h


def chi2_pvalue(u, pdf, min_expected=5.0):
    """p-value of Pearson's chi-square test of samples ``u (n, 3)`` against the density ``pdf``.

    Bins with expected count below ``min_expected`` are pooled into one (as Mitsuba's ChiSquareTest does).
    Samples below the horizon go into their own bin (expected: the density's mass there, i.e. 1 - total).
    """
    n = len(u)
    exp = expected_frequencies(pdf).ravel() * n
    obs = observed_frequencies(u).ravel()
    below = float(np.sum(np.asarray(u)[:, 2] <= 0))
    small = exp < min_expected
    e = np.concatenate([exp[~small], [exp[small].sum()], [max(n - exp.sum(), 0.0)]])
    o = np.concatenate([obs[~small], [obs[small].sum()], [below]])
    keep = e > 1e-9 * n
    assert np.all(o[~keep] == 0), "samples where the density is 0"
    e, o = e[keep], o[keep]
    chi2 = float(np.sum((o - e) ** 2 / e))
    from scipy import stats  # here, not at the top: every xdist worker imports this file to collect (1.9 s)

    return float(stats.chi2.sf(chi2, len(e) - 1))


def sample_many(sampler, v, n, seed=0):
    u, p = sampler.sample(jax.random.PRNGKey(seed), jnp.asarray(v), n)
    return np.asarray(u), np.asarray(p)
