"""Shape and material from photographs: captures without normals, 8-bit images, ``fit_capture`` and its relighting.

A synthetic capture is rendered with numpy (a sphere's known normals, a diffuse albedo per pixel and a Blinn-Phong
lobe of two strengths) and fitted without its normals: the recovered normals, the relit held-out lights and a
gradient against finite differences are checked. The loader's 8-bit, no-normal folders are written here in DiLiGenT's
layout.
"""

import os

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import png
import pytest

import polyjax as pj
from polyjax.cli import main

jax.config.update("jax_enable_x64", True)


def sphere(h, w):
    ys = (h / 2 - (np.arange(h) + 0.5)) / (0.45 * h)
    xs = ((np.arange(w) + 0.5) - w / 2) / (0.45 * h)
    x, y = np.meshgrid(xs, ys)
    r2 = x**2 + y**2
    mask = r2 < 0.9
    n = np.stack([x, y, np.sqrt(np.clip(1 - r2, 0, 1))], -1)
    return np.where(mask[..., None], n, [0.0, 0.0, 1.0]), mask


def lights(n_lights, seed=0):
    """Unit directions spread over a cap of the upper hemisphere (polar angles up to about 55 degrees)."""
    rng = np.random.default_rng(seed)
    phi = np.linspace(0, 2 * np.pi, n_lights, endpoint=False) + 0.3 * rng.random(n_lights)
    theta = np.radians(10 + 45 * ((np.arange(n_lights) * 0.618) % 1.0))
    return np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], -1)


def render(normals, mask, dirs, intensity, ks):
    """``E max(0, n.d) (rho / pi + ks (n.h)^40 (shininess normalised))`` of every pixel: ``(L, H, W, 3)``."""
    h, w = mask.shape
    rho = np.stack([0.5 + 0.2 * np.linspace(0, 1, w)[None].repeat(h, 0), np.full((h, w), 0.4),
                    np.full((h, w), 0.3)], -1)
    half = dirs + np.array([0.0, 0.0, 1.0])
    half /= np.linalg.norm(half, axis=1, keepdims=True)
    cos = np.maximum(np.einsum("hwk,lk->lhw", normals, dirs), 0)
    spec = ks[None] * (42 / (8 * np.pi)) * np.maximum(np.einsum("hwk,lk->lhw", normals, half), 0) ** 40
    img = intensity[:, None, None, :] * cos[..., None] * (rho[None] / np.pi + spec[..., None])
    return np.where(mask[None, ..., None], img, 0.0)


@pytest.fixture(scope="module")
def synthetic():
    normals, mask = sphere(20, 20)
    dirs = lights(32)
    intensity = 1.0 + 0.1 * np.random.default_rng(1).random((32, 3))
    ks = np.where(np.arange(20)[None, :].repeat(20, 0) < 10, 0.3, 0.05)
    images = render(normals, mask, dirs, intensity, ks)
    capture = pj.Capture(images=images, mask=mask, normals=None, light_directions=dirs,
                         light_intensities=intensity, names=tuple(f"{i:03d}.png" for i in range(32)),
                         quantisation=1 / 65535)
    return capture, normals, mask


def write_folder(path, images8, mask, dirs, intensity, normals_txt=None):
    os.makedirs(path, exist_ok=True)
    names = [f"{i + 1:03d}.png" for i in range(len(images8))]
    for name, img in zip(names, images8):
        h, w, _ = img.shape
        with open(os.path.join(path, name), "wb") as fh:
            png.Writer(w, h, greyscale=False, bitdepth=8).write(fh, img.reshape(h, w * 3))
    with open(os.path.join(path, "mask.png"), "wb") as fh:
        png.Writer(mask.shape[1], mask.shape[0], greyscale=True, bitdepth=8).write(fh, mask.astype(np.uint8) * 255)
    with open(os.path.join(path, "filenames.txt"), "w") as fh:
        fh.write("\n".join(names) + "\n")
    np.savetxt(os.path.join(path, "light_directions.txt"), dirs)
    np.savetxt(os.path.join(path, "light_intensities.txt"), intensity)
    if normals_txt is not None:
        np.savetxt(os.path.join(path, "normal.txt"), normals_txt.reshape(-1, 3))
    return names


