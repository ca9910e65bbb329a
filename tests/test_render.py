"""Renderer: analytic checks, effect planning, reciprocity, grids, images."""

import jax.numpy as jnp
import numpy as np
import pytest

import polyjax as pj
import polyjax.render as pr

from _render_problems import LIGHT_DIR, lone_sphere, ortho_camera, sphere_normals, sphere_on_plane


def test_lambertian_sphere_matches_cosine_law():
    albedo = np.array([0.2, 0.5, 0.9])
    res = pr.render(lone_sphere(pr.Lambertian(albedo)), dtype=jnp.float64)
    n, hit = sphere_normals()
    expected = albedo * np.clip(n @ LIGHT_DIR, 0, None)[..., None]  # (albedo / pi) * E cos, E = pi
    assert np.array_equal(np.asarray(res.hit), hit)
    np.testing.assert_allclose(np.asarray(res.image)[hit], expected[hit], rtol=0, atol=1e-12)
    assert np.all(np.asarray(res.image)[~hit] == 0.0)
    assert res.effects == pr.Effects(direct_point=True) and res.spp == 0


def test_point_light_inverse_square():
    # a point light far along the light direction: irradiance I / r^2 at each point, r from the point itself
    pos = 10 * LIGHT_DIR
    res = pr.render(lone_sphere(pr.Lambertian(1.0), [pr.PointLight(pos, 100.0)]), dtype=jnp.float64)
    n, hit = sphere_normals()
    delta = pos - n
    r2 = np.sum(delta**2, -1)
    expected = 100.0 / np.pi * np.clip(np.sum(n * delta, -1) / np.sqrt(r2), 0, None) / r2
    np.testing.assert_allclose(np.asarray(res.image)[..., 1][hit], expected[hit], rtol=1e-10)


def test_effects_follow_the_scene():
    lone = lone_sphere(pr.Phong())
    assert pr.plan_effects(lone) == pr.Effects(direct_point=True, shadows=False)
    assert pr.render(lone).effects.names() == ("direct_point",)
    on_plane = sphere_on_plane(pr.Phong())
    assert pr.plan_effects(on_plane) == pr.Effects(direct_point=True, shadows=True)
    sky = pr.procedural_sky(16, 32)
    assert pr.plan_effects(lone_sphere(pr.Phong(), [sky])) == pr.Effects(environment=True)
    assert pr.plan_effects(lone_sphere(pr.Phong(), max_bounces=2)).indirect is False  # nothing to bounce off
    assert pr.plan_effects(sphere_on_plane(pr.Phong(), max_bounces=1)) == pr.Effects(True, True, False, True)
    assert pr.render(lone, force_all_effects=True, spp=2).effects == pr.Effects.all()


def test_shadow_of_sphere_on_plane():
    with_sphere = sphere_on_plane(pr.Lambertian(0.7))
    res = pr.render(with_sphere)
    assert res.effects.shadows
    img = np.asarray(res.image)
    # the plane point straight below the sphere, towards the light, is in shadow: compare with the plane alone
    alone = pr.render(pr.Scene(with_sphere.camera, [with_sphere.objects[1]], with_sphere.lights))
    assert not alone.effects.shadows
    plane_only = np.asarray(alone.image)
    sphere_px = np.asarray(pr.render(pr.Scene(with_sphere.camera, [with_sphere.objects[0]], with_sphere.lights)).hit)
    on_plane = np.asarray(alone.hit) & ~sphere_px  # pixels that see the plane in both renders
    diff = (plane_only - img)[..., 0]
    shadowed = on_plane & (diff > 1e-6)
    # some plane pixels visible in both renders lose all their light, none gains any
    assert shadowed.sum() > 10
    assert np.all(img[shadowed][..., 0] == 0.0)
    assert np.all(np.abs(diff[on_plane & ~shadowed]) <= 1e-6)


