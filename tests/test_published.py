"""The published compact models SGD and ABC: evaluation against the formulas of the data's SOURCE.md, fits."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import baselines as bl
import polyjax as pj

from _baseline_problems import synthetic_geometry

# -- independent numpy evaluation, straight from the formulas (i light, o view, normal +z) ---------------


def _np_frame(i, o):
    h = i + o
    h = h / np.linalg.norm(h, axis=-1, keepdims=True)
    cos_h = h[..., 2]
    cos_d = np.clip(np.sum(i * h, -1), 0.0, 1.0)
    return h, cos_h, cos_d


def np_sgd(row, i, o):
    """SGD with the 11 published parameters of one channel: rhoD, rhoS, alpha, p, f0, f1, kap, lambda, c, k, theta0."""
    rho_d, rho_s, alpha, p, f0, f1, kap, lam, c, k, theta0 = row
    _, cos_h, cos_d = _np_frame(i, o)
    t2 = (1 - cos_h**2) / cos_h**2
    a = alpha + t2 / alpha
    d = kap * np.exp(-a) / (np.pi * a**p * cos_h**4)
    f = f0 - cos_d * f1 + (1 - cos_d) ** 5 * (1 - f0)

    def g1(w):
        with np.errstate(over="ignore"):
            return np.clip(1 + lam * (1 - np.exp(c * np.maximum(0.0, np.arccos(w[..., 2]) - theta0) ** k)), 0, 1)

    val = (rho_d + rho_s * f * d * g1(i) * g1(o) / (i[..., 2] * o[..., 2])) / np.pi
    return np.where((i[..., 2] > 0) & (o[..., 2] > 0), val, 0.0).astype(np.float64)


def np_abc(kd, a_, b, c, ior, i, o):
    h, cos_h, cos_d = _np_frame(i, o)
    d = a_ / (1 + b * (1 - cos_h)) ** c
    g = np.minimum(np.minimum(1, 2 * cos_h * i[..., 2] / np.sum(h * i, -1)),
                   np.minimum(1, 2 * cos_h * o[..., 2] / np.sum(h * o, -1)))
    gg = np.sqrt(ior**2 + cos_d**2 - 1)
    fr = 0.5 * ((gg - cos_d) ** 2 / (gg + cos_d) ** 2) * (
        1 + (cos_d * (gg + cos_d) - 1) ** 2 / (cos_d * (gg - cos_d) + 1) ** 2)
    val = kd / np.pi + fr * d * g / (np.pi * i[..., 2] * o[..., 2])
    return np.where((i[..., 2] > 0) & (o[..., 2] > 0), val, 0.0)


def _read_csv(name, root):
    import csv

    with open(f"{root}/published_fits/{name}_merl.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def _directions(n, seed):
    """Random unit pairs on the upper hemisphere, a quarter near the mirror direction (the glossy peaks)."""
    rng = np.random.default_rng(seed)
    w = rng.normal(size=(2, n, 3))
    w[..., 2] = np.abs(w[..., 2]) + 0.02
    k = n // 4
    w[1, :k] = w[0, :k] * np.array([-1, -1, 1]) + 0.02 * rng.normal(size=(k, 3))
    w[1, :k, 2] = np.abs(w[1, :k, 2]) + 0.02
    w /= np.linalg.norm(w, axis=-1, keepdims=True)
    return w[0], w[1]


def _rel(a, b):
    scale = np.maximum(np.abs(b), 1e-300)
    return np.max(np.where((a == 0) & (b == 0), 0.0, np.abs(a - b) / scale))


@pytest.mark.data
def test_sgd_published_matches_the_source_formulas(data_root):
    rows = _read_csv("sgd", data_root)
    params = bl.published("sgd")
    assert params.shape == (100, 3, 10) and bl.published_materials("sgd")[0] == rows[0]["material"]
    u, v = _directions(400, 0)
    model = jax.jit(jax.vmap(bl.sgd, in_axes=(0, None, None)))
    got = np.asarray(model(jnp.asarray(params.reshape(300, 10)), jnp.asarray(u), jnp.asarray(v))).reshape(100, 3, -1)
    cols = ("rhoD", "rhoS", "alpha", "p", "f0", "f1", "kap", "lambda", "c", "k", "theta0")
    worst = 0.0
    for m, r in enumerate(rows):
        for c, ch in enumerate("rgb"):
            # extended precision: acos near 1 and x^k with k ~ 800 amplify float64 rounding of the reference
            want = np_sgd([np.longdouble(r[f"{k}_{ch}"]) for k in cols], u.astype(np.longdouble),
                          v.astype(np.longdouble))
            worst = max(worst, _rel(got[m, c], want))
    assert worst < 1e-10, worst
    assert np.all(np.isfinite(got)) and np.any(got > 1.0)  # glossy peaks are in the sample


@pytest.mark.data
def test_abc_published_matches_the_source_formulas(data_root):
    rows = _read_csv("abc", data_root)
    params = bl.published("abc")
    assert params.shape == (100, 3, 5)
    u, v = _directions(400, 1)
    model = jax.jit(jax.vmap(bl.abc, in_axes=(0, None, None)))
    got = np.asarray(model(jnp.asarray(params.reshape(300, 5)), jnp.asarray(u), jnp.asarray(v))).reshape(100, 3, -1)
    worst = 0.0
    for m, r in enumerate(rows):
        for c, ch in enumerate("rgb"):
            want = np_abc(float(r[f"kD_{ch}"]), float(r[f"A_{ch}"]), float(r["B"]), float(r["C"]), float(r["ior"]),
                          u, v)
            worst = max(worst, _rel(got[m, c], want))
    assert worst < 1e-10, worst
    np.testing.assert_array_equal(bl.published("abc", "gold-metallic-paint"),
                                  params[bl.published_materials("abc").index("gold-metallic-paint")])


@pytest.mark.data
def test_published_bad_names_are_named():
    with pytest.raises(pj.UnknownNameError, match="published model 'ggx'"):
        bl.published("ggx", "gold-metallic-paint")
    with pytest.raises(pj.InputError, match="material 'gold-plated'"):
        bl.published("sgd", "gold-plated")
    assert bl.published("sgd", ["alum-bronze", "gold_metallic_paint"]).shape == (2, 3, 10)


@pytest.mark.parametrize("name", ["sgd", "abc"])
def test_gradients_finite_at_published_extremes(name):
    """Huge c (1e38), k (~900), tiny p and alpha: values and parameter gradients stay finite."""
    u, v = _directions(200, 2)
    if name == "sgd":
        ps = jnp.asarray([[0.05, 40.0, 2e-5, 1e-14, 6.0, 5.0, 1.4e7, 1e38, 855.0, -0.6],
                          [0.3, 2.0, 0.8, 1.7, 0.03, -1.0, 4.6e-8, 4.8e-8, 5.6, 1.2]])
    else:
        ps = jnp.asarray([[0.0, 5700.0, 8e6, 2.67, 99.9], [0.4, 0.08, 11.2, 0.0235, 1.04]])
    fn = bl.get_model(name).evaluate
    value = jax.jit(fn)  # compiled: op by op, every operation of the model and its derivative compiles on its own
    grad = jax.jit(jax.grad(lambda q: jnp.sum(fn(q, jnp.asarray(u), jnp.asarray(v)))))
    for p in ps:
        f = value(p, jnp.asarray(u), jnp.asarray(v))
        g = grad(p)
        assert np.all(np.isfinite(np.asarray(f))) and np.all(np.isfinite(np.asarray(g)))


TRUE = {"sgd": [0.3, 0.8, 0.05, 0.4, 0.1, 0.02, 2.0, 1e-3, 8.0, 0.3], "abc": [0.3, 2.0, 300.0, 1.2, 1.6]}


@pytest.mark.parametrize("name", ["sgd", "abc"])
def test_fit_recovers_synthetic_data(name):
    """Noise-free data of the model's own form: the multi-start fit reaches L2 ~ 0 and reproduces the values."""
    u, v = synthetic_geometry(600, seed=3)
    p = jnp.asarray(TRUE[name])
    b = bl.get_model(name).evaluate(p, u, v)
    fit = bl.fit(name, u, v, b, n_starts=16, key=jax.random.PRNGKey(1), max_steps=300)
    scale = float(pj.l2_error(b, 0.0 * b, u, v))
    assert float(fit.l2) < 1e-3 * scale, (float(fit.l2), scale)
    np.testing.assert_allclose(np.asarray(fit(u, v))[..., :], np.asarray(b), rtol=0, atol=2e-3 * float(jnp.max(b)))
