"""Hard cases at the edges of the inputs: a principal component that is constant up to rounding,
NaN values under an outer ``jit`` with masks or per-lane weights, and direction vectors of extreme length."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import polyjax as pj

from _problems import random_hemisphere
from _robust_problems import baseline_fit_at, baseline_params


@pytest.fixture(scope="module")
def retro():
    """Retro-reflection only (u = v for every sample): Lafortune's X_1 + X_2 = |u|^2 = 1, so the
    second principal component is rounding noise (~1e-16), not exactly 0."""
    u, _ = random_hemisphere(300, seed=0, min_cos=0.2)
    return u, 0.1 + u[:, 2] ** 3


@pytest.mark.parametrize("variables", ["lafortune", "lafortune-anisotropic", "ashikhmin-shirley"])
def test_component_constant_up_to_rounding_flagged_in_both_bases(retro, variables):
    """Before, column equilibration blew the noise component up: Legendre coefficients ~3e10, monomial
    ~1e57 with status OK, and the model exploded off the u = v line. Now the component gets
    halfwidth inf (t = 0): RANK_DEFICIENT, coefficients O(1), both bases the same model everywhere."""
    u, b = retro
    fits = {basis: pj.fit_polynomial(u, u, b, variables=variables, degree=4, basis=basis)
            for basis in ("legendre", "monomial")}
    a, c = random_hemisphere(200, seed=5, min_cos=0.2)
    for m in fits.values():
        assert int(m.status) == pj.RESULTS.RANK_DEFICIENT and np.isinf(float(m.condition))
        assert np.isinf(np.asarray(m.halfwidth)).sum() >= 1
        assert np.abs(np.asarray(m.coefficients)).max() < 10.0
        assert float(m.l2) < 2e-3
        off = np.asarray(m(a, c))  # off the fitted u = v manifold: bounded, like the data
        assert np.all(np.isfinite(off)) and np.abs(off).max() < 10.0
        np.testing.assert_allclose(np.asarray(m(a, a)), 0.1 + a[:, 2] ** 3, atol=0.02)
    np.testing.assert_allclose(np.asarray(fits["monomial"](a, c)), np.asarray(fits["legendre"](a, c)),
                               rtol=1e-7, atol=1e-9)
    # the paper's coefficients (equation (3) in the raw components) drop the constant component too
    m = fits["legendre"]
    z = (pj.explanatory_variables(variables, a, c) - m.mean) @ m.rotation
    beta = m.paper_coefficients()
    np.testing.assert_allclose(np.asarray(pj.evaluate_paper_form(beta, z, 4)), np.asarray(m(a, c)),
                               rtol=1e-9, atol=1e-12)


def test_constant_component_model_survives_save_and_load(retro, tmp_path):
    """The inf halfwidth is stored and restored: the loaded model predicts the same values."""
    u, b = retro
    m = pj.fit_polynomial(u, u, b, degree=4)
    pj.save_model(tmp_path / "m.npz", m)
    back = pj.load_model(tmp_path / "m.npz")
    a, c = random_hemisphere(50, seed=6)
    np.testing.assert_array_equal(np.asarray(back(a, c)), np.asarray(m(a, c)))


@pytest.fixture(scope="module")
def two_lanes():
    u, v = random_hemisphere(100, seed=0)
    b = np.stack([0.1 + u[:, 2] * v[:, 2], 0.2 + u[:, 0] * v[:, 0]])
    bad = b.copy()
    bad[1, 5] = np.nan
    return u, v, b, bad


@pytest.mark.parametrize("how", ["no mask", "mask", "per-lane weights"])
def test_nan_under_outer_jit_flagged_whatever_the_mask(two_lanes, how):
    """nonfinite='error' under jit: the lane with NaN is NONFINITE_VALUES (L2 inf, coefficients 0),
    the other lane exact. With a mask or per-lane weights the NaN sample used to be dropped silently (OK)."""
    u, v, b, bad = two_lanes
    extra = {"no mask": {}, "mask": {"mask": np.ones(b.shape, bool)},
             "per-lane weights": {"weights": np.ones(b.shape)}}[how]
    m = jax.jit(lambda vals: pj.fit_polynomial(u, v, vals, degree=3, **extra))(bad)
    np.testing.assert_array_equal(np.asarray(m.status), [pj.RESULTS.OK, pj.RESULTS.NONFINITE])
    assert np.isinf(float(m.l2[1])) and np.all(np.asarray(m.coefficients[1]) == 0.0)
    ref = pj.fit_polynomial(u, v, b[0], degree=3)
    np.testing.assert_allclose(np.asarray(m.coefficients[0]), np.asarray(ref.coefficients), rtol=1e-10, atol=1e-13)


def test_nonfinite_mask_under_outer_jit_drops_the_sample(two_lanes):
    """nonfinite='mask' under jit: the NaN sample is dropped, the fit equals the concrete masked fit."""
    u, v, _, bad = two_lanes
    m = jax.jit(lambda vals: pj.fit_polynomial(u, v, vals, degree=3, nonfinite="mask"))(bad)
    ref = pj.fit_polynomial(u, v, bad, degree=3, nonfinite="mask")
    np.testing.assert_array_equal(np.asarray(m.status), [pj.RESULTS.OK, pj.RESULTS.OK])
    np.testing.assert_array_equal(np.asarray(m.n_used), np.asarray(ref.n_used))
    np.testing.assert_allclose(np.asarray(m.coefficients), np.asarray(ref.coefficients), rtol=1e-10, atol=1e-13)


@pytest.mark.parametrize(
    "scale, dtype, valid",
    [(1e200, np.float64, True), (1e30, np.float32, True), (1e-11, np.float64, True), (1e-13, np.float64, False),
     (0.0, np.float64, False)],
)
def test_safe_normalize_extreme_lengths(scale, dtype, valid):
    """Lengths whose square overflows (1e200; 1e30 in float32) are normalised, not turned into a
    zero 'unit' vector reported valid; below 1e-12 a vector has no direction (+z, invalid)."""
    w = np.array([0.3, 0.4, 0.866], dtype)
    unit, ok = pj.safe_normalize(jnp.asarray(w * dtype(scale), dtype))
    assert bool(ok) is valid
    want = w / np.linalg.norm(w.astype(np.float64)) if valid else np.array([0.0, 0.0, 1.0])
    np.testing.assert_allclose(np.asarray(unit, np.float64), want, rtol=1e-6 if dtype == np.float32 else 1e-14)


def test_models_scale_free_at_extreme_lengths():
    """The polynomial and every baseline through BaselineFit: f(1e200 u, 1e-11 v) = f(u, v)."""
    u, v = random_hemisphere(40, seed=9)
    b = 0.2 + u[:, 2] * v[:, 2]
    m = pj.fit_polynomial(u, v, b, degree=5)
    np.testing.assert_allclose(np.asarray(m(1e200 * u, 1e-11 * v)), np.asarray(m(u, v)), rtol=1e-12)
    for name in ("cook-torrance", "zernike"):
        f = baseline_fit_at(name, baseline_params(name))
        want = np.asarray(f(u, v))
        np.testing.assert_allclose(np.asarray(f(1e200 * u, 1e-11 * v)), want, rtol=1e-10, atol=1e-12)
        assert np.all(np.isfinite(want))


@pytest.mark.parametrize("dtype", [jnp.float16, jnp.bfloat16])
def test_half_precision_values_fitted_in_float32(dtype):
    """LAPACK has no half precision (the solve crashed inside XLA with NotImplementedError): float16 and
    bfloat16 values are fitted in float32, with the L2 of the float64 fit of the rounded values."""
    u, v = random_hemisphere(100, seed=0)
    b = jnp.asarray(0.1 + u[:, 2] * v[:, 2] + 0.2 * u[:, 0] * v[:, 0], dtype)
    m = pj.fit_polynomial(u, v, b, degree=3)
    ref = pj.fit_polynomial(u, v, np.asarray(b, np.float64), degree=3)
    assert m.coefficients.dtype == jnp.float32 and int(m.status) == pj.RESULTS.OK
    np.testing.assert_allclose(float(m.l2), float(ref.l2), rtol=1e-3, atol=1e-6)


def test_complex_values_rejected_by_both_fitters():
    """Complex values used to lose their imaginary part silently; both fitters name ``values``."""
    import baselines as bl

    u, v = random_hemisphere(30, seed=0)
    b = (0.1 + u[:, 2]).astype(np.complex64)
    with pytest.raises(pj.InputError, match="values: expected real BRDF values, found dtype complex64"):
        pj.fit_polynomial(u, v, b, degree=2)
    with pytest.raises(pj.InputError, match="values: expected real BRDF values, found dtype complex64"):
        bl.fit("ward", u, v, b)
