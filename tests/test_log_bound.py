"""The log link's bound: a log-link fit evaluates ``f = exp(min(P, log_top)) - eps``, ``log_top`` the largest ``P``
at the fitted samples (``PolynomialBRDF.log_top``), so that it never exceeds its largest value at the samples. Every
evaluator honours it (calls, the exported programs, saved files and texture shards), and a stored bound is checked
when read."""

import dataclasses
import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import polyjax as pj

from _problems import band_directions, narrow_lobe


@pytest.fixture(scope="module")
def fitted():
    """A degree-6 log fit (three lanes) to pairs up to 40 degrees, and pairs at 60-85 degrees, where the polynomial
    diverges (no clamp)."""
    u, v = band_directions(2000, 0, 40, 1), band_directions(2000, 0, 40, 2)
    uo, vo = band_directions(200, 60, 85, 3), band_directions(200, 60, 85, 4)
    model = pj.fit_log_polynomial(u, v, _values(u, v), "lafortune", 6, cutoff_deg=None)
    return model, u, v, uo, vo


def _values(u, v):
    return np.stack([narrow_lobe(u, v), 0.5 * narrow_lobe(u, v), 0.25 * narrow_lobe(u, v)])


@pytest.mark.parametrize("shared", [True, False], ids=["one design", "per-lane samples"])
def test_bound_is_the_largest_polynomial_at_the_fitted_samples(fitted, shared):
    """Both fitting paths (the lanes' one design, and a solve per lane when their masks differ) set the bound to the
    largest ``P`` at each lane's fitted samples; at the samples the bound changes nothing, and where ``P`` exceeds
    it the model is ``exp(log_top) - eps``."""
    model, u, v, uo, vo = fitted
    mask = None
    if not shared:
        mask = np.ones((3, u.shape[0]), bool)
        mask[1, :500] = False
        model = pj.fit_log_polynomial(u, v, _values(u, v), "lafortune", 6, cutoff_deg=None, mask=mask)
    assert model.link == "log" and model.log_top.shape == (3,)
    p = np.asarray(model.polynomial(u, v))
    keep = np.ones_like(p, bool) if mask is None else mask
    np.testing.assert_allclose(np.asarray(model.log_top), np.where(keep, p, -np.inf).max(-1), rtol=0, atol=1e-12)
    free = dataclasses.replace(model, log_top=None)
    np.testing.assert_allclose(np.asarray(model(u, v))[keep], np.asarray(free(u, v))[keep], rtol=1e-14)
    top = np.asarray(model.log_top)[:, None]
    po = np.asarray(model.polynomial(uo, vo))
    assert (po > top + 1).any()  # the polynomial diverges beyond the samples
    np.testing.assert_allclose(np.asarray(model(uo, vo)), np.exp(np.minimum(po, top)) - model.eps, rtol=1e-12)
    assert np.asarray(free(uo, vo)).max() > 10 * np.exp(top.max())  # unbounded, it exceeds the data tenfold


def test_bound_is_kept_by_saved_files_shards_and_exported_programs(fitted, tmp_path):
    model, u, v, uo, vo = fitted
    want = np.asarray(model(uo, vo))
    for suffix in (".npz", ".json"):
        back = pj.load_model(pj.save_model(tmp_path / f"m{suffix}", model))
        np.testing.assert_array_equal(np.asarray(back.log_top), np.asarray(model.log_top))
        np.testing.assert_array_equal(np.asarray(back(uo, vo)), want)
    fn = pj.export.numpy_function(model)
    np.testing.assert_allclose(fn(uo, vo).T, want, rtol=1e-12)
    assert pj.export.glsl(model).count("min(") == 3  # one bound per lane
    texture = jax.tree.map(lambda a: jnp.broadcast_to(a, (2, 3) + a.shape), model)
    for fmt in ("npz", "exr"):
        pj.svbrdf.write_texture_shards(tmp_path / fmt, texture, formats=fmt)
        back = pj.svbrdf.read_texture_shards(tmp_path / fmt)
        # npz exact; EXR's float32 pairs within 2^-48 relative (polyjax/svbrdf/_exr.py)
        np.testing.assert_allclose(np.asarray(back.log_top), np.asarray(texture.log_top), rtol=4 * 2.0**-48)
    identity = pj.fit_polynomial(u, v, narrow_lobe(u, v), "lafortune", 3, cutoff_deg=None)
    assert identity.log_top is None
    assert pj.load_model(pj.save_model(tmp_path / "identity.npz", identity)).log_top is None
    # a bounded file is version 3, which a reader of version 2 refuses instead of evaluating it unbounded
    versions = [json.loads(pj.save_model(tmp_path / f"{n}.json", m).read_text())["version"]
                for n, m in (("bounded", model), ("identity", identity))]
    assert versions == [3, 2]


def test_a_file_saved_without_the_bound_loads_unbounded_and_a_bad_bound_is_named(fitted, tmp_path):
    """A model saved before the field existed (no ``log_top``, version 2) loads without a bound; a bound of the
    wrong shape, a NaN or a bound on an identity-link model is a DataFormatError naming the file."""
    model = fitted[0]
    path = pj.save_model(tmp_path / "old.json", dataclasses.replace(model, log_top=None))
    assert json.loads(path.read_text())["version"] == 2
    old = pj.load_model(path)
    assert old.log_top is None and old.link == "log"
    path = pj.save_model(tmp_path / "m.json", model)
    text = json.loads(path.read_text())
    arrays = text["arrays"]
    assert "log_top" in arrays
    wrong = [dict(arrays["log_top"], shape=[2], data=[0.5] * 2), dict(arrays["log_top"], data=[0.5, "NaN", 0.5])]
    for bad, match in zip(wrong, ("shape", "NaN")):
        p = tmp_path / "bad.json"
        p.write_text(json.dumps(dict(text, arrays=dict(arrays, log_top=bad))))
        with pytest.raises(pj.DataFormatError, match=match):
            pj.load_model(p)
    p = tmp_path / "identity.json"
    p.write_text(json.dumps(dict(text, static=dict(text["static"], link="identity"))))
    with pytest.raises(pj.DataFormatError, match="identity link"):
        pj.load_model(p)


def test_bounded_model_derivatives_match_finite_differences(fitted):
    """Through the fit (d/d values) at pairs where the bound acts and where it does not: where it acts the model is
    ``exp(log_top) - eps``, and ``log_top`` moves with the fitted values."""
    model, u, v, uo, vo = fitted
    top = float(model.log_top[0])
    over = np.flatnonzero(np.asarray(model.polynomial(uo, vo))[0] > top + 0.5)[:3]
    under = np.flatnonzero(np.asarray(model.polynomial(u, v))[0] < top - 0.5)[:3]
    assert len(over) == 3 and len(under) == 3
    a, c = np.concatenate([uo[over], u[under]]), np.concatenate([vo[over], v[under]])
    probe = jnp.asarray(np.random.default_rng(5).normal(size=6))

    def objective(values):
        m = pj.fit_log_polynomial(u, v, values, "lafortune", 6, cutoff_deg=None)
        return jnp.sum(m(a, c) * probe)

    y = jnp.asarray(narrow_lobe(u, v))
    d = jnp.asarray(np.random.default_rng(6).normal(size=y.shape))
    h = 1e-6
    fd = (objective(y + h * d) - objective(y - h * d)) / (2 * h)
    np.testing.assert_allclose(float(jnp.dot(jax.grad(objective)(y), d)), float(fd), rtol=1e-5)
