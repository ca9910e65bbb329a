"""The polynomial model: Table 1, agreement with an independent solver, recovery, reciprocity, batching."""

import numpy as np
import pytest

import polyjax as pj
from benchmarks.paper.constants import PAPER_TABLE1
from benchmarks.paper.references import numpy_reference_fit

from _problems import SYMMETRIC_SETS, VARIABLE_SETS, curet, polynomial_data, random_hemisphere

PAPER_TABLE1_QUARRY = PAPER_TABLE1["Quarry Tile"]

TABLE2 = tuple(pj.data.TABLE2_SAMPLES)


@pytest.mark.data
def test_table1_quarry_tile_within_15_percent_and_non_increasing():
    d = curet((25,))
    m = pj.fit_polynomial(d.u, d.v, d.values, variables="lafortune", degree=[1, 2, 3, 4, 5, 6])
    l2 = np.asarray(m.l2)[:, 0]
    ratio = l2 / np.asarray(PAPER_TABLE1_QUARRY)
    assert np.all(np.abs(ratio - 1) < 0.15), ratio
    assert np.all(np.diff(l2) <= 1e-12), l2
    assert np.all(np.asarray(m.status) == pj.RESULTS.OK)
    assert np.all(np.asarray(m.n_params)[:, 0] == 2 * np.arange(1, 7) + 1)


@pytest.mark.data
@pytest.mark.parametrize("variables", VARIABLE_SETS)
def test_table2_samples_agree_with_numpy_reference(variables):
    d = curet(TABLE2)
    degrees = list(range(1, 9))
    m = pj.fit_polynomial(d, variables=variables, degree=degrees)
    l2 = np.asarray(m.l2)  # (degree, sample)
    assert l2.shape == (8, 5)
    assert np.all(np.isfinite(l2))
    assert np.all(np.diff(l2, axis=0) <= 1e-12)
    for j in range(5):
        for i, p in enumerate(degrees):
            ref, pred = numpy_reference_fit(d.u, d.v, d.values[j], variables, p)
            assert l2[i, j] == pytest.approx(ref, rel=1e-7)
        np.testing.assert_allclose(np.asarray(m[i, j](d.u, d.v)), pred, rtol=1e-7, atol=1e-9)
    # the reported L2 is exactly the project's metric on the model's predictions
    np.testing.assert_allclose(np.asarray(pj.l2_error(d.values, m[-1](d.u, d.v), d.u, d.v)), l2[-1], rtol=1e-12)


@pytest.mark.parametrize("variables", SYMMETRIC_SETS)
def test_reciprocity_of_symmetric_sets(variables):
    u, v, values, _ = polynomial_data("lafortune", 3)
    m = pj.fit_polynomial(u, v, values + 0.1 * u[:, 2], variables=variables, degree=5)
    a, b = random_hemisphere(300, seed=7)
    np.testing.assert_allclose(np.asarray(m(a, b)), np.asarray(m(b, a)), rtol=1e-12, atol=1e-13)


@pytest.mark.parametrize("variables", SYMMETRIC_SETS)
@pytest.mark.parametrize("basis", ["legendre", "monomial"])
def test_recovers_polynomial_of_its_own_form(variables, basis):
    degree = 4
    u, v, values, beta = polynomial_data(variables, degree)
    m = pj.fit_polynomial(u, v, values, variables=variables, degree=degree, basis=basis, cutoff_deg=None)
    assert float(m.l2) < 1e-10
    np.testing.assert_allclose(m.paper_coefficients(), beta, rtol=1e-8, atol=1e-8)
    np.testing.assert_allclose(np.asarray(m(u, v)), values, atol=1e-10)


def test_paper_coefficients_evaluate_like_the_model():
    u, v = random_hemisphere(300, seed=3)
    values = 0.2 + np.maximum(-u[:, 0] * v[:, 0] + u[:, 2] * v[:, 2], 0) ** 5
    m = pj.fit_polynomial(u, v, values, variables="ashikhmin-shirley", degree=6)
    x = pj.explanatory_variables("ashikhmin-shirley", u, v)
    z = (x - m.mean) @ m.rotation
    np.testing.assert_allclose(
        np.asarray(pj.evaluate_paper_form(m.paper_coefficients(), z, 6)), np.asarray(m(u, v)), rtol=1e-9, atol=1e-11
    )


def test_batched_fit_equals_individual_fits_and_both_code_paths_agree():
    data = pj.data.synthetic_default()
    batched = pj.fit_polynomial(data, variables="ward", degree=[2, 6])
    for j in range(3):
        single = pj.fit_polynomial(data.u, data.v, data.values[j], variables="ward", degree=6)
        np.testing.assert_allclose(np.asarray(batched.l2)[1, j], np.asarray(single.l2), rtol=1e-12)
        np.testing.assert_allclose(np.asarray(batched[1, j].coefficients), np.asarray(single.coefficients), rtol=1e-9,
                                   atol=1e-12)
    # a per-material mask forces the per-lane path; masking nothing must give the shared path's answer
    mask = np.ones(data.values.shape, bool)
    kept = np.asarray(pj.cutoff_mask(data.u, data.v, 80.0))
    first_kept = int(np.argmax(kept))
    mask[0, first_kept] = False
    per_lane = pj.fit_polynomial(data.u, data.v, data.values, variables="ward", degree=6, mask=mask)
    np.testing.assert_allclose(np.asarray(per_lane.l2)[1:], np.asarray(batched.l2)[1, 1:], rtol=1e-10)
    n = int(kept.sum())
    assert np.asarray(per_lane.n_used).tolist() == [n - 1, n, n]


