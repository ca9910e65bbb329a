"""Tabulating any BRDF callable (fitted model, baseline fit, neural network, a function) into Measurements."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

import polyjax as pj

from _problems import random_hemisphere


@pytest.fixture(scope="module")
def model():
    return pj.fit_polynomial(pj.data.synthetic_default(), variables="lafortune", degree=4)


def test_tabulate_fitted_model_on_given_directions(model):
    u, v = random_hemisphere(300, seed=4)
    d = pj.data.tabulate(model, u=u, v=v, names=pj.data.synthetic_default().names, axes=("material",))
    assert isinstance(d, pj.Measurements) and d.values.shape == (3, 300) and d.axes == ("material",)
    np.testing.assert_allclose(np.asarray(d.values), np.asarray(model(u, v)), rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(np.asarray(d.weights), np.ones(300))
    assert bool(jnp.all(d.mask))
    refit = pj.fit_polynomial(d, variables="lafortune", degree=4)  # other samples, so another PCA: not exact
    zero = pj.l2_error(d.values, 0.0, d.u, d.v)
    assert np.all(np.asarray(refit.l2) < 0.05 * np.asarray(zero))


def _pair_keys(u, v):
    """One byte string per direction pair: (u, v) rounded to 1e-10 (signed zeros made positive)."""
    r = np.ascontiguousarray(np.round(np.concatenate([u, v], axis=1), 10) + 0.0)
    return r.view(np.dtype((np.void, r.itemsize * r.shape[1]))).ravel()


def test_tabulate_rgb_last_callable_on_the_merl_grid():
    def brdf(u, v):  # (..., 3) like NeuralBRDF and the renderer's BRDFs
        c = jnp.clip(u[..., 2] * v[..., 2], 0, None)
        return jnp.stack([0.1 + c, 0.2 * c, 0.3 + 0 * c], axis=-1)

    d = pj.data.tabulate(brdf, grid="merl", subsample=2000, seed=5)
    assert d.values.shape == (3, 2000) and d.channels == ("R", "G", "B") and d.axes == ("channel",)
    u, v, w, above = pj.data.merl_grid()
    uu = np.asarray(d.u)
    # every tabulated pair is a MERL bin centre above the horizon, weighted by the bin's solid angle: each pair is
    # looked up among the bin centres (u, v rounded to 1e-10) by a binary search of their byte keys
    centres = _pair_keys(u[above], v[above])
    order = np.argsort(centres)
    at = np.minimum(np.searchsorted(centres[order], _pair_keys(uu, np.asarray(d.v))), order.size - 1)
    assert np.array_equal(centres[order][at], _pair_keys(uu, np.asarray(d.v)))
    np.testing.assert_allclose(np.asarray(d.weights), w[above][order[at]], rtol=1e-12)
    np.testing.assert_allclose(np.asarray(d.values), np.asarray(brdf(d.u, d.v)).T, rtol=1e-15)
    same = pj.data.tabulate(brdf, grid="merl", subsample=2000, seed=5)
    np.testing.assert_array_equal(np.asarray(same.u), uu)


def test_tabulate_is_differentiable_in_the_model(model):
    u, v = random_hemisphere(50, seed=6)

    def total(m):
        return jnp.sum(pj.data.tabulate(m, u=u, v=v).values ** 2)

    g = eqx.filter_grad(total)(model)
    g_ref = eqx.filter_grad(lambda m: jnp.sum(m(u, v) ** 2))(model)
    assert np.any(np.asarray(g.coefficients) != 0)
    np.testing.assert_allclose(np.asarray(g.coefficients), np.asarray(g_ref.coefficients), rtol=1e-12)


def test_tabulate_baseline_fit_and_bad_input(model):
    import baselines

    u, v = random_hemisphere(120, seed=7)
    d = pj.data.tabulate(model, u=u, v=v)
    fit = baselines.fit("lafortune", d, n_starts=2)
    t = pj.data.tabulate(fit, u=u, v=v)
    np.testing.assert_allclose(np.asarray(t.values), np.asarray(fit(u, v)), rtol=1e-12, atol=1e-15)
    with pytest.raises(pj.InputError, match="grid"):
        pj.data.tabulate(model, grid="cornell")
    with pytest.raises(pj.InputError, match="grid"):
        pj.data.tabulate(model, grid="merl", u=u, v=v)
    with pytest.raises(pj.InputError, match="u and v"):
        pj.data.tabulate(model, u=u)
    with pytest.raises(pj.InputError, match="brdf"):
        pj.data.tabulate(lambda a, b: jnp.zeros((7,)), u=u, v=v)