def test_force_all_effects_gives_identical_pixels():
    m = pj.data.synthetic_default()
    model = pj.fit_polynomial(m, variables="lafortune", degree=3)[1]
    for lights in ([pr.PointLight((2.0, 2.0, 4.0), 24.0)], [pr.procedural_sky(16, 32)]):
        scene = lone_sphere(pr.rgb_brdf(model), lights, size=32)
        a = pr.render(scene, spp=4)
        b = pr.render(scene, spp=4, force_all_effects=True)
        assert a.effects != b.effects
        assert np.array_equal(np.asarray(a.image), np.asarray(b.image))


def test_uniform_environment_on_lambertian_sphere():
    # a white sphere in a uniform environment of radiance 1 reflects exactly albedo everywhere
    env = pr.EnvironmentLight(np.ones((16, 32, 3)))
    res = pr.render(lone_sphere(pr.Lambertian(0.6), [env], size=24), spp=256, dtype=jnp.float64)
    hit = np.asarray(res.hit)
    vals = np.asarray(res.image)[hit]
    assert res.effects == pr.Effects(environment=True) and res.spp == 256
    assert abs(vals.mean() - 0.6) < 0.01
    assert np.all(np.asarray(res.image)[~hit] == 1.0)  # the background is the map


def test_swapped_uv_of_reciprocal_model_gives_same_image():
    m = pj.data.synthetic_default()
    model = pj.fit_polynomial(m, variables="lafortune", degree=5)[2]
    light = [pr.PointLight((1.0, 3.0, 3.0), 20.0)]
    for brdf in (pr.Phong(ks=0.6, exponent=40.0), model):
        a = pr.render(lone_sphere(brdf, light), dtype=jnp.float64).image
        b = pr.render(lone_sphere(pr.SwapUV(brdf), light), dtype=jnp.float64).image
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-9, atol=1e-12)

    # a non-reciprocal BRDF (weighted by the light's cosine only) changes under the swap
    def skew(u, v):
        return 0.3 * jnp.maximum(u[..., 2], 0.0) ** 4

    a = np.asarray(pr.render(lone_sphere(skew, light)).image)
    b = np.asarray(pr.render(lone_sphere(pr.SwapUV(skew), light)).image)
    assert np.max(np.abs(a - b)) > 0.01


def test_grid_matches_single_renders():
    brdfs = [[pr.Lambertian(0.3), pr.Lambertian(0.8)], [pr.Phong(ks=0.2), lambda u, v: jnp.full(u.shape[:-1], 0.1)]]
    scene = pr.sphere_scene(24)
    grid = pr.render_grid(brdfs, scene, dtype=jnp.float64)
    assert grid.images.shape == (2, 2, 24, 24, 3) and grid.effects == pr.Effects(direct_point=True)
    for i, row in enumerate(brdfs):
        for j, b in enumerate(row):
            one = pr.render(pr.Scene(scene.camera, [pr.Sphere(b)], scene.lights), dtype=jnp.float64)
            np.testing.assert_allclose(np.asarray(grid.images[i, j]), np.asarray(one.image), rtol=1e-12, atol=1e-14)


def test_grid_of_fitted_materials_under_environment():
    m = pj.data.synthetic_default()
    model = pj.fit_polynomial(m, variables="lafortune", degree=[2, 5])  # batch (degrees, materials)
    rows = [[model[d, k] for k in range(3)] for d in range(2)]
    scene = lone_sphere(pr.Lambertian(), [pr.procedural_sky(16, 32)], size=16)
    grid = pr.render_grid(rows, scene, spp=8)
    assert grid.images.shape == (2, 3, 16, 16, 3)
    one = pr.render(pr.Scene(scene.camera, [pr.Sphere(model[1, 2])], scene.lights), spp=8)
    np.testing.assert_allclose(np.asarray(grid.images[1, 2]), np.asarray(one.image), rtol=1e-4, atol=1e-5)


