"""``polyjax view``: the page in a real browser (headless Chromium, software WebGL2 through SwiftShader).

One browser for the module; small canvases. The sphere is compared with polyjax's own render of the same scene
(PSNR in 8-bit sRGB), before and after a synthetic drag of the light; the polar plot's numbers with the model.
Chromium missing: skipped locally, a failure in CI (``CI`` set).
"""

import json
import os
import re
import subprocess
import sys
import urllib.request

import equinox as eqx
import numpy as np
import pytest
from _browser import Browser, find_chromium

import polyjax as pj

from _problems import polynomial_data

SIZE = 64
LIGHT = (2.0, 2.0, 4.0)
INTENSITY = 24.0


@pytest.fixture(scope="module")
def browser():
    exe = find_chromium()
    problem = None
    if exe is None:
        problem = "no Chromium (install Debian's chromium, or set POLYJAX_CHROMIUM)"
    else:
        try:
            import websocket  # noqa: F401
        except ImportError:
            problem = "the websocket-client package is missing (pip install websocket-client, the test extra)"
    if problem:
        if os.environ.get("CI"):
            pytest.fail(f"CI: {problem}: the viewer's browser tests must run in CI")
        pytest.skip(problem)
    b = Browser(exe)
    yield b
    b.close()


@pytest.fixture(scope="module")
def model():
    """An RGB polynomial (three lanes of different values: distinct channels in the shader)."""
    u, v, values, _ = polynomial_data("lafortune", 3, n=300, seed=3)
    lobe = np.maximum(u[:, 2] * v[:, 2] - u[:, 0] * v[:, 0] - u[:, 1] * v[:, 1], 0.0) ** 4
    rgb = np.stack([0.25 + 2.0 * lobe, 0.15 + 1.2 * lobe, 0.05 + 0.6 * lobe]) + 0.01 * values
    data = pj.make_measurements(u, v, rgb, channels=("R", "G", "B"), axes=("channel",), names=("lobe",))
    return pj.fit_polynomial(data, variables="lafortune", degree=3)


@pytest.fixture(scope="module")
def page(model, tmp_path_factory):
    """A page of the fit (program), a tabulated BRDF (table) and scattered samples (points)."""
    u, v, _, _ = polynomial_data("ward", 2, n=120, seed=5)
    points = pj.make_measurements(u, v, 0.3 + 0.0 * u[:, 0], names=("scattered",))
    table = pj.render.Lambertian(0.6)
    settings = pj.view.ViewSettings(size=SIZE, light=LIGHT, intensity=INTENSITY)
    path = tmp_path_factory.mktemp("view") / "page.html"
    pj.view.write_page([("fit", model), ("matte", table), points], path, settings=settings, resolution=(16, 16, 32))
    return path


def _open(browser, path, **kw):
    browser.open(path.resolve().as_uri(), **kw)
    assert browser.evaluate("window.polyjaxView.error") is None


def reference(model, light, exposure=0.0):
    """polyjax's render of the page's scene as 8-bit sRGB."""
    r = pj.render
    scene = r.Scene(r.Camera(width=SIZE, height=SIZE), [r.Sphere(model)],
                    [r.PointLight(position=light, intensity=INTENSITY)])
    image = np.asarray(r.render(scene).image)
    return np.round(r.to_srgb(image, exposure) * 255).astype(np.uint8)


def psnr8(a, b) -> float:
    mse = np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2)
    return float("inf") if mse == 0 else 10 * np.log10(255.0**2 / mse)


def _select(browser, which, index):
    frame = browser.evaluate("window.polyjaxView.frame")
    browser.evaluate(f"(() => {{ const s = document.getElementById('{which}'); s.value = '{index}'; "
                     "s.dispatchEvent(new Event('change')); })()")
    browser.wait_for(f"window.polyjaxView.frame > {frame}")


