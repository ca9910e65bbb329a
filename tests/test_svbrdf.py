"""The SVBRDF pipeline end to end on neural MERL materials: simulated capture, per-texel fits, coefficient
textures, re-rendering under a new light; and its command line."""

import json

import jax.numpy as jnp
import numpy as np
import pytest

import polyjax as pj
from polyjax import svbrdf

# two diffuse-to-glossy materials that equation (3) follows well at low degree (docs/scale.md has the others)
MATERIALS, VARIABLES, DEGREE = ("pink-fabric", "pink-felt"), "lafortune", 3
TEXELS = [(0, 0), (3, 5), (7, 7), (2, 6), (5, 1)]


def _capture_fit(materials):
    mats = [pj.data.load_nbrdf(n) for n in materials]
    cap = svbrdf.simulate_capture(mats, 8, 8, n_lights=48)
    return mats, cap, svbrdf.fit_capture(cap, VARIABLES, DEGREE)


@pytest.fixture(scope="module")
def capture_fit():
    return _capture_fit(MATERIALS)


def _recovery_ratios(capture_fit, at_least_one=True):
    """Per texel and channel: L2 of the texel's fit (48 photographs at one view direction) on the MERL grid
    against the texel's true blend, over the L2 of the fit to that blend's own MERL-grid data at the same degree."""
    mats, cap, model = capture_fit
    assert np.all(np.asarray(model.status) == pj.RESULTS.OK)
    materials = MATERIALS
    grid = pj.data.load_merl_nbrdf(list(materials), subsample=20000)
    a = np.asarray(cap.blend)
    truth = np.stack([sum(a[i, j, m] * grid.values[m] for m in range(len(mats))) for i, j in TEXELS])
    own = pj.fit_polynomial(grid.u, grid.v, truth, VARIABLES, DEGREE, weights=grid.weights)
    ratios = np.stack([np.asarray(pj.l2_error(truth[t], model[i, j](grid.u, grid.v), grid.u, grid.v,
                                              weights=grid.weights)) / np.asarray(own.l2[t])
                       for t, (i, j) in enumerate(TEXELS)])
    assert ratios.shape == (5, 3)
    if at_least_one:  # one view: the grid fit is the optimum there (see the several-views test for why not always)
        assert np.all(ratios >= 1.0 - 1e-9), ratios
    return ratios


@pytest.mark.data
def test_texels_recover_their_material(capture_fit):
    """A bound on what is measured (1.10 to 1.61, median 1.37 for these 5 texels x 3 channels), not the issue's
    1.2x target, which the next test holds as an expected failure."""
    ratios = _recovery_ratios(capture_fit)
    assert np.all(ratios <= 2.0), ratios


@pytest.mark.data
@pytest.mark.xfail(strict=True, reason="not met: 1.10 to 1.61 (48 lights), 1.09 to 1.58 with 1500 lights down to "
                   "1 degree elevation; one fixed view reaches uz vz <= cos(theta_v), |ux vx + uy vy| <= sin(theta_v) "
                   "only (16-27% of equation (11)'s weight is outside; every view's MERL data inside that part fit to "
                   "1.04-1.27x on the whole grid) and sees one slice of the BRDF there; lights, weighting, PCA, "
                   "variables, degree and camera examined in docs/scale.md")
def test_texels_recover_their_material_within_target(capture_fit):
    """The issue's target: every texel within 1.2x."""
    assert np.all(_recovery_ratios(capture_fit) <= 1.2)


