"""The log-space metric against its definition in numpy, its edge cases and its derivative."""

import jax
import numpy as np

import polyjax as pj

from _problems import random_hemisphere


def _reference(values, predicted, u, w):
    cu = np.clip(u[:, 2], 0.0, None)
    keep = (u[:, 2] > 0) & (w > 0)
    r = np.log1p(np.maximum(predicted, 0) * cu) - np.log1p(np.maximum(values, 0) * cu)
    return np.sqrt(np.sum(np.where(keep, w * r * r, 0), -1) / np.sum(np.where(keep, w, 0), -1))


def test_log_error_equals_its_definition_and_clamps_negative_predictions():
    u, v = random_hemisphere(500, seed=3)
    rng = np.random.default_rng(0)
    values = rng.gamma(0.5, 2.0, size=(3, 500))
    predicted = values * rng.uniform(0.5, 1.5, size=values.shape) - 0.2   # some negative predictions
    w = rng.uniform(0.5, 2.0, size=500)
    got = np.asarray(pj.log_error(values, predicted, u, v, weights=w))
    np.testing.assert_allclose(got, _reference(values, predicted, np.asarray(u), w), rtol=1e-12)
    assert np.all(got > 0)
    np.testing.assert_array_equal(np.asarray(pj.log_error(values, values, u, v)), 0.0)


def test_log_error_is_inf_for_nonfinite_kept_predictions_and_ignores_masked_ones():
    u, v = random_hemisphere(50, seed=1)
    values = np.ones(50)
    bad = values.copy()
    bad[7] = np.nan
    assert np.isinf(float(pj.log_error(values, bad, u, v)))
    mask = np.ones(50, bool)
    mask[7] = False
    assert np.isfinite(float(pj.log_error(values, bad, u, v, mask=mask)))


def test_log_error_gradient_matches_finite_differences():
    u, v = random_hemisphere(60, seed=5)
    values = np.linspace(0.1, 3.0, 60)
    pred = values * 1.3 + 0.05
    g = np.asarray(jax.grad(lambda p: pj.log_error(values, p, u, v))(pred))
    e = np.zeros(60)
    e[11] = 1e-6
    fd = (float(pj.log_error(values, pred + e, u, v)) - float(pj.log_error(values, pred - e, u, v))) / 2e-6
    np.testing.assert_allclose(g[11], fd, rtol=1e-5)
