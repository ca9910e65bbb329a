"""Photographs under calibrated lights: the DiLiGenT-layout loader, the normal-map scenes, fits and relighting.

A synthetic capture is rendered by polyjax (a known polynomial BRDF on the normal map of a sphere), written in
DiLiGenT's layout with 16-bit PNGs, and loaded back: the float images refit exactly, the loaded (quantised) ones
within the quantisation. The shared capture is loaded and compared with a direct pypng reading.
"""

import dataclasses
import json
import os
import shutil

import jax
import jax.numpy as jnp
import numpy as np
import png
import pytest

import polyjax as pj
from polyjax.cli import main
from polyjax.render import Camera, DirectionalLight, Lambertian, NormalMap, Scene, Sphere, render

from _fuzz_problems import write_diligent as write_fuzz_diligent

#: ``fit-photos``' bound on the condition number of the degree it keeps (its --help and docs/photometric.md)
MAX_CONDITION = 50.0

H, W = 12, 14  # a small frame: the sphere's disc inside it
LIGHTS = np.array([[0.1, 0.2, 1.0], [-0.5, 0.3, 0.8], [0.6, -0.2, 0.75], [0.0, -0.6, 0.8], [0.4, 0.5, 0.7],
                   [-0.3, -0.4, 0.85], [0.7, 0.1, 0.7], [-0.6, -0.1, 0.8]])
LIGHTS = LIGHTS / np.linalg.norm(LIGHTS, axis=1, keepdims=True)
INTENSITY = np.array([[1.0, 0.9, 0.8], [1.2, 1.1, 1.3], [0.8, 0.85, 0.9], [1.1, 1.0, 0.95], [0.9, 1.05, 1.0],
                      [1.0, 1.0, 1.1], [0.95, 0.9, 1.2], [1.15, 1.0, 0.9]])


def sphere_normals(h=H, w=W):
    """Normals and mask of an orthographic view of a unit sphere filling most of the frame (+y up)."""
    ys = (h / 2 - (np.arange(h) + 0.5)) / (0.45 * h)
    xs = ((np.arange(w) + 0.5) - w / 2) / (0.45 * h)
    x, y = np.meshgrid(xs, ys)
    r2 = x**2 + y**2
    mask = r2 < 0.97
    n = np.stack([x, y, np.sqrt(np.clip(1 - r2, 0, 1))], -1)
    return np.where(mask[..., None], n, [0.0, 0.0, 1.0]), mask


@pytest.fixture(scope="module")
def truth():
    """A polynomial BRDF (Lafortune variables, p = 2, interactions) fitted to a glossy Phong-like lobe."""
    rng = np.random.default_rng(0)
    u = rng.normal(size=(400, 3))
    u[:, 2] = np.abs(u[:, 2]) + 0.2
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.array([0.0, 0.0, 1.0]) + 0 * u
    r = 2 * u[:, 2:3] * np.array([0, 0, 1.0]) - u
    lobe = 0.2 + 0.6 * np.clip(r @ np.array([0, 0, 1.0]), 0, 1) ** 2
    values = np.stack([lobe, 0.8 * lobe, 0.6 * lobe])
    return pj.fit_polynomial(u, v, values, "lafortune", 2, interactions=True, cutoff_deg=None)


@pytest.fixture(scope="module")
def synthetic(truth, tmp_path_factory):
    """``(folder, float images (L, H, W, 3), normals, mask)``: ``truth`` rendered and written in DiLiGenT's layout
    (16-bit PNGs, normal.txt and Normal_gt.mat)."""
    import scipy.io

    normals, mask = sphere_normals()
    cap = pj.Capture(np.zeros((len(LIGHTS), H, W, 3)), mask, normals, LIGHTS, INTENSITY,
                     tuple(f"{i + 1:03d}.png" for i in range(len(LIGHTS))))
    images = np.asarray(pj.relight(truth, cap)) * 0.5  # well inside [0, 1)
    cap = pj.Capture(images, mask, normals, LIGHTS, INTENSITY * 0.5, cap.names)
    folder = tmp_path_factory.mktemp("photometric") / "sphPNG"
    write_diligent(folder, cap)
    scipy.io.savemat(folder / "Normal_gt.mat", {"Normal_gt": normals}, do_compression=True)
    return folder, cap


