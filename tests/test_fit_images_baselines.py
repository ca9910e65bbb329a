"""``baselines.fit_to_images``: a nonlinear model fitted to images rendered by polyjax's renderer."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import baselines as bl
import polyjax as pj
import polyjax.render as pr

TRUE = jnp.array([0.3, 0.2, 0.3, 0.1])  # Cook-Torrance: rho_d, rho_s, Beckmann m, F0
LIGHTS = [(3.0, 2.0, 4.0), (-3.0, 1.0, 3.0), (0.0, -3.0, 4.0), (2.0, -1.0, 5.0)]


def _scenes(brdf, lights=LIGHTS):
    cam = pr.Camera(eye=(0, 0, 5), fov_deg=30, width=48, height=48)
    return [pr.Scene(cam, [pr.Sphere(brdf)], [pr.PointLight(p, 30.0)]) for p in lights]


@pytest.fixture(scope="module")
def fitted():
    images = [pr.render(s, dtype=jnp.float64).image for s in _scenes(pr.ParametricBRDF(bl.cook_torrance, TRUE))]
    return images, bl.fit_to_images("cook-torrance", _scenes(pr.Lambertian()), images, n_starts=16,
                                    key=jax.random.PRNGKey(0))


def test_cook_torrance_sphere_recovered(fitted):
    images, fit = fitted
    assert fit.params.shape == (3, 4)
    assert np.all(np.asarray(fit.status) == pj.Result.OK)
    np.testing.assert_allclose(fit.params, jnp.broadcast_to(TRUE, (3, 4)), rtol=1e-4)
    assert float(jnp.max(fit.l2)) < 1e-6
    # the fitted model re-renders the images under a light not used in the fit
    held_out = [(-2.0, -2.0, 4.0)]
    ref = pr.render(_scenes(pr.ParametricBRDF(bl.cook_torrance, TRUE), held_out)[0], dtype=jnp.float64).image
    new = pr.render(_scenes(pr.ParametricBRDF(bl.cook_torrance, fit.params[0]), held_out)[0], dtype=jnp.float64).image
    assert float(pj.psnr(new, ref)) > 60.0


def test_bad_scenes_and_images(fitted):
    images, _ = fitted
    with pytest.raises(pj.InputError, match="one image per scene"):
        bl.fit_to_images("cook-torrance", _scenes(pr.Lambertian()), images[:2])
    two = pr.Scene(_scenes(pr.Lambertian())[0].camera, [pr.Sphere(pr.Lambertian())],
                   [pr.PointLight(LIGHTS[0], 30.0), pr.PointLight(LIGHTS[1], 30.0)])
    with pytest.raises(pj.InputError, match="exactly one point or directional light"):
        bl.fit_to_images("cook-torrance", [two], images[:1])
    with pytest.raises(pj.InputError, match="linear"):
        bl.fit_to_images("zernike", _scenes(pr.Lambertian()), images)
