"""The OpenPBR Surface and UsdPreviewSurface baselines: their BRDFs against independent numpy implementations of the
reference shaders (tests/_standard_problems.py), reciprocity, energy, parameter recovery from synthetic data of grey
materials, derivatives against finite differences, and clear errors."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _standard_problems import (
    STANDARD_MODELS,
    STANDARD_PARAMS,
    grey_fit,
    hoffman_fresnel,
    openpbr_reference,
    oren_nayar_bsdf,
    usd_preview_reference,
)

import baselines as bl
import polyjax as pj
from baselines import open_pbr_surface, usd_preview_surface

from _baseline_problems import synthetic_geometry


@pytest.fixture(scope="module")
def pairs():
    u, v = synthetic_geometry(120, seed=5)
    return np.asarray(u), np.asarray(v)


OPENPBR_CASES = [
    dict(base_color=0.5, specular_color=0.8, base_metalness=0.3, specular_roughness=0.4, specular_ior=1.6,
         base_diffuse_roughness=0.5),
    dict(base_color=0.9, specular_color=0.6, base_metalness=1.0, specular_roughness=0.2, specular_ior=1.5,
         base_diffuse_roughness=0.0, specular_roughness_anisotropy=0.6),
    dict(base_color=0.2, specular_color=1.0, base_metalness=0.0, specular_roughness=0.7, specular_ior=2.2,
         base_diffuse_roughness=1.0, base_weight=0.7, specular_weight=0.5),
    dict(base_color=0.6, specular_color=0.9, base_metalness=0.5, specular_roughness=0.3, specular_ior=1.4,
         base_diffuse_roughness=0.3, coat_weight=0.8, coat_roughness=0.1, coat_ior=1.6, coat_color=0.7),
    dict(base_color=0.4, specular_color=0.9, base_metalness=0.1, specular_roughness=0.5, specular_ior=1.8,
         base_diffuse_roughness=0.3, coat_weight=1.0, coat_roughness=0.25, coat_ior=2.0, coat_darkening=0.5),
]
USD_CASES = [
    dict(diffuseColor=0.5, metallic=0.3, roughness=0.4, ior=1.6),
    dict(diffuseColor=0.9, metallic=1.0, roughness=0.2, ior=1.5),
    dict(diffuseColor=0.3, useSpecularWorkflow=1, specularColor=0.2, roughness=0.6),
    dict(diffuseColor=0.5, metallic=0.1, roughness=0.5, ior=1.8, clearcoat=0.7, clearcoatRoughness=0.05),
]


@pytest.mark.parametrize("case", range(len(OPENPBR_CASES)))
def test_openpbr_matches_the_materialx_glsl_closures(pairs, case):
    u, v = pairs
    p = OPENPBR_CASES[case]
    ours = np.asarray(jax.jit(open_pbr_surface)(p, u, v))
    np.testing.assert_allclose(ours, openpbr_reference(p, u, v), rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("case", range(len(USD_CASES)))
def test_usd_preview_matches_storms_preview_surface(pairs, case):
    u, v = pairs
    p = USD_CASES[case]
    spec = {k: x for k, x in p.items() if k != "useSpecularWorkflow"}
    ours = np.asarray(jax.jit(lambda q, u, v: usd_preview_surface(
        dict(q, useSpecularWorkflow=p.get("useSpecularWorkflow", 0)), u, v))(spec, u, v))
    np.testing.assert_allclose(ours, usd_preview_reference(p, u, v), rtol=1e-10, atol=1e-12)


def test_special_cases_of_the_closures(pairs):
    """EON is Lambert at zero diffuse roughness; Hoffman's F82 reaches ``F82 * Schlick`` at cos = 1/7 and is
    Schlick's Fresnel for F82 = 1: the reference closures (tests/_standard_problems.py) have these properties, and
    ``open_pbr_surface`` is the reference on the materials that use them (a dielectric base of zero diffuse
    roughness; metals whose F82 tint is white, and tinted)."""
    u, v = pairs
    nl = np.clip(u[:, 2], 1e-8, 1.0)  # the reference clamps the cosines at its EPS
    np.testing.assert_allclose(oren_nayar_bsdf(u, v, 1.0, 0.6, 0.0), 0.6 * nl / np.pi, rtol=1e-7)
    c = np.asarray([1 / 7, 0.3, 0.9])
    schlick = 0.4 + 0.6 * (1 - c) ** 5
    np.testing.assert_allclose(hoffman_fresnel(c, 0.4, 0.5, 1.0, 5.0)[0], 0.5 * schlick[0], rtol=1e-12)
    np.testing.assert_allclose(hoffman_fresnel(c, 0.4, 1.0, 1.0, 5.0), schlick, rtol=1e-12)
    common = dict(specular_roughness=0.35, specular_ior=1.5, base_diffuse_roughness=0.0)
    for p in (dict(common, base_color=0.6, specular_color=0.9, base_metalness=0.0),
              dict(common, base_color=0.4, specular_color=1.0, base_metalness=1.0),
              dict(common, base_color=0.4, specular_color=0.5, base_metalness=1.0)):
        ours = np.asarray(jax.jit(open_pbr_surface)(p, u, v))
        np.testing.assert_allclose(ours, openpbr_reference(p, u, v), rtol=1e-10, atol=1e-12)


def test_reciprocity_where_the_model_is_reciprocal(pairs):
    """UsdPreviewSurface is reciprocal; OpenPBR as MaterialX evaluates it is not (its energy compensation and the
    albedo scaling of the layers below a lobe are taken at the view direction only)."""
    u, v = pairs
    for p in USD_CASES:
        np.testing.assert_allclose(usd_preview_surface(p, u, v), usd_preview_surface(p, v, u), rtol=1e-12)
    for p in OPENPBR_CASES[:2]:
        gap = np.abs(np.asarray(open_pbr_surface(p, u, v)) / np.asarray(open_pbr_surface(p, v, u)) - 1)
        assert 1e-3 < gap.max() < 0.5  # stated: not reciprocal, though close


def _hemisphere(n_theta=160, n_phi=160):
    """Midpoint quadrature of the hemisphere in (theta, phi): directions and weights (sum 2 pi)."""
    t = (np.arange(n_theta) + 0.5) * (0.5 * np.pi / n_theta)
    ph = (np.arange(n_phi) + 0.5) * (2 * np.pi / n_phi)
    tt, pp = np.meshgrid(t, ph, indexing="ij")
    d = np.stack([np.sin(tt) * np.cos(pp), np.sin(tt) * np.sin(pp), np.cos(tt)], -1).reshape(-1, 3)
    w = (np.sin(tt) * (0.5 * np.pi / n_theta) * (2 * np.pi / n_phi)).ravel()
    return jnp.asarray(d), jnp.asarray(w)


#: Largest directional albedo of a white material (colours 1) over the grid and views: the models as their
#: references evaluate them are not exactly energy conserving at oblique views. OpenPBR as MaterialX writes it:
#: 1.075 at 70 degrees (the GLSL clamps l.v to >= 0 in the EON lobe, and the layering uses analytic albedo fits);
#: UsdPreviewSurface: 1.163 at 80 degrees (Storm's ``1 - F`` weighting of the diffuse is not an energy-conserving
#: layering). Measured with this grid; the bounds hold them with a margin of 0.01.
WHITE_BOUND = {"openpbr": 1.085, "openpbr-coat": 1.08, "usd-preview": 1.175, "usd-preview-specular": 1.105}


@pytest.mark.parametrize("name", [pytest.param(k, marks=pytest.mark.slow) if k == "openpbr-coat" else k
                                  for k in WHITE_BOUND])
def test_albedo_at_most_one_on_a_grid_of_parameters(name):
    """Directional albedo ``int f cos`` on a grid of 24 random parameter sets, at views of 0, 30, 60 and 80 degrees:
    at most 1 for colours up to 0.8, and for white at normal view; white materials at oblique views stay under the
    stated bounds. (Roughness 0.3 .. 1: the quadrature resolves lobes of ``alpha >= 0.09``. UsdPreviewSurface's
    clearcoat adds its lobe without taking energy from the layers below, so the clearcoat variant is not tested.)"""
    m = bl.get_model(name)
    d, w = _hemisphere()
    views = jnp.asarray([[np.sin(t), 0.0, np.cos(t)] for t in np.radians([0.0, 30.0, 60.0, 80.0])])
    grid_ = np.array(m.to_params(jnp.asarray(np.random.default_rng(0).uniform(0, np.pi / 2, (24, m.n_params)))))
    names = m.param_names
    colours = [names.index(k) for k in ("base_color", "specular_color", "diffuseColor", "specularColor") if k in names]
    for k in ("specular_roughness", "roughness", "coat_roughness", "clearcoatRoughness"):
        if k in names:
            grid_[:, names.index(k)] = np.maximum(grid_[:, names.index(k)], 0.3)
    grey, white = grid_.copy(), grid_.copy()
    grey[:, colours] *= 0.8
    white[:, colours] = 1.0

    @jax.jit
    def albedo(p):
        return jax.vmap(lambda view: jnp.sum(w * d[:, 2] * m.evaluate(p, d, jnp.broadcast_to(view, d.shape))))(views)

    a = np.asarray(jax.lax.map(albedo, jnp.asarray(np.concatenate([grey, white]))))
    assert np.all(a > 0.0)
    assert np.all(a[:24] <= 1.0), a[:24].max()
    assert np.all(a[24:, 0] <= 1.0 + 1e-3), a[24:, 0].max()
    assert np.all(a[24:] <= WHITE_BOUND[name]), a[24:].max()


# the coat and anisotropic variants run every path of the OpenPBR graph, the clearcoat and specular ones every path
# of UsdPreviewSurface
@pytest.mark.parametrize("name", ["openpbr-coat", pytest.param("openpbr-anisotropic", marks=pytest.mark.slow),
                                  "usd-preview-clearcoat", "usd-preview-specular"])
def test_parameter_derivatives_match_finite_differences(pairs, name):
    u, v = pairs
    m = bl.get_model(name)
    raw = m.to_raw(jnp.asarray(STANDARD_PARAMS[name]))
    f = jax.jit(lambda r: m.evaluate(m.to_params(r), u, v))
    jac = np.asarray(jax.jacfwd(f)(raw))
    h = 1e-6
    fd = np.stack([(np.asarray(f(raw.at[i].add(h))) - np.asarray(f(raw.at[i].add(-h)))) / (2 * h)
                   for i in range(m.n_params)], -1)
    np.testing.assert_allclose(jac, fd, rtol=1e-5, atol=1e-6 * np.abs(fd).max())
    assert np.all(np.abs(jac).max(0) > 0)  # every parameter moves the BRDF


def test_registry_records_and_materials():
    for name in STANDARD_MODELS:
        m = bl.get_model(name)
        assert m.n_params == len(STANDARD_PARAMS[name]) and m.guesses.shape[1] == m.n_params
        p = jnp.asarray(STANDARD_PARAMS[name])
        np.testing.assert_allclose(m.to_params(m.to_raw(p)), p, rtol=1e-9)
        assert set(m.shared_across_channels) < set(m.param_names)
        mat = m.to_material(np.stack([p, p, p]))
        assert mat["model"] == name
        for k, x in zip(m.param_names, p):
            np.testing.assert_allclose(mat[k], [float(x)] * 3 if k not in m.shared_across_channels else float(x))
    mat = bl.get_model("openpbr").to_material(np.tile(STANDARD_PARAMS["openpbr"], (3, 1)))
    assert mat["base_weight"] == 1.0 and mat["specular_weight"] == 1.0 and mat["specular_roughness_anisotropy"] == 0
    assert "coat_weight" not in mat and bl.get_model("openpbr-coat").to_material(
        np.tile(STANDARD_PARAMS["openpbr-coat"], (3, 1)))["coat_color"] == [1.0] * 3
    mat = bl.get_model("usd-preview-specular").to_material(np.tile(STANDARD_PARAMS["usd-preview-specular"], (3, 1)))
    assert mat["useSpecularWorkflow"] == 1 and mat["metallic"] == 0.0


# OpenPBR's fit compiles the largest program of the suite's baselines (about 35 CPU-seconds with the tests' compile
# options): run with the slow tests
@pytest.mark.parametrize("name", [pytest.param("openpbr", marks=pytest.mark.slow), "usd-preview"])
def test_grey_material_parameters_recovered(name):
    """Noise-free R, G, B data of a grey material (the same colour in the three channels): every parameter back
    to 1e-6 and the three channels alike (so the shared ones agree, as a joint fit requires)."""
    m = bl.get_model(name)
    p = jnp.asarray(STANDARD_PARAMS[name])
    fit = grey_fit(name)[3]
    assert bool(jnp.all(fit.success)) and float(jnp.max(fit.l2)) < 1e-8
    np.testing.assert_allclose(fit.params, jnp.broadcast_to(p, (3, m.n_params)), atol=1e-6)
    mat = m.to_material(fit.params)
    np.testing.assert_allclose([mat[k] if k in m.shared_across_channels else mat[k][1] for k in m.param_names], p,
                               atol=1e-6)


def test_bad_parameters_give_clear_errors():
    with pytest.raises(pj.UnknownNameError, match="baseline model 'openpbr-glass'"):
        bl.get_model("openpbr-glass")
    for name in ("openpbr", "usd-preview"):
        m = bl.get_model(name)
        with pytest.raises(pj.InputError, match=r"to_material: expected the \(3, %d\) R, G, B parameters" % m.n_params):
            m.to_material(np.zeros((2, m.n_params)))
        with pytest.raises(pj.InputError, match="to_material: expected finite"):
            m.to_material(np.full((3, m.n_params), np.nan))


@pytest.mark.slow  # a forward derivative of the fit compiled, and two more fits: about a minute on 2 loaded cores
def test_fit_derivative_matches_finite_differences():
    """The fit's implicit derivative (``jax.jvp`` of ``baselines.fit`` w.r.t. the values) against central
    differences of refits, on the grey UsdPreviewSurface material."""
    u, v, values, _ = grey_fit("usd-preview")
    direction = values * jnp.linspace(0.5, 1.5, values.shape[-1]) * jnp.asarray([[1.0], [0.8], [1.2]])

    def params(y):
        return bl.fit("usd-preview", u, v, y, n_starts=6, rtol=1e-10, atol=1e-12).params

    _, tangent = jax.jvp(params, (values,), (direction,))
    h = 1e-4
    fd = (params(values + h * direction) - params(values - h * direction)) / (2 * h)
    np.testing.assert_allclose(tangent, fd, rtol=1e-4, atol=1e-6)
    assert float(jnp.max(jnp.abs(tangent))) > 1e-2