def test_every_view_loads_offline_without_console_errors(browser, page):
    _open(browser, page)
    kinds = [it["kind"] for it in json.loads(re.search(r'id="polyjax-data">(.*?)</script>', page.read_text(),
                                                       re.S).group(1))["items"]]
    assert kinds == ["program", "table", "points"]
    for a, b in ((0, 1), (1, 0), (2, 0), (0, 2), (1, -1)):
        _select(browser, "itemA", a)
        _select(browser, "itemB", b)
        shown = browser.evaluate("[...document.querySelectorAll('main > section')].filter(s => !s.hidden)"
                                 ".map(s => s.id)")
        if kinds[a] == "points":
            assert "pointsView" in shown and "sphereView" not in shown
            assert browser.evaluate("window.polyjaxView.points.n") == 120
        else:
            assert {"sphereView", "polarView", "infoView"} <= set(shown)
            if b >= 0 and kinds[b] == "points":
                assert browser.evaluate("window.polyjaxView.points.relative_rms") > 0
    assert browser.errors() == []
    assert browser.requests() == [page.resolve().as_uri()]  # nothing fetched but the page itself
    # a narrow window: everything wraps, nothing wider than the window
    _open(browser, page, width=360, height=640)
    assert browser.evaluate("document.documentElement.scrollWidth <= window.innerWidth")
    assert browser.errors() == []


def test_sphere_matches_polyjax_render(browser, page, model):
    _open(browser, page)
    shot = browser.screenshot("#sphereA")
    assert shot.shape == (SIZE, SIZE, 3)
    expected = reference(model, LIGHT)
    assert expected.mean() > 20 and (expected.max(axis=(0, 1)) > 150).all()  # a lit sphere, not a blank image
    value = psnr8(shot, expected)
    print(f"sphere vs pj.render: PSNR {value:.1f} dB, {np.mean(shot != expected):.4f} of the values differ")
    assert value >= 35.0
    # one stop more exposure: 2^1 L before sRGB, as polyjax.render.to_srgb
    frame = browser.evaluate("window.polyjaxView.frame")
    browser.evaluate("(() => { const e = document.getElementById('exposure'); e.value = '1'; "
                     "e.dispatchEvent(new Event('input')); })()")
    browser.wait_for(f"window.polyjaxView.frame > {frame}")
    brighter = browser.screenshot("#sphereA")
    assert psnr8(brighter, reference(model, LIGHT, exposure=1.0)) >= 35.0
    assert psnr8(brighter, shot) < 30.0
    # the error image |A - B| x gain against the difference of the two renders (B: the Lambertian's table)
    error = browser.screenshot("#sphereErr")
    r = pj.render
    scene = [r.Scene(r.Camera(width=SIZE, height=SIZE), [r.Sphere(brdf)],
                     [r.PointLight(position=LIGHT, intensity=INTENSITY)]) for brdf in (model, r.Lambertian(0.6))]
    a, b = (np.asarray(r.render(s).image) for s in scene)
    expected = np.round(r.to_srgb(np.abs(a - b) * 4.0, 1.0) * 255).astype(np.uint8)
    # inside 80% of the sphere's radius on the image (30.8 pixels): nearer the silhouette the table's trilinear
    # look-up mixes in the bins below the horizon (docs/viewer.md)
    yy, xx = np.mgrid[:SIZE, :SIZE] + 0.5 - SIZE / 2
    inside = np.hypot(xx, yy) < 0.8 * 30.8
    value, whole = psnr8(error[inside], expected[inside]), psnr8(error, expected)
    print(f"error image vs |render(A) - render(B)|: PSNR {value:.1f} dB inside, {whole:.1f} dB whole image")
    assert value >= 35.0