def test_channels_first_adapter():
    m = pj.data.synthetic_default()
    rgb_values = np.stack([m.values[0], m.values[1], m.values[2]])  # pretend channels
    model = pj.fit_polynomial(m.u, m.v, rgb_values, degree=3)
    brdf = pr.rgb_brdf(model)
    assert isinstance(brdf, pr.ChannelsFirst)
    u = np.array([[0.0, 0.0, 1.0], [0.3, 0.0, 0.954]])
    out = np.asarray(brdf(u, u[::-1]))
    assert out.shape == (2, 3)
    np.testing.assert_allclose(out, np.asarray(model(u, u[::-1])).T)
    with pytest.raises(pj.InputError, match="batch shape"):
        pr.rgb_brdf(pj.fit_polynomial(m, degree=[1, 2]))


def test_tabulated_brdf_is_reciprocal_and_interpolates():
    m = pj.data.synthetic_default(n=300)
    vals = np.asarray(m.values[1])
    tab = pr.TabulatedBRDF(m.u, m.v, vals, k=1, isotropic=False)
    got = np.asarray(tab(jnp.asarray(m.u[:5]), jnp.asarray(m.v[:5])))
    np.testing.assert_allclose(got, np.repeat(vals[:5, None], 3, 1), rtol=1e-9)
    iso = pr.TabulatedBRDF(m.u, m.v, vals, k=4)
    u, v = np.asarray(m.u[10:40]), np.asarray(m.v[50:80])
    np.testing.assert_allclose(np.asarray(iso(u, v)), np.asarray(iso(v, u)), rtol=1e-12)
    assert np.ptp(np.asarray(iso(u, v))) > 0
    below = np.array([[0.0, 0.6, -0.8]])
    assert np.all(np.asarray(iso(below, u[:1])) == 0.0)


def test_scene_input_errors():
    with pytest.raises(pj.InputError, match="objects"):
        pr.Scene(ortho_camera(), ["not a sphere"], [])
    with pytest.raises(pj.InputError, match="radius"):
        pr.Sphere(pr.Lambertian(), radius=-1.0)
    with pytest.raises(pj.InputError, match="spp"):
        pr.render(lone_sphere(pr.Lambertian()), spp=0)
    with pytest.raises(pj.InputError, match="output of shape"):
        pr.render(lone_sphere(lambda u, v: jnp.zeros((2,) + u.shape)))
    with pytest.raises(pj.InputError, match="exactly one Sphere"):
        pr.render_grid([[pr.Lambertian()]], sphere_on_plane(pr.Lambertian()))


def test_huge_scene_values_are_refused_or_normalised_without_overflow():
    """Directions of any finite size are normalised exactly (|d| overflowed for components near 1e300 and left a
    zero light direction, a NaN camera); positions and sizes past 1e15 scene units, whose squares the ray
    intersections form, are named errors."""
    d = np.asarray(pr.DirectionalLight(direction=(1e300, 1e300, 1e300)).direction)
    np.testing.assert_allclose(d, np.full(3, 3 ** -0.5), rtol=1e-15)
    n = np.asarray(pr.Plane(pr.Lambertian(), normal=(0.0, 1e300, 1e300)).normal)
    np.testing.assert_allclose(n, [0.0, 2 ** -0.5, 2 ** -0.5], rtol=1e-15)
    for make, name in [(lambda: pr.Camera(eye=(1e300, 1e300, 1e300)), "eye"),
                       (lambda: pr.Camera(eye=(0.0, 0.0, 0.0)), "target"),
                       (lambda: pr.Sphere(pr.Lambertian(), radius=1e300), "radius"),
                       (lambda: pr.Sphere(pr.Lambertian(), center=(0.0, -1e16, 0.0)), "center"),
                       (lambda: pr.Plane(pr.Lambertian(), height=1e300), "height"),
                       (lambda: pr.PointLight(position=(1e20, 0.0, 0.0)), "position")]:
        with pytest.raises(pj.InputError, match=name):
            make()
    o, dirs = pr.Camera(eye=(0.0, 0.0, 1e15)).rays()  # the largest distance allowed renders finite rays
    assert np.all(np.isfinite(np.asarray(dirs))) and np.all(np.isfinite(np.asarray(o)))
