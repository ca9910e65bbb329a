"""Property tests (hypothesis): sample-order invariance, linearity in the data, reciprocity of the
symmetric variable sets, and stable PCA rotation and sign conventions. Shapes are fixed so that
every example reuses one compiled fit."""

import functools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import polyjax as pj

from _problems import SYMMETRIC_SETS, LazyModels, polynomial_data, random_hemisphere

N = 80
SETTINGS = settings(max_examples=20, deadline=None, derandomize=True)
U, V = random_hemisphere(N, seed=21, min_cos=0.15)
B = 0.1 + 0.5 * U[:, 2] * V[:, 2] + 0.8 * np.maximum(np.sum(np.asarray(pj.reflect(U)) * V, -1), 0) ** 6


def _fit(u, v, b, variables="lafortune"):
    return pj.fit_polynomial(u, v, b, variables=variables, degree=4, cutoff_deg=80.0)


@functools.cache
def _ref():
    """The reference fit, made by the first test that needs it (not at collection, in every xdist worker)."""
    return _fit(U, V, B)


@SETTINGS
@given(st.permutations(range(N)))
def test_fit_invariant_to_sample_order(perm):
    perm = np.asarray(perm)
    m = _fit(U[perm], V[perm], B[perm])
    np.testing.assert_allclose(np.asarray(m.coefficients), np.asarray(_ref().coefficients), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(np.asarray(m.rotation), np.asarray(_ref().rotation), rtol=0, atol=1e-12)
    assert float(m.l2) == pytest.approx(float(_ref().l2), rel=1e-10)


@SETTINGS
@given(st.floats(-6, 6), st.booleans())
def test_fitting_c_times_b_gives_c_times_the_coefficients(log_c, negative):
    c = (-1.0 if negative else 1.0) * 10.0**log_c
    m = _fit(U, V, c * B)
    scale = abs(c) * np.max(np.abs(np.asarray(_ref().coefficients)))
    np.testing.assert_allclose(np.asarray(m.coefficients), c * np.asarray(_ref().coefficients),
                               rtol=1e-9, atol=1e-12 * scale)
    assert float(m.l2) == pytest.approx(abs(c) * float(_ref().l2), rel=1e-8, abs=1e-14 * abs(c))


MODELS = LazyModels(SYMMETRIC_SETS, lambda: {
    s: pj.fit_polynomial(*polynomial_data("lafortune", 3)[:2], polynomial_data("lafortune", 3)[2] + 0.2, variables=s,
                         degree=5) for s in SYMMETRIC_SETS})


@SETTINGS
@given(st.integers(0, 2**31 - 1), st.sampled_from(SYMMETRIC_SETS))
def test_symmetric_variable_sets_are_reciprocal(seed, variables):
    a, b = random_hemisphere(64, seed=seed, min_cos=1e-3)
    m = MODELS[variables]
    x_ab = np.asarray(pj.explanatory_variables(variables, a, b))
    np.testing.assert_allclose(x_ab, np.asarray(pj.explanatory_variables(variables, b, a)), rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(np.asarray(m(a, b)), np.asarray(m(b, a)), rtol=1e-11, atol=1e-12)


@SETTINGS
@given(st.permutations(range(N)), st.floats(-3, 3))
def test_pca_rotation_and_signs_stable(perm, log_scale):
    """Same rotation for reordered samples and for scaled variables (variance ratios unchanged); each
    column's largest-magnitude entry positive; repeated runs bit-identical."""
    x = np.asarray(pj.explanatory_variables("ashikhmin-shirley", U, V))
    ref = pj.fit_pca(x)
    rot = np.asarray(ref.rotation)
    idx = np.argmax(np.abs(rot), axis=0)
    assert np.all(rot[idx, np.arange(rot.shape[1])] > 0)
    np.testing.assert_array_equal(np.asarray(pj.fit_pca(x).rotation), rot)
    p = pj.fit_pca(x[np.asarray(perm)] * 10.0**log_scale)
    np.testing.assert_allclose(np.asarray(p.rotation), rot, rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.asarray(p.variance), np.asarray(ref.variance) * 10.0 ** (2 * log_scale), rtol=1e-9)