def test_dragging_the_light_changes_the_image_as_the_renderer_predicts(browser, page, model):
    _open(browser, page)
    before = browser.screenshot("#sphereA")
    box = browser.box("#sphereA")
    x, y = box["x"] + SIZE / 2, box["y"] + SIZE / 2
    frame = browser.evaluate("window.polyjaxView.frame")
    browser.drag(x, y, x - 60, y + 30)  # 0.5 degree per pixel: azimuth -30, elevation -15
    browser.wait_for(f"window.polyjaxView.frame > {frame}")
    state = browser.evaluate("window.polyjaxView.state")
    az0, el0 = np.degrees(np.arctan2(LIGHT[0], LIGHT[2])), np.degrees(np.arcsin(LIGHT[1] / np.linalg.norm(LIGHT)))
    assert state["azimuth"] == pytest.approx(az0 - 30, abs=1e-6)
    assert state["elevation"] == pytest.approx(el0 - 15, abs=1e-6)
    a, e, r = np.radians(az0 - 30), np.radians(el0 - 15), np.linalg.norm(LIGHT)
    moved = (r * np.cos(e) * np.sin(a), r * np.sin(e), r * np.cos(e) * np.cos(a))
    np.testing.assert_allclose(state["light"]["position"], moved, rtol=1e-9)
    after = browser.screenshot("#sphereA")
    value = psnr8(after, reference(model, moved))
    print(f"dragged sphere vs pj.render at the moved light: PSNR {value:.1f} dB")
    assert value >= 35.0
    assert psnr8(after, before) < 30.0  # the image did change
    # the keyboard moves it too: arrow right = +5 degrees of azimuth
    browser.evaluate("document.getElementById('sphereA').focus()")
    frame = browser.evaluate("window.polyjaxView.frame")
    browser.key("ArrowRight", 39)
    browser.wait_for(f"window.polyjaxView.frame > {frame}")
    assert browser.evaluate("window.polyjaxView.state.azimuth") == pytest.approx(az0 - 25, abs=1e-6)
    assert browser.errors() == []


def test_polar_plot_matches_the_model(browser, page, model):
    _open(browser, page)
    polar = browser.evaluate("window.polyjaxView.polar[0]")
    assert polar["item"] == 0 and polar["theta_in_deg"] == 45
    pick = np.linspace(4, len(polar["values"]) - 5, 16).round().astype(int)  # 16 angles inside (-90, 90)
    u = np.asarray(polar["u"], float).reshape(-1, 3)[pick]
    v = np.asarray(polar["v"], float).reshape(-1, 3)[pick]
    np.testing.assert_allclose(u, np.broadcast_to([-np.sin(np.pi / 4), 0, np.cos(np.pi / 4)], u.shape), atol=1e-7)
    expected = np.asarray(pj.render.evaluate_rgb(pj.render.rgb_brdf(model), u, v))
    got = np.asarray(polar["values"], float)[pick]
    assert np.ptp(expected[:, 0]) > 0.1  # a lobe, not a constant
    np.testing.assert_allclose(got, expected, rtol=2e-4, atol=2e-5)
    # the albedo of the Lambertian table: rho = 0.6 (quadrature and float16 texels), below 70 degrees of view
    # elevation; nearer the horizon the 16 x 16 x 32 table's trilinear look-up mixes in the bins below it (0)
    _select(browser, "itemA", 1)
    albedo = browser.evaluate("window.polyjaxView.albedo[0]")
    below = np.asarray(albedo["theta_v_deg"]) < 70
    assert below.sum() == 12
    np.testing.assert_allclose(np.asarray(albedo["values"])[below], 0.6, rtol=2e-3)