def write_diligent(folder, cap, normal_file="normal.txt"):
    """``cap`` in DiLiGenT's layout: 16-bit PNGs of ``round(65535 x)``, 8-bit mask, exact light files."""
    os.makedirs(folder, exist_ok=True)
    (folder / "filenames.txt").write_text("".join(f"{n}\n" for n in cap.names))
    (folder / "light_directions.txt").write_text("".join(" ".join(repr(float(x)) for x in d) + "\n"
                                                         for d in cap.light_directions))
    (folder / "light_intensities.txt").write_text("".join(" ".join(repr(float(x)) for x in e) + "\n"
                                                          for e in cap.light_intensities))
    for name, img in zip(cap.names, np.asarray(cap.images)):
        px = np.round(np.clip(img, 0, 1) * 65535).astype(np.uint16)
        with open(folder / name, "wb") as fh:
            png.Writer(W, H, greyscale=False, bitdepth=16).write(fh, px.reshape(H, W * 3))
    with open(folder / "mask.png", "wb") as fh:
        png.Writer(W, H, greyscale=True, bitdepth=8).write(fh, (np.asarray(cap.mask) * 255).astype(np.uint8))
    rows = np.asarray(cap.normals).reshape(-1, 3)
    (folder / normal_file).write_text("".join(" ".join(repr(float(x)) for x in r) + "\n" for r in rows))


def test_normal_map_renders_like_the_sphere():
    """An orthographic render of a sphere and of its normal map agree pixel for pixel (the frames are the same)."""
    h = w = 16
    cam = Camera(eye=(0, 0, 3), width=w, height=h, ortho_height=2.2)
    light = DirectionalLight((0.3, 0.5, 1.0), (1.0, 0.8, 0.6))
    brdf = pj.render.Phong(0.3, 0.5, 12.0)
    ref = render(Scene(cam, [Sphere(brdf)], [light]), dtype=jnp.float64)
    o, d = (np.asarray(a) for a in cam.rays())
    hit = np.asarray(ref.hit).reshape(-1)
    b = np.sum(o * d, -1)
    t = -b - np.sqrt(np.maximum(b * b - (np.sum(o * o, -1) - 1), 0))
    n = np.where(hit[:, None], o + t[:, None] * d, [0, 0, 1.0])
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    img = render(Scene(cam, [NormalMap(brdf, n.reshape(h, w, 3), hit.reshape(h, w))], [light]), dtype=jnp.float64)
    np.testing.assert_allclose(np.asarray(img.image), np.asarray(ref.image), atol=1e-9)


