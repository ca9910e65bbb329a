"""Rusinkiewicz variable sets and the log-space polynomial model f = exp(poly) - eps (polyjax._fit.log)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import polyjax as pj

from _baseline_problems import synthetic_geometry

RUS = ["rusinkiewicz", "rusinkiewicz-phid"]


@pytest.fixture(scope="module")
def geometry():
    return synthetic_geometry(500, seed=4)


def test_rusinkiewicz_variables_are_the_merl_bin_angles():
    """Independent check: the MERL grid's own (theta_h, theta_d, phi_d) bin centres, mapped to directions."""
    th, td, pd = (a[::331] for a in pj.data.merl_bin_angles())
    u, v = pj.data.rusinkiewicz_to_directions(th, td, pd)
    ok = (u[:, 2] > 0) & (v[:, 2] > 0)
    x = np.asarray(pj.explanatory_variables("rusinkiewicz-phid", jnp.asarray(u[ok]), jnp.asarray(v[ok])))
    np.testing.assert_allclose(x[:, 0], th[ok], atol=1e-12)
    np.testing.assert_allclose(x[:, 1], td[ok], atol=1e-12)
    np.testing.assert_allclose(x[:, 2], np.sin(td[ok]) ** 2 * np.cos(2 * pd[ok]), atol=1e-12)
    x2 = np.asarray(pj.explanatory_variables("rusinkiewicz", jnp.asarray(u[ok]), jnp.asarray(v[ok])))
    np.testing.assert_array_equal(x2, x[:, :2])


@pytest.mark.parametrize("variables", RUS)
def test_rusinkiewicz_gradients_finite_at_theta_zero(variables):
    """u = v = n (theta_h = theta_d = 0), u = v (theta_d = 0), h = n (theta_h = 0): finite Jacobians."""
    z = jnp.array([0.0, 0.0, 1.0])
    a = jnp.array([0.3, 0.0, np.sqrt(1 - 0.09)])
    pairs = [(z, z), (a, a), (a, a * jnp.array([-1.0, -1.0, 1.0]))]
    for u, v in pairs:
        ju, jv = jax.jacfwd(lambda p, q: pj.explanatory_variables(variables, p, q), argnums=(0, 1))(u, v)
        gu = jax.jacrev(lambda p, q=v: pj.explanatory_variables(variables, p, q))(u)
        assert np.all(np.isfinite(np.asarray(ju))) and np.all(np.isfinite(np.asarray(jv)))
        assert np.all(np.isfinite(np.asarray(gu)))


def _lobe(u, v):
    """A measured-like BRDF: diffuse plus a narrow Beckmann-like lobe with Fresnel."""
    h = pj.half_vector(u, v)
    t2 = 1.0 / h[:, 2] ** 2 - 1.0
    vh = jnp.sum(v * h, -1)
    return 0.1 + 3.0 * jnp.exp(-t2 / 0.02) * (0.05 + 0.95 * (1 - vh) ** 5) / h[:, 2] ** 4


