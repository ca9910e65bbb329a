"""The standard material models (glTF 2.0 metallic-roughness and its extensions, Mitsuba 3's principled BRDF):
evaluation against independent implementations (the glTF specification's formulas written here in numpy,
Mitsuba's own ``principled`` and ``roughconductor`` plugins), reciprocity, energy, the joint R, G, B fit
(parameter recovery, layout, derivatives against finite differences) and its errors."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import baselines as bl
import polyjax as pj

from _baseline_problems import STANDARD_PARAMS, synthetic_geometry
from _robust_problems import baseline_fit_at

#: per-channel base colours of the synthetic materials
COLOURS = np.array([0.2, 0.5, 0.8])
TIGHT = dict(n_starts=6, rtol=1e-12, atol=1e-14, max_steps=200)


def _hemi(n, seed):
    rng = np.random.default_rng(seed)
    w = rng.normal(size=(n, 3))
    w[:, 2] = np.abs(w[:, 2]) + 0.05
    return w / np.linalg.norm(w, axis=1, keepdims=True)


def _rgb_params(name, colours=COLOURS):
    """``(3, P)``: the problem's shared parameters with a base colour per channel."""
    p = np.tile(np.asarray(STANDARD_PARAMS[name], float), (3, 1))
    p[:, 0] = colours
    return p


def _evaluate(name, params, u, v):
    """``(L, n)``: the model at ``params (L, P)`` (one compiled call)."""
    return np.asarray(_evaluate_jit(name, jnp.asarray(params, float), jnp.asarray(u), jnp.asarray(v)))


@functools.partial(jax.jit, static_argnames="name")
def _evaluate_jit(name, params, u, v):
    m = bl.get_model(name)
    return jax.vmap(lambda q: m.evaluate(q, u, v))(params)


# --- the glTF specification's formulas, written out independently ------------------------------------------------


def _spec_gltf(bc, metallic, roughness, u, v, specular=1.0, ior=1.5, strength=0.0, rotation=0.0):
    """Appendix B.3.5's full code with KHR_materials_specular's dielectric_fresnel (white specularColor),
    KHR_materials_ior's f0 and KHR_materials_anisotropy's D_GGX_anisotropic / V_GGX_anisotropic (unclamped)."""
    h = (u + v) / np.linalg.norm(u + v, axis=-1, keepdims=True)
    n_l, n_v, n_h, v_h = u[:, 2], v[:, 2], h[:, 2], np.abs(np.sum(v * h, -1))
    t = np.array([np.cos(rotation), np.sin(rotation), 0.0])
    b = np.cross([0.0, 0.0, 1.0], t)
    alpha = roughness**2
    at, ab = alpha + (1 - alpha) * strength**2, alpha
    a2 = at * ab
    w2 = a2 / np.sum(np.stack([ab * h @ t, at * h @ b, a2 * n_h]) ** 2, 0)
    d = a2 * w2**2 / np.pi
    ggxv = n_l * np.linalg.norm(np.stack([at * v @ t, ab * v @ b, n_v]), axis=0)
    ggxl = n_v * np.linalg.norm(np.stack([at * u @ t, ab * u @ b, n_l]), axis=0)
    specular_brdf = 0.5 / (ggxv + ggxl) * d
    fresnel_w = (1 - v_h) ** 5
    f0 = ((ior - 1) / (ior + 1)) ** 2
    dielectric_fresnel = f0 * specular + (specular - f0 * specular) * fresnel_w
    dielectric_brdf = (1 - dielectric_fresnel) * bc / np.pi + dielectric_fresnel * specular_brdf
    metal_brdf = (bc + (1 - bc) * fresnel_w) * specular_brdf
    return (1 - metallic) * dielectric_brdf + metallic * metal_brdf


@pytest.mark.parametrize("name", ["gltf-pbr", "gltf-pbr-specular", "gltf-pbr-anisotropic"])
def test_gltf_equals_the_specification_formulas(name):
    u, v = _hemi(200, 0), _hemi(200, 1)
    rng = np.random.default_rng(2)
    for _ in range(3):
        p = np.asarray(STANDARD_PARAMS[name], float)
        p[:3] = rng.uniform([0, 0, 0.05], [1, 1, 1])
        extra = {}
        if name == "gltf-pbr-specular":
            p[3:] = rng.uniform([0, 1.0], [1, 2.5])
            extra = dict(specular=p[3], ior=p[4])
        elif name == "gltf-pbr-anisotropic":
            p[3:] = rng.uniform([0, 0], [1, np.pi])
            extra = dict(strength=p[3], rotation=p[4])
        ours = _evaluate(name, p[None], u, v)[0]
        np.testing.assert_allclose(ours, _spec_gltf(p[0], p[1], p[2], u, v, **extra), rtol=1e-12)


