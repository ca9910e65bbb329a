"""Hard case: optimiser trouble in the baselines. Starts that overflow to NaN/inf loss, starts on the
parameter bounds, far starts, step limits: reported through RESULTS, never selected when
non-finite, and parameters never NaN."""

import jax.numpy as jnp
import numpy as np
import pytest

import baselines as bl
import polyjax as pj

from _baseline_problems import TRUE_PARAMS, synthetic_geometry

NAME = "cook-torrance"


@pytest.fixture(scope="module")
def problem():
    u, v = synthetic_geometry(150, seed=4)
    m = bl.get_model(NAME)
    return u, v, m.evaluate(jnp.asarray(TRUE_PARAMS[NAME]), u, v), m


def test_best_of_starts_never_picks_a_nan_or_inf_start(problem):
    """Starts at raw 1e200 / 1e154 overflow (rho = raw^2 = inf): loss NaN/inf, flagged NONFINITE, not chosen,
    even when listed first and with a worse finite start beside them."""
    u, v, y, m = problem
    good = m.to_raw(jnp.asarray(TRUE_PARAMS[NAME])) + 0.3
    starts = jnp.stack([jnp.full((4,), 1e200), good, jnp.array([1e154, 1e154, 0.5, 0.5])])
    f = bl.fit(NAME, u, v, y, starts=starts, max_steps=60, refine=None)
    sl2, ss = np.asarray(f.start_l2), np.asarray(f.start_status)
    assert np.isinf(sl2[[0, 2]]).all() and np.all(ss[[0, 2]] == pj.RESULTS.NONFINITE)
    assert int(f.best_start) == 1 and bool(f.success) and float(f.l2) < 1e-8
    np.testing.assert_allclose(np.asarray(f.params), TRUE_PARAMS[NAME], rtol=1e-5)


def test_every_start_nonfinite_reported_and_parameters_not_nan(problem):
    u, v, y, _ = problem
    # three starts and 60 steps, as above, so that the compiled fit of the test above serves (the steps are never
    # taken: every start is non-finite from the outset)
    f = bl.fit(NAME, u, v, y, starts=jnp.full((3, 4), 1e200), max_steps=60, refine=None)
    assert int(f.status) == pj.RESULTS.NONFINITE and not bool(f.success)
    assert not np.any(np.isnan(np.asarray(f.params))) and np.isinf(float(f.l2))


def test_start_exactly_on_the_bounds_stalls_and_multistart_recovers(problem):
    """raw = 0 puts rho_d = rho_s = 0 and m at its lower bound, where every transform's derivative
    vanishes: a stationary point. LM stops there (poor L2); with the generated starts added the
    fit recovers the true parameters."""
    u, v, y, m = problem
    # three starts in each fit, as in the tests above, so that one compiled fit serves them all: the edge start
    # three times (each run stalls at the same point), then the edge start and two generated starts
    edge = jnp.zeros((1, 4))
    f = bl.fit(NAME, u, v, y, starts=jnp.tile(edge, (3, 1)), max_steps=60, refine=None)
    assert np.isfinite(float(f.l2)) and float(f.l2) > 0.1
    gen = bl.initial_guesses(NAME, u, v, y, n_starts=2)
    g = bl.fit(NAME, u, v, y, starts=jnp.concatenate([edge, gen], axis=0), max_steps=60, refine=None)
    assert int(g.best_start) != 0 and float(g.l2) < 1e-8


def test_far_start_and_step_limit_reported_as_max_steps(problem):
    """A start 1e6 times too bright with three steps (and no finishing steps at the range limits):
    MAX_STEPS, success False, finite parameters and L2."""
    u, v, y, m = problem
    far = m.to_raw(jnp.array([1e5, 1e5, 2.9, 0.999]))[None]
    f = bl.fit(NAME, u, v, y, starts=far, max_steps=3, refine=None, limit_steps=0)
    assert int(f.status) == pj.RESULTS.MAX_STEPS and not bool(f.success)
    assert np.all(np.isfinite(np.asarray(f.params))) and np.isfinite(float(f.l2))


@pytest.mark.parametrize("backend, refine", [("optimistix", 1), ("optimistix", 2), ("jaxopt", 1)])
def test_best_of_starts_skips_nonfinite_starts_on_both_backends_and_in_the_two_stage_path(problem, backend, refine):
    """The same overflowing starts through the staged run (every start a few steps, then the
    best one (the default) or two refined) on both backends: the finite start is kept, the others are NONFINITE
    with L2 inf."""
    u, v, y, m = problem
    good = m.to_raw(jnp.asarray(TRUE_PARAMS[NAME])) + 0.3
    starts = jnp.stack([jnp.full((4,), 1e200), good, jnp.array([1e154, 1e154, 0.5, 0.5])])
    f = bl.fit(NAME, u, v, y, starts=starts, max_steps=60, refine=refine, backend=backend)
    sl2, ss = np.asarray(f.start_l2), np.asarray(f.start_status)
    assert np.isinf(sl2[[0, 2]]).all() and np.all(ss[[0, 2]] == pj.RESULTS.NONFINITE)
    assert int(f.best_start) == 1 and bool(f.success) and float(f.l2) < 1e-8
    assert np.all(np.isfinite(np.asarray(f.params)))


@pytest.mark.parametrize("name, params, limit", [
    ("ashikhmin-shirley", (0.3, 0.5, 0.1, 1.0), [False, False, True, True]),  # n at its lower limit, F0 = 1
    ("cook-torrance", (0.3, 0.05, 0.3, 1.0), [False, False, False, True]),  # F0 = 1
])
def test_optimum_on_a_range_limit_converges_and_is_flagged(name, params, limit):
    """Data whose best parameters lie on a limit of their range: Gauss-Newton alone creeps towards it
    (the sin^2 transform's Jacobian column vanishes there) and used to end at the step limit; the fit
    puts the parameter on the limit, converges, recovers the parameters and reports ``at_limit``."""
    u, v = synthetic_geometry(300, seed=7)
    y = bl.get_model(name).evaluate(jnp.asarray(params), u, v)
    f = bl.fit(name, u, v, y, n_starts=8)
    assert bool(f.success) and int(f.status) == pj.RESULTS.OK, (int(f.status), int(f.steps))
    assert float(f.l2) < 1e-6 * float(jnp.sqrt(jnp.mean(y * y)))
    np.testing.assert_allclose(f.params, params, rtol=1e-3, atol=1e-6)
    assert np.asarray(f.at_limit).tolist() == limit


@pytest.mark.data
def test_curet_fits_at_range_limits_converge():
    """Real cases: CUReT samples whose Ashikhmin-Shirley fit (F0 -> 1, n -> 0.1) used to stop at the step
    limit now converge, with the limited parameters flagged, at an L2 no worse than a run given 3x the steps."""
    import polyjax as pj

    data = pj.data.load_curet(samples=[6, 7, 13, 19, 22])
    f = bl.fit("ashikhmin-shirley", data)
    assert np.all(np.asarray(f.success)), np.asarray(f.status)
    at = np.asarray(f.at_limit)
    assert np.all(at.any(axis=-1)) and not at[:, :2].any()  # F0 or n on a limit, albedos never
    long = bl.fit("ashikhmin-shirley", data, max_steps=300)
    assert np.all(np.asarray(f.l2) <= np.asarray(long.l2) * (1 + 1e-4))
