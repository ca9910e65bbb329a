"""The compact model families (polyjax/_compact/families): sizes, bounds over the MERL grid, derivatives, and the
leave-one-out basis of the benchmark."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import polyjax as pj
from benchmarks.learn_compact_basis import learn
from polyjax.internal import (
    COMPACT_FAMILIES,
    COMPACT_TIE,
    CompactBasisFamily,
    choose_compact,
    compact_choice_order,
    compact_fold_ids,
    compact_pack_mask,
    compact_select_columns,
    compact_unpack_mask,
)

MATERIALS = ("chrome", "white-paint")


@pytest.fixture(scope="module")
def merl():
    fit = pj.data.load_merl_nbrdf(list(MATERIALS), subsample=3000, seed=11)
    # every direction pair of a coarse MERL grid (both above the horizon), and near-grazing pairs
    u, v, _, above = pj.data.merl_grid((30, 30, 60))
    rng = np.random.default_rng(0)
    t = np.deg2rad(rng.uniform(85.0, 89.999, (2000, 2)))
    p = rng.uniform(0.0, 2 * np.pi, (2000, 2))
    graze = [np.stack([np.sin(t[:, i]) * np.cos(p[:, i]), np.sin(t[:, i]) * np.sin(p[:, i]), np.cos(t[:, i])], -1)
             for i in (0, 1)]
    return fit, np.concatenate([u[above], graze[0]]), np.concatenate([v[above], graze[1]])


def test_configs_fit_the_budget_and_count_three_channels():
    for fam in COMPACT_FAMILIES.values():
        for budget in (9, 16, 33, 64):
            configs = fam.configs(budget)
            assert all(fam.n_numbers(c) <= budget for c in configs)
            assert set(fam.candidates(budget)) <= set(configs)
    basis, poly = COMPACT_FAMILIES["basis"], COMPACT_FAMILIES["polynomial"]
    assert (11, -1) in basis.configs(33) and (12, -1) not in basis.configs(33) and basis.n_numbers((11, -1)) == 33
    assert basis.n_numbers((7, 1)) == 33 and basis.n_numbers((1, 2)) == 33  # 4 and 10 polynomial terms
    # the polynomial stores, per channel, its 10 coefficients and its components' mean (2), rotation (4), box
    # centre (2) and half-widths (2): 20 numbers, 60 per material
    assert poly.n_numbers(("rusinkiewicz", 3, True)) == 60
    assert poly.configs(33) == [] and ("rusinkiewicz", 3, True) in poly.configs(64)
    # the choice tries the largest k of each degree and its halvings, the largest degree of each variable set
    # (k = 1, the mean row alone, is not a model of a material unlike MERL's mean: never tried)
    assert basis.candidates(33)[:4] == [(11, -1), (6, -1), (3, -1), (2, -1)]
    assert all(k >= 2 for k, _ in basis.candidates(33)) and basis.candidates(5) == []
    assert ("rusinkiewicz", 3, True) in poly.candidates(64) and ("rusinkiewicz", 2, True) not in poly.candidates(64)
    skew = COMPACT_FAMILIES["skew"]
    assert skew.configs(33) == [(10, 1), (9, 2), (8, 3), (6, 5)] and skew.n_numbers((8, 3)) == 33
    assert skew.configs(9) == [] and skew.configs(21) == [(6, 1)]
    assert skew.candidates(33) == [(10, 1), (9, 2)]  # the choice tries m = 1, 2; every m still loads
    # one shape for the three channels: its coefficients, then three offsets and three scales
    shared = COMPACT_FAMILIES["shared"]
    assert shared.configs(33) == [(27, 0, -1), (22, 5, -1), (7, 0, 3)] and shared.n_numbers((7, 0, 3)) == 33
    assert shared.configs(9) == [(3, 0, -1)] and shared.n_numbers((3, 0, -1)) == 9
    assert shared.candidate_chains(33) == [[(27, 0, -1), (22, 5, -1)], [(7, 0, 3)]]
    # terms chosen per material: 22 of the dictionary's 106 columns, the mask in 5 numbers of 24 bits, the colour
    sparse = COMPACT_FAMILIES["sparse"]
    assert sparse.configs(33)[-1] == (22, 106) and sparse.n_numbers((22, 106)) == 33
    assert sparse.candidates(33) == [(22, 106)] and sparse.configs(11) == [] and sparse.configs(12) == [(1, 106)]
    # a basis degree whose largest k is 1 is not tried
    assert (1, 2) in basis.configs(33) and (1, 2) not in basis.candidates(33) and (7, 1) in basis.candidates(33)


def test_padded_program_fits_as_the_configuration_alone(merl):
    """Every configuration of a width shares one compiled fit: zero columns padded, the same coefficients."""
    fit = merl[0]
    fam = COMPACT_FAMILIES["basis"]
    for config in [(2, 1), (6, -1)]:
        key, arrays = fam.program(config)
        assert key == 8
        padded = fam.fit_program(key, arrays, fit.u, fit.v, fit.values, fit.weights, fit.mask, "log")
        alone = fam.fit(config, fit.u, fit.v, fit.values, fit.weights, fit.mask, "log")
        assert np.allclose(np.asarray(fam.unpad(config, padded)), np.asarray(alone), rtol=1e-9, atol=1e-9)
        assert np.all(np.asarray(padded)[..., 6:] == 0)  # both have 6 columns of their own
        y_pad = fam.evaluate_program(key, arrays, padded, fit.u, fit.v)
        assert np.allclose(np.asarray(y_pad), np.asarray(fam.evaluate(config, alone, fit.u, fit.v)), rtol=1e-9)


@pytest.mark.slow  # three more fits compiled
def test_skew_family_fits_a_non_reciprocal_model_the_basis_cannot(merl):
    """Values made by the skew model itself (white paint's 8-row basis fit, its first 3 rows again times
    ``cos theta_u - cos theta_v``: ``f(u, v) != f(v, u)``): the skew fit finds the coefficients again, to rounding;
    the reciprocal basis family of as many numbers cannot (9 % relative error)."""
    fit, _, _ = merl
    skew, basis = COMPACT_FAMILIES["skew"], COMPACT_FAMILIES["basis"]
    c8 = np.asarray(basis.fit((8, -1), fit.u, fit.v, fit.values[1], fit.weights, None, "log"))
    c = jnp.asarray(np.concatenate([c8, c8[:, :3]], -1))
    truth, swapped = (skew.evaluate((8, 3), c, a, b) for a, b in ((fit.u, fit.v), (fit.v, fit.u)))
    assert float(jnp.sqrt(jnp.sum((truth - swapped) ** 2) / jnp.sum(truth ** 2))) > 0.01
    got = skew.fit((8, 3), fit.u, fit.v, truth, fit.weights, None, "log")
    np.testing.assert_allclose(np.asarray(got), np.asarray(c), atol=1e-5)
    recip = basis.evaluate((11, -1), basis.fit((11, -1), fit.u, fit.v, truth, fit.weights, None, "log"), fit.u, fit.v)
    rel = float(jnp.sqrt(jnp.sum((recip - truth) ** 2) / jnp.sum(truth ** 2)))
    assert rel > 0.05, rel


@pytest.mark.parametrize("family, config", [("basis", (11, -1)), ("basis", (7, 1)), ("skew", (8, 3)),
                                            ("polynomial", ("rusinkiewicz", 3, True)), ("shared", (22, 5, -1)),
                                            ("shared", (7, 0, 3)), ("sparse", (22, 106))])
def test_finite_non_negative_bounded_over_the_merl_grid(merl, family, config):
    fit, u, v = merl
    fam = COMPACT_FAMILIES[family]
    params = fam.fit(config, fit.u, fit.v, fit.values, fit.weights, fit.mask, "log")
    y = np.asarray(fam.evaluate(config, params, jnp.asarray(u), jnp.asarray(v)))
    assert y.shape == (len(MATERIALS), 3, u.shape[0])
    assert np.all(np.isfinite(y)) and np.all(y >= 0)
    # bounded: no grazing blow-up far past the measured range of each material
    top = np.asarray(jnp.max(fit.values, axis=(-2, -1)))
    assert np.all(y.max(axis=(-2, -1)) <= 20 * top), (y.max(axis=(-2, -1)), top)
    own = np.asarray(fam.evaluate(config, params, fit.u, fit.v))
    err = np.sqrt(np.mean(np.asarray(pj.log_error(fit.values, own, fit.u, fit.v, fit.weights)) ** 2, -1))
    assert np.all(err < 0.2), err  # a fit, not just a bounded function


@pytest.mark.parametrize("family, config, c0", [
    ("basis", (4, -1), np.random.default_rng(2).normal(size=(3, 4)) * 0.1 + [[1.0, 0, 0, 0]] * 3),
    ("shared", (3, 1, 2), np.concatenate([[1.0, 0.05, -0.05, 0.1], np.random.default_rng(2).normal(size=10) * 0.05,
                                          [0.01, 0.02, 0.0, 0.9, 1.0, 1.1]]))])
def test_gradients_match_finite_differences(family, config, c0):
    fam = COMPACT_FAMILIES[family]
    assert np.shape(c0)[-1] == fam.n_numbers(config) // (3 if family == "basis" else 1)
    rng = np.random.default_rng(1)
    u = rng.normal(size=(6, 3)) * [0.4, 0.4, 0.1] + [0, 0, 1]
    v = rng.normal(size=(6, 3)) * [0.4, 0.4, 0.1] + [0, 0, 1]
    u, v = (jnp.asarray(x / np.linalg.norm(x, axis=-1, keepdims=True)) for x in (u, v))
    c0 = jnp.asarray(c0)

    @jax.jit
    def loss(c, u):
        return jnp.sum(fam.evaluate(config, c, u, v) ** 2)

    g_c, g_u = jax.jit(jax.grad(loss, argnums=(0, 1)))(c0, u)
    h = 1e-6
    i = (1, 2) if c0.ndim == 2 else (2,)
    e = jnp.zeros_like(c0).at[i].set(h)
    assert float(g_c[i]) != 0.0
    assert float(g_c[i]) == pytest.approx(float(loss(c0 + e, u) - loss(c0 - e, u)) / (2 * h), rel=1e-5)
    j = (-1,) if c0.ndim == 1 else (1, 2)  # a channel's scale
    e = jnp.zeros_like(c0).at[j].set(h)
    assert float(g_c[j]) == pytest.approx(float(loss(c0 + e, u) - loss(c0 - e, u)) / (2 * h), rel=1e-5)
    e = jnp.zeros_like(u).at[2, 0].set(h)
    assert float(g_u[2, 0]) == pytest.approx(float(loss(c0, u + e) - loss(c0, u - e)) / (2 * h), rel=1e-4)


def test_leave_one_out_basis_excludes_the_material():
    rng = np.random.default_rng(2)
    names = ("a", "b", "c", "d")
    tables = rng.uniform(0.0, 2.0, (4, 3, 50))
    mass = np.full(50, 1 / 50)
    basis, used = learn(tables, mass, names, exclude=("c",), n_components=3)
    assert used == ("a", "b", "d") and basis.shape == (3, 50)
    fam = CompactBasisFamily(basis, used)
    assert "c" not in fam.trained_on and fam.configs(9) == [(1, -1), (2, -1), (3, -1)]
    # the first row is the mean of the other materials' transformed tables
    assert np.allclose(basis[0], np.log1p(tables[[0, 1, 3]]).reshape(-1, 50).mean(0))
    shipped = COMPACT_FAMILIES["basis"].trained_on
    assert len(shipped) == 100 and set(shipped) == set(pj.data.MERL_NAMES)


@pytest.mark.parametrize("family,budget", [("basis", 6), ("skew", 21), ("shared", 9), ("sparse", 16)])
def test_cross_validation_scores_each_fold_fitted_without_it(merl, family, budget):
    """The choice's held-out errors (every fold fitted at once from shared factorisations) are those of the
    family's own fit on the other folds' samples, scored on the fold's: the root mean square over the folds."""
    fit = merl[0][0]
    fam = COMPACT_FAMILIES[family]
    (config,) = [c for chain in fam.candidate_chains(budget) for c in chain][:1]
    ch = choose_compact(fit, budget, families={family: fam})
    assert (ch.family, ch.config, ch.tried) == (family, config, 1)
    ids = compact_fold_ids(fit.n_samples, 3)
    l2s, logs = [], []
    for k in range(3):
        params = fam.fit(config, fit.u, fit.v, fit.values, fit.weights, fit.mask & (ids != k), "log")
        pred = fam.evaluate(config, params, fit.u, fit.v)
        held = fit.mask & (ids == k)
        for out, metric in ((l2s, pj.l2_error), (logs, pj.log_error)):
            per_channel = np.asarray(metric(fit.values, pred, fit.u, fit.v, fit.weights, mask=held))
            out.append(np.sqrt(np.mean(per_channel ** 2)))
    assert float(ch.l2) == pytest.approx(np.sqrt(np.mean(np.square(l2s))), rel=1e-8)
    assert float(ch.log) == pytest.approx(np.sqrt(np.mean(np.square(logs))), rel=1e-8)
    whole = fam.fit(config, fit.u, fit.v, fit.values, fit.weights, fit.mask, "log")
    assert np.allclose(np.asarray(ch.params), np.asarray(whole), rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("config", [(22, 5, -1), (7, 0, 3)])
def test_shared_fold_fits_are_the_fit_without_the_fold(merl, config):
    """The shared family's fold fits (the basis fit of the channels' mean from shared factorisations, then each
    channel's offset and scale) are its own fit with the fold masked out."""
    fit = merl[0][1]
    fam = COMPACT_FAMILIES["shared"]
    key, arrays = fam.program(config)
    ids = compact_fold_ids(fit.n_samples, 3)
    held = jnp.asarray(ids[None, :] == np.arange(3)[:, None])
    parts = pj.internal.compact_fold_parts(fit.n_samples, 3)
    folds = fam.fit_folds(key, arrays, fit.u, fit.v, fit.values, fit.weights, fit.mask, held, parts, "log")
    assert folds.shape == (3, fam.n_numbers(config))
    for k in range(3):
        alone = fam.fit(config, fit.u, fit.v, fit.values, fit.weights, fit.mask & (ids != k), "log")
        np.testing.assert_allclose(np.asarray(folds[k]), np.asarray(alone), rtol=1e-7, atol=1e-9)


def test_shared_family_finds_a_colour_in_six_numbers(merl):
    """Channels that differ by an offset and a scale of one shape (white paint's 8-row basis fit, offsets
    (0.02, -0.01, -0.01), scales (1.3, 0.9, 0.8)): the shared family of 14 numbers finds them again, to rounding;
    the basis family of 15 numbers (5 rows a channel) cannot (over 1 % relative error)."""
    fit, _, _ = merl
    shared, basis = COMPACT_FAMILIES["shared"], COMPACT_FAMILIES["basis"]
    c8 = np.asarray(basis.fit((8, -1), fit.u, fit.v, fit.values[1], fit.weights, None, "log"))[1]
    d, s = np.array([0.02, -0.01, -0.01]), np.array([1.3, 0.9, 0.8])  # the mean scale 1: the mean is the shape
    shape = jnp.expm1(shared.columns((8, 0, -1), fit.u, fit.v) @ c8)  # the model where its bound is not reached
    ok = shape > 0.05  # and no channel clamped at 0
    assert int(jnp.sum(ok)) > 2000
    truth = d[:, None] + s[:, None] * jnp.where(ok, shape, 0.1)
    got = shared.fit((8, 0, -1), fit.u, fit.v, truth, fit.weights, ok, "log")
    np.testing.assert_allclose(np.asarray(got), np.concatenate([c8, d, s]), atol=1e-6)
    five = basis.evaluate((5, -1), basis.fit((5, -1), fit.u, fit.v, truth, fit.weights, ok, "log"), fit.u, fit.v)
    rel = float(jnp.sqrt(jnp.sum(jnp.where(ok, five - truth, 0.0) ** 2) / jnp.sum(jnp.where(ok, truth, 0.0) ** 2)))
    assert rel > 0.01, rel


def test_sparse_mask_packs_into_numbers_float32_holds():
    """The column mask round-trips through its 24-bit numbers, in float64 and in float32."""
    rng = np.random.default_rng(4)
    chosen = jnp.asarray(rng.uniform(size=(3, 106)) < 0.3)
    words = compact_pack_mask(chosen)
    assert words.shape == (3, 5) and float(jnp.max(words)) < 2.0 ** 24
    for dtype in (jnp.float64, jnp.float32):
        back = compact_unpack_mask(words.astype(dtype), 106)
        np.testing.assert_array_equal(np.asarray(back) > 0.5, np.asarray(chosen))


def _ormp(a, y, k):
    """Order-recursive matching pursuit, written out in numpy: the column whose part orthogonal to those taken
    best explains the residual, ``k`` times."""
    a = a / np.linalg.norm(a, axis=0)
    taken = []
    for _ in range(k):
        q = np.linalg.qr(a[:, taken])[0] if taken else np.zeros((len(y), 0))
        r = y - q @ (q.T @ y)
        perp = a - q @ (q.T @ a)
        n2 = np.sum(perp ** 2, 0)
        score = np.where(n2 > 1e-10, (perp.T @ r) ** 2 / np.maximum(n2, 1e-300), -1.0)
        score[taken] = -2.0
        taken.append(int(np.argmax(score)))
    return sorted(taken)


def test_sparse_selection_is_matching_pursuit_and_finds_a_sparse_truth():
    """The selection in the Gram matrix takes the columns order-recursive matching pursuit takes on the rows
    themselves; on a sparse truth (5 of 40 random columns), exactly its columns."""
    rng = np.random.default_rng(5)
    a = rng.normal(size=(400, 40)) * rng.uniform(0.1, 3.0, 40)
    truth = [3, 11, 17, 29, 38]
    y = a[:, truth] @ rng.uniform(1.0, 2.0, 5)
    got = np.nonzero(np.asarray(compact_select_columns(jnp.asarray(a.T @ a), jnp.asarray(a.T @ y), 5)))[0]
    assert got.tolist() == truth
    noisy = y + rng.normal(size=400) * 2.0
    got = np.nonzero(np.asarray(compact_select_columns(jnp.asarray(a.T @ a), jnp.asarray(a.T @ noisy), 9)))[0]
    assert got.tolist() == _ormp(a, noisy, 9)
    # a zero column is never taken while others remain
    a[:, 7] = 0.0
    got = np.asarray(compact_select_columns(jnp.asarray(a.T @ a), jnp.asarray(a.T @ noisy), 39))
    assert not got[7] and got.sum() == 39


@pytest.mark.parametrize("metric", ["log", "l2"])
def test_sparse_fold_fits_are_the_fit_without_the_fold(merl, metric):
    """Each fold's columns are chosen from the fold Gram matrices of one pass over the samples, and fitted: the
    family's own fit with the fold masked out, mask and all."""
    fit = merl[0][1]
    fam, config = COMPACT_FAMILIES["sparse"], (10, 106)
    key, arrays = fam.program(config)
    ids = compact_fold_ids(fit.n_samples, 3)
    held = jnp.asarray(ids[None, :] == np.arange(3)[:, None])
    parts = pj.internal.compact_fold_parts(fit.n_samples, 3)
    folds = fam.fit_folds(key, arrays, fit.u, fit.v, fit.values, fit.weights, fit.mask, held, parts, metric)
    assert folds.shape == (3, fam.n_numbers(config))
    masks = []
    for k in range(3):
        alone = fam.fit(config, fit.u, fit.v, fit.values, fit.weights, fit.mask & (ids != k), metric)
        np.testing.assert_array_equal(np.asarray(folds[k, :5]), np.asarray(alone[:5]))  # the same columns
        np.testing.assert_allclose(np.asarray(folds[k]), np.asarray(alone), rtol=1e-7, atol=1e-9)
        masks.append(tuple(np.asarray(alone[:5])))
    assert len(set(masks)) > 1 or metric == "l2"  # the folds choose for themselves (not one choice for all)


def test_sparse_gradients_match_finite_differences(merl):
    """A fitted sparse model differentiates in its coefficients, its colour and the directions; the mask's
    numbers have no derivative (a mask, not a value)."""
    fit = merl[0][0]
    fam, config = COMPACT_FAMILIES["sparse"], (6, 106)
    c0 = fam.fit(config, fit.u, fit.v, fit.values, fit.weights, fit.mask, "log")
    rng = np.random.default_rng(1)
    u = rng.normal(size=(6, 3)) * [0.4, 0.4, 0.1] + [0, 0, 1]
    v = rng.normal(size=(6, 3)) * [0.4, 0.4, 0.1] + [0, 0, 1]
    u, v = (jnp.asarray(x / np.linalg.norm(x, axis=-1, keepdims=True)) for x in (u, v))

    @jax.jit
    def loss(c, u):
        return jnp.sum(fam.evaluate(config, c, u, v) ** 2)

    g_c, g_u = jax.jit(jax.grad(loss, argnums=(0, 1)))(c0, u)
    assert np.all(np.asarray(g_c[:5]) == 0.0)
    h = 1e-6
    for i in (6, 11, 16):  # a coefficient, an offset, a scale
        e = jnp.zeros_like(c0).at[i].set(h)
        assert float(g_c[i]) != 0.0
        assert float(g_c[i]) == pytest.approx(float(loss(c0 + e, u) - loss(c0 - e, u)) / (2 * h), rel=1e-5)
    e = jnp.zeros_like(u).at[2, 0].set(h)
    assert float(g_u[2, 0]) == pytest.approx(float(loss(c0, u + e) - loss(c0, u - e)) / (2 * h), rel=1e-4)


def test_choice_order_takes_the_tie_better_on_the_other_metric():
    """Candidates within ``COMPACT_TIE`` of the least held-out error are tied and refitted in the order of their
    error in the other metric; the rest follow by their own error; a non-finite score comes last."""
    inside, outside = 1.0 + 0.9 * COMPACT_TIE, 1.0 + 1.1 * COMPACT_TIE
    primary = [outside, 1.0, inside, np.inf, 1.5]
    secondary = [0.1, 3.0, 2.0, 0.0, 0.5]
    assert compact_choice_order(primary, secondary) == [2, 1, 0, 4, 3]
    # no tie: the order of the metric asked for, whatever the other says
    assert compact_choice_order([2.0, 1.0, 3.0], [0.0, 9.0, 1.0]) == [1, 0, 2]
    # equal scores keep the order they were tried in
    assert compact_choice_order([1.0, 1.0], [5.0, 5.0]) == [0, 1]
    # nothing finite: every candidate tied, by the other metric
    assert compact_choice_order([np.inf, np.inf], [1.0, 0.0]) == [1, 0]
