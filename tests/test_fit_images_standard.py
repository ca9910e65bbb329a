"""``baselines.fit_to_images`` of a standard material model: a glTF PBR sphere rendered by polyjax's renderer, its
R, G, B channels fitted jointly (one metallic and roughness, a base colour per channel), under one light per image
(through :func:`baselines.fit`) and under two (the joint light-summed kernel), and the fit's derivative against
finite differences of refits."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import baselines as bl
import polyjax as pj
import polyjax.render as pr

#: glTF PBR (baseColorFactor, metallicFactor, roughnessFactor) per channel; metallic and roughness are none of the
#: model's starting guesses, so the solver, not a start, finds them
TRUE = np.array([[0.8, 0.35, 0.45], [0.5, 0.35, 0.45], [0.2, 0.35, 0.45]])
LIGHTS = [(3.0, 2.0, 4.0), (-3.0, 1.0, 3.0), (0.0, -3.0, 4.0), (2.0, -1.0, 5.0)]
TIGHT = dict(rtol=1e-12, atol=1e-14, max_steps=200)


def _gltf_rgb(params, u, v):
    """glTF PBR with parameters ``(3, 3)``, one row per colour channel: ``(..., 3)``."""
    return jnp.stack([bl.gltf_pbr(p, u, v) for p in params], axis=-1)


def _scenes(brdf, lights: str, size: int = 16, intensity: float = 30.0):
    """Four scenes of one point light each, or two of two point lights (one beside and behind the sphere)."""
    cam = pr.Camera(eye=(0, 0, 5), fov_deg=30, width=size, height=size)
    if lights == "one":
        return [pr.Scene(cam, [pr.Sphere(brdf)], [pr.PointLight(p, intensity)]) for p in LIGHTS]
    pairs = [(LIGHTS[0], (4.0, 0.0, -1.0)), (LIGHTS[2], LIGHTS[1])]
    return [pr.Scene(cam, [pr.Sphere(brdf)], [pr.PointLight(a, intensity), pr.PointLight(b, 20.0)])
            for a, b in pairs]


def _images(params, lights, size=16):
    return jnp.stack([pr.render(s, dtype=jnp.float64).image
                      for s in _scenes(pr.ParametricBRDF(_gltf_rgb, jnp.asarray(params)), lights, size)])


@pytest.mark.parametrize("lights", ["one", "two"])
def test_gltf_sphere_recovered(lights):
    """Noise-free 16 x 16 images: every parameter to 1e-6 with the default options, one metallic and roughness for
    the three channels, per-channel L2 ~ 0, the fit's glTF material, and the fit re-renders the images."""
    images = _images(TRUE, lights)
    fit = bl.fit_to_images("gltf-pbr", _scenes(pr.Lambertian(), lights), images, n_starts=4)
    assert fit.params.shape == (3, 3) and fit.l2.shape == (3,) and fit.status.shape == (3,)
    assert np.all(np.asarray(fit.status) == pj.RESULTS.OK), fit.status
    np.testing.assert_allclose(np.asarray(fit.params), TRUE, atol=1e-6)
    np.testing.assert_array_equal(np.asarray(fit.params[:, 1:]), np.asarray(fit.params[:1, 1:]).repeat(3, 0))
    assert float(jnp.max(fit.l2)) < 1e-8
    material = bl.standard_material(fit)
    np.testing.assert_allclose(material["baseColorFactor"], TRUE[:, 0], atol=1e-6)
    np.testing.assert_allclose([material["metallicFactor"], material["roughnessFactor"]], TRUE[0, 1:], atol=1e-6)
    again = _images(fit.params, lights)
    assert float(jnp.max(jnp.abs(again - images))) < 1e-6 * float(jnp.max(images))


def _derivative_problem(lights):
    """A noisy 8 x 8 problem: ``(images, tangent, params(images, intensity))``, the fit at tolerance 1e-12."""
    rng = np.random.default_rng(3)
    base = _images(TRUE, lights, size=8)
    base = base * (1 + 0.03 * jnp.asarray(rng.normal(size=base.shape)))
    tangent = 0.01 * jnp.asarray(rng.normal(size=base.shape)) * base

    def params(images, intensity=30.0):
        return bl.fit_to_images("gltf-pbr", _scenes(pr.Lambertian(), lights, 8, intensity), images, n_starts=2,
                                **TIGHT).params

    return base, tangent, params


def _check_tangent(a, b):
    """Forward-mode ``a`` against central differences ``b``: relative error <= 1e-5, the shared parameters'
    derivatives equal in the three channels."""
    assert float(jnp.max(jnp.abs(b))) > 1e-4
    assert float(jnp.max(jnp.abs(a - b))) <= 1e-5 * float(jnp.max(jnp.abs(b)))
    np.testing.assert_allclose(np.asarray(a[:, 1:]), np.asarray(a[:1, 1:]).repeat(3, 0), rtol=1e-10, atol=1e-14)


# the refits stop ~1e-10 from their optimum: a step large enough that this noise stays below 1e-7 of the derivative
H = 1e-2


@pytest.mark.parametrize("lights", ["two", pytest.param("one", marks=pytest.mark.slow)])
def test_gltf_sphere_derivative_matches_finite_differences(lights):
    """d params / d images of a noisy 8 x 8 fit by the implicit function theorem against central differences of
    refits at tolerance 1e-12 (two lights: the joint light-summed kernel; one: through :func:`baselines.fit`)."""
    base, tangent, params = _derivative_problem(lights)
    _, jv = jax.jvp(params, (base,), (tangent,))
    _check_tangent(jv, (params(base + H * tangent) - params(base - H * tangent)) / (2 * H))


@pytest.mark.slow
@pytest.mark.parametrize("lights", ["two", "one"])
def test_gltf_sphere_light_derivative_and_reverse_mode(lights):
    """d params / d (the lights' intensity) against central differences, and reverse mode (d roughness / d images)
    against forward mode."""
    base, tangent, params = _derivative_problem(lights)
    _, jv_i = jax.jvp(lambda i: params(base, i), (30.0,), (1.0,))
    _check_tangent(jv_i, (params(base, 30.0 + H) - params(base, 30.0 - H)) / (2 * H))
    _, jv = jax.jvp(params, (base,), (tangent,))
    g = jax.grad(lambda x: params(x)[0, 2])(base)
    np.testing.assert_allclose(float(jnp.sum(g * tangent)), float(jv[0, 2]), rtol=1e-8)