def test_channels_and_materials_batch_dimensions():
    data = pj.data.synthetic_default()
    values = np.stack([data.values, 2 * data.values], axis=1)  # (material, channel, n)
    m = pj.fit_polynomial(data.u, data.v, values, variables="lafortune", degree=3)
    assert m.batch_shape == (3, 2)
    np.testing.assert_allclose(np.asarray(m.l2)[:, 1], 2 * np.asarray(m.l2)[:, 0], rtol=1e-10)
    assert m(data.u[:5], data.v[:5]).shape == (3, 2, 5)


def test_qr_and_svd_methods_agree():
    data = pj.data.synthetic_default()
    a = pj.fit_polynomial(data, variables="ashikhmin-shirley", degree=7, method="qr")
    b = pj.fit_polynomial(data, variables="ashikhmin-shirley", degree=7, method="svd")
    np.testing.assert_allclose(np.asarray(a.l2), np.asarray(b.l2), rtol=1e-10)
    np.testing.assert_allclose(np.asarray(a.coefficients), np.asarray(b.coefficients), rtol=1e-7, atol=1e-10)


def test_interactions_extension_counts_and_improves():
    data = pj.data.synthetic_default()
    plain = pj.fit_polynomial(data, variables="ashikhmin-shirley", degree=4)
    full = pj.fit_polynomial(data, variables="ashikhmin-shirley", degree=4, interactions=True)
    assert int(np.asarray(full.n_params)[0]) == 35  # C(3 + 4, 4)
    assert int(np.asarray(plain.n_params)[0]) == 13  # 3 * 4 + 1
    assert np.all(np.asarray(full.l2) <= np.asarray(plain.l2) + 1e-12)
    assert np.all(np.asarray(full.l2) < 0.99 * np.asarray(plain.l2))


def test_user_registered_variables():
    name = "test-theta-sum"

    def fn(u, v):
        import jax.numpy as jnp

        return jnp.stack([u[..., 2] + v[..., 2], u[..., 2] * v[..., 2]], axis=-1)

    pj.register_variables(name, fn, 2, symmetric=True, description="cos sum, cos product", overwrite=True)
    data = pj.data.synthetic_default()
    m = pj.fit_polynomial(data, variables=name, degree=3)
    assert m.variables == name and np.all(np.isfinite(np.asarray(m.l2)))
    with pytest.raises(pj.InputError, match="symmetric"):
        pj.register_variables("test-asym", lambda u, v: u[..., :1] + 2 * v[..., :1], 1, symmetric=True, overwrite=True)


@pytest.mark.parametrize("suffix", [".npz", ".json"])
def test_save_and_load_agree_exactly(tmp_path, suffix):
    data = pj.data.synthetic_default()
    m = pj.fit_polynomial(data, variables="lafortune", degree=[3, 5])
    path = pj.save_model(tmp_path / f"model{suffix}", m)
    back = pj.load_model(path)
    a, b = random_hemisphere(100, seed=11)
    assert np.array_equal(np.asarray(back(a, b)), np.asarray(m(a, b)))
    assert np.array_equal(np.asarray(back.l2), np.asarray(m.l2))
    assert back.variables == m.variables and back.max_degree == m.max_degree


def test_load_model_rejects_other_files(tmp_path):
    bad = tmp_path / "x.json"
    bad.write_text('{"format": "something else"}')
    with pytest.raises(pj.DataFormatError, match="format"):
        pj.load_model(bad)
    with pytest.raises(pj.DataNotFoundError):
        pj.load_model(tmp_path / "missing.npz")


def test_approximation_error_equation_14_and_16():
    u, v, values, _ = polynomial_data("lafortune", 3)
    exact = pj.approximation_error(u, v, values, "lafortune", 3, sigma2=0.01, cutoff_deg=None)
    # true model inside the model space: no bias, and the variance terms sum to sigma^2 * (kp + 1)
    assert float(exact.delta_max) < 1e-20
    assert float(np.sum(exact.variance)) == pytest.approx(0.01 * 7, rel=1e-9)
    truth = values + np.sin(5 * u[:, 0] * v[:, 0])
    ae = pj.approximation_error(u, v, truth, "lafortune", 3, cutoff_deg=None)
    fitted_l2 = float(pj.fit_polynomial(u, v, truth, variables="lafortune", degree=3, cutoff_deg=None).l2)
    assert float(ae.delta_max) == pytest.approx(float(np.max(np.asarray(ae.bias) ** 2)))
    assert float(ae.delta_max) > 0
    # the weighted variant is the fit polyjax performs: its bias reproduces the fit's L2
    aw = pj.approximation_error(u, v, truth, "lafortune", 3, cutoff_deg=None, weighted=True)
    l2_from_bias = np.sqrt(np.mean((u[:, 2] * np.asarray(aw.bias)) ** 2))
    assert l2_from_bias == pytest.approx(fitted_l2, rel=1e-9)
