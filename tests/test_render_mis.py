"""The environment term with BRDF importance sampling and MIS: unbiased, less noisy on glossy BRDFs,
differentiable."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import polyjax as pj
import polyjax.render as pr

from _render_problems import ortho_camera, sphere_on_plane


def _mean_hit(result):
    img, hit = np.asarray(result.image), np.asarray(result.hit)
    return img[hit]


@pytest.mark.parametrize("mode", ["mis", "brdf", "cosine"])
def test_white_furnace_lambertian(mode):
    """A Lambertian sphere under a uniform unit environment reflects its albedo (exactly 0.5)."""
    scene = pr.Scene(ortho_camera(16), [pr.Sphere(pr.Lambertian(0.5))], [pr.EnvironmentLight(np.ones((16, 32, 3)))])
    px = _mean_hit(pr.render(scene, spp=128, sampling=mode, dtype=jnp.float64))
    assert abs(px.mean() - 0.5) < 0.01
    if mode == "cosine":  # f cos / pdf = albedo exactly
        np.testing.assert_allclose(px, 0.5, rtol=1e-12)


def test_modes_agree_and_mis_beats_cosine_on_a_glossy_sphere():
    env = pr.procedural_sky(32, 64, sun_radiance=50.0, sun_radius_deg=5.0)
    scene = pr.Scene(ortho_camera(24), [pr.Sphere(pr.Phong(0.05, 0.8, 200.0))], [env])
    ref = np.asarray(pr.render(scene, spp=2048, sampling="mis", dtype=jnp.float64).image)
    errs = {}
    for mode in ("environment", "mis", "brdf", "cosine"):
        img = np.asarray(pr.render(scene, spp=32, sampling=mode, dtype=jnp.float64, seed=7).image)
        errs[mode] = np.sqrt(np.mean((img - ref) ** 2))
        if mode in ("mis", "brdf"):  # environment-only and cosine sampling: rare, very bright sun highlights
            assert abs(img.mean() - ref.mean()) < 0.03 * ref.mean(), (mode, img.mean(), ref.mean())
    assert errs["mis"] * 3 < errs["cosine"], errs
    assert errs["mis"] < errs["environment"], errs


def test_mis_with_shadows_and_a_plane():
    scene = sphere_on_plane(pr.Phong(0.3, 0.4, 20.0), lights=[pr.procedural_sky(16, 32)], size=16)
    a = np.asarray(pr.render(scene, spp=512, sampling="mis", dtype=jnp.float64).image)
    b = np.asarray(pr.render(scene, spp=512, sampling="environment", dtype=jnp.float64).image)
    assert np.all(np.isfinite(a))
    assert abs(a.mean() - b.mean()) < 0.03 * b.mean()


def test_gradient_through_mis_environment_render_wrt_coefficients():
    data = pj.data.synthetic_default()
    model = pj.fit_polynomial(data, variables="lafortune", degree=3)
    # the renderer transports max(f, 0): a constant (Legendre term 0) lifts the model above 0 on the hemisphere, so
    # the render is linear in the coefficients and central differences are exact
    g_ = np.linspace(0.0, 1.0, 24)
    th, ph = np.meshgrid(g_ * np.pi / 2, g_ * 2 * np.pi, indexing="ij")
    dirs = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1).reshape(-1, 3)
    low = float(jnp.min(model(np.repeat(dirs, len(dirs), axis=0), np.tile(dirs, (len(dirs), 1)))))
    model = eqx.tree_at(lambda x: x.coefficients, model, model.coefficients.at[..., 0].add(max(0.0, -low) + 0.05))
    env = pr.procedural_sky(16, 32, sun_radiance=2.0, sun_radius_deg=20.0)  # smooth: low-noise estimates

    def loss(coef, sampling, spp):
        m = eqx.tree_at(lambda x: x.coefficients, model, coef)
        scene = pr.Scene(ortho_camera(8), [pr.Sphere(m)], [env])
        return jnp.sum(pr.render(scene, spp=spp, sampling=sampling, dtype=jnp.float64).image)

    g = jax.grad(loss)(model.coefficients, "mis", 64)
    assert g.shape == model.coefficients.shape
    assert np.all(np.isfinite(np.asarray(g))) and np.any(np.asarray(g) != 0)
    # cosine sampling does not depend on the coefficients: the render is linear in them, the gradient exact
    gc = jax.grad(loss)(model.coefficients, "cosine", 64)
    d = jnp.zeros_like(model.coefficients).at[1, 0].set(1e-3)
    fd = (loss(model.coefficients + d, "cosine", 64) - loss(model.coefficients - d, "cosine", 64)) / 2e-3
    np.testing.assert_allclose(float(gc[1, 0]), float(fd), rtol=1e-6)
    # the MIS gradient estimates the same derivative (the densities are sampling choices, held fixed)
    assert np.linalg.norm(np.asarray(g - gc)) < 0.1 * np.linalg.norm(np.asarray(gc))


def test_unknown_sampling_raises():
    scene = pr.Scene(ortho_camera(4), [pr.Sphere(pr.Lambertian())], [pr.procedural_sky(8, 16)])
    with pytest.raises(pj.InputError, match="sampling"):
        pr.render(scene, sampling="bsdf")


def test_brdf_sampled_indirect_bounces_agree_with_cosine_bounces():
    """Sphere on a plane, point light: the indirect term with BRDF-sampled bounces has the cosine-sampled
    bounces' expectation."""
    scene = sphere_on_plane(pr.Phong(0.2, 0.6, 30.0), size=12, max_bounces=1)
    a = pr.render(scene, spp=512, sampling="mis", dtype=jnp.float64)
    b = pr.render(scene, spp=512, sampling="cosine", dtype=jnp.float64)
    assert a.effects.indirect
    direct = np.asarray(pr.render(sphere_on_plane(pr.Phong(0.2, 0.6, 30.0), size=12), dtype=jnp.float64).image)
    ia, ib = np.asarray(a.image) - direct, np.asarray(b.image) - direct
    assert np.all(np.isfinite(ia))
    assert ib.mean() > 0.02 * direct.mean()  # the indirect term is not negligible
    assert abs(ia.mean() - ib.mean()) < 0.05 * ib.mean(), (ia.mean(), ib.mean())
