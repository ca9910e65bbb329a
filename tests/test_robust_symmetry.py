"""Hard case: symmetric samples and the PCA sign convention (hypothesis, small derandomised example counts).

Samples closed under swapping ``x`` and ``y`` give covariance eigenvectors like ``(a, -a, b)``
whose two largest entries are tied up to rounding; a plain ``argmax`` sign rule then flipped
components (and the signs of odd coefficients) with the order of the samples.
"""

import functools

import jax
import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import polyjax as pj

from _problems import SYMMETRIC_SETS, random_hemisphere

SMALL = settings(max_examples=20, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
seeds = st.integers(0, 2**31 - 1)


@functools.lru_cache(maxsize=None)
def xy_symmetric_problem():
    """60 random pairs and their mirror images under x <-> y (lafortune-anisotropic: var(ux vx) == var(uy vy))."""
    u, v = random_hemisphere(60, seed=2, min_cos=0.2)
    swap = [1, 0, 2]
    u, v = np.concatenate([u, u[:, swap]]), np.concatenate([v, v[:, swap]])
    values = 0.1 + np.maximum(-0.9 * u[:, 0] * v[:, 0] - 0.5 * u[:, 1] * v[:, 1] + u[:, 2] * v[:, 2], 0.0) ** 4
    return u, v, values


def fit(u, v, values):
    return pj.fit_polynomial(u, v, values, variables="lafortune-anisotropic", degree=[2, 5, 8])


@SMALL
@given(seed=seeds)
def test_sample_order_invariance_with_tied_eigenvector_entries(seed):
    """Any order of x <-> y symmetric samples: the same rotation (signs included) and coefficients.
    Before the tie-aware sign rule, 30 permutations gave 4 different sign patterns."""
    u, v, b = xy_symmetric_problem()
    ref = fit(u, v, b)
    rot = np.asarray(ref.rotation)[0]
    assert abs(abs(rot[0, 1]) - abs(rot[1, 1])) < 1e-9 and abs(rot[0, 1]) > 0.5  # the tie is really there
    p = np.random.default_rng(seed).permutation(len(b))
    m = fit(u[p], v[p], b[p])
    np.testing.assert_allclose(np.asarray(m.rotation), np.asarray(ref.rotation), rtol=0, atol=1e-10)
    c = np.asarray(ref.coefficients)
    np.testing.assert_allclose(np.asarray(m.coefficients), c, rtol=1e-8, atol=1e-8 * np.abs(c).max())


_pca = jax.jit(pj.fit_pca)


@SMALL
@given(seed=seeds, k=st.integers(2, 4), symmetric=st.booleans())
def test_pca_signs_follow_the_first_largest_entry_for_any_row_order(seed, k, symmetric):
    """Rotation orthonormal, variances decreasing, each column's first (near-)largest entry positive,
    and the same rotation for any row order, also with two variables of exactly equal variance."""
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(80, k)) @ rng.normal(size=(k, k)) + rng.normal(size=k)
    if symmetric:
        swap = np.arange(k)
        swap[[0, 1]] = [1, 0]
        x = np.concatenate([x, x[:, swap]])
    a = _pca(x)
    r = np.asarray(a.rotation)
    np.testing.assert_allclose(r.T @ r, np.eye(k), atol=1e-12)
    var = np.asarray(a.variance)
    assert np.all(np.diff(var) <= 1e-12 * var[0])
    mag = np.abs(r)
    first = np.argmax(mag >= mag.max(axis=0) - np.sqrt(np.finfo(float).eps), axis=0)
    assert np.all(r[first, np.arange(k)] > 0)
    if np.min(np.abs(np.diff(var))) > 1e-6 * var[0]:  # distinct variances: eigenvectors determined
        shuffled = _pca(x[rng.permutation(len(x))])
        np.testing.assert_allclose(np.asarray(shuffled.rotation), r, atol=1e-8)


@functools.lru_cache(maxsize=None)
def fitted(variables):
    """The model fitted to non-reciprocal data, as a jitted ``f(u, v)``."""
    u, v = random_hemisphere(120, seed=11, min_cos=0.05)
    b = 0.15 + 0.8 * np.maximum(-0.9 * (u[:, 0] * v[:, 0] + u[:, 1] * v[:, 1]) + u[:, 2] * v[:, 2], 0.0) ** 6
    model = pj.fit_polynomial(u, v, b + 0.05 * u[:, 0], variables=variables, degree=8)
    return jax.jit(lambda uu, vv: model(uu, vv))


angles = st.tuples(st.floats(0.0, np.deg2rad(100.0)), st.floats(-np.pi, np.pi))
scales = st.floats(1e-3, 1e3)


@SMALL
@given(a=angles, b=angles, sa=scales, sb=scales, variables=st.sampled_from(SYMMETRIC_SETS))
def test_reciprocal_at_any_pair_including_non_unit_and_below_horizon(a, b, sa, sb, variables):
    """``f(s u, t v) = f(v, u)`` for a model fitted to non-reciprocal data: grazing, below the
    horizon (0) and non-unit vectors (renormalised) included."""
    m = fitted(variables)
    u = np.asarray(pj.spherical_to_cartesian(*a))
    v = np.asarray(pj.spherical_to_cartesian(*b))
    f = float(m(sa * u, sb * v))
    assert np.isfinite(f)
    assert abs(f - float(m(v, u))) <= 1e-12 * max(1.0, abs(f))
    if u[2] <= 0 or v[2] <= 0:
        assert f == 0.0
