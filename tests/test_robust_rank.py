"""Hard case: rank deficiency and empty fits. Flagged (minimum-norm, RANK_DEFICIENT / NO_SAMPLES) or a
clear FitError, by the caller's choice; never NaN."""

import numpy as np
import pytest

import polyjax as pj

from _robust_problems import random_hemisphere


@pytest.fixture(scope="module")
def problem():
    u, v = random_hemisphere(40, seed=3, min_cos=0.2)
    return u, v, 0.2 + u[:, 2] * v[:, 2] + 0.1 * u[:, 0] * v[:, 0]


def _all_finite(m):
    """Finite coefficients and PCA; halfwidths positive (inf marks a component constant over the samples)."""
    finite = all(bool(np.all(np.isfinite(np.asarray(a)))) for a in (m.coefficients, m.mean, m.rotation, m.centre))
    return finite and bool(np.all(np.asarray(m.halfwidth) > 0))


def test_fewer_samples_than_parameters_flagged_minimum_norm_interpolant(problem):
    """10 samples, p = 15 (31 parameters): rank 10, RANK_DEFICIENT, the data interpolated, finite everywhere."""
    u, v, b = problem
    m = pj.fit_polynomial(u[:10], v[:10], b[:10], degree=15, cutoff_deg=None)
    assert int(m.status) == pj.RESULTS.RANK_DEFICIENT and int(m.rank) == 10 and int(m.n_params) == 31
    assert np.isinf(float(m.condition)) and _all_finite(m)
    np.testing.assert_allclose(np.asarray(m(u[:10], v[:10])), b[:10], atol=1e-9)
    assert np.all(np.isfinite(np.asarray(m(u, v))))
    with pytest.raises(pj.FitError, match=r"are rank-deficient .* rank 10 of 31 parameters, 10 samples used"):
        pj.fit_polynomial(u[:10], v[:10], b[:10], degree=15, cutoff_deg=None, rank_deficient="error")


def test_constant_explanatory_variable_gives_the_fit_in_the_other_variable(problem):
    """u fixed at the normal: Lafortune's ux vx + uy vy is 0 for every sample. The fit is the
    polynomial in uz vz alone (checked against numpy), flagged RANK_DEFICIENT."""
    _, v, b = problem
    u = np.tile([0.0, 0.0, 1.0], (len(v), 1))
    p = 4
    m = pj.fit_polynomial(u, v, b, degree=p)
    assert int(m.status) == pj.RESULTS.RANK_DEFICIENT and int(m.rank) == p + 1 and _all_finite(m)
    x = v[:, 2]  # uz vz with uz = 1; every sample is kept (cos >= 0.2)
    ref = np.polynomial.polynomial.polyvander(x, p)
    beta = np.linalg.lstsq(ref, b, rcond=None)[0]
    np.testing.assert_allclose(np.asarray(m(u, v)), ref @ beta, rtol=1e-9, atol=1e-12)


def test_duplicated_explanatory_variables_rank_drops_by_the_duplicate(problem):
    """ux vx == uy vy for every sample (directions on the diagonal plane): lafortune-anisotropic's
    first two variables coincide, one component has zero variance, rank 1 + 2p of 1 + 3p."""
    u, v, b = problem
    diag = lambda w: (np.stack([w[:, 0], w[:, 0], w[:, 2]], -1)  # noqa: E731
                      / np.linalg.norm(np.stack([w[:, 0], w[:, 0], w[:, 2]], -1), axis=-1, keepdims=True))
    ud, vd = diag(u), diag(v)
    p = 3
    m = pj.fit_polynomial(ud, vd, b, variables="lafortune-anisotropic", degree=p)
    assert int(m.status) == pj.RESULTS.RANK_DEFICIENT and int(m.rank) == 1 + 2 * p and _all_finite(m)
    assert float(m.l2) < float(pj.fit_polynomial(ud, vd, b, variables="lafortune-anisotropic", degree=1).l2)
    with pytest.raises(pj.FitError, match="rank-deficient"):
        pj.fit_polynomial(ud, vd, b, variables="lafortune-anisotropic", degree=p, rank_deficient="error")


def test_all_samples_cut_by_80_degree_rule_no_samples(problem):
    """Every light at 85 degrees: NO_SAMPLES, L2 inf, coefficients 0, model evaluates to 0; 'error' raises."""
    u, v, b = problem
    graz = np.tile(np.asarray(pj.spherical_to_cartesian(np.deg2rad(85.0), 0.4)), (len(u), 1))
    m = pj.fit_polynomial(graz, v, b, degree=3)
    assert int(m.status) == pj.RESULTS.NO_SAMPLES and int(m.n_used) == 0 and np.isinf(float(m.l2))
    assert np.all(np.asarray(m.coefficients) == 0.0) and _all_finite(m)
    assert np.all(np.asarray(m(u, v)) == 0.0)
    with pytest.raises(pj.FitError, match="have no samples left"):
        pj.fit_polynomial(graz, v, b, degree=3, rank_deficient="error")


def test_one_empty_lane_in_a_batch_leaves_the_others_untouched(problem):
    """Per-lane masks: lane 1 fully masked is NO_SAMPLES; lanes 0 and 2 equal their single fits."""
    u, v, b = problem
    vals = np.stack([b, 2 * b, b**2])
    mask = np.ones(vals.shape, bool)
    mask[1] = False
    m = pj.fit_polynomial(u, v, vals, mask=mask, degree=3)
    np.testing.assert_array_equal(np.asarray(m.status), [pj.RESULTS.OK, pj.RESULTS.NO_SAMPLES, pj.RESULTS.OK])
    for j in (0, 2):
        single = pj.fit_polynomial(u, v, vals[j], degree=3)
        np.testing.assert_allclose(float(m.l2[j]), float(single.l2), rtol=1e-10)
    assert np.isinf(float(m.l2[1])) and _all_finite(m)


def test_error_names_the_first_bad_lane_and_its_own_counts(problem):
    """Three lanes, the middle one masked down to 5 samples: the error points at batch index (1,) and quotes
    that lane's rank and sample count, not those of lane 0."""
    u, v, b = problem
    values = np.stack([b, 2 * b, 3 * b])
    mask = np.ones(values.shape, bool)
    mask[1, 5:] = False
    flagged = pj.fit_polynomial(u, v, values, degree=3, mask=mask, cutoff_deg=None)
    assert [int(s) for s in flagged.status] == [0, pj.RESULTS.RANK_DEFICIENT, 0]
    with pytest.raises(pj.FitError, match=r"1 of 3 fits are rank-deficient \(first at batch index \(1,\): "
                                          r"rank 5 of 7 parameters, 5 samples used"):
        pj.fit_polynomial(u, v, values, degree=3, mask=mask, cutoff_deg=None, rank_deficient="error")
