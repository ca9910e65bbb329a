"""Neural-BRDF MERL networks: statistics of SOURCE.md, the JAX evaluation, the MERL-size fit."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import polyjax as pj

pytestmark = pytest.mark.data

# SOURCE.md of nbrdf_sztrajman2021: valid-region min, max, median of the raw network (R, G, B)
YELLOW_PLASTIC = dict(min=(0.072, 0.061, 0.0085), max=(11.18, 9.98, 8.55), median=(0.091, 0.081, 0.020))


@pytest.fixture(scope="module")
def yellow():
    return pj.data.load_nbrdf("yellow-plastic")


def test_names():
    assert len(pj.data.MERL_NAMES) == 100 == len(set(pj.data.MERL_NAMES))
    assert set(pj.data.TABLE3_MATERIALS) <= set(pj.data.MERL_NAMES)
    assert pj.data.resolve_merl_name("Yellow_Plastic") == "yellow-plastic"


def test_yellow_plastic_statistics(yellow):
    u, v, _, above = pj.data.merl_grid()
    raw = np.asarray(eqx.filter_jit(yellow.raw)(jnp.asarray(u[above]), jnp.asarray(v[above])))
    assert raw.shape == (1_111_432, 3)
    np.testing.assert_allclose(raw.min(0), YELLOW_PLASTIC["min"], rtol=0.02)
    np.testing.assert_allclose(raw.max(0), YELLOW_PLASTIC["max"], rtol=0.01)
    np.testing.assert_allclose(np.median(raw, 0), YELLOW_PLASTIC["median"], rtol=0.03)
    # 76.2 % of the grid is in the valid hemisphere
    assert above.mean() == pytest.approx(0.762, abs=5e-4)


def test_call_masks_clamps_jits_and_vmaps(yellow):
    u = pj.spherical_to_cartesian(jnp.array([0.3, 0.5, 1.2, 0.4]), jnp.array([0.0, 1.0, 2.0, 3.0]))
    v = pj.spherical_to_cartesian(jnp.array([0.4, 0.2, 0.7, 1.7]), jnp.array([3.0, -2.0, 0.5, 0.0]))
    f = jax.jit(lambda m, a, b: m(a, b))(yellow, u, v)
    np.testing.assert_allclose(np.asarray(eqx.filter_jit(yellow)(u, v)), np.asarray(f), rtol=1e-12)
    assert f.shape == (4, 3)
    assert np.all(np.asarray(f[:3]) > 0) and np.all(np.asarray(f[3]) == 0.0)  # v below the horizon
    fv = jax.vmap(yellow)(u, v)
    np.testing.assert_allclose(np.asarray(fv), np.asarray(f), rtol=1e-12)
    # reciprocity of the parametrisation: swapping u and v maps phi_d -> phi_d + pi (same bin value)
    # and isotropy: rotating both about the normal leaves the value unchanged
    rot = jnp.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(np.asarray(yellow(u @ rot.T, v @ rot.T)), np.asarray(f), rtol=1e-5)
    # the model is a pytree: a batch of two networks vmaps over its leaves
    green = pj.data.load_nbrdf("green-latex")
    two = pj.data.NeuralBRDF(*(jnp.stack([a, b]) for a, b in zip(yellow.params, green.params)), name="two")
    out = jax.vmap(lambda m: m(u, v))(two)
    assert out.shape == (2, 4, 3)
    np.testing.assert_allclose(np.asarray(out[0]), np.asarray(f), rtol=1e-12)
    g = jax.grad(lambda x: jnp.sum(yellow(x, v)))(u)
    assert np.all(np.isfinite(np.asarray(g)))


def test_grid_values_match_call_and_subsample_is_reproducible(yellow):
    d = pj.data.load_merl_nbrdf("yellow-plastic", subsample=5000, seed=1)
    assert d.values.shape == (3, 5000) and d.axes == ("channel",) and d.channels == ("R", "G", "B")
    np.testing.assert_allclose(np.asarray(yellow(d.u, d.v)).T, np.asarray(d.values), rtol=1e-4, atol=1e-6)
    d2 = pj.data.load("merl-nbrdf:yellow-plastic", subsample=5000, seed=1)
    np.testing.assert_array_equal(np.asarray(d2.u), np.asarray(d.u))
    d3 = pj.data.load_merl_nbrdf(["yellow-plastic", "green-latex"], subsample=5000, seed=1)
    assert d3.values.shape == (2, 3, 5000) and d3.names == ("yellow-plastic", "green-latex")
    np.testing.assert_allclose(np.asarray(d3.values[0]), np.asarray(d.values), rtol=1e-5, atol=1e-7)
    t3 = pj.data.load("merl-nbrdf:table3", subsample=100)
    assert t3.names == pj.data.TABLE3_MATERIALS


def test_unknown_material():
    with pytest.raises(pj.data.UnknownMaterialError, match="yellow-plastic"):
        pj.data.load("merl-nbrdf:yelow-plastic")
    with pytest.raises(pj.UnknownNameError):
        pj.data.load_nbrdf("not-a-material")


def test_fit_on_all_valid_merl_bins():
    """The core polynomial fit takes the full MERL-size measurements (1.1 M samples x 3 channels) in one call."""
    d = pj.data.load("merl-nbrdf:green-latex")
    assert d.values.shape == (3, 1_111_432)
    model = pj.fit_polynomial(d, variables="lafortune", degree=[0, 5])
    assert model.status.shape == (2, 3) and np.all(np.asarray(model.status) == 0)
    assert np.all(np.asarray(model.n_used) == np.asarray(model.n_used)[0, 0])
    assert int(model.n_used[1, 0]) > 900_000  # the 80-degree cutoff removes the rest
    l2 = np.asarray(model.l2)
    assert np.all(np.isfinite(l2))
    # degree 5 is far better than the best constant (eq. (11) error, green-latex ~0.002 1/sr)
    assert np.all(l2[1] < 0.5 * l2[0])
    assert np.all(l2[1] < 0.005)