def _environment_reference(model, env, size):
    """The page's sphere under ``env`` and the light: pj.render's point-light image plus the midpoint rule over the
    map's texels (docs/viewer.md) on the renderer's primary rays and sphere frames; misses see the map."""
    r = pj.render
    cam = r.Camera(width=size, height=size)
    light = np.asarray(r.render(r.Scene(cam, [r.Sphere(model)], [r.PointLight(LIGHT, INTENSITY)])).image)
    o, d = (np.asarray(a, np.float64) for a in cam.rays())
    b = np.sum(o * d, -1)
    disc = b * b - np.sum(o * o, -1) + 1.0
    hit = disc >= 0
    n = o + (-b - np.sqrt(np.maximum(disc, 0)))[:, None] * d
    tx = np.stack([n[:, 2], 0 * n[:, 0], -n[:, 0]], -1)
    tx /= np.linalg.norm(tx, axis=-1, keepdims=True)
    bx = np.cross(n, tx)
    h, w = env.shape[:2]
    th, ph = np.meshgrid((np.arange(h) + 0.5) * np.pi / h, (np.arange(w) + 0.5) * 2 * np.pi / w - np.pi, indexing="ij")
    dirs = np.stack([np.sin(th) * np.sin(ph), np.cos(th), -np.sin(th) * np.cos(ph)], -1).reshape(-1, 3)
    weight = env.reshape(-1, 3) * (np.sin(th) * (np.pi / h) * (2 * np.pi / w)).reshape(-1, 1)
    local = lambda x: np.stack([x @ tx.T, x @ bx.T, x @ n.T], -1)  # noqa: E731 - (K, P, 3)
    ul = local(dirs)
    vl = np.broadcast_to(local(-d)[np.arange(len(d)), np.arange(len(d))], ul.shape)
    f = np.asarray(r.evaluate_rgb(r.rgb_brdf(model), ul.reshape(-1, 3), np.ascontiguousarray(vl).reshape(-1, 3)))
    cos = np.maximum(ul[..., 2], 0.0)
    env_term = np.einsum("kpc,kp,kc->pc", f.reshape(ul.shape), cos, weight)
    theta, phi = np.arccos(np.clip(d[:, 1], -1, 1)), np.arctan2(d[:, 0], -d[:, 2])
    i = np.clip(np.floor(theta / np.pi * h).astype(int), 0, h - 1)
    j = np.clip(np.floor((phi + np.pi) / (2 * np.pi) * w).astype(int), 0, w - 1)
    image = np.where(hit[:, None], light.reshape(-1, 3) + env_term, env[i, j]).reshape(size, size, 3)
    return np.round(r.to_srgb(image) * 255).astype(np.uint8)


def _power(m):
    """``int L dw`` of a latitude-longitude map (midpoint rule over its texels)."""
    h, w = m.shape[:2]
    return np.sum(m * np.sin((np.arange(h) + 0.5) * np.pi / h)[:, None, None]) * (np.pi / h) * (2 * np.pi / w)


def test_environment_map_lights_the_sphere_by_quadrature(browser, model, tmp_path):
    rng = np.random.default_rng(7)
    env = rng.uniform(0.05, 0.6, (32, 64, 3))  # averaged down to 16 x 32 by solid angle
    coarse = pj.view.environment_map(env)
    assert _power(coarse) == pytest.approx(_power(env), rel=1e-6)  # the map's power is kept
    size = 32
    path = pj.view.write_page([("fit", model)], tmp_path / "env.html", settings=pj.view.ViewSettings(
        size=size, light=LIGHT, intensity=INTENSITY, environment=env))
    _open(browser, path)
    lit = browser.screenshot("#sphereA")
    value = psnr8(lit, _environment_reference(model, coarse.astype(np.float64), size))
    print(f"environment-lit sphere vs the quadrature on pj.render's rays: PSNR {value:.1f} dB")
    assert value >= 35.0
    frame = browser.evaluate("window.polyjaxView.frame")
    browser.evaluate("document.getElementById('environment').click()")  # off: the point light alone
    browser.wait_for(f"window.polyjaxView.frame > {frame}")
    assert browser.evaluate("window.polyjaxView.state.environment") is False
    shot = browser.screenshot("#sphereA")
    r = pj.render
    alone = r.render(r.Scene(r.Camera(width=size, height=size), [r.Sphere(model)], [r.PointLight(LIGHT, INTENSITY)]))
    assert psnr8(shot, np.round(r.to_srgb(np.asarray(alone.image)) * 255).astype(np.uint8)) >= 35.0
    assert browser.errors() == []