@pytest.mark.data
def test_one_view_region_costs_the_target(capture_fit):
    """Part of why the 1.2x target is not met from one view. A texel seen from ``theta_v`` has Lafortune variables
    ``x1 = ux vx + uy vy`` and ``x2 = uz vz`` only in ``|x1| <= sin theta_v``, ``x2 <= cos theta_v`` whatever the
    lights (16-27% of equation (11)'s weight lies outside). Fitting the blend's own MERL-grid data (every view
    direction, far more than one view's slice) restricted to that part of the domain, and measuring equation (11)
    on the whole grid, gives 1.04-1.27x: the domain alone exceeds 1.2x for 4 of the 15 texel channels. The rest of
    the gap to the capture's 1.10-1.61x is the slice itself: one view sees one curve of values at each ``(x1, x2)``
    where the grid fit averages over every view (the BRDF is not a function of the two variables)."""
    mats, cap, _ = capture_fit
    grid = pj.data.load_merl_nbrdf(list(MATERIALS), subsample=20000)
    a = np.asarray(cap.blend)
    truth = np.stack([sum(a[i, j, m] * grid.values[m] for m in range(len(mats))) for i, j in TEXELS])  # (5, 3, n)
    x = np.asarray(pj.get_variables(VARIABLES)(grid.u, grid.v))
    cos_v = np.array([float(svbrdf.directions(cap.positions[i, j], cap.lights, cap.camera)[1][2]) for i, j in TEXELS])
    seen = (x[None, :, 1] <= cos_v[:, None]) & (np.abs(x[None, :, 0]) <= np.sqrt(1 - cos_v[:, None] ** 2))
    ok = (np.asarray(grid.u)[:, 2] >= np.cos(np.radians(80))) & (np.asarray(grid.v)[:, 2] >= np.cos(np.radians(80)))
    wc2 = np.asarray(grid.weights) * np.asarray(grid.u)[:, 2] ** 2 * ok
    outside = 1 - (seen * wc2).sum(-1) / wc2.sum()
    assert np.all((outside > 0.15) & (outside < 0.28)), outside  # 0.16 - 0.27 of equation (11)'s weight unseen
    own = pj.fit_polynomial(grid.u, grid.v, truth, VARIABLES, DEGREE, weights=grid.weights)
    part = pj.fit_polynomial(grid.u, grid.v, truth, VARIABLES, DEGREE, weights=grid.weights,
                             mask=np.broadcast_to(seen[:, None], truth.shape))
    ratio = np.asarray(pj.l2_error(truth, part(grid.u, grid.v), grid.u, grid.v, weights=grid.weights)) / own.l2
    assert ratio.shape == (5, 3) and np.all(ratio >= 1.0), ratio
    # measured 1.04 - 1.27: texel (5, 1) (all channels) and (0, 0) (G) above 1.2 from the domain alone
    assert np.sum(ratio > 1.2) >= 3 and ratio.max() > 1.25 and np.median(ratio) < 1.2, ratio


@pytest.mark.data
def test_rerender_under_new_light(capture_fit, tmp_path):
    mats, cap, model = capture_fit
    for light in [(0.7, 0.9, 2.2), (-1.2, 0.8, 2.0)]:
        image, ref = svbrdf.relight(model, cap, light), svbrdf.photograph(mats, cap, light)
        assert image.shape == (8, 8, 3)
        assert float(pj.psnr(image, ref)) >= 35.0
    # the coefficient textures written and read back
    svbrdf.write_texture_shards(tmp_path, model)
    back = svbrdf.read_texture_shards(tmp_path)
    np.testing.assert_array_equal(back.coefficients, model.coefficients)
    np.testing.assert_allclose(svbrdf.relight(back, cap, (0.7, 0.9, 2.2)), svbrdf.relight(model, cap, (0.7, 0.9, 2.2)))


