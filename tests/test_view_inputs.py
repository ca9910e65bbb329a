"""``polyjax view`` of photometric captures, RGL-EPFL files and saved fit times, in headless Chromium.

A small capture is rendered by polyjax (a known BRDF on a sphere's normal map), written in DiLiGenT's layout and
viewed beside a fit from its images: the page's BRDF samples are the BRDF, its relit images equal
``pj.relight`` and its errors those of ``polyjax relight``. An RGL-EPFL file written by the test is a table of its
BSDF at the bin centres. A fit saved by ``polyjax fit --save`` keeps its time, which the page shows.
"""

import json
import os
import re

import numpy as np
import png
import pytest
from test_view import _open, browser, psnr8  # noqa: F401 - the module's browser fixture

import polyjax as pj

from _rgl_problems import rgl_fields, write_tensor_file

H, W = 10, 12
LIGHTS = np.array([[0.1, 0.2, 1.0], [-0.5, 0.3, 0.8], [0.6, -0.2, 0.75], [0.0, -0.6, 0.8], [0.4, 0.5, 0.7]])
LIGHTS = LIGHTS / np.linalg.norm(LIGHTS, axis=1, keepdims=True)
INTENSITY = np.array([[1.0, 0.9, 0.8], [1.2, 1.1, 1.3], [0.8, 0.85, 0.9], [1.1, 1.0, 0.95], [0.9, 1.05, 1.0]])


class Truth:
    """A glossy RGB BRDF ``(..., 3)``: a Lambertian base and a Phong-like lobe about the mirror direction."""

    def __call__(self, u, v):
        import jax.numpy as jnp

        r = 2 * u[..., 2:3] * jnp.array([0.0, 0.0, 1.0]) - u
        lobe = jnp.clip(jnp.sum(r * v, -1), 0, 1) ** 4
        return jnp.stack([0.2 + 0.8 * lobe, 0.15 + 0.6 * lobe, 0.1 + 0.4 * lobe], -1)


def _write_capture(folder, images, mask, normals):
    """DiLiGenT's layout: names, lights, 16-bit PNGs of ``round(65535 x)``, an 8-bit mask, ``normal.txt``."""
    os.makedirs(folder)
    names = [f"{i + 1:03d}.png" for i in range(len(images))]
    (folder / "filenames.txt").write_text("".join(f"{n}\n" for n in names))
    for file, rows in (("light_directions.txt", LIGHTS), ("light_intensities.txt", INTENSITY)):
        (folder / file).write_text("".join(" ".join(repr(float(x)) for x in r) + "\n" for r in rows))
    for name, img in zip(names, images):
        with open(folder / name, "wb") as fh:
            px = np.round(np.clip(img, 0, 1) * 65535).astype(np.uint16)
            png.Writer(W, H, greyscale=False, bitdepth=16).write(fh, px.reshape(H, W * 3))
    with open(folder / "mask.png", "wb") as fh:
        png.Writer(W, H, greyscale=True, bitdepth=8).write(fh, mask.astype(np.uint8) * 255)
    (folder / "normal.txt").write_text("".join(" ".join(repr(float(x)) for x in r) + "\n"
                                               for r in normals.reshape(-1, 3)))


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    """``(folder, loaded capture, fit)``: the truth rendered on a sphere's normals (one pixel of image 2
    saturated), written and loaded back, and a Lafortune p = 2 fit to its images (imperfect on purpose)."""
    ys, xs = (H / 2 - (np.arange(H) + 0.5)) / (0.45 * H), ((np.arange(W) + 0.5) - W / 2) / (0.45 * H)
    x, y = np.meshgrid(xs, ys)
    mask = x**2 + y**2 < 0.95
    normals = np.where(mask[..., None], np.stack([x, y, np.sqrt(np.clip(1 - x**2 - y**2, 0, 1))], -1), [0, 0, 1.0])
    blank = pj.Capture(np.zeros((len(LIGHTS), H, W, 3)), mask, normals, LIGHTS, INTENSITY,
                       tuple(f"{i + 1:03d}.png" for i in range(len(LIGHTS))))
    images = 0.5 * np.asarray(pj.relight(Truth(), blank))
    i, j = np.argwhere(mask)[7]
    images[2, i, j] = 1.0  # saturated: left out of the samples and the errors
    folder = tmp_path_factory.mktemp("capture") / "sphPNG"
    _write_capture(folder, images, mask, normals)
    loaded = pj.data.load_photometric(folder)
    fit = pj.fit_polynomial_to_images(loaded.scenes, loaded.images, "lafortune", 2, weighting="brdf",
                                      saturation=loaded.saturation, cutoff_deg=None)
    return folder, loaded, fit


