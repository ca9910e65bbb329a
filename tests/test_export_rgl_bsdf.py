"""A fitted model written as an RGL-EPFL measured BSDF file (``pj.export.rgl_bsdf``): read back by polyjax's reader
(the reference evaluation) and by Mitsuba 3's own ``measured`` plugin."""

import warnings

import numpy as np
import pytest

import polyjax as pj
import polyjax.render as pr

from _rgl_problems import hemisphere, mitsuba_measured

PHONG = pr.Phong(kd=(0.3, 0.5, 0.7), ks=0.4, exponent=20.0)
#: light and view directions above 3 degrees of elevation
U, V = hemisphere(3000, 1, 0.05), hemisphere(3000, 2, 0.05)


def _twisted(u, v):
    """Isotropic (a function of the elevations and the azimuth difference) but not symmetric in the azimuth: ``1 +
    0.5 (u x v)_z``, grey."""
    return 1.0 + 0.5 * (u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0])


def test_the_file_holds_the_model_at_its_nodes_and_close_between(tmp_path):
    """At the table's nodes the reader returns the model to float32 rounding; between them within 2 % (relative
    RMS) for a Phong lobe of exponent 20; ``load_rgl`` reads the file as the database's."""
    path = pj.export.rgl_bsdf(PHONG, tmp_path / "phong.bsdf", resolution=(32, 64), description="a Phong lobe")
    back = pj.data.read_rgl(path)
    assert back.isotropic and back.jacobian and back.description == "a Phong lobe"
    wi, wo, _, theta = pj.export.rgl_table_directions(32, 64)
    for t in (0, 10, 25):
        keep = wo[t, ..., 2] > 0.05
        want = np.asarray(pr.evaluate_rgb(PHONG, wo[t][keep], wi[t][keep]))
        got = np.asarray(back(wo[t][keep], wi[t][keep])).T
        np.testing.assert_allclose(got, want, rtol=3e-6, atol=3e-7 * want.max())
    want, got = np.asarray(pr.evaluate_rgb(PHONG, U, V)), np.asarray(back(U, V)).T
    assert np.sqrt(np.mean((got - want) ** 2) / np.mean(want**2)) < 0.02
    data = pj.data.load_rgl(path, directions=(U[:50], V[:50]))
    np.testing.assert_allclose(np.asarray(data.values), got[:50].T, rtol=1e-12)


def test_a_fitted_model_and_its_file_agree(tmp_path):
    """A compact fit written as a file evaluates within a tenth of its own distance to the data."""
    u, v = hemisphere(4000, 3, 0.02), hemisphere(4000, 4, 0.02)
    vals = np.asarray(pr.evaluate_rgb(PHONG, u, v)).T
    model = pj.fit_polynomial(u, v, vals, "rusinkiewicz", 4, interactions=True, link="log", cutoff_deg=None)
    back = pj.data.read_rgl(pj.export.rgl_bsdf(model, tmp_path / "m.bsdf"))
    mine = np.asarray(model(U, V))
    own = pj.l2_error(np.asarray(pr.evaluate_rgb(PHONG, U, V)).T, mine, U, V)
    gap = pj.l2_error(mine, np.asarray(back(U, V)), U, V)
    assert float(np.max(gap)) < 0.1 * float(np.max(own))


def test_a_model_not_symmetric_in_the_azimuth_is_written_as_the_mean_with_a_warning(tmp_path):
    with pytest.warns(pj.export.NotSymmetricWarning, match="phi and -phi"):
        path = pj.export.rgl_bsdf(_twisted, tmp_path / "t.bsdf", resolution=(8, 16))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the mean, 1, is symmetric: no warning
        grey = pj.export.rgl_bsdf(lambda u, v: 1.0 + 0.0 * u[..., 0], tmp_path / "one.bsdf", resolution=(8, 16))
    np.testing.assert_allclose(np.asarray(pj.data.read_rgl(path)(U, V)), np.asarray(pj.data.read_rgl(grey)(U, V)),
                               rtol=1e-6)


def test_bad_arguments_are_named_before_any_work_and_a_failed_write_leaves_no_file(tmp_path):
    for bad in ((1, 64), (32,), "32x64", (32.5, 64)):
        with pytest.raises(pj.InputError, match="resolution"):
            pj.export.rgl_bsdf(PHONG, tmp_path / "a.bsdf", resolution=bad)
    with pytest.raises(pj.InputError, match="does not exist"):
        pj.export.rgl_bsdf(PHONG, tmp_path / "missing" / "a.bsdf")
    (tmp_path / "kept.bsdf").write_bytes(b"the user's file")

    def broken(u, v):
        raise RuntimeError("no")

    with pytest.raises(RuntimeError):
        pj.export.rgl_bsdf(broken, tmp_path / "kept.bsdf")
    assert (tmp_path / "kept.bsdf").read_bytes() == b"the user's file"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kept.bsdf"]


@pytest.mark.slow
def test_mitsuba_measured_plugin_evaluates_and_samples_the_file(tmp_path):
    """Mitsuba 3's ``measured`` plugin evaluates the written file as polyjax's reader does, and its importance
    sampling is consistent with its evaluation: the mean of the sampled weights ``f cos / pdf`` is the albedo that
    a quadrature of the evaluation gives (within 2 %)."""
    mi = pytest.importorskip("mitsuba")
    path = pj.export.rgl_bsdf(PHONG, tmp_path / "phong.bsdf", resolution=(16, 32))
    back = pj.data.read_rgl(path)
    ours = np.asarray(back(U[:200], V[:200])).T
    np.testing.assert_allclose(mitsuba_measured(path, U[:200], V[:200]), ours, rtol=1e-4, atol=1e-5 * ours.max())
    mi.set_variant("scalar_rgb")
    bsdf = mi.load_dict({"type": "measured", "filename": str(path)})
    ctx, si = mi.BSDFContext(), mi.SurfaceInteraction3f()
    si.sh_frame = mi.Frame3f(mi.Vector3f(0.0, 0.0, 1.0))
    rng = np.random.default_rng(5)
    for theta in (0.3, 1.1):
        view = np.array([np.sin(theta), 0.0, np.cos(theta)])
        si.wi = mi.Vector3f(*view)
        weights = [np.asarray(bsdf.sample(ctx, si, 0.5, mi.Point2f(*rng.random(2)))[1], float)
                   for _ in range(4000)]
        sampled = np.mean(weights, 0)
        light = hemisphere(400_000, 6)  # uniform on the hemisphere: albedo = 2 pi mean(f cos)
        f = np.asarray(back(light, np.broadcast_to(view, light.shape))).T
        quadrature = 2 * np.pi * np.mean(f * light[:, 2:3], 0)
        np.testing.assert_allclose(sampled, quadrature, rtol=0.02)
