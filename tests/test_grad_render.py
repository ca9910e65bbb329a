"""Derivatives of renders against central finite differences, for every effect the renderer computes.

Each test differentiates a scalar ``sum(weights * image)`` (fixed random weights) with respect to one
kind of parameter, by reverse mode (``jax.grad``) and forward mode (``jax.jvp``), and compares both
with central differences in float64. Scenes are built inside the differentiated functions.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import polyjax as pj
import polyjax.render as pr
from polyjax.data import NeuralBRDF

SIZE = 12
RTOL = 1e-6


def _camera(**kw):
    return pr.Camera(eye=(0.0, 0.0, 5.0), width=SIZE, height=SIZE, fov_deg=30.0, **kw)


def _weights(seed=0):
    return jnp.asarray(np.random.default_rng(seed).uniform(0.5, 1.5, (SIZE, SIZE, 3)))


def _loss(scene_of, spp=4):
    w = _weights()

    def loss(x):
        return jnp.sum(w * pr.render(scene_of(x), spp=spp, dtype=jnp.float64).image)

    return loss


def _check(loss, x, directions=2, h=1e-5, rtol=RTOL, seed=1):
    """Reverse- and forward-mode derivatives of ``loss`` at ``x`` against central differences."""
    x = jnp.asarray(x, jnp.float64)
    g = jax.grad(loss)(x)
    assert np.all(np.isfinite(np.asarray(g)))
    assert float(jnp.max(jnp.abs(g))) > 0, "the derivative is identically zero: the test would prove nothing"
    rng = np.random.default_rng(seed)
    for _ in range(directions):
        t = jnp.asarray(rng.normal(size=x.shape))
        fd = (loss(x + h * t) - loss(x - h * t)) / (2 * h)
        _, jv = jax.jvp(loss, (x,), (t,))
        scale = max(abs(float(fd)), 1e-12)
        assert abs(float(jnp.vdot(g, t)) - float(fd)) <= rtol * scale + 1e-10, (float(jnp.vdot(g, t)), float(fd))
        assert abs(float(jv) - float(fd)) <= rtol * scale + 1e-10, (float(jv), float(fd))
    return g


def _poly_model():
    data = pj.data.synthetic_default(n=300)
    return pj.fit_polynomial(data.u, data.v, data.values, variables="lafortune", degree=3)


def test_polynomial_coefficients_point_and_directional():
    model = _poly_model()
    lights = [pr.PointLight((2.0, 2.0, 4.0), 24.0), pr.DirectionalLight((-1.0, 0.5, 1.0), 2.0)]

    def scene(c):
        m = eqx.tree_at(lambda m: m.coefficients, model, c)
        return pr.Scene(_camera(), [pr.Sphere(m)], lights)

    _check(_loss(scene), model.coefficients)


def test_parametric_brdf_params():
    def blinn(params, u, v):
        kd, ks, n = params[:3], params[3], params[4]
        h = pj.half_vector(u, v)
        return kd / jnp.pi + ks * (n + 8) / (8 * jnp.pi) * jnp.maximum(h[..., 2], 0.0)[..., None] ** n

    def scene(p):
        return pr.Scene(_camera(), [pr.Sphere(pr.ParametricBRDF(blinn, p))], [pr.PointLight((2.0, 2.0, 4.0), 24.0)])

    _check(_loss(scene), [0.3, 0.5, 0.7, 0.4, 20.0])


def test_phong_parameters():
    def scene(p):
        brdf = pr.Phong(kd=p[:3], ks=p[3], exponent=p[4])
        return pr.Scene(_camera(), [pr.Sphere(brdf)], [pr.DirectionalLight((1.0, 1.0, 1.5), 3.0)])

    _check(_loss(scene), [0.3, 0.5, 0.7, 0.4, 20.0])


def test_neural_weights():
    rng = np.random.default_rng(3)
    shapes = [(6, 21), (21,), (21, 21), (21,), (21, 3), (3,)]
    params = [jnp.asarray(0.3 * rng.normal(size=s)) for s in shapes]
    sizes = [int(np.prod(s)) for s in shapes]
    flat = jnp.concatenate([p.reshape(-1) for p in params])

    def scene(x):
        parts = jnp.split(x, np.cumsum(sizes)[:-1])
        net = NeuralBRDF(*(p.reshape(s) for p, s in zip(parts, shapes)))
        return pr.Scene(_camera(), [pr.Sphere(net)], [pr.PointLight((2.0, 2.0, 4.0), 24.0)])

    _check(_loss(scene), flat, h=1e-6)


def test_point_light_intensity_and_position():
    def scene(x):
        light = pr.PointLight(position=x[:3], intensity=x[3:])
        return pr.Scene(_camera(), [pr.Sphere(pr.Phong())], [light])

    _check(_loss(scene), [2.0, 2.0, 4.0, 20.0, 24.0, 28.0])


def test_directional_light_direction_and_irradiance():
    def scene(x):
        light = pr.DirectionalLight(direction=x[:3], irradiance=x[3:])
        return pr.Scene(_camera(), [pr.Sphere(pr.Phong())], [light])

    _check(_loss(scene), [1.0, 1.0, 1.5, 2.0, 3.0, 4.0])


def test_shadowed_scene_light_and_brdf():
    """Sphere on a plane: the shadow-ray effect is on; derivatives of the lit pixels (visibility is piecewise
    constant: a shadow edge moving with the light has no derivative)."""
    cam = pr.Camera(eye=(0.0, 1.5, 6.0), target=(0.0, -0.3, 0.0), width=SIZE, height=SIZE)

    def scene(x):
        objects = [pr.Sphere(pr.Phong(kd=x[4:7])), pr.Plane(pr.Lambertian(x[7]), height=-1.0)]
        return pr.Scene(cam, objects, [pr.PointLight(position=x[:3], intensity=x[3])])

    x0 = [2.0, 4.0, 2.0, 30.0, 0.3, 0.5, 0.7, 0.6]
    assert pr.plan_effects(scene(jnp.asarray(x0))).shadows
    _check(_loss(scene), x0)


def test_environment_texels_fixed_pool():
    """Texels of a map built outside: its sampling tables are fixed, the estimator is linear in the texels."""
    sky = pr.procedural_sky(8, 16, sun_radiance=20.0)
    brdf = pr.Phong(kd=0.5, ks=0.3, exponent=10.0)

    def scene(img):
        return pr.Scene(_camera(), [pr.Sphere(brdf)], [eqx.tree_at(lambda e: e.image, sky, img)])

    _check(_loss(scene), sky.image)


def test_environment_with_shadows_and_indirect():
    """Sphere on a plane lit by a map and a point light, one indirect bounce: texels, BRDF parameter, intensity."""
    sky = pr.procedural_sky(8, 16, sun_radiance=20.0)
    cam = pr.Camera(eye=(0.0, 1.5, 6.0), target=(0.0, -0.3, 0.0), width=SIZE, height=SIZE)
    n_tex = sky.image.size

    def scene(x):
        env = eqx.tree_at(lambda e: e.image, sky, x[:n_tex].reshape(sky.image.shape))
        objects = [pr.Sphere(pr.Phong(kd=x[n_tex], ks=0.3, exponent=10.0)), pr.Plane(pr.Lambertian(0.5), height=-1.0)]
        return pr.Scene(cam, objects, [env, pr.PointLight((2.0, 4.0, 2.0), x[n_tex + 1])], max_bounces=1)

    x0 = jnp.concatenate([sky.image.reshape(-1), jnp.asarray([0.4, 30.0])])
    assert pr.plan_effects(scene(x0)) == pr.Effects(True, True, True, True)
    _check(_loss(scene, spp=2), x0)


def test_environment_built_inside_jit_is_linear_in_its_texels():
    """A map built from traced texels (sampling tables computed in JAX, their derivative stopped): the
    estimator is linear in the radiance for its fixed samples, so ``loss(img) = <grad loss(img), img>``."""
    img0 = pr.procedural_sky(8, 16, sun_radiance=20.0).image
    brdf = pr.Phong(kd=0.5, ks=0.3, exponent=10.0)

    def scene(img):
        return pr.Scene(_camera(), [pr.Sphere(brdf)], [pr.EnvironmentLight(img)])

    loss = jax.jit(_loss(scene))
    g = jax.grad(loss)(img0)
    assert np.all(np.isfinite(np.asarray(g)))
    np.testing.assert_allclose(float(jnp.vdot(g, img0)), float(loss(img0)), rtol=1e-10)


def test_environment_built_inside_jit_renders_like_the_eager_one():
    """The environment samples are the same numbers whether the map's tables are traced or not: a render of
    a map built inside ``jit`` equals the eager render of the same map (not only in expectation)."""
    img0 = pr.procedural_sky(8, 16, sun_radiance=20.0).image
    brdf = pr.Phong(kd=0.5, ks=0.3, exponent=10.0)

    def scene(img):
        return pr.Scene(_camera(), [pr.Sphere(brdf)], [pr.EnvironmentLight(img)])

    eager = pr.render(scene(img0), spp=4, dtype=jnp.float64).image
    traced = jax.jit(lambda img: pr.render(scene(img), spp=4, dtype=jnp.float64).image)(img0)
    assert float(jnp.max(eager)) > 0
    np.testing.assert_allclose(np.asarray(traced), np.asarray(eager), rtol=1e-9, atol=1e-12)


def test_vmap_of_grad_over_intensities():
    def loss(i):
        scene = pr.Scene(_camera(), [pr.Sphere(pr.Lambertian(0.5))], [pr.PointLight((2.0, 2.0, 4.0), i)])
        return jnp.sum(pr.render(scene, dtype=jnp.float64).image)

    xs = jnp.asarray([10.0, 20.0, 30.0])
    g = jax.vmap(jax.grad(loss))(xs)
    # radiance is linear in the intensity: the derivative is the render at unit intensity
    np.testing.assert_allclose(np.asarray(g), float(loss(1.0)) * np.ones(3), rtol=1e-12)


def test_camera_and_objects_built_inside_jit():
    @jax.jit
    def img(fov, radius, centre):
        cam = pr.Camera(eye=(0.0, 0.0, 5.0), width=SIZE, height=SIZE, fov_deg=fov)
        plane = pr.Plane(pr.Lambertian(0.5), height=centre[1] - 2.0, normal=jnp.asarray([0.0, 1.0, 0.0]))
        scene = pr.Scene(cam, [pr.Sphere(pr.Lambertian(0.5), center=centre, radius=radius), plane],
                         [pr.DirectionalLight((0.0, 1.0, 1.0), 1.0)])
        return pr.render(scene, dtype=jnp.float64).image

    a = img(30.0, 1.0, jnp.zeros(3))
    cam = pr.Camera(eye=(0.0, 0.0, 5.0), width=SIZE, height=SIZE, fov_deg=30.0)
    scene = pr.Scene(cam, [pr.Sphere(pr.Lambertian(0.5)), pr.Plane(pr.Lambertian(0.5), height=-2.0)],
                     [pr.DirectionalLight((0.0, 1.0, 1.0), 1.0)])
    np.testing.assert_allclose(np.asarray(a), np.asarray(pr.render(scene, dtype=jnp.float64).image), atol=1e-12)


def test_traced_shape_errors_are_clear():
    with pytest.raises(pj.InputError, match="position"):
        jax.jit(lambda p: pr.PointLight(position=p).position)(jnp.zeros(2))


def test_tabulated_values_built_inside_grad():
    rng = np.random.default_rng(5)
    u = rng.normal(size=(60, 3))
    u[:, 2] = np.abs(u[:, 2])
    v = rng.normal(size=(60, 3))
    v[:, 2] = np.abs(v[:, 2])
    values = rng.uniform(0.1, 0.5, (60, 3))
    concrete = pr.TabulatedBRDF(u, v, values)

    def scene(x):
        return pr.Scene(_camera(), [pr.Sphere(pr.TabulatedBRDF(u, v, x))], [pr.PointLight((2.0, 2.0, 4.0), 24.0)])

    _check(_loss(scene), values)
    # the traced construction gives the same table as the concrete one
    traced = jax.jit(lambda x: pr.TabulatedBRDF(u, v, x).features)(jnp.asarray(values))
    np.testing.assert_allclose(np.asarray(traced), np.asarray(concrete.features), atol=1e-15)


def test_baseline_model_parameters():
    """A baseline model (Cook-Torrance, ``f(params, u, v)``) through ParametricBRDF: derivatives w.r.t. its
    parameters."""
    baselines = pytest.importorskip("baselines")

    def scene(p):
        brdf = pr.ParametricBRDF(baselines.cook_torrance, p)
        return pr.Scene(_camera(), [pr.Sphere(brdf)], [pr.PointLight((2.0, 2.0, 4.0), 24.0)])

    _check(_loss(scene), [0.3, 0.2, 0.3, 0.1])


def test_jitted_environment_render_equals_eager():
    """A map built outside ``jit`` (and not passed in as a traced argument) draws its samples from its concrete
    tables: the same pixels under ``jit``, here with the BRDF traced."""
    sky = pr.procedural_sky(8, 16, sun_radiance=20.0)

    def image(kd):
        return pr.render(pr.Scene(_camera(), [pr.Sphere(pr.Phong(kd=kd))], [sky]), spp=4, dtype=jnp.float64).image

    eager = image(0.5)
    jitted = jax.jit(image)(0.5)
    np.testing.assert_allclose(np.asarray(jitted), np.asarray(eager), rtol=1e-12, atol=1e-14)
