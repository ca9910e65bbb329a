"""Hard case: extreme data. A lacquer mirror peak (~650 1/sr) beside 1e-4 values, all-zero and
constant materials, negative noise values, NaN/inf inside an otherwise valid array."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import baselines as bl
import polyjax as pj

from _robust_problems import F32_L2_FACTOR, as_dtype, random_hemisphere


@pytest.fixture(scope="module")
def problem():
    u, v = random_hemisphere(60, seed=11, min_cos=0.2)
    return u, v, 0.2 + u[:, 2] * v[:, 2] + 0.3 * np.maximum(np.sum(pj.reflect(u) * v, -1), 0) ** 4


@pytest.mark.data
def test_cayman_lacquer_peak_650_beside_1e_minus_4_fits_finite_float32_close():
    """Cornell Cayman: 3 channels, peak ~640 1/sr, smallest |values| ~1e-4; p = 1..15 stays OK and finite."""
    c = pj.data.load("cornell:cayman")
    vals = np.asarray(c.values)
    assert vals.max() > 600 and np.min(np.abs(vals[vals != 0])) < 1e-3
    degrees = [1, 5, 10, 15]
    m = pj.fit_polynomial(c, degree=degrees)
    assert np.all(np.asarray(m.status) == pj.RESULTS.OK) and float(jnp.max(m.condition)) < 100
    l2 = np.asarray(m.l2)
    assert np.all(np.isfinite(l2)) and np.all(np.diff(l2, axis=0) <= 1e-9)
    assert np.all(np.isfinite(np.asarray(m(c.u, c.v))))
    m32 = pj.fit_polynomial(**as_dtype(c, jnp.float32), mask=c.mask, degree=degrees)
    ratio = np.asarray(m32.l2) / l2
    assert np.all(np.abs(np.log(ratio)) < np.log(F32_L2_FACTOR)), ratio


@pytest.mark.data
def test_curet_negative_noise_values_are_kept_and_fitted():
    """All 61 CUReT samples hold 29 negative values and 14 zeros (measurement noise); they are data, not masked."""
    d = pj.data.load("curet")
    vals = np.asarray(d.values)
    assert int(np.sum(vals < 0)) == 29 and int(np.sum(vals == 0)) == 14
    assert bool(np.all(np.broadcast_to(np.asarray(d.mask), vals.shape)[vals < 0]))
    m = pj.fit_polynomial(d, degree=5)
    assert np.all(np.asarray(m.status) == pj.RESULTS.OK) and np.all(np.isfinite(np.asarray(m.l2)))
    kept = np.asarray(pj.cutoff_mask(d.u, d.v))
    lane = int(np.argwhere((vals[:, kept] < 0).any(-1)).ravel()[0])  # a negative value inside the 80-degree cutoff
    clipped = pj.fit_polynomial(d.u, d.v, np.maximum(vals[lane], 0.0), degree=5)
    assert float(m.l2[lane]) != float(clipped.l2)  # the negative values entered the fit


def test_all_zero_and_constant_materials_fitted_exactly(problem):
    """Zeros give zero coefficients and L2 = 0; a constant c is reproduced with L2 < 1e-12 c, any scale."""
    u, v, _ = problem
    vals = np.stack([np.zeros(60), np.full(60, 1e-4), np.full(60, 650.0)])
    m = pj.fit_polynomial(u, v, vals, degree=8)
    assert np.all(np.asarray(m.status) == pj.RESULTS.OK)
    assert np.all(np.asarray(m.coefficients[0]) == 0.0) and float(m.l2[0]) == 0.0
    for j, c in ((1, 1e-4), (2, 650.0)):
        assert float(m.l2[j]) < 1e-12 * c
        np.testing.assert_allclose(np.asarray(m[j](u, v)), c, rtol=1e-10)
    for name in ("ward",):
        f = bl.fit(name, u, v, vals, n_starts=2)
        assert np.all(np.isfinite(np.asarray(f.params))) and np.all(np.isfinite(np.asarray(f.l2)))
        assert float(f.l2[0]) < 1e-12 and float(f.l2[1]) < 1e-3 * 1e-4 and float(f.l2[2]) < 1e-3 * 650


def test_nan_and_inf_inside_values_error_names_the_argument_or_are_masked(problem):
    u, v, b = problem
    vals = np.stack([b, b, b])
    vals[1, 7] = np.inf
    vals[2, 3] = np.nan
    with pytest.raises(pj.InputError,
                       match=r"values: expected finite numbers, found 2 NaN/inf \(first at index \(1, 7\)\)"):
        pj.fit_polynomial(u, v, vals)
    m = pj.fit_polynomial(u, v, vals, nonfinite="mask", degree=3)
    np.testing.assert_array_equal(np.asarray(m.n_used), [60, 59, 59])
    ref = pj.fit_polynomial(np.delete(u, 7, 0), np.delete(v, 7, 0), np.delete(b, 7), degree=3)
    np.testing.assert_allclose(float(m.l2[1]), float(ref.l2), rtol=1e-10)
    msg = r"values: expected finite numbers, found 2 NaN/inf \(first at index \(1, 7\)\) where mask is True"
    with pytest.raises(pj.InputError, match=msg):
        bl.fit("ward", u, v, vals)
    mask = np.isfinite(vals)
    f = bl.fit("ward", u, v, vals, mask=mask, n_starts=2)
    assert np.all(np.isfinite(np.asarray(f.l2)))


def test_nan_under_outer_jit_flags_nonfinite_values_lane_only(problem):
    """Under jit no error can be raised: the bad lane is NONFINITE_VALUES (L2 inf, coefficients 0), others exact."""
    u, v, b = problem
    vals = np.stack([b, b.copy(), 2 * b])
    vals[1, 5] = np.nan
    m = jax.jit(lambda u, v, y: pj.fit_polynomial(u, v, y, degree=3))(u, v, vals)
    np.testing.assert_array_equal(np.asarray(m.status), [0, pj.RESULTS.NONFINITE, 0])
    assert np.isinf(float(m.l2[1])) and np.all(np.asarray(m.coefficients[1]) == 0.0)
    ref = pj.fit_polynomial(u, v, np.stack([b, 2 * b]), degree=3)
    np.testing.assert_allclose(np.asarray(m.coefficients[np.array([0, 2])]), np.asarray(ref.coefficients),
                               rtol=1e-10, atol=1e-13)
    masked = jax.jit(lambda u, v, y: pj.fit_polynomial(u, v, y, degree=3, nonfinite="mask"))(u, v, vals)
    assert np.all(np.asarray(masked.status) == pj.RESULTS.OK) and int(masked.n_used[1]) == 59