def test_load_equals_direct_png_reading(synthetic):
    folder, cap = synthetic
    loaded = pj.data.load_photometric(folder)
    for name, img in zip(loaded.names, np.asarray(loaded.images)):
        w, h, rows, info = png.Reader(filename=str(folder / name)).read()
        assert info["bitdepth"] == 16
        direct = np.array([np.asarray(r, float) for r in rows]).reshape(h, w, 3) / 65535
        np.testing.assert_array_equal(img, direct)
    np.testing.assert_array_equal(np.asarray(loaded.mask), np.asarray(cap.mask))
    np.testing.assert_allclose(np.asarray(loaded.normals), np.asarray(cap.normals), atol=1e-15)
    np.testing.assert_allclose(loaded.light_directions, cap.light_directions, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(loaded.light_intensities, cap.light_intensities)
    assert np.max(np.abs(np.asarray(loaded.images) - np.asarray(cap.images))) <= 0.5 / 65535 + 1e-15
    sub = pj.data.load_photometric(folder, lights=[1, 3])
    np.testing.assert_array_equal(np.asarray(sub.images), np.asarray(loaded.images)[[1, 3]])
    assert sub.names == (loaded.names[1], loaded.names[3])


def test_mat_reader_matches_scipy(synthetic):
    import scipy.io

    folder, cap = synthetic
    ref = scipy.io.loadmat(folder / "Normal_gt.mat")["Normal_gt"]
    np.testing.assert_array_equal(pj.data.read_mat_array(str(folder / "Normal_gt.mat"), "Normal_gt"), ref)


def test_float_capture_refits_exactly(truth, synthetic):
    """Images rendered from a polynomial of the fitted space give it back: predictions to 1e-8 (every fit path),
    and the 16-bit capture within its quantisation."""
    folder, cap = synthetic
    for opts in (dict(weighting="radiance"), dict(weighting="brdf", robust_steps=1)):
        model = pj.fit_polynomial_to_images(cap.scenes, cap.images, "lafortune", 2, interactions=True,
                                            cutoff_deg=None, link="identity", **opts)
        assert np.all(np.asarray(model.status) == 0)
        np.testing.assert_allclose(np.asarray(pj.relight(model, cap)), np.asarray(cap.images), atol=1e-8, rtol=0)
    loaded = pj.data.load_photometric(folder)
    model = pj.fit_polynomial_to_images(loaded.scenes, loaded.images, "lafortune", 2, interactions=True,
                                        cutoff_deg=None, link="identity", saturation=loaded.saturation)
    err = np.abs(np.asarray(pj.relight(model, loaded)) - np.asarray(cap.images))
    assert err.max() < 2 / 65535  # the fit averages the rounding error of 1/2 step


def test_log_link_fit_from_images(synthetic):
    """``link="log"`` fits from the capture's scenes and predicts its images closely (a smooth lobe)."""
    _, cap = synthetic
    model = pj.fit_polynomial_to_images(cap.scenes, cap.images, "lafortune", 2, interactions=True, cutoff_deg=None,
                                        link="log", weighting="brdf")
    rel = np.linalg.norm(np.asarray(pj.relight(model, cap)) - cap.images) / np.linalg.norm(cap.images)
    assert model.link == "log" and rel < 0.02


def test_clamped_fit_from_images_is_bounded_under_lights_outside_the_fitted_range(synthetic):
    """Fitted under four lights up to 37 degrees from the view, a degree-6 polynomial diverges under lights at 40-45
    degrees (their ``theta_d`` lies outside the fitted range); with ``clamp`` it predicts them within 10%, and under
    the fitted lights it is the same model."""
    _, cap = synthetic
    fit, out = cap.select([0, 1, 3, 5]), cap.select([2, 4, 6, 7])
    kw = dict(interactions=True, weighting="brdf", cutoff_deg=None, link="identity")
    free = pj.fit_polynomial_to_images(fit.scenes, fit.images, "rusinkiewicz", 6, clamp=False, **kw)
    model = pj.fit_polynomial_to_images(fit.scenes, fit.images, "rusinkiewicz", 6, clamp=True, **kw)
    assert model.clamp and not free.clamp
    np.testing.assert_allclose(np.asarray(pj.relight(model, fit)), np.asarray(pj.relight(free, fit)), rtol=1e-12,
                               atol=1e-15)

    def rel(m):
        return np.linalg.norm(np.asarray(pj.relight(m, out)) - out.images) / np.linalg.norm(out.images)

    assert rel(free) > 1.0 and rel(model) < 0.15, (rel(free), rel(model))


def test_fit_photos_clamps_by_default(synthetic, tmp_path):
    folder, _ = synthetic
    for flags, clamp in (([], True), (["--no-clamp"], False)):
        path = tmp_path / f"m{len(flags)}.json"
        assert main(["--no-cache", "fit-photos", str(folder), "--variables", "lafortune", "--degree", "2", "--save",
                     str(path), *flags]) == 0
        assert pj.load_model(path).clamp is clamp


def _break(folder, tmp_path, what):
    bad = tmp_path / "bad"
    shutil.copytree(folder, bad)
    if what == "missing image":
        os.remove(bad / "003.png")
    elif what == "light count":
        with open(bad / "light_directions.txt", "a") as fh:
            fh.write("0 0 1\n")
    elif what == "8-bit":
        with open(bad / "002.png", "wb") as fh:
            png.Writer(W, H, greyscale=False, bitdepth=8).write(fh, np.zeros((H, W * 3), np.uint8))
    elif what == "normals":
        os.remove(bad / "Normal_gt.mat")
        rows = np.loadtxt(bad / "normal.txt")
        rows[5 * W + 7] *= 1.1
        np.savetxt(bad / "normal.txt", rows)
    return bad


@pytest.mark.parametrize("what, error, named", [
    ("missing image", pj.DataNotFoundError, "003.png"),
    ("light count", pj.DataFormatError, "light_directions.txt"),
    ("8-bit", pj.DataFormatError, "002.png"),
    ("normals", pj.DataFormatError, "normal.txt"),
])
def test_bad_captures_name_the_file(synthetic, tmp_path, what, error, named):
    bad = _break(synthetic[0], tmp_path, what)
    with pytest.raises(error, match=named):
        pj.data.load_photometric(bad)


def test_bad_arguments(synthetic):
    folder, cap = synthetic
    with pytest.raises(pj.InputError, match="lights"):
        pj.data.load_photometric(folder, lights=[0, 99])
    with pytest.raises(pj.DataNotFoundError):
        pj.data.load_photometric(folder / "nowhere")
    with pytest.raises(pj.InputError, match="weighting"):
        pj.fit_polynomial_to_images(cap.scenes, cap.images, "lafortune", 1, weighting="pixels")
    with pytest.raises(pj.InputError, match="only object"):
        Scene(cap.scenes[0].camera, [cap.scenes[0].objects[0], Sphere(Lambertian(0.5))], [DirectionalLight()])
    with pytest.raises(pj.InputError, match="unit normals"):
        NormalMap(Lambertian(0.5), np.full((2, 2, 3), 0.5))


@pytest.mark.parametrize("opts", [dict(), dict(weighting="brdf", robust_steps=1, link="identity", clamp=False),
                                  dict(weighting="brdf", robust_steps=1, clamp=False),
                                  dict(weighting="brdf", robust_steps=1, link="identity")])
def test_fit_derivative_wrt_images_matches_finite_differences(synthetic, opts):
    """d(prediction . r) / d(images) of the fit, against central differences in a random direction ``d``.

    With robust steps the fit is piecewise smooth, not smooth: Tukey's weights use the median of the relative
    residuals ``t`` and their MAD, taken by a sort, and where two pixels swap places at the middle of the sorted
    order the derivative jumps (it is exact on each side). A central difference of step ``h`` is the derivative
    (to ``O(h^2)``) only if no such kink lies within ``x +- h d``: here, with the log link, the median of ``t``
    changes pixel at ``x - 6.8e-7 d``, where the directional derivative jumps from -1.687 to -1.910, so a step
    ``h = 1e-5`` gave -1.791 (half the jump: ``(h - 6.8e-7) / (2 h) * 0.223``) where the forward difference and
    steps below 6.8e-7 give -1.687, the derivative. Hence the small step, and a check that the differences at
    ``h`` and ``2 h`` agree (a kink within ``2 h`` would part them); rounding costs ~1e-8 of the derivative at this
    step. The check has teeth: the derivative with the robust weights held constant is 14 % off (-1.444).
    """
    _, cap = synthetic
    small = cap.select([0, 1, 2, 3, 4])
    scenes = small.scenes
    rng = np.random.default_rng(1)
    direction = rng.normal(size=small.images.shape) * np.asarray(small.mask)[None, ..., None]
    probe = jnp.asarray(rng.normal(size=(3, 3)))
    dirs = jnp.asarray(LIGHTS[5:8])

    def objective(images):
        m = pj.fit_polynomial_to_images(scenes, images, "lafortune", 2, interactions=True, cutoff_deg=None, **opts)
        return jnp.sum(m(dirs, jnp.broadcast_to(jnp.asarray([0.0, 0.0, 1.0]), dirs.shape)) * probe)

    x = jnp.asarray(small.images + 0.01 * rng.normal(size=small.images.shape))
    g = jax.grad(objective)(x)
    fd = [float((objective(x + h * direction) - objective(x - h * direction)) / (2 * h)) for h in (1e-7, 2e-7)]
    np.testing.assert_allclose(fd[0], fd[1], rtol=1e-6)  # no kink within +-2h: the differences are the derivative
    np.testing.assert_allclose(float(jnp.sum(g * direction)), fd[0], rtol=1e-5, atol=1e-9)
    assert abs(fd[0]) > 0.1  # a derivative that matters, not a trivial zero


def test_fit_photos_and_relight_command_line(synthetic, tmp_path, capsys):
    folder, cap = synthetic
    model = tmp_path / "model.npz"
    with pytest.raises(SystemExit):
        main(["fit-photos", str(folder)])  # --save is required
    assert main(["--no-cache", "fit-photos", str(folder), "--lights", "0:8:2", "--variables", "lafortune",
                 "--degree", "2", "--link", "identity", "--save", str(model)]) == 0  # the data's own polynomial
    assert model.is_file()
    meta = pj.model_metadata(model)  # the fit's time, as printed, kept in the file
    assert meta["fit_command"] == "fit-photos" and f"({meta['fit_seconds']:.2f} s)" in capsys.readouterr().out
    assert main(["--no-cache", "fit-photos", str(folder), "--save", str(tmp_path / "none" / "m.npz")]) == 2
    out = tmp_path / "relit"
    capsys.readouterr()
    assert main(["--no-cache", "relight", str(model), str(folder), "--lights", "1,3", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "relative RMS" in text
    names = sorted(p.name for p in out.iterdir())
    assert names == sorted(f"{s}_{k}.{e}" for s in ("002", "004") for k in ("predicted", "error")
                           for e in ("exr", "png"))
    pred = pj.render.read_exr(out / "002_predicted.exr")
    assert np.max(np.abs(pred - cap.images[1])) < 1e-3  # noise-free data: the held-out light is predicted
    (tmp_path / "file").write_text("x")
    assert main(["--no-cache", "relight", str(model), str(folder), "--out", str(tmp_path / "file")]) == 2


@pytest.mark.data
def test_diligent_ball_loads(data_root):
    """The shared DiLiGenT ball: 16 bits kept, normals from the .mat file, images in camera units."""
    folder = os.path.join(data_root, "diligent", "ballPNG")
    cap = pj.data.load_photometric(folder, lights=[0, 5])
    assert cap.images.shape == (2, 512, 612, 3) and int(np.sum(cap.mask)) == 15791
    w, h, rows, _ = png.Reader(filename=os.path.join(folder, cap.names[1])).read()
    direct = np.array([np.asarray(r, float) for r in rows]).reshape(h, w, 3) / 65535
    np.testing.assert_array_equal(cap.images[1], direct)
    assert len(np.unique(np.round(cap.images[1] * 65535) % 256)) > 200  # not 8-bit values scaled
    np.testing.assert_allclose(np.linalg.norm(cap.normals[cap.mask], axis=-1), 1.0, atol=1e-6)


def test_fit_photos_and_the_api_default_to_the_same_bounded_fit(synthetic, tmp_path, capsys):
    """``polyjax fit-photos`` and ``pj.fit_polynomial_to_images`` with no options make the same model, clamped, at
    the same degree chosen by the same step-down (``degree="auto"``); ``--degree 8`` and ``degree=8`` keep 8."""
    folder, _ = synthetic
    cap = pj.data.load_photometric(folder).cropped()
    api = pj.fit_polynomial_to_images(cap.scenes, cap.images, saturation=cap.saturation)
    for option, model in (([], api), (["--degree", "8"], pj.fit_polynomial_to_images(
            cap.scenes, cap.images, degree=8, saturation=cap.saturation))):
        path = tmp_path / "m.npz"
        main(["--no-cache", "fit-photos", str(folder), *option, "--json", "--save", str(path)])
        out = json.loads(capsys.readouterr().out)  # strict JSON: a rank-deficient fit's condition number is null
        saved = pj.load_model(path)
        assert saved.spec == model.spec and model.clamp and model.link == "log" and model.variables == "rusinkiewicz"
        assert out["degree"] == model.max_degree
        np.testing.assert_allclose(np.asarray(saved.coefficients), np.asarray(model.coefficients), rtol=1e-9,
                                   atol=1e-12)
    assert out["degrees_left_out"] == [] and model.max_degree == 8
    assert api.max_degree < 8  # these 8 lights do not determine degree 8


def test_the_api_default_degree_is_the_highest_well_conditioned_one(synthetic):
    """``pj.fit_polynomial_to_images`` with ``degree="auto"`` (the default) keeps the highest degree up to 8 whose
    fit has full rank and a condition number of at most 50 (the next degree up is not), the same model as that
    degree given; ``spec=`` fixes the degree; under ``jax.jit`` and for a wrong string it raises a named error."""
    _, cap = synthetic
    api = pj.fit_polynomial_to_images(cap.scenes, cap.images, saturation=1.0)
    p = api.max_degree
    assert 1 <= p < 8 and np.all(np.asarray(api.status) == 0) and float(np.max(np.asarray(api.condition))) <= 50
    higher = pj.fit_polynomial_to_images(cap.scenes, cap.images, degree=p + 1, saturation=1.0)
    assert np.any(np.asarray(higher.status) != 0) or float(np.max(np.asarray(higher.condition))) > MAX_CONDITION
    same = pj.fit_polynomial_to_images(cap.scenes, cap.images, degree=p, saturation=1.0)
    assert same.spec == api.spec
    np.testing.assert_allclose(np.asarray(api.coefficients), np.asarray(same.coefficients), rtol=1e-12, atol=1e-14)
    fixed = pj.fit_polynomial_to_images(cap.scenes, cap.images, saturation=1.0,
                                        spec=dataclasses.replace(api.spec, degree=p + 1))
    assert fixed.max_degree == p + 1
    with pytest.raises(pj.InputError, match="degree='auto'.*integer degree"):
        jax.jit(lambda im: pj.fit_polynomial_to_images(cap.scenes, im, saturation=1.0).coefficients)(
            jnp.asarray(cap.images))
    with pytest.raises(pj.InputError, match="degree: expected one non-negative integer or 'auto'"):
        pj.fit_polynomial_to_images(cap.scenes, cap.images, degree="eight")


@pytest.mark.slow
def test_fit_photos_without_a_degree_keeps_the_highest_well_conditioned_one(synthetic, tmp_path, capsys):
    """With ``--degree`` left out, ``fit-photos`` steps down from 8 to the highest well-conditioned degree (these 8
    lights do not determine degree 8), says which degrees it left out and why, and fits the API's model at it."""
    folder, _ = synthetic
    cap = pj.data.load_photometric(folder).cropped()
    auto = tmp_path / "a.npz"
    assert main(["--no-cache", "fit-photos", str(folder), "--json", "--save", str(auto)]) == 0
    out = json.loads(capsys.readouterr().out)
    model = pj.load_model(auto)
    p = model.max_degree
    assert 1 <= p < 8 and out["degree"] == p and [d for d, _ in out["degrees_left_out"]] == list(range(8, p, -1))
    assert max(out["condition_rgb"]) <= MAX_CONDITION and out["status_rgb"] == ["OK"] * 3
    higher = pj.fit_polynomial_to_images(cap.scenes, cap.images, degree=p + 1, saturation=cap.saturation)
    assert (np.any(np.asarray(higher.status) != 0)
            or float(np.max(np.asarray(higher.condition))) > MAX_CONDITION)  # the next degree up is not kept
    same = pj.fit_polynomial_to_images(cap.scenes, cap.images, degree=p, saturation=cap.saturation)
    np.testing.assert_allclose(np.asarray(model.coefficients), np.asarray(same.coefficients), rtol=1e-9, atol=1e-12)


@pytest.mark.slow
def test_fit_photos_with_few_lights_keeps_a_degree_that_relights_them(data_root, tmp_path, capsys):
    """DiLiGenT's ball from 6 of its lights: at the API's degree 8 the fit is rank-deficient and relights the
    interleaved 6 others at a relative RMS above 1; ``fit-photos`` with ``--degree`` left out keeps a lower degree
    that relights them within 0.15."""
    ball = str(data_root / "diligent" / "ballPNG")
    errs = {}
    for name, extra in (("auto", []), ("eight", ["--degree", "8"])):
        path = tmp_path / f"{name}.npz"
        main(["--no-cache", "fit-photos", ball, "--lights", "0:48:8", *extra, "--save", str(path)])
        capsys.readouterr()
        assert main(["--no-cache", "relight", str(path), ball, "--lights", "1:48:8", "--json",
                     "--out", str(tmp_path / name)]) == 0
        errs[name] = json.loads(capsys.readouterr().out)["relative_rms_all"]
    assert pj.load_model(tmp_path / "auto.npz").max_degree < 8
    assert errs["auto"] < 0.15 and errs["eight"] > 1.0, errs


def test_a_capture_folder_by_name_is_found_under_the_data_root(tmp_path, monkeypatch, capsys):
    """``load_photometric("catPNG")`` and ``polyjax fit-photos catPNG`` look under the data root's ``diligent/`` and
    ``diligent/crop8/`` when no such folder is in the working directory; a name found nowhere is a named error that
    lists every place tried."""
    root = tmp_path / "root"
    write_fuzz_diligent(root / "diligent" / "crop8" / "toyPNG")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv(pj.DATA_ENV, str(root))
    cap = pj.data.load_photometric("toyPNG")
    assert cap.n_lights == 3 and cap.images.shape == (3, 4, 5, 3)
    assert pj.data.resolve_photometric_folder("toyPNG") == str(root / "diligent" / "crop8" / "toyPNG")
    local = write_fuzz_diligent(tmp_path / "toyPNG", lights=2)  # a folder of that name here wins
    assert pj.data.load_photometric("toyPNG").n_lights == 2
    shutil.rmtree(local)
    with pytest.raises(pj.DataNotFoundError, match="looked at dogPNG, .*diligent.dogPNG, .*crop8.dogPNG"):
        pj.data.load_photometric("dogPNG")
    assert main(["fit-photos", "toyPNG", "--variables", "lafortune", "--degree", "1",
                 "--save", str(tmp_path / "t.npz")]) in (0, 1)
    assert "scanned normals; --fit-normals fits the normals" in capsys.readouterr().out
    assert main(["fit-photos", "dogPNG", "--save", str(tmp_path / "d.npz")]) == 2
    assert "dogPNG: not a folder" in capsys.readouterr().err and not (tmp_path / "d.npz").exists()
