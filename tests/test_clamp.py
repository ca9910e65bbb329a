"""Bounded extrapolation: a model with ``clamp`` evaluates its polynomial at the scaled principal components clamped
to the fitted box ``[-1, 1]^k``: the fitted model inside, the value at the nearest point of the box outside. Every
evaluator honours it (calls, the exported programs, saved files)."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import polyjax as pj

from _baseline_problems import synthetic_geometry
from _problems import band_directions, narrow_lobe


@pytest.fixture(scope="module")
def narrow():
    """Samples with polar angles up to 40 degrees (the fitted range), and pairs at 60-85 degrees (outside it)."""
    u, v = band_directions(3000, 0, 40, 1), band_directions(3000, 0, 40, 2)
    uo, vo = band_directions(200, 60, 85, 3), band_directions(200, 60, 85, 4)
    return u, v, np.stack([narrow_lobe(u, v), 0.5 * narrow_lobe(u, v)]), uo, vo


def _components(model, u, v):
    """The scaled components ``t (lanes, n, k)`` of ``model`` at ``u, v`` from its public fields."""
    x = np.asarray(pj.explanatory_variables(model.variables, jnp.asarray(u), jnp.asarray(v)))
    mean, rot = np.asarray(model.mean), np.asarray(model.rotation)
    centre, hw = np.asarray(model.centre), np.asarray(model.halfwidth)
    return np.stack([((x - mean[i]) @ rot[i] - centre[i]) / hw[i] for i in range(mean.shape[0])])


@pytest.mark.parametrize("variables, degree, link", [("lafortune", 6, "identity"), ("rusinkiewicz", 8, "identity"),
                                                     ("rusinkiewicz", 6, "log")])
def test_clamped_model_is_the_fit_inside_the_box_and_bounded_outside(narrow, variables, degree, link):
    u, v, b, uo, vo = narrow
    kw = dict(variables=variables, degree=degree, interactions=variables == "rusinkiewicz", cutoff_deg=None, link=link)
    free = pj.fit_polynomial(u, v, b, **kw)
    model = pj.fit_polynomial(u, v, b, clamp=True, **kw)
    assert model.clamp and not free.clamp
    np.testing.assert_array_equal(np.asarray(model.coefficients), np.asarray(free.coefficients))  # the same fit
    assert np.all(np.abs(_components(model, u, v)) <= 1 + 1e-12)  # every fitted sample lies in the box
    np.testing.assert_allclose(np.asarray(model(u, v)), np.asarray(free(u, v)), rtol=1e-12, atol=1e-14)
    t = _components(model, uo, vo)
    assert np.all(np.max(np.abs(t), axis=-1) > 1)  # every outside pair lies outside the box
    # outside: the polynomial at the nearest point of the box (from the public basis), bounded by its range there
    inner = np.stack([np.asarray(pj.design_matrix(jnp.asarray(np.clip(ti, -1, 1)), degree, "legendre",
                                                  kw["interactions"])) @ np.asarray(c)
                      for ti, c in zip(t, model.coefficients)])
    expected = np.exp(inner) - model.eps if link == "log" else inner
    np.testing.assert_allclose(np.asarray(model(uo, vo)), expected, rtol=1e-11, atol=1e-13)
    grid = np.stack(np.meshgrid(*[np.linspace(-1, 1, 81)] * t.shape[-1]), -1).reshape(-1, t.shape[-1])
    on_box = np.stack([np.asarray(pj.design_matrix(jnp.asarray(grid), degree, "legendre", kw["interactions"]))
                       @ np.asarray(c) for c in model.coefficients])
    bound = np.exp(on_box.max()) if link == "log" else np.abs(on_box).max()
    assert np.abs(np.asarray(model(uo, vo))).max() <= 1.01 * bound
    unbounded = dataclasses.replace(free, log_top=None)  # the log link's own bound aside (tests/test_log_bound.py)
    assert np.abs(np.asarray(unbounded(uo, vo))).max() > 10 * bound  # the polynomial itself diverges there


def test_clamp_is_kept_by_saved_files_and_exported_programs(narrow, tmp_path):
    """The numpy print of the expression program (the GLSL and Dr.Jit prints' arithmetic) and saved files evaluate the
    clamped model; a log-link model's program evaluates ``exp(poly) - eps``."""
    u, v, b, uo, vo = narrow
    for link in ("identity", "log"):
        model = pj.fit_polynomial(u, v, b[0], "lafortune", 6, cutoff_deg=None, link=link, clamp=True)
        fn = pj.export.numpy_function(model)
        for a, c in ((u, v), (uo, vo)):
            np.testing.assert_allclose(fn(a, c)[:, 0], np.maximum(np.asarray(model(a, c)), 0.0), rtol=1e-12,
                                       atol=1e-14)
        assert "min(" in pj.export.glsl(model) and ("exp(" in pj.export.glsl(model)) == (link == "log")
        for suffix in (".npz", ".json"):
            back = pj.load_model(pj.save_model(tmp_path / f"m-{link}{suffix}", model))
            assert back.clamp and back.link == link
            np.testing.assert_array_equal(np.asarray(back(uo, vo)), np.asarray(model(uo, vo)))
    off = dataclasses.replace(model, clamp=False)
    assert not pj.load_model(pj.save_model(tmp_path / "off.json", off)).clamp


def test_clamped_model_derivatives_match_finite_differences(narrow):
    """Through the fit (d/d values) and the evaluation (d/d u) at pairs inside and outside the box."""
    u, v, b, uo, vo = narrow
    a, c = np.concatenate([u[:3], uo[:3]]), np.concatenate([v[:3], vo[:3]])
    probe = jnp.asarray(np.random.default_rng(5).normal(size=6))

    def objective(values):
        m = pj.fit_polynomial(u, v, values, "rusinkiewicz", 6, interactions=True, cutoff_deg=None, clamp=True)
        return jnp.sum(m(a, c) * probe)

    y = jnp.asarray(b[0])
    d = jnp.asarray(np.random.default_rng(6).normal(size=y.shape))
    h = 1e-5
    fd = (objective(y + h * d) - objective(y - h * d)) / (2 * h)
    np.testing.assert_allclose(float(jnp.dot(jax.grad(objective)(y), d)), float(fd), rtol=1e-6)
    model = pj.fit_polynomial(u, v, y, "rusinkiewicz", 6, interactions=True, cutoff_deg=None, clamp=True)
    at = jax.grad(lambda w, view: model(w, view))
    for i in range(6):
        g = at(jnp.asarray(a[i]), jnp.asarray(c[i]))
        e = jnp.asarray([0.3, -0.2, 0.1])
        fd = (model(a[i] + h * e, c[i]) - model(a[i] - h * e, c[i])) / (2 * h)
        np.testing.assert_allclose(float(jnp.dot(g, e)), float(fd), rtol=1e-5, atol=1e-8)


def test_clamp_options_are_checked():
    u, v = synthetic_geometry(200, seed=3)
    b = np.ones(200)
    with pytest.raises(pj.InputError, match="clamp: only for the Legendre basis"):
        pj.fit_polynomial(u, v, b, "lafortune", 2, basis="monomial", clamp=True)
    with pytest.raises(pj.InputError, match="clamp: expected True or False"):
        pj.fit_polynomial(u, v, b, "lafortune", 2, clamp="yes")
    model = pj.fit_polynomial(u, v, b, "lafortune", 2, basis="monomial")
    with pytest.raises(pj.InputError, match="clamp: only for the Legendre basis"):
        dataclasses.replace(model, clamp=True)