def test_missing_webgl2_is_a_message_on_the_page(browser, page):
    script = browser.send("Page.addScriptToEvaluateOnNewDocument", {"source": (
        "const g = HTMLCanvasElement.prototype.getContext; HTMLCanvasElement.prototype.getContext = "
        "function (k, o) { return k === 'webgl2' ? null : g.call(this, k, o); };")})
    try:
        browser.open(page.resolve().as_uri())
        message = browser.evaluate("document.getElementById('message').hidden ? '' : "
                                   "document.getElementById('message').textContent")
    finally:
        browser.send("Page.removeScriptToEvaluateOnNewDocument", {"identifier": script["identifier"]})
    assert "WebGL2" in message


def _saved(model, tmp_path):
    path = tmp_path / "fit.json"
    pj.save_model(path, model)
    return path


def test_cli_writes_a_page_and_names_bad_arguments(model, tmp_path, capsys):
    from polyjax.cli import main

    fit = _saved(model, tmp_path)
    out = tmp_path / "page.html"
    assert main(["view", str(fit), "--out", str(out), "--size", "32"]) == 0
    text = out.read_text()
    assert "vec3 brdf_0(vec3 u, vec3 v)" in text and "<script src" not in text and "http" not in text.lower()
    assert main(["view", str(tmp_path / "nope.json"), "--out", str(out)]) == 2
    assert "nope.json" in capsys.readouterr().err
    assert main(["view", "not-a-spec", "--out", str(out)]) == 2
    assert "not-a-spec" in capsys.readouterr().err


def test_serve_answers_on_loopback_only(model, tmp_path):
    fit = _saved(model, tmp_path)
    out = tmp_path / "served.html"
    env = dict(os.environ, POLYJAX_CACHE="off")
    proc = subprocess.Popen([sys.executable, "-m", "polyjax", "view", str(fit), "--out", str(out), "--serve",
                             "--port", "0", "--size", "32"], stdout=subprocess.PIPE, text=True, env=env)
    try:
        line = ""
        while "http://" not in line:
            line = proc.stdout.readline()
            assert line, "the server exited before printing its address"
        address = re.search(r"http://[0-9.]+:\d+/", line).group(0)
        assert address.startswith("http://127.0.0.1:")
        with urllib.request.urlopen(address, timeout=30) as reply:
            assert reply.read() == out.read_bytes()
    finally:
        proc.terminate()
        proc.wait(30)


def test_models_without_an_expression_are_tabulated_on_the_merl_grid(model):
    from _sampling_problems import cook_torrance

    ct = cook_torrance()
    items = pj.view.as_items([("ct", ct), ("fit", model)], resolution=(8, 8, 16))
    assert [i.kind for i in items] == ["table", "program"]
    assert "tabulated" in items[0].info["shown as"]
    u, v, _, above = pj.data.merl_grid((8, 8, 16))
    expected = np.where(above[:, None], np.asarray(pj.render.evaluate_rgb(ct, u, v)), 0.0)
    np.testing.assert_allclose(items[0].table.reshape(-1, 3), expected, rtol=1e-6, atol=1e-7)
    failed = eqx.tree_at(lambda m: m.l2, model, np.full(model.l2.shape, np.nan))  # a failed fit: L2 NaN
    assert "null" in pj.view.page_html(pj.view.as_items([failed]))
    with pytest.raises(pj.DataNotFoundError, match="no-such"):
        pj.view.as_items(["no-such.json"])