def test_gltf_metal_limit_against_mitsuba_roughconductor():
    """glTF's metal with baseColor 1 (F = 1) against Mitsuba's ``roughconductor`` (GGX, ``material="none"``,
    F = 1): the same GGX ``D``; Mitsuba's separable Smith ``G1(u) G1(v)`` against glTF's height-correlated
    ``1 / (1 + Lambda(u) + Lambda(v))`` (Heitz 2014), the ratio computed here."""
    pytest.importorskip("mitsuba")
    from polyjax.render import mitsuba_bsdf_eval

    u, v = _hemi(60, 3), _hemi(60, 4)
    roughness = 0.5
    alpha = roughness**2
    theirs = mitsuba_bsdf_eval({"type": "roughconductor", "distribution": "ggx", "alpha": alpha,
                                "material": "none"}, u, v)[:, 0]
    ours = _evaluate("gltf-pbr", [[1.0, 1.0, roughness]], u, v)[0]
    lam = lambda c: 0.5 * (np.sqrt(1 + alpha**2 * (1 - c**2) / c**2) - 1)  # noqa: E731
    g_sep = 1 / ((1 + lam(u[:, 2])) * (1 + lam(v[:, 2])))
    g_hc = 1 / (1 + lam(u[:, 2]) + lam(v[:, 2]))
    np.testing.assert_allclose(ours, theirs * g_hc / g_sep, rtol=2e-5)  # Mitsuba evaluates in float32


@pytest.mark.parametrize("params", [
    dict(roughness=0.3, metallic=0.0, specular=0.5, anisotropic=0.0),
    dict(roughness=0.5, metallic=0.7, specular=0.2, anisotropic=0.6),
    dict(roughness=0.1, metallic=1.0, specular=0.9, anisotropic=0.0),
])
def test_principled_equals_mitsuba_principled_eval(params):
    pytest.importorskip("mitsuba")
    from polyjax.render import mitsuba_bsdf_eval

    u, v = _hemi(60, 5), _hemi(60, 6)
    bsdf = {"type": "principled", "base_color": {"type": "rgb", "value": COLOURS.tolist()}, **params}
    theirs = mitsuba_bsdf_eval(bsdf, u, v)
    p = np.array([[c, params["roughness"], params["metallic"], params["specular"], params["anisotropic"]]
                  for c in COLOURS])
    ours = _evaluate("principled-anisotropic", p, u, v).T
    np.testing.assert_allclose(ours, theirs, rtol=3e-6)  # Mitsuba evaluates in float32


@pytest.mark.parametrize("name", list(STANDARD_PARAMS))
def test_reciprocal(name):
    u, v = _hemi(100, 7), _hemi(100, 8)
    p = _rgb_params(name)
    np.testing.assert_allclose(_evaluate(name, p, u, v), _evaluate(name, p, v, u), rtol=1e-12)


def _albedo(name, params, view_deg, n=256):
    """Directional albedo ``int f(u, v) cos(theta_u) du`` by the midpoint rule in (cos theta, phi)."""
    mu = (np.arange(n) + 0.5) / n
    phi = (np.arange(2 * n) + 0.5) / (2 * n) * 2 * np.pi
    mu, phi = np.meshgrid(mu, phi, indexing="ij")
    s = np.sqrt(1 - mu**2)
    u = np.stack([s * np.cos(phi), s * np.sin(phi), mu], -1).reshape(-1, 3)
    out = []
    for t in np.radians(view_deg):
        v = np.broadcast_to([np.sin(t), 0.0, np.cos(t)], u.shape)
        out.append((_evaluate(name, params, u, v) * u[:, 2]).sum(-1) * (1.0 / n) * (2 * np.pi / (2 * n)))
    return np.asarray(out)


def _white(name, roughness, metallic):
    """One channel's parameters of a white material (the problem's other parameters)."""
    m = bl.get_model(name)
    p = np.asarray(STANDARD_PARAMS[name], float)
    names = list(m.param_names)
    p[0] = 1.0
    p[names.index("roughness" if "roughness" in names else "roughnessFactor")] = roughness
    p[names.index("metallic" if "metallic" in names else "metallicFactor")] = metallic
    return p[None]


@pytest.mark.parametrize("name, dielectric_max", [("gltf-pbr", 1.23), ("gltf-pbr-specular", 1.23),
                                                  ("principled", 1.32)])