@pytest.mark.data
def test_svbrdf_cli(tmp_path, capsys):
    from polyjax.cli import main

    rc = main(["svbrdf", "--size", "8", "--lights", "48", "--materials", ",".join(MATERIALS), "--degree",
               str(DEGREE), "--out", str(tmp_path / "tex"), "--json"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert out["texels"] == 64 and out["processes"] == 1 and out["not_ok_local"] == 0
    assert out["psnr_new_light"] >= 35.0
    meta = json.loads((tmp_path / "tex" / "manifest.json").read_text())
    assert meta["fields"]["coefficients"]["shape"] == [8, 8, 3, 2 * DEGREE + 1]
    assert meta["formats"] == ["npz", "exr"] and (tmp_path / "tex" / "rows-0-8.exr").is_file()
    npz, exr = (svbrdf.read_texture_shards(tmp_path / "tex", format=f) for f in ("npz", "exr"))
    assert npz.batch_shape == exr.batch_shape == (8, 8, 3)
    np.testing.assert_allclose(exr.coefficients, npz.coefficients, rtol=2.0**-48, atol=0)


@pytest.mark.data
def test_svbrdf_cli_cameras(tmp_path, capsys):
    """``--cameras 3`` (``svbrdf.spread_cameras(3)``) and explicit positions: every texel fitted from C K
    photographs, re-rendered from every camera."""
    from polyjax.cli import main

    for cams, c in (("3", 3), ("0,-1.5,2.5;1,1,2", 2)):
        out_dir = tmp_path / f"tex{c}"
        rc = main(["svbrdf", "--size", "4", "--lights", "16", "--cameras", cams, "--materials", ",".join(MATERIALS),
                   "--degree", "2", "--out", str(out_dir), "--format", "npz", "--json"])
        assert rc == 0
        out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
        assert out["cameras"] == c and out["texels"] == 16 and out["not_ok_local"] == 0
        assert 25.0 < out["psnr_new_light"] < 80.0
        model = svbrdf.read_texture_shards(out_dir)
        np.testing.assert_array_equal(model.n_used, c * 16)
        assert np.load(out_dir / "rows-0-4.npz").files and np.load(out_dir / "relit-rows-0-4.npz")["relit"].shape == (
            c, 4, 4, 3)


def test_svbrdf_cli_bad_light(tmp_path, capsys):
    from polyjax.cli import main

    assert main(["svbrdf", "--new-light", "1,2", "--out", str(tmp_path)]) == 2
    assert "--new-light: expected 3 comma-separated numbers" in capsys.readouterr().err
    assert main(["svbrdf", "--format", "npz,tiff", "--out", str(tmp_path)]) == 2
    assert "--format: expected npz, exr or npz,exr, found 'npz,tiff'" in capsys.readouterr().err
    assert main(["svbrdf", "--cameras", "1,2,3;4,5", "--out", str(tmp_path)]) == 2
    assert "--cameras: expected an integer or x,y,z[;x,y,z...], found '1,2,3;4,5'" in capsys.readouterr().err
    assert main(["svbrdf", "--cameras", "0", "--out", str(tmp_path)]) == 2
    assert "--cameras: expected at least one camera, found '0'" in capsys.readouterr().err


def test_capture_observations_are_the_brdf():
    """b = L / (E cos theta_u) at every texel and light returns the BRDF itself; the weights E^2 make the fit's
    residuals radiance errors."""
    f = lambda u, v: jnp.stack([u[..., 2] * v[..., 2], u[..., 0] ** 2 + 0.1, 0.3 + 0 * u[..., 1]], -1)  # noqa: E731
    cap = svbrdf.simulate_capture([f], 4, 6, n_lights=10, intensity=(10.0, 5.0, 2.0))
    u, v, b, w = cap.observations()
    assert u.shape == (4, 6, 10, 3) and b.shape == (4, 6, 3, 10) and w.shape == (4, 6, 10)
    np.testing.assert_allclose(b, jnp.moveaxis(f(u, v), -1, -2), rtol=1e-12)
    d2 = np.sum((np.asarray(cap.lights)[None, None] - np.asarray(cap.positions)[:, :, None]) ** 2, -1)
    np.testing.assert_allclose(w, (np.mean([10.0, 5.0, 2.0]) / d2) ** 2, rtol=1e-12)


def _small_texture(h=4, w=6, degree=2):
    """A fitted 4 x 6 texture of an analytic material (no data needed): a capture and its per-texel fits."""
    f = lambda u, v: jnp.stack([0.3 + u[..., 2] * v[..., 2], 0.1 + (u[..., 0] * v[..., 0]) ** 2,  # noqa: E731
                                0.2 + 0.5 * u[..., 1] ** 2 * v[..., 2]], -1)
    cap = svbrdf.simulate_capture([f], h, w, n_lights=24)
    return cap, svbrdf.fit_capture(cap, "lafortune", degree)


def test_texture_shards_exr_round_trip(tmp_path):
    """EXR shards (float64 as float32 hi + lo channels) read back within 2^-48 relative of the fit; integer fields
    exactly; the npz shards written beside them exactly; the hi channels are the coefficient textures in float32."""
    import OpenEXR

    cap, model = _small_texture()
    model = eqx_tree_set(model, "l2", model.l2.at[1, 2, 0].set(jnp.inf))  # an empty lane's L2 is inf
    manifest = svbrdf.write_texture_shards(tmp_path, model, formats=("npz", "exr"))
    meta = json.loads(manifest.read_text())
    assert meta["formats"] == ["npz", "exr"] and meta["exr_precision"] == "hi-lo"
    assert meta["shards"] == [dict(rows=[0, 4], file="rows-0-4.npz", files=dict(npz="rows-0-4.npz",
                                                                                exr="rows-0-4.exr"), process=0)]
    coef = meta["fields"]["coefficients"]["exr"]
    assert coef["encoding"] == "float64-hi-lo-float32" and coef["channels"][:4] == [
        "coefficients.0.R", "coefficients.1.R", "coefficients.2.R", "coefficients.3.R"]
    assert coef["lo_channels"][0] == "coefficients.0.lo.R"
    assert meta["fields"]["status"]["exr"] == dict(encoding="int32-bits-uint32", channels=["status.R", "status.G",
                                                                                         "status.B"], lo_channels=[])
    with OpenEXR.File(str(tmp_path / "rows-0-4.exr"), separate_channels=True) as f:
        ch = {k: np.asarray(c.pixels) for k, c in f.channels().items()}
    assert ch["coefficients.3.G"].dtype == np.float32 and ch["coefficients.3.G"].shape == (4, 6)
    np.testing.assert_array_equal(ch["coefficients.3.G"], np.asarray(model.coefficients[:, :, 1, 3], np.float32))

    back = svbrdf.read_texture_shards(tmp_path, format="exr")
    exact = svbrdf.read_texture_shards(tmp_path)  # npz, the first format written
    for name in ("coefficients", "mean", "rotation", "centre", "halfwidth", "l2", "condition"):
        want, got = np.asarray(getattr(model, name)), np.asarray(getattr(back, name))
        assert got.dtype == np.float64 and got.shape == want.shape, name
        fin = np.isfinite(want)
        assert np.all(np.abs(got[fin] - want[fin]) <= 2.0**-48 * np.abs(want[fin])), name
        np.testing.assert_array_equal(got[~fin], want[~fin])
        np.testing.assert_array_equal(getattr(exact, name), want)
    assert not np.array_equal(back.coefficients, model.coefficients)  # two float32s are not a float64
    for name in ("degree", "rank", "n_used", "status"):
        np.testing.assert_array_equal(getattr(back, name), getattr(model, name))
        assert getattr(back, name).dtype == getattr(model, name).dtype
    np.testing.assert_allclose(svbrdf.relight(back, cap, (0.7, 0.9, 2.2)), svbrdf.relight(model, cap, (0.7, 0.9, 2.2)),
                               rtol=1e-13)
    part = svbrdf.read_texture_shards(tmp_path, rows=(1, 3), format="exr")
    np.testing.assert_array_equal(part.coefficients, back.coefficients[1:3])
    grey = model[:, :, 1]  # batch (H, W): no colour axis, channels named by index
    meta = json.loads(svbrdf.write_texture_shards(tmp_path / "grey", grey, formats="exr").read_text())
    assert meta["fields"]["coefficients"]["exr"]["channels"][:2] == ["coefficients.0", "coefficients.1"]
    assert meta["fields"]["l2"]["exr"] == dict(encoding="float64-hi-lo-float32", channels=["l2"],
                                               lo_channels=["l2.lo"])
    g = svbrdf.read_texture_shards(tmp_path / "grey")
    assert g.batch_shape == (4, 6)
    np.testing.assert_allclose(g.rotation, grey.rotation, rtol=2.0**-48, atol=0)


def test_texture_shards_exr_float32_and_errors(tmp_path):
    cap, model = _small_texture()
    svbrdf.write_texture_shards(tmp_path / "f32", model, formats="exr", exr_precision="float32")
    meta = json.loads((tmp_path / "f32" / svbrdf.MANIFEST).read_text())
    assert meta["formats"] == ["exr"] and meta["shards"][0]["file"] == "rows-0-4.exr"
    back = svbrdf.read_texture_shards(tmp_path / "f32")
    np.testing.assert_array_equal(back.coefficients, np.asarray(model.coefficients, np.float32).astype(np.float64))
    with pytest.raises(pj.InputError, match="formats: expected one or more of"):
        svbrdf.write_texture_shards(tmp_path / "x", model, formats="png")
    with pytest.raises(pj.InputError, match="exr_precision: expected one of"):
        svbrdf.write_texture_shards(tmp_path / "x", model, formats="exr", exr_precision="float16")
    flat = svbrdf.fit_capture(cap, "lafortune", 2)[0, 0]  # batch (3,): not a texture
    with pytest.raises(pj.InputError, match=r"model: expected a texture of batch shape \(H, W, ...\)"):
        svbrdf.write_texture_shards(tmp_path / "x", flat, formats="exr")
    assert not (tmp_path / "x").exists()  # nothing written
    huge = eqx_tree_set(model, "condition", model.condition.at[0, 0, 0].set(1e300))
    with pytest.raises(pj.InputError, match="condition: expected values within float32's range"):
        svbrdf.write_texture_shards(tmp_path / "y", huge, formats="exr")
    with pytest.raises(pj.InputError, match=r"format: expected one of the formats written, \['exr'\]"):
        svbrdf.read_texture_shards(tmp_path / "f32", format="npz")
    bad = dict(meta, format="polyjax-texture-shards/9")
    (tmp_path / "bad").mkdir()
    (tmp_path / "bad" / svbrdf.MANIFEST).write_text(json.dumps(bad))
    with pytest.raises(pj.DataFormatError, match="expected format 'polyjax-texture-shards/2', found "):
        svbrdf.read_texture_shards(tmp_path / "bad")
    (tmp_path / "f32" / "rows-0-4.exr").write_bytes(b"not an exr")
    with pytest.raises(pj.DataFormatError, match="an OpenEXR texture shard"):
        svbrdf.read_texture_shards(tmp_path / "f32")


def eqx_tree_set(model, name, value):
    import equinox as eqx

    return eqx.tree_at(lambda m: getattr(m, name), model, value)


# ---- several camera positions -------------------------------------------------------------------------------------

# three cameras at elevations 70, 42.5 and 15 degrees (azimuths -90, 30, 150): the fewest found whose views cover
# the Lafortune domain that one view leaves unseen (docs/scale.md); two (70 and 15) reach 1.23x, three at one
# elevation (45) 1.54x: the elevations matter
CAMERAS = 3


@pytest.fixture(scope="module")
def multiview_fit():
    mats = [pj.data.load_nbrdf(n) for n in MATERIALS]
    cap = svbrdf.simulate_capture(mats, 8, 8, n_lights=48, camera=svbrdf.spread_cameras(CAMERAS))
    return mats, cap, svbrdf.fit_capture(cap, VARIABLES, DEGREE)


@pytest.mark.data
def test_texels_recover_their_material_from_several_views(multiview_fit):
    """The issue's target met with three camera positions (``svbrdf.spread_cameras(3)``, 48 lights each, 144
    observations per texel): every one of the same 5 texels x 3 channels within 1.2x of the fit to its blend's own
    MERL-grid data (measured 0.94 - 1.10, against 1.10 - 1.61 from the one default camera).

    Ratios below 1 are possible here: equation (3) is a sum of one-variable polynomials in the principal components
    (no cross terms), so its family depends on the PCA rotation, and the grid fit is the optimum for the grid's
    rotation only; a texel fitted from views spread over the domain, with its own rotation, can do better."""
    _, cap, model = multiview_fit
    assert cap.images.shape == (CAMERAS, 48, 8, 8, 3) and model.batch_shape == (8, 8, 3)
    assert np.all(np.asarray(model.n_used) == CAMERAS * 48)
    ratios = _recovery_ratios(multiview_fit, at_least_one=False)
    assert np.all(ratios > 0.9) and np.all(ratios <= 1.2), ratios


@pytest.mark.data
def test_several_views_rerender_under_new_light(multiview_fit):
    """The multi-view fit re-rendered under new lights, seen from the one-camera capture's camera (not one of the
    three capture views): >= 35 dB against the simulated photograph there."""
    mats, cap, model = multiview_fit
    for light in [(0.7, 0.9, 2.2), (-1.2, 0.8, 2.0)]:
        image = svbrdf.relight(model, cap, light, camera=(0.0, -1.5, 2.5))
        ref = svbrdf.photograph(mats, cap, light, camera=(0.0, -1.5, 2.5))
        assert image.shape == (8, 8, 3)
        assert float(pj.psnr(image, ref)) >= 35.0


def test_several_cameras_observations_and_relight():
    """C cameras give every texel C K observations (camera-major), each camera's the same numbers as a capture by
    that camera alone; a camera given as (1, 3) is the one-camera capture; relight/photograph render from every
    camera, or from a new one."""
    f = lambda u, v: jnp.stack([0.3 + u[..., 2] * v[..., 2], 0.1 + (u[..., 0] * v[..., 0]) ** 2,  # noqa: E731
                                0.2 + 0.5 * u[..., 1] ** 2 * v[..., 2]], -1)
    cams = svbrdf.spread_cameras(2)
    cap = svbrdf.simulate_capture([f], 4, 6, n_lights=10, camera=cams)
    u, v, b, w = cap.observations()
    assert cap.images.shape == (2, 10, 4, 6, 3)
    assert u.shape == v.shape == (4, 6, 20, 3) and b.shape == (4, 6, 3, 20) and w.shape == (4, 6, 20)
    np.testing.assert_allclose(b, jnp.moveaxis(f(u, v), -1, -2), rtol=1e-12)
    for c in range(2):
        one = svbrdf.simulate_capture([f], 4, 6, n_lights=10, camera=cams[c])
        for got, want, ax in zip((u, v, b, w), one.observations(), (2, 2, 3, 2)):
            np.testing.assert_array_equal(np.take(np.asarray(got), np.arange(10 * c, 10 * c + 10), axis=ax), want)
    assert not np.allclose(v[..., 0, :], v[..., 10, :])  # two view directions per texel
    c1 = svbrdf.simulate_capture([f], 4, 6, n_lights=10, camera=[[0.0, -1.5, 2.5]])
    c0 = svbrdf.simulate_capture([f], 4, 6, n_lights=10)
    for got, want in zip(c1.observations(), c0.observations()):
        np.testing.assert_array_equal(got, want)
    m1, m0 = svbrdf.fit_capture(c1, "lafortune", 2), svbrdf.fit_capture(c0, "lafortune", 2)
    np.testing.assert_array_equal(m1.coefficients, m0.coefficients)

    model = svbrdf.fit_capture(cap, "lafortune", 2)
    light = (0.7, 0.9, 2.2)
    image, ref = svbrdf.relight(model, cap, light), svbrdf.photograph([f], cap, light)
    assert image.shape == ref.shape == (2, 4, 6, 3)
    np.testing.assert_allclose(image[1], svbrdf.relight(model, cap, light, camera=cams[1]), rtol=1e-14)
    new = svbrdf.photograph([f], cap, light, camera=(1.0, 1.0, 2.0))
    assert new.shape == (4, 6, 3) and float(pj.psnr(svbrdf.relight(model, cap, light, camera=(1.0, 1.0, 2.0)),
                                                    new)) > 30.0
    with pytest.raises(pj.InputError, match=r"camera: expected a position \(3,\) or C positions \(C, 3\)"):
        svbrdf.simulate_capture([f], 4, 6, n_lights=10, camera=(1.0, 2.0))
    with pytest.raises(pj.InputError, match="c: expected at least one camera"):
        svbrdf.spread_cameras(0)


def test_several_cameras_fit_differentiates():
    """The fit of a two-camera capture differentiates with respect to the camera positions (forward and reverse)."""
    import jax
    from jax.test_util import check_grads

    f = lambda u, v: jnp.stack([0.3 + u[..., 2] * v[..., 2]] * 3, -1)  # noqa: E731
    cams = jnp.asarray(svbrdf.spread_cameras(2))

    def coef(c):
        cap = svbrdf.simulate_capture([f], 2, 2, n_lights=8, camera=c)
        return svbrdf.fit_capture(cap, "lafortune", 1).coefficients.sum()

    # compiled, as in test_grad_fit: eagerly every primitive of the capture and the fit is a program of its own (the
    # eager gradient alone took about 6.7 s against 3.6 s compiled); check_grads' tracers see the same traced path
    assert np.isfinite(float(jax.jit(jax.grad(coef))(cams).sum()))
    check_grads(jax.jit(coef), (cams,), order=1, modes=("fwd", "rev"), atol=1e-5, rtol=1e-5)