def _page_data(path):
    return json.loads(re.search(r'id="polyjax-data">(.*?)</script>', path.read_text(), re.S).group(1))


def _errors(predicted, capture):
    """Per light ``(relative RMS, PSNR in dB)`` of ``predicted (L, H, W, 3)`` against the capture's photographs and
    the relative RMS of all lights together, over the mask's pixels with no saturated channel (PSNR's peak: the
    camera's white, ``capture.saturation``): the errors ``polyjax relight`` prints (docs/photometric.md)."""
    images = np.asarray(capture.images, np.float64)
    keep = np.asarray(capture.mask)[None] & np.all(images < capture.saturation, axis=-1)
    diff2 = [np.sum((np.asarray(p)[k] - i[k]) ** 2) for p, i, k in zip(predicted, images, keep)]
    rows = [(float(np.sqrt(d2 / np.sum(i[k] ** 2))), float(10 * np.log10(capture.saturation**2 / (d2 / (3 * k.sum())))))
            for d2, i, k in zip(diff2, images, keep)]
    return rows, float(np.sqrt(sum(diff2) / np.sum(images[keep] ** 2)))


def test_capture_samples_photographs_and_relit_fit(browser, capture, tmp_path):  # noqa: F811
    folder, loaded, fit = capture
    path = pj.view.write_page([("fit", fit), str(folder)], tmp_path / "capture.html",
                              settings=pj.view.ViewSettings(size=48))
    items = pj.view.as_items([str(folder)])
    assert [it.kind for it in items] == ["points"] and items[0].name == "sphPNG"
    shown = items[0].capture
    assert np.shape(shown.mask) == (H, W)  # cropped with a margin of 2: the whole small frame
    lit = np.asarray(shown.mask)[None] & (np.einsum("hwc,lc->lhw", np.asarray(shown.normals), LIGHTS) > 0)
    kept = lit & np.all(np.asarray(shown.images) < 1.0, axis=-1)
    assert items[0].u.shape == (int(kept.sum()), 3) and kept.sum() == lit.sum() - 1  # the saturated pixel out
    # the samples I / (E cos) are the BRDF at their directions (0.5 x: the images' scale), to the PNGs'
    # quantisation 0.5 / 65535 / (E cos), E >= 0.8
    u, v, b = (np.asarray(a, np.float64) for a in (items[0].u, items[0].v, items[0].values))
    error = np.abs(b - 0.5 * np.asarray(Truth()(u, v)))
    assert np.all(error <= 0.5 / 65535 / (0.8 * u[:, 2:3]) + 1e-5) and b.max() > 0.4

    _open(browser, path)
    photos = browser.evaluate("window.polyjaxView.photos")
    assert (photos["item"], photos["fit"], photos["light"], photos["n_lights"]) == (1, 0, 0, 5)
    relit = np.asarray(pj.relight(fit, shown))
    mask = np.asarray(shown.mask)
    np.testing.assert_allclose(np.asarray(photos["predicted"]).reshape(-1, 3), relit[0][mask], rtol=1e-4, atol=1e-6)
    rows, total = _errors(relit, shown)
    print(f"page vs polyjax relight: relative RMS {photos['relative_rms_all']:.6f} vs {total:.6f}")
    assert 0.01 < total < 0.5  # an imperfect fit: the comparison means something
    np.testing.assert_allclose(photos["relative_rms"], [r for r, _ in rows], rtol=1e-4)
    np.testing.assert_allclose(photos["psnr_db"], [p for _, p in rows], atol=1e-3)
    assert photos["relative_rms_all"] == pytest.approx(total, rel=1e-4)
    # the photograph and the relit fit on screen: 2^0 x, clipped, sRGB, 8 bits; 4 screen pixels a pixel
    k = 48 // W
    for canvas, image in (("#photo", np.asarray(shown.images)[0]), ("#photoFit", relit[0])):
        shot = browser.screenshot(canvas)[k // 2::k, k // 2::k]
        expected = np.where(mask[..., None], np.round(pj.render.to_srgb(image) * 255), 0).astype(np.uint8)
        assert shot.shape == (H, W, 3) and psnr8(shot, expected) >= 45.0
    # the BRDF samples against the fit at their directions (the points view)
    f = np.moveaxis(np.asarray(fit(u, v)), 0, -1)
    rel = np.sqrt(np.sum((f - b) ** 2) / np.sum(b**2))
    assert browser.evaluate("window.polyjaxView.points.relative_rms") == pytest.approx(rel, rel=1e-4)
    # another light: its photograph and prediction
    frame = browser.evaluate("window.polyjaxView.frame")
    browser.evaluate("(() => { const e = document.getElementById('photoLight'); e.value = '3'; "
                     "e.dispatchEvent(new Event('input')); })()")
    browser.wait_for(f"window.polyjaxView.frame > {frame}")
    photos = browser.evaluate("window.polyjaxView.photos")
    assert photos["light"] == 3
    np.testing.assert_allclose(np.asarray(photos["predicted"]).reshape(-1, 3), relit[3][mask], rtol=1e-4, atol=1e-6)
    assert browser.errors() == []


def test_rgl_file_is_a_table_of_its_bsdf_at_the_bin_centres(browser, tmp_path):  # noqa: F811
    bsdf = write_tensor_file(tmp_path / "iso.bsdf", rgl_fields(seed=3))
    res = (8, 8, 16)
    items = pj.view.as_items([f"rgl:{bsdf}"], resolution=res)
    assert [it.kind for it in items] == ["table"] and "centres of the 8x8x16" in items[0].info["shown as"]
    u, v, _, above = pj.data.merl_grid(res)
    # a measured BSDF need not be reciprocal (this one is not): phi_d over the whole turn, f(u, v) in the first
    # 16 bins, f(v, u) in the next 16
    assert not items[0].reciprocal and items[0].table.shape == (8, 8, 32, 3)
    assert "whole turn" in items[0].info["shown as"]
    halves = []
    for a, b, half in ((u, v, slice(0, 16)), (v, u, slice(16, 32))):
        truth = np.asarray(pj.data.load_rgl(bsdf, directions=(a[above], b[above])).values).T
        table = items[0].table[:, :, half].reshape(-1, 3)
        np.testing.assert_allclose(table[above], truth, rtol=1e-6)
        assert np.all(table[~above] == 0) and truth.max() > 0
        halves.append(table)
    assert np.max(np.abs(halves[0] - halves[1])) > 1e-3 * np.max(halves[0])
    path = pj.view.write_page([f"rgl:{bsdf}"], tmp_path / "rgl.html", resolution=res,
                              settings=pj.view.ViewSettings(size=32))
    _open(browser, path)
    # the page's look-up at bin centres away from the horizon, both orders: the table's values (float16 texels;
    # pairs in the plane of incidence among them, whose turned difference vector has y = -0.0)
    pick = np.flatnonzero(above & (u[:, 2] > 0.2) & (v[:, 2] > 0.2))[::7]
    assert len(pick) > 40
    for (a, b), table in zip(((u, v), (v, u)), halves):
        got = browser.evaluate(f"window.polyjaxView.evaluate(0, {a[pick].ravel().tolist()}, "
                               f"{b[pick].ravel().tolist()})")
        np.testing.assert_allclose(np.asarray(got), table[pick], rtol=2e-3, atol=1e-5)
    assert browser.errors() == []


@pytest.mark.data
def test_shared_rgl_file_by_name(tmp_path):
    from polyjax.cli import main

    out = tmp_path / "paper.html"
    assert main(["view", "rgl:paper_white_rgb", "--table-resolution", "6,6,12", "--out", str(out)]) == 0
    (item,) = _page_data(out)["items"]
    assert item["kind"] == "table" and item["resolution"] == [6, 6, 24]  # not reciprocal: the whole turn
    assert item["info"]["source"] == "RGL-EPFL measured BSDF paper_white_rgb"


def test_fit_time_is_kept_in_the_saved_model_and_shown(browser, tmp_path, monkeypatch, capsys):  # noqa: F811
    from polyjax.cli import main

    monkeypatch.delenv(pj.DATA_ENV, raising=False)  # the synthetic data set
    saved = tmp_path / "fit.json"
    assert main(["fit", "--degree", "2", "--save", str(saved), "--json"]) == 0
    seconds = json.loads(capsys.readouterr().out)["seconds"]
    assert pj.model_metadata(saved) == {"fit_seconds": seconds, "fit_command": "fit"} and seconds > 0
    model = pj.load_model(saved)
    plain = tmp_path / "plain.npz"
    pj.save_model(plain, model)  # from Python: no time
    assert pj.model_metadata(plain) == {}
    with pytest.raises(pj.InputError, match="metadata"):
        pj.save_model(tmp_path / "bad.npz", model, metadata={"fit_seconds": float("nan")})
    out = tmp_path / "times.html"
    assert main(["view", str(saved), str(plain), "--out", str(out), "--size", "32"]) == 0
    timed, untimed = _page_data(out)["items"]
    assert timed["fit_seconds"] == seconds and untimed["fit_seconds"] is None
    assert timed["info"]["fit time"] == f"{seconds:.3f} s (polyjax fit, compilation included)"
    assert untimed["info"]["fit time"].startswith("not recorded")
    assert list(timed["info"]).index("fit time") == list(timed["info"]).index("L2") + 1
    _open(browser, out)
    rows = browser.evaluate("[...document.querySelectorAll('#infoA tr, #infoB tr')].map(r => [...r.cells]"
                            ".map(c => c.textContent))")
    shown = [b for a, b in rows if a == "fit time"]
    assert shown == [timed["info"]["fit time"], untimed["info"]["fit time"]]
    assert browser.errors() == []


@pytest.mark.data
def test_diligent_ball_photographs_on_the_page(browser, data_root, tmp_path):  # noqa: F811
    from polyjax.cli import main

    folder = data_root / "diligent" / "ballPNG"
    out = tmp_path / "ball.html"
    assert main(["view", str(folder), "--lights", "0,24", "--out", str(out), "--size", "64"]) == 0
    shown, step = pj.view._capture.shown_capture(pj.data.load_photometric(folder, [0, 24]))
    assert step == 2 and np.shape(shown.mask) == (73, 73)
    _open(browser, out)
    photos = browser.evaluate("window.polyjaxView.photos")
    assert (photos["fit"], photos["n_lights"], photos["width"]) == (None, 2, 73)
    assert photos["pixels"] == int(np.sum(shown.mask))
    shot = browser.screenshot("#photo")
    expected = np.where(np.asarray(shown.mask)[..., None],
                        np.round(pj.render.to_srgb(np.asarray(shown.images)[0]) * 255), 0).astype(np.uint8)
    assert shot.shape == (73, 73, 3) and psnr8(shot, expected) >= 45.0
    assert browser.evaluate("window.polyjaxView.points.n") == _page_data(out)["items"][0]["n"] > 2000
    assert browser.errors() == []


def test_polynomials_the_export_does_not_write_are_tables():
    d = pj.data.synthetic_default()
    fit = pj.fit_polynomial(d.u, d.v, np.asarray(d.values)[0], "rusinkiewicz", 2)
    (item,) = pj.view.as_items([("r", fit)], resolution=(4, 4, 8))
    assert item.kind == "table" and item.info["variables"] == "rusinkiewicz"
    assert "'rusinkiewicz' cannot be exported" in item.info["shown as"]
    u, v, _, above = pj.data.merl_grid((4, 4, 8))
    expected = np.where(above, np.maximum(np.asarray(fit(u, v)), 0.0), 0.0)
    np.testing.assert_allclose(item.table[..., 0].ravel(), expected, rtol=1e-6, atol=1e-7)
    assert item.fit_seconds is None and item.info["fit time"].startswith("not recorded")