def test_load_8bit_without_normals(tmp_path):
    normals, mask = sphere(6, 7)
    dirs = lights(4)
    rng = np.random.default_rng(3)
    images8 = rng.integers(0, 256, size=(4, 6, 7, 3)).astype(np.uint8)
    write_folder(str(tmp_path), images8, mask, dirs, np.ones((4, 3)))
    capture = pj.data.load_photometric(str(tmp_path))
    assert capture.normals is None
    assert capture.quantisation == pytest.approx(1 / 255)
    np.testing.assert_allclose(np.asarray(capture.images), images8 / 255.0)
    cropped = capture.strided(2)
    assert cropped.normals is None and cropped.quantisation == capture.quantisation
    with pytest.raises(pj.InputError, match="normals"):
        _ = capture.scenes


def test_load_zero_normals_leave_the_mask(tmp_path):
    normals, mask = sphere(6, 7)
    normals = normals.copy()
    i, j = np.argwhere(mask)[0]
    normals[i, j] = 0.0
    write_folder(str(tmp_path), np.zeros((4, 6, 7, 3), np.uint8), mask, lights(4), np.ones((4, 3)), normals)
    capture = pj.data.load_photometric(str(tmp_path))
    assert not bool(capture.mask[i, j]) and int(np.sum(capture.mask)) == int(mask.sum()) - 1
    np.testing.assert_allclose(np.linalg.norm(np.asarray(capture.normals), axis=-1), 1.0)


def test_fit_capture_bad_input(synthetic):
    capture, _, _ = synthetic
    with pytest.raises(pj.InputError, match="capture"):
        pj.fit_capture("not a capture")
    with pytest.raises(pj.InputError, match="lobes"):
        pj.fit_capture(capture, lobes=0)
    with pytest.raises(pj.InputError, match="use_normals"):
        pj.fit_capture(capture, use_normals=True)


@pytest.mark.slow
def test_fit_capture_sphere(synthetic):
    capture, normals, mask = synthetic
    fit_lights, held = np.arange(0, 32, 2), np.arange(1, 32, 2)
    fit = pj.fit_capture(capture.select(fit_lights), lobes=2)
    err = np.degrees(np.arccos(np.clip(np.sum(np.asarray(fit.normals)[mask] * normals[mask], -1), -1, 1)))
    assert fit.normals.shape == (20, 20, 3) and fit.mix.shape == (20, 20, 2)
    assert np.median(err) < 0.5 and np.mean(err) < 4.0, (np.median(err), np.mean(err))
    assert np.all(np.asarray(fit.mix) >= 0) and np.all(np.asarray(fit.diffuse)[mask] > 0)
    test = capture.select(held)
    pred, img = np.asarray(pj.relight(fit, test)), np.asarray(test.images)
    rel = np.sqrt(np.sum((pred - img)[:, mask] ** 2) / np.sum(img[:, mask] ** 2))
    # 16 fitted lights sample a Blinn-Phong lobe of exponent 40 sparsely: 0.206 measured with the joint normal steps
    assert rel < 0.22, rel
    assert int(fit.status) in (pj.RESULTS.OK, pj.RESULTS.MAX_STEPS)
    g = np.asarray(fit.brdf(np.array([[0.0, 0.0, 1.0]]), np.array([[0.0, 0.0, 1.0]])))
    assert g.shape == (20, 20, 1, 3) and np.all(np.isfinite(g))


