"""Images: EXR round trip, sRGB previews, PSNR, difference images, figures."""

import numpy as np
import pytest

import polyjax as pj
import polyjax.render as pr


def test_exr_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    img = (rng.random((7, 11, 3)) * 50).astype(np.float32)
    img[0, 0] = [0.0, 1e-6, 6.5e4]
    path = pr.write_exr(tmp_path / "a.exr", img)
    back = pr.read_exr(path)
    assert back.dtype == np.float32 and back.shape == (7, 11, 3)
    np.testing.assert_array_equal(back, img)


def test_exr_errors(tmp_path):
    with pytest.raises(pj.DataNotFoundError):
        pr.read_exr(tmp_path / "missing.exr")
    bad = tmp_path / "bad.exr"
    bad.write_bytes(b"not an exr file")
    with pytest.raises(pj.DataFormatError, match="OpenEXR"):
        pr.read_exr(bad)
    with pytest.raises(pj.InputError, match="H, W, 3"):
        pr.write_exr(tmp_path / "x.exr", np.zeros((2, 3, 5)))


def test_envmap_from_exr(tmp_path):
    img = np.zeros((8, 16, 3), np.float32)
    img[2, 5] = 10.0
    env = pr.load_envmap(pr.write_exr(tmp_path / "env.exr", img))
    d, lp = pr.sample_pool(env, 64, seed=1)
    # every sample falls in the only bright pixel, and L / pdf is its radiance times its solid angle / p = 1
    theta = np.arccos(d[:, 1])
    assert np.all((theta >= 2 * np.pi / 8) & (theta <= 3 * np.pi / 8))
    np.testing.assert_allclose(np.asarray(env.radiance(np.asarray(d))), np.full((64, 3), 10.0))
    solid = (2 * np.pi / 16) * (np.cos(2 * np.pi / 8) - np.cos(3 * np.pi / 8))
    np.testing.assert_allclose(lp.mean(0), 10.0 * solid, rtol=0.05)


def test_psnr_identical_and_known_perturbation():
    rng = np.random.default_rng(1)
    ref = rng.random((16, 16, 3))
    assert float(pj.psnr(ref, ref, peak=1.0)) == np.inf
    # a constant error of 0.01 at peak 1: MSE 1e-4, PSNR 40 dB
    assert float(pj.psnr(ref + 0.01, ref, peak=1.0)) == pytest.approx(40.0, abs=1e-9)
    # half the pixels off by 0.1: MSE 5e-3, PSNR 10 log10(1 / 5e-3)
    pert = ref.copy()
    pert[:8] += 0.1
    assert float(pj.psnr(pert, ref, peak=1.0)) == pytest.approx(10 * np.log10(1 / 5e-3), abs=1e-9)


def test_srgb_and_png(tmp_path):
    x = np.array([[[0.0, 0.0031308, 1.0], [0.5, 2.0, np.nan]]])
    s = pr.to_srgb(x)
    np.testing.assert_allclose(s[0, 0], [0.0, 0.0031308 * 12.92, 1.0], rtol=1e-6)
    assert s[0, 1, 0] == pytest.approx(1.055 * 0.5 ** (1 / 2.4) - 0.055)
    assert s[0, 1, 1] == pytest.approx(1.0) and s[0, 1, 2] == 0.0
    import matplotlib.image

    path = pr.write_png(tmp_path / "p.png", np.full((4, 5, 3), 0.5))
    back = matplotlib.image.imread(str(path))
    assert back.shape[:2] == (4, 5)
    assert back[0, 0, 0] == pytest.approx(round(255 * (1.055 * 0.5 ** (1 / 2.4) - 0.055)) / 255)


def test_difference_images_share_one_scale():
    ref = np.zeros((4, 4, 3))
    a = ref + 0.1
    b = ref.copy()
    b[0, 0] = 0.4
    d, s = pr.difference_images([a, b], ref)
    assert s == pytest.approx(0.4)
    np.testing.assert_allclose(d[0], 0.25)
    assert d[1, 0, 0] == pytest.approx(1.0) and d[1, 1, 1] == 0.0
    d2, s2 = pr.difference_images([a], ref, scale=0.2)
    assert s2 == 0.2 and np.allclose(d2, 0.5)


def test_mosaic_and_comparison_figure(tmp_path):
    ims = [[np.full((3, 4, 3), k + 2 * r, float) for k in range(2)] for r in range(2)]
    mo = pr.mosaic(ims, pad=1)
    assert mo.shape == (2 * 3 + 3, 2 * 4 + 3, 3)
    assert mo[1, 1, 0] == 0 and mo[1 + 3 + 1, 1 + 4 + 1, 0] == 3
    ref = np.full((8, 8, 3), 0.5)
    scores = pr.comparison_figure(tmp_path / "fig.png", ref, [ref, ref * 0.9], ["same", "darker"])
    assert scores["same"] == np.inf and np.isfinite(scores["darker"])
    assert (tmp_path / "fig.png").stat().st_size > 0