def test_a_model_that_is_not_reciprocal_is_tabulated_over_the_whole_turn_of_phi_d():
    """f(u, v) != f(v, u) cannot live in MERL's phi_d in [0, pi) (both orders of a pair read one bin: a seam on
    the sphere): such a model's table has 2 N_p bins of phi_d, f(u, v) in the first N_p and f(v, u) in the rest;
    a reciprocal one keeps N_p."""
    import jax.numpy as jnp

    def skewed(u, v):
        return jnp.stack([0.2 + 0.3 * u[..., 2] * (1 - v[..., 2])] * 3, -1)  # light and view in different roles

    res = (8, 8, 16)
    items = pj.view.as_items([("skewed", skewed), ("matte", pj.render.Lambertian(0.6))], resolution=res)
    assert not items[0].reciprocal and items[0].table.shape == (8, 8, 32, 3)
    assert "whole turn" in items[0].info["shown as"]
    assert items[1].reciprocal and items[1].table.shape == (8, 8, 16, 3)
    u, v, _, above = pj.data.merl_grid(res)
    for a, b, half in ((u, v, slice(0, 16)), (v, u, slice(16, 32))):
        expected = np.where(above[:, None], np.asarray(skewed(a, b)), 0.0)
        np.testing.assert_allclose(items[0].table[:, :, half].reshape(-1, 3), expected, rtol=1e-6, atol=1e-7)
    assert "merl_lookup(table_0, vec3(8.0, 8.0, 32.0), u, v, 2.0 * PI)" in pj.view.page_html(items)
    assert "merl_lookup(table_1, vec3(8.0, 8.0, 16.0), u, v, PI)" in pj.view.page_html(items)

@pytest.mark.slow
def test_report_html_is_a_page_of_the_reports_fits(browser, tmp_path, monkeypatch, capsys):
    from polyjax.cli import main

    monkeypatch.delenv(pj.DATA_ENV, raising=False)
    out = tmp_path / "report.html"
    assert main(["report", "--html", str(out)]) == 0
    assert "L2 for p = 1..8" in capsys.readouterr().out
    _open(browser, out)
    assert browser.evaluate("window.polyjaxView.items") == [
        "synthetic-matte", "ashikhmin-shirley p=5", "lafortune p=7", "ward p=7"]
    assert "L2 for p = 1..8" in browser.evaluate("document.getElementById('text').textContent")
    assert browser.evaluate("window.polyjaxView.points.relative_rms") < 0.5  # the data against the first fit
    assert browser.errors() == []


@pytest.mark.data
def test_neural_fits_run_their_network_in_the_page(browser, tmp_path):
    nbrdf = pj.data.load_nbrdf("gold-metallic-paint")
    path = pj.view.write_page([("nbrdf", nbrdf)], tmp_path / "nbrdf.html",
                              settings=pj.view.ViewSettings(size=32))
    _open(browser, path)
    polar = browser.evaluate("window.polyjaxView.polar[0]")
    u = np.asarray(polar["u"], float).reshape(-1, 3)[4:-4:5]
    v = np.asarray(polar["v"], float).reshape(-1, 3)[4:-4:5]
    assert len(u) == 17
    expected = np.asarray(nbrdf(u, v))
    np.testing.assert_allclose(np.asarray(polar["values"], float)[4:-4:5], expected, rtol=1e-3,
                               atol=1e-4 * expected.max())
    assert browser.errors() == []


@pytest.mark.data
def test_measured_data_sets_become_points_or_tables():
    curet = pj.view.as_items(["curet:25"])
    assert [i.kind for i in curet] == ["points"] and curet[0].u.shape == (205, 3)
    merl = pj.view.as_items([pj.data.load("merl-nbrdf:green-latex", subsample=60000, seed=0)],
                            resolution=(24, 24, 48))
    assert [i.kind for i in merl] == ["table"] and merl[0].table.shape == (24, 24, 48, 3)
    assert float(merl[0].table.max()) > 0
    cornell = pj.view.as_items(["cornell:cayman"])
    assert [i.kind for i in cornell] == ["points"] and cornell[0].values.shape[1] == 3
