"""Defects a new user ran into (items 5, 6, 7, 8 and 12 of the user report), one test per case, and the one way in
shared by every fitter (traced inputs, one result code, ``throw=`` under ``jit``)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import baselines as bl
import polyjax as pj

from _problems import random_hemisphere


@pytest.fixture(scope="module")
def problem():
    u, v = random_hemisphere(205, seed=3)
    return u, v, 0.1 + u[:, 2] * v[:, 2] + 0.2 * u[:, 0] * v[:, 0]


def test_zernike_order_20_on_205_samples_is_rank_deficient_not_ok(problem):
    u, v, b = problem
    f = bl.fit("zernike", u, v, b, order=20)  # 506 terms, at most 205 samples
    assert int(f.status) == pj.RESULTS.RANK_DEFICIENT and not bool(f.success)
    assert int(bl.fit("zernike", u, v, b, order=8).status) == pj.RESULTS.OK


def test_zernike_absurd_order_is_refused_up_front(problem):
    u, v, b = problem
    with pytest.raises(pj.InputError, match=r"order=40 \(Zernike\): expected at most 820 parameters .* found 3311"):
        bl.fit("zernike", u, v, b, order=40)


def test_absurd_degree_with_interactions_is_refused_with_the_parameter_count(problem):
    u, v, b = problem
    with pytest.raises(pj.InputError, match=r"degree=100, interactions=True.*found 176851 parameters"):
        pj.fit_polynomial(u, v, b, variables="ashikhmin-shirley", degree=100, interactions=True)


def test_empty_input_is_an_input_error():
    with pytest.raises(pj.InputError, match="empty input"):
        pj.fit_polynomial(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))
    with pytest.raises(pj.InputError, match="empty input"):
        bl.fit("ward", np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))


def test_mask_of_wrong_length_names_mask(problem):
    u, v, b = problem
    with pytest.raises(pj.InputError, match=r"mask: expected shape \(205,\) .*found \(5,\)"):
        pj.fit_polynomial(u, v, b, mask=np.ones(5, bool))
    with pytest.raises(pj.InputError, match=r"mask: expected shape \(205,\) .*found \(5,\)"):
        bl.fit("ward", u, v, b, mask=np.ones(5, bool))


def test_weights_message_gives_two_distinct_shapes(problem):
    u, v, b = problem
    with pytest.raises(pj.InputError, match=r"weights: expected shape \(205,\) \(samples"):
        pj.fit_polynomial(u, v, b, weights=np.ones(204))
    with pytest.raises(pj.InputError, match=r"weights: expected shape \(205,\) or \(2, 205\)"):
        pj.fit_polynomial(u, v, np.stack([b, b]), weights=np.ones(204))


def test_l2_error_shape_mismatch_names_predicted(problem):
    u, v, b = problem
    with pytest.raises(pj.InputError, match=r"predicted: expected a shape that broadcasts with values' \(205,\)"):
        pj.l2_error(b, b[:-1], u, v)


def test_model_call_with_mismatched_directions_names_u_and_v(problem):
    u, v, b = problem
    m = pj.fit_polynomial(u, v, b, degree=2)
    with pytest.raises(pj.InputError, match=r"u and v: expected shapes that broadcast together"):
        m(u, v[:3])


def test_overflowing_l2_is_flagged_nonfinite_not_ok(problem):
    u, v, b = problem
    m = pj.fit_polynomial(u, v, b * 1e300, degree=3)
    assert not np.isfinite(float(m.l2)) and int(m.status) == pj.RESULTS.NONFINITE


def test_one_result_code_for_every_fitter():
    assert [(r.name, int(r)) for r in pj.RESULTS] == [
        ("OK", 0), ("RANK_DEFICIENT", 1), ("NO_SAMPLES", 2), ("NONFINITE", 3), ("MAX_STEPS", 4), ("FAILED", 5)]
    assert pj.RESULTS.RANK_DEFICIENT.message.startswith("the weighted design")
    assert "RESULTS" in pj.__all__ and not {"Result", "FitStatus"} & set(pj.__all__)
    assert "BaselineStatus" not in bl.__all__
    # the former names: the same enumeration (and code 3 under its former second name), with a warning
    for get in (lambda: pj.Result, lambda: pj.FitStatus, lambda: bl.BaselineStatus):
        with pytest.warns(DeprecationWarning, match="use polyjax.RESULTS"):
            assert get() is pj.RESULTS
    with pytest.warns(DeprecationWarning, match="use RESULTS.NONFINITE"):
        assert pj.RESULTS.NONFINITE_VALUES is pj.RESULTS.NONFINITE
    with pytest.warns(DeprecationWarning, match="use RESULTS.RANK_DEFICIENT"):
        assert pj.RESULTS.rank_deficient is pj.RESULTS.RANK_DEFICIENT


def test_baselines_fit_under_jit_prepares_traced_inputs(problem):
    u, v, b = problem
    eager = bl.fit("ward", u, v, b, n_starts=2)
    jitted = jax.jit(lambda y: bl.fit("ward", u, v, y, n_starts=2).l2)(jnp.asarray(b))
    np.testing.assert_allclose(float(jitted), float(eager.l2), rtol=1e-10)


def test_throw_raises_under_jit_and_eagerly_names_the_first_bad_lane(problem):
    u, v, b = problem
    y = np.stack([b[:10], b[:10]])
    with pytest.raises(pj.FitError, match=r"2 of 2 fits are rank-deficient \(first at batch index \(0,\)"):
        pj.fit_polynomial(u[:10], v[:10], y, degree=15, cutoff_deg=None, throw=True)
    fn = jax.jit(lambda y: pj.fit_polynomial(u[:10], v[:10], y, degree=15, cutoff_deg=None, throw=True).l2)
    with pytest.raises((eqx.EquinoxRuntimeError, jax.errors.JaxRuntimeError), match="RANK_DEFICIENT"):
        jax.block_until_ready(fn(jnp.asarray(y)))
    ok = jax.jit(lambda y: pj.fit_polynomial(u, v, y, degree=2, throw=True).l2)(jnp.asarray(b))
    assert np.isfinite(float(ok))


def test_shared_mask_of_shape_n_takes_the_shared_design_path(problem):
    u, v, b = problem
    mask = np.ones(205, bool)
    mask[:20] = False
    inp, _ = pj.internal.prepare_inputs("test", u, v, np.stack([b, 2 * b]), mask=mask)
    assert inp.shared and inp.mask.shape == (1, 205)
    m = pj.fit_polynomial(u, v, np.stack([b, 2 * b]), mask=mask, degree=3)
    ref = pj.fit_polynomial(u[20:], v[20:], np.stack([b, 2 * b])[:, 20:], degree=3)
    np.testing.assert_allclose(np.asarray(m.l2), np.asarray(ref.l2), rtol=1e-10)
