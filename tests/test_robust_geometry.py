"""Hard case: grazing and degenerate geometry (theta near 90 degrees, u = v, mirror pairs, u = -v,
directions below the horizon, non-unit and zero vectors) for every variable set and every baseline.

Non-unit vectors: the fitters (``fit_polynomial``, ``baselines.fit``, ``make_measurements``) and the
fitted models (``PolynomialBRDF``, ``BaselineFit``) renormalise them, so ``c u`` acts as ``u``; a zero
vector has no direction and is masked (fit) or gives 0 (evaluation). The low-level functions
(``explanatory_variables``, the model functions in ``baselines``, ``l2_error``, ``cutoff_mask``) take
unit vectors as given.
"""

import jax.numpy as jnp
import numpy as np
import pytest

import baselines as bl
import polyjax as pj

from _robust_problems import baseline_fit_at, baseline_params, hard_directions, random_hemisphere


@pytest.fixture(scope="module")
def smooth_data():
    u, v = random_hemisphere(200, seed=5)
    return u, v, 0.3 + 2.0 * np.maximum(np.sum(pj.reflect(u) * v, -1), 0) ** 8 + 0.1 * u[:, 2]


@pytest.mark.parametrize("variables", pj.variable_sets())
def test_polynomial_finite_at_degenerate_directions_and_zero_below_horizon(variables, smooth_data):
    u, v, b = smooth_data
    m = pj.fit_polynomial(u, v, b, variables=variables, degree=3)
    hu, hv, above = hard_directions()
    f = np.asarray(m(hu, hv))
    assert np.all(np.isfinite(f))
    assert np.all(f[~above] == 0.0) and np.any(f[above] != 0.0)
    x = np.asarray(pj.explanatory_variables(variables, jnp.asarray(hu), jnp.asarray(hv)))
    assert np.all(np.isfinite(x))
    # non-unit vectors act as their directions, zero vectors give 0
    np.testing.assert_allclose(np.asarray(m(3.0 * u, 0.25 * v)), np.asarray(m(u, v)), rtol=1e-12, atol=1e-12)
    assert np.all(np.asarray(m(np.zeros((3, 3)), v[:3])) == 0.0)


@pytest.mark.parametrize("variables", pj.variable_sets())
def test_polynomial_fit_with_degenerate_samples_inside(variables, smooth_data):
    """Degenerate pairs among the samples (no cutoff): below-horizon and 90-degree pairs dropped, the rest fitted
    finite."""
    u, v, b = smooth_data
    hu, hv, above = hard_directions()
    uu, vv = np.concatenate([u, hu]), np.concatenate([v, hv])
    bb = np.concatenate([b, np.full(len(hu), 0.5)])
    m = pj.fit_polynomial(uu, vv, bb, variables=variables, degree=3, cutoff_deg=None)
    assert int(m.n_used) == len(u) + int(np.sum(above))
    assert np.all(np.isfinite(np.asarray(m.coefficients))) and np.isfinite(float(m.l2))
    # scaling the inputs changes nothing: the fitter renormalises
    m2 = pj.fit_polynomial(2.0 * uu, 0.5 * vv, bb, variables=variables, degree=3, cutoff_deg=None)
    np.testing.assert_allclose(np.asarray(m2.coefficients), np.asarray(m.coefficients), rtol=1e-8, atol=1e-10)


def test_zero_and_nonfinite_direction_vectors():
    """A zero vector is masked in the fit (and rejected by make_measurements); NaN directions raise."""
    u, v = random_hemisphere(30, seed=2)
    b = 0.1 + u[:, 2]
    uz = u.copy()
    uz[4] = 0.0
    m = pj.fit_polynomial(uz, v, b, degree=2, cutoff_deg=None)
    assert int(m.n_used) == 29 and np.isfinite(float(m.l2))
    with pytest.raises(pj.InputError, match="u: expected non-zero direction vectors"):
        pj.make_measurements(uz, v, b)
    un = u.copy()
    un[3, 1] = np.nan
    with pytest.raises(pj.InputError, match="u: expected finite direction vectors"):
        pj.fit_polynomial(un, v, b)
    with pytest.raises(pj.InputError, match="u: expected finite direction vectors"):
        bl.fit("ward", un, v, b)


@pytest.mark.parametrize("name", bl.MODELS)
def test_every_baseline_finite_at_degenerate_directions_through_the_fitted_model(name):
    """Every baseline via BaselineFit's call: finite at every hard pair, 0 for zero vectors, scale-free in u, v."""
    f = baseline_fit_at(name, baseline_params(name))
    hu, hv, above = hard_directions()
    out = np.asarray(f(hu, hv))[0]
    assert np.all(np.isfinite(out))
    if name != "zernike":  # the Zernike expansion is a plain polynomial on the disk, not masked
        assert np.all(out[~above] == np.asarray(f(hu, hv))[0][~above])  # deterministic
    np.testing.assert_allclose(np.asarray(f(4.0 * hu, 0.3 * hv)), np.asarray(f(hu, hv)), rtol=1e-10, atol=1e-12)
    u, v = random_hemisphere(5, seed=1)
    assert np.all(np.asarray(f(np.zeros((5, 3)), v)) == 0.0)


def test_cutoff_float32_keeps_every_merl_bin_float64_keeps():
    """Hard case: MERL bin centres lie exactly at 80 degrees; float32 rounding dropped some (tolerance 1e-9)."""
    th, td, pd = pj.data.merl_bin_angles()
    u, v = pj.data.rusinkiewicz_to_directions(th, td, pd)
    near = (np.abs(u[:, 2] - np.cos(np.deg2rad(80))) < 1e-6) | (np.abs(v[:, 2] - np.cos(np.deg2rad(80))) < 1e-6)
    assert near.sum() > 100
    u, v = u[near], v[near]
    k64 = np.asarray(pj.cutoff_mask(jnp.asarray(u, jnp.float64), jnp.asarray(v, jnp.float64)))
    k32 = np.asarray(pj.cutoff_mask(jnp.asarray(u, jnp.float32), jnp.asarray(v, jnp.float32)))
    assert 0 < k64.sum() < k64.size
    assert np.all(k32[k64])  # every bin float64 keeps, float32 keeps
    # float32 may keep a few more: only bins within its resolution (4 eps) of the cutoff cosine
    extra = k32 & ~k64
    gap = np.cos(np.deg2rad(80)) - np.minimum(u[extra, 2], v[extra, 2])
    assert np.all(gap < 4 * np.finfo(np.float32).eps)