def test_energy_albedo(name, dielectric_max):
    """Directional albedo of white materials, roughness 0.3, 0.6, 1 at views of 0, 45, 80 degrees. The metals
    (single-scattering GGX) reflect at most what they receive. The dielectric mixes of both specifications do not
    conserve energy at grazing views: glTF's ``fresnel_mix`` weights the Lambertian base by ``1 - F(v.h)`` per
    pair of directions, not by the specular lobe's albedo (white, roughness 0.3, 80 degrees: 1.221), and Burley's
    diffuse adds its retro-reflection (roughness 1, 80 degrees: 1.311; 1.05 at normal view); glTF's is at most 1
    at normal view."""
    views = [0.0, 45.0, 80.0]
    for roughness in (0.3, 0.6, 1.0):
        metal = _albedo(name, _white(name, roughness, 1.0), views)
        assert np.all(metal <= 1.0) and np.all(metal > 0.3), (roughness, metal)
        dielectric = _albedo(name, _white(name, roughness, 0.0), views)
        assert np.all(dielectric <= dielectric_max) and np.all(dielectric > 0.9), (roughness, dielectric)
        if name.startswith("gltf"):
            assert float(dielectric[0, 0]) <= 1.0


# --- the joint R, G, B fit ---------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def geometry():
    return synthetic_geometry(300, seed=0)  # n = 300: the command line test's --samples


@pytest.mark.parametrize("name, materials", [("gltf-pbr", 1), ("principled", 2)])
def test_joint_fit_recovers_parameters(geometry, name, materials):
    """Noise-free synthetic data of one material (``(3, n)``: the shapes and default options of the command line's
    test, one compiled fit) or two (``(2, 3, n)``), three channels each: every parameter to 1e-6 with the default
    options, one roughness (metallic, specular) per material, per-channel L2 ~ 0, the material's result code in each
    channel."""
    u, v = geometry
    p = np.stack([_rgb_params(name), _rgb_params(name, COLOURS[::-1])])[:materials]
    if materials == 2:
        p[1, :, 1] *= 0.7
    values = np.stack([_evaluate(name, q, u, v) for q in p])  # (materials, 3, n)
    batch = (3,) if materials == 1 else (2, 3)
    fit = bl.fit(name, u, v, values.reshape(batch + values.shape[-1:]))
    assert fit.params.shape == batch + p.shape[-1:] and fit.l2.shape == batch and fit.status.shape == batch
    assert bool(jnp.all(fit.success)), fit.status
    np.testing.assert_allclose(np.asarray(fit.params), p.reshape(fit.params.shape), atol=1e-6)
    assert float(jnp.max(fit.l2)) < 1e-8
    material = bl.standard_material(fit, () if materials == 1 else 1)
    assert material["model"] == name and len(material["base_color" if name == "principled" else "baseColorFactor"]) == 3
    np.testing.assert_allclose(np.asarray(fit(u, v)), values.reshape(fit.l2.shape + values.shape[-1:]), atol=1e-7)


def test_joint_fit_derivative_matches_finite_differences(geometry):
    """d params / d values of a noisy joint fit (implicit function theorem) against central differences of fits."""
    u, v = geometry
    rng = np.random.default_rng(9)
    values = _evaluate("gltf-pbr", _rgb_params("gltf-pbr"), u, v) * (1 + 0.05 * rng.normal(size=(3, u.shape[0])))
    direction = jnp.asarray(rng.normal(size=values.shape)) * 0.1
    fit = lambda y: bl.fit("gltf-pbr", u, v, y, **TIGHT).params  # noqa: E731
    _, tangent = jax.jvp(fit, (jnp.asarray(values),), (direction,))
    eps = 1e-4
    fd = (fit(values + eps * direction) - fit(values - eps * direction)) / (2 * eps)
    assert float(jnp.max(jnp.abs(tangent))) > 1e-3
    np.testing.assert_allclose(np.asarray(tangent), np.asarray(fd), rtol=1e-4, atol=1e-7)
    # the shared parameters' derivatives are the same in the three channels
    np.testing.assert_allclose(np.asarray(tangent[:, 1:]), np.asarray(tangent[:1, 1:]).repeat(3, 0), rtol=1e-12)


def test_joint_fit_needs_a_channel_axis_of_three(geometry):
    u, v = geometry
    with pytest.raises(pj.InputError, match=r"R, G, B channels .* expects values of shape \(\.\.\., 3, n\)"):
        bl.fit("gltf-pbr", u, v, np.ones((2, u.shape[0])))
    with pytest.raises(pj.InputError, match="standard material model"):
        bl.standard_material(baseline_fit_at("ward", [0.3, 0.2, 0.15]))