@pytest.mark.slow
def test_fit_capture_gradient(synthetic):
    """The relit images differentiate with respect to the fit's maps (checked against finite differences), and the
    whole fit with respect to the images (finite; the fit's discrete choices, its active sets, accepted steps and
    lobe owners, make it piecewise smooth only, so its derivative is not compared with finite differences)."""
    capture, normals, mask = synthetic
    small = capture.strided(4).select(np.arange(0, 32, 2))
    fit = pj.fit_capture(small, lobes=1, iterations=1)
    rng = np.random.default_rng(5)
    d_diffuse, d_mix = rng.normal(size=fit.diffuse.shape), rng.normal(size=fit.mix.shape)

    def relit(t):
        moved = eqx.tree_at(lambda f: (f.diffuse, f.mix), fit, (fit.diffuse + t * d_diffuse, fit.mix + t * d_mix))
        return jnp.sum(pj.relight(moved, small, residuals=False) ** 2)

    g = jax.grad(relit)(0.0)
    fd = (relit(1e-5) - relit(-1e-5)) / 2e-5
    np.testing.assert_allclose(float(g), float(fd), rtol=1e-6)
    direction = rng.normal(size=small.images.shape) * np.asarray(small.mask)[None, ..., None]

    def loss(t):
        c = pj.Capture(small.images + t * direction, small.mask, None, small.light_directions,
                       small.light_intensities, small.names, small.saturation, small.quantisation)
        out = pj.fit_capture(c, lobes=1, iterations=1)
        return jnp.sum(out.diffuse) + jnp.sum(out.normals[..., 0])

    gl = float(jax.grad(loss)(0.0))
    assert np.isfinite(gl) and gl != 0.0


@pytest.mark.slow
def test_fit_photos_without_normals(tmp_path, synthetic):
    capture, _, mask = synthetic
    images8 = np.clip(np.round(np.asarray(capture.images) / 2.0 * 255), 0, 255).astype(np.uint8)
    folder = tmp_path / "obj"
    write_folder(str(folder), images8, mask, np.asarray(capture.light_directions),
                 np.asarray(capture.light_intensities) / 2.0)
    out = tmp_path / "fit.npz"
    assert main(["--no-cache", "fit-photos", str(folder), "--lights", "0:32:2", "--lobes", "1", "--save",
                 str(out)]) == 0
    fit = pj.load_model(out)
    assert isinstance(fit, pj.CaptureFit) and fit.n_lobes == 1
    assert fit.normals.shape[-1] == 3 and fit.residuals.shape[0] == 16
    textures = tmp_path / "fit_textures"  # the normal map and material maps beside the saved fit
    assert {"normal.png", "normal.exr", "basecolor.png", "roughness.png", "metallic.png", "mix.exr"} <= {
        p.name for p in textures.iterdir()}
    card = tmp_path / "card.glb"  # and the saved fit exported as a .glb card
    assert main(["export", str(out), "--to", "gltf", "--out", str(card)]) == 0 and card.stat().st_size > 1000


@pytest.mark.data
@pytest.mark.slow
def test_fit_capture_diligent_cat():
    folder = os.path.join(os.environ.get("POLYJAX_DATA", ""), "diligent", "crop8", "catPNG")
    if not os.path.isdir(folder):
        pytest.skip("DiLiGenT crop8 not in POLYJAX_DATA")
    capture = pj.data.load_photometric(folder).strided(6)
    train = capture.select(np.arange(0, 96, 2))
    blind = pj.Capture(train.images, train.mask, None, train.light_directions, train.light_intensities,
                       train.names, train.saturation, train.quantisation)
    fit = pj.fit_capture(blind)
    mask, gt = np.asarray(capture.mask), np.asarray(capture.normals)
    ours = np.degrees(np.arccos(np.clip(np.sum(np.asarray(fit.normals)[mask] * gt[mask], -1), -1, 1))).mean()
    obs = np.asarray(train.images)[:, mask] / np.asarray(train.light_intensities)[:, None, :]
    b = np.linalg.lstsq(np.asarray(train.light_directions), obs.mean(-1), rcond=None)[0].T
    lam = np.degrees(np.arccos(np.clip(np.sum(b / np.linalg.norm(b, axis=1, keepdims=True) * gt[mask], -1),
                                       -1, 1))).mean()
    assert ours < 0.85 * lam, (ours, lam)