@pytest.mark.parametrize("variables", RUS)
def test_identity_response_surface_recovers_its_own_form(variables, geometry):
    """Data that is a quadratic in the variables: the full response surface (eq. 2) of degree 2 fits it exactly."""
    u, v = geometry
    x = pj.explanatory_variables(variables, u, v)
    b = 0.3 + 0.5 * x[:, 0] - 0.4 * x[:, 0] ** 2 + 0.2 * x[:, 0] * x[:, 1] + 0.1 * x[:, -1]
    m = pj.fit_polynomial(u, v, b, variables=variables, degree=2, interactions=True, cutoff_deg=None)
    assert float(m.l2) < 1e-12 and int(m.status) == 0
    np.testing.assert_allclose(np.asarray(m(u, v)), np.asarray(b), rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("variables", RUS)
def test_log_fit_recovers_its_own_form(variables, geometry):
    """b = exp(quadratic) - eps: the log-space start is exact and the Gauss-Newton steps keep it."""
    u, v = geometry
    x = pj.explanatory_variables(variables, u, v)
    eps = 1e-7  # below the data's smallest exp(...) ~ 1e-5, so no value is clamped at 0
    b = jnp.exp(0.5 - 6.0 * x[:, 0] ** 2 + 0.3 * x[:, 1] + 0.8 * x[:, 0] * x[:, 1] - 0.2 * x[:, -1]) - eps
    m = pj.fit_log_polynomial(u, v, b[None].repeat(2, 0), variables=variables, degree=2, eps=eps, steps=2)
    assert m.link == "log" and m.eps == eps and m.batch_shape == (2,)
    assert np.all(np.asarray(m.l2) < 1e-10)
    np.testing.assert_allclose(np.asarray(m(u, v))[1], np.asarray(b), rtol=1e-9, atol=1e-12)


def test_log_fit_steps_lower_equation_11(geometry):
    """On data outside the model's form, the reweighted solves reduce the L2 of eq. (11); the reported l2 is it."""
    u, v = geometry
    b = _lobe(u, v)
    ls = []
    for steps in (0, 1, 3):
        m = pj.fit_log_polynomial(u, v, b, variables="rusinkiewicz", degree=3, steps=steps)
        np.testing.assert_allclose(float(m.l2), float(pj.l2_error(b, m(u, v), u, v)), rtol=1e-12)
        ls.append(float(m.l2))
    # the weighted log-space start is already close: the steps gain ~1% here (strictly, not by rounding)
    assert ls[2] <= ls[1] <= ls[0] and ls[2] < (1 - 5e-3) * ls[0], ls
    lin = pj.fit_polynomial(u, v, b, variables="rusinkiewicz", degree=3, interactions=True)
    assert ls[2] < 0.75 * float(lin.l2), (ls, float(lin.l2))  # same degree, same terms: 0.71x here


@pytest.mark.parametrize("variables", RUS)
def test_log_model_is_reciprocal(variables, geometry):
    u, v = geometry
    m = pj.fit_log_polynomial(u, v, _lobe(u, v), variables=variables, degree=3, steps=1)
    np.testing.assert_allclose(np.asarray(m(v, u)), np.asarray(m(u, v)), rtol=1e-10, atol=1e-12)


def test_fit_polynomial_link_option_and_save_load(tmp_path, geometry):
    u, v = geometry
    b = _lobe(u, v)
    a = pj.fit_polynomial(u, v, b, variables="rusinkiewicz", degree=3, interactions=True, link="log", steps=2)
    c = pj.fit_log_polynomial(u, v, b, variables="rusinkiewicz", degree=3, interactions=True, steps=2)
    np.testing.assert_array_equal(np.asarray(a.coefficients), np.asarray(c.coefficients))
    for suffix in (".npz", ".json"):
        back = pj.load_model(pj.save_model(tmp_path / f"m{suffix}", a))
        assert back.link == "log" and back.eps == a.eps
        np.testing.assert_array_equal(np.asarray(back(u, v)), np.asarray(a(u, v)))
    with pytest.raises(pj.InputError, match="link: expected"):
        pj.fit_polynomial(u, v, b, link="sqrt")
    with pytest.raises(pj.InputError, match="eps: expected a positive offset"):
        pj.fit_log_polynomial(u, v, b, eps=0.0)
    with pytest.raises(pj.InputError, match="values: expected finite"):
        pj.fit_log_polynomial(u, v, b.at[3].set(jnp.nan))


def _loss(u, v, b):
    return pj.fit_log_polynomial(u, v, b, variables="rusinkiewicz", degree=3, steps=2).l2


def test_log_fit_jvp_matches_finite_differences(geometry):
    """Forward-mode derivative of the fitted L2 w.r.t. the values (the step choice is locally constant)."""
    u, v = geometry
    b = _lobe(u, v)
    d = jnp.asarray(np.random.default_rng(0).normal(size=b.shape)) * 0.01
    _, t = jax.jvp(lambda y: _loss(u, v, y), (b,), (d,))
    h = 1e-5
    fd = (_loss(u, v, b + h * d) - _loss(u, v, b - h * d)) / (2 * h)
    assert np.isfinite(float(t))
    np.testing.assert_allclose(float(t), float(fd), rtol=1e-5)


def test_log_fit_grad_matches_finite_differences(geometry):
    u, v = geometry
    b = _lobe(u, v)
    g = jax.grad(lambda y: _loss(u, v, y))(b)
    d = jnp.asarray(np.random.default_rng(1).normal(size=b.shape)) * 0.01
    h = 1e-5
    fd = (_loss(u, v, b + h * d) - _loss(u, v, b - h * d)) / (2 * h)
    assert np.all(np.isfinite(np.asarray(g)))
    np.testing.assert_allclose(float(jnp.dot(g, d)), float(fd), rtol=1e-5)


FACTORISATIONS = ("qr", "svd", "eigh", "cholesky", "householder_product", "geqrf", "geqp3")


def _programs_that_solve(fn, *args) -> int:
    """How many programs (the top-level ``jit`` calls of ``fn``'s trace) factorise a matrix: the solves' programs."""

    def solves(jaxpr) -> bool:
        for eqn in jaxpr.eqns:
            if eqn.primitive.name in FACTORISATIONS:
                return True
            for p in eqn.params.values():
                for sub in p if isinstance(p, (list, tuple)) else (p,):
                    inner = getattr(sub, "jaxpr", sub)
                    if hasattr(inner, "eqns") and solves(inner):
                        return True
        return False

    top = jax.make_jaxpr(fn)(*args).jaxpr.eqns
    return sum(1 for eqn in top if "jaxpr" in eqn.params and solves(getattr(eqn.params["jaxpr"], "jaxpr",
                                                                           eqn.params["jaxpr"])))


@pytest.fixture(scope="module")
def three_lanes(geometry):
    """``(u, v, values (3, n), weights (n,), options, the fit of one fit_polynomial call per solve)``: lanes that may
    keep different samples get that fit (here per-lane weights under ``jit``, the same in every lane: traced, their
    zeros are unknown), as the trace's programs show: one program per solve, and the whole sequence in one program
    for the weights shared by shape."""
    u, v = geometry
    lobe = _lobe(u, v)
    b = jnp.stack([lobe, 0.5 * lobe + 0.05, 0.2 + 0.1 * u[:, 0]])
    w = jnp.asarray(np.random.default_rng(2).uniform(0.5, 1.5, b.shape[-1]))
    kw = dict(variables="rusinkiewicz", degree=3, cutoff_deg=70.0)

    def per_lane(lane_w):
        return pj.fit_log_polynomial(u, v, b, weights=lane_w, **kw)

    lane_w = jnp.broadcast_to(w, b.shape)
    assert _programs_that_solve(lambda a: per_lane(a).l2, lane_w) >= 4  # 1 + steps solves, one program each
    assert _programs_that_solve(lambda y: pj.fit_log_polynomial(u, v, y, weights=w, **kw).l2, b) == 1
    return u, v, b, w, kw, jax.jit(per_lane)(lane_w)


@pytest.mark.parametrize("stream", [False, True])
def test_log_fit_shared_program_equals_one_fit_per_solve(monkeypatch, three_lanes, stream):
    """Lanes keeping the same samples run every solve in one program on their shared design (held whole, or streamed
    as for tall data: here from 100 samples on, ``$POLYJAX_STREAM_ROWS``): the fit of one ``fit_polynomial`` call per
    solve (:func:`three_lanes`)."""
    u, v, b, w, kw, per_solve = three_lanes
    monkeypatch.setenv("POLYJAX_STREAM_ROWS", "100" if stream else str(10**9))
    shared = pj.fit_log_polynomial(u, v, b, weights=w, **kw)
    c = np.asarray(per_solve.coefficients)
    np.testing.assert_allclose(np.asarray(shared.coefficients), c, rtol=0, atol=1e-12 * np.abs(c).max())
    np.testing.assert_allclose(np.asarray(shared.l2), np.asarray(per_solve.l2), rtol=1e-12)
    for field in ("rank", "status", "n_used"):
        np.testing.assert_array_equal(np.asarray(getattr(shared, field)), np.asarray(getattr(per_solve, field)))
    assert np.all(np.asarray(shared.l2) < np.asarray(pj.fit_log_polynomial(u, v, b, steps=0, weights=w, **kw).l2))


#: ``$POLYJAX_STREAM_ROWS`` of the tall fits below: 24,000 samples take the lanes' passes of polyjax._fit.lanes as
#: the 352,745 of the DiLiGenT ball do by default (several blocks of rows, a sample of them for the preconditioner)
TALL = {"POLYJAX_STREAM_ROWS": "10000"}


@pytest.fixture(scope="module")
def tall_geometry():
    return tuple(jnp.asarray(a) for a in synthetic_geometry(24_000, seed=7))


def _tall_lanes(u, v, kind):
    """Three lanes whose Gauss-Newton weights differ by large factors: ``"alike"`` (a sharp lobe, a constant, a dim
    broad lobe: one preconditioner serves them all) or ``"opposed"`` (a sharp lobe, its complement, a constant: the
    lanes' own preconditioners are needed, a second pass per solve)."""
    h = pj.half_vector(u, v)
    t2 = 1.0 / h[:, 2] ** 2 - 1.0
    if kind == "alike":
        lobe = _lobe(u, v)
        return jnp.stack([lobe, jnp.full_like(lobe, 0.2), 0.002 * jnp.exp(-t2 / 0.3) + 1e-4])
    lobe = 3.0 * jnp.exp(-t2 / 0.01) + 1e-3
    return jnp.stack([lobe, 3.0 * (1.0 - jnp.exp(-t2 / 0.01)) * jnp.exp(-5.0 * t2) + 1e-3, jnp.full_like(lobe, 0.2)])


@pytest.mark.parametrize("kind", ["alike", "opposed"])
def test_log_fit_on_tall_data_equals_the_dense_solves(tall_geometry, kind, monkeypatch):
    """A concrete tall fit (one preconditioner for every lane and solve, one pass over the held rows per solve) is the
    traced fit's (the design held whole, each lane's solve a QR of its weighted design) to rounding."""
    for key, value in TALL.items():
        monkeypatch.setenv(key, value)
    u, v = tall_geometry
    b = _tall_lanes(u, v, kind)
    kw = dict(variables="rusinkiewicz", degree=4, interactions=True, cutoff_deg=70.0)
    fast = pj.fit_log_polynomial(u, v, b, **kw)
    dense = jax.jit(lambda y: pj.fit_log_polynomial(u, v, y, **kw))(b)
    c = np.asarray(dense.coefficients)
    np.testing.assert_allclose(np.asarray(fast.coefficients), c, rtol=0, atol=1e-11 * np.abs(c).max())
    np.testing.assert_allclose(np.asarray(fast.l2), np.asarray(dense.l2), rtol=1e-11, atol=1e-14)  # 0.2: 1e-16
    for field in ("rank", "status", "n_used", "mean", "rotation", "centre", "halfwidth"):
        np.testing.assert_allclose(np.asarray(getattr(fast, field)), np.asarray(getattr(dense, field)), rtol=1e-12)
    np.testing.assert_allclose(np.asarray(fast.condition), np.asarray(dense.condition), rtol=1e-8)
    assert np.all(np.asarray(fast.status) == 0)


def test_log_fit_on_tall_rank_deficient_data_is_the_dense_fit(monkeypatch):
    """24,000 samples (tall: :data:`TALL`) at 30 distinct direction pairs and 45 terms: no Cholesky factor exists
    (the shared one fails, then each lane's own), each lane falls back to the dense solve: rank 30,
    ``RANK_DEFICIENT``, the traced fit's model to rounding."""
    for key, value in TALL.items():
        monkeypatch.setenv(key, value)
    u, v = synthetic_geometry(30, seed=1)
    u, v = np.tile(u, (800, 1)), np.tile(v, (800, 1))
    h = np.asarray(pj.half_vector(jnp.asarray(u), jnp.asarray(v)))
    b = np.stack([0.2 + np.exp(-(1 / h[:, 2] ** 2 - 1) / 0.1), np.full(len(u), 0.3), 0.1 + 0.5 * h[:, 2]])
    kw = dict(variables="rusinkiewicz", degree=8, interactions=True, cutoff_deg=None)
    fast = pj.fit_log_polynomial(u, v, b, **kw)
    dense = jax.jit(lambda y: pj.fit_log_polynomial(u, v, y, **kw))(jnp.asarray(b))
    assert np.all(np.asarray(fast.status) == pj.RESULTS.RANK_DEFICIENT) and np.all(np.asarray(fast.rank) == 30)
    np.testing.assert_array_equal(np.asarray(fast.rank), np.asarray(dense.rank))
    np.testing.assert_allclose(np.asarray(fast(u[:30], v[:30])), np.asarray(dense(u[:30], v[:30])), rtol=1e-12,
                               atol=1e-13)
