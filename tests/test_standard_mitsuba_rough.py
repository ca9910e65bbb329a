"""Mitsuba's ``roughconductor`` and ``roughplastic`` as standard material models: evaluation against Mitsuba's own
plugins' ``eval`` (``mi.load_dict``), reciprocity, energy, the joint R, G, B fit, the derivative of the plastic's
tables, and the Mitsuba XML export's choice of plugin."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _mitsuba_rough_problems import ROUGH_PARAMS

import baselines as bl
import polyjax as pj
import polyjax.render as pr
from polyjax.cli import main
from polyjax.export import choose_mitsuba_plugin as choose_plugin

from _baseline_problems import synthetic_geometry
from _robust_problems import baseline_fit_at

ETA, K = [0.2, 0.9, 1.4], [3.0, 2.5, 1.8]


def _hemi(n, seed):
    rng = np.random.default_rng(seed)
    w = rng.normal(size=(n, 3))
    w[:, 2] = np.abs(w[:, 2]) + 0.05
    return w / np.linalg.norm(w, axis=1, keepdims=True)


@functools.partial(jax.jit, static_argnames="name")
def _evaluate(name, params, u, v):
    """``(L, n)``: the model at ``params (L, P)``."""
    m = bl.get_model(name)
    return jax.vmap(lambda q: m.evaluate(q, u, v))(params)


def _rgb(name, colours):
    """``(3, P)``: ROUGH_PARAMS with the colour parameters of each channel."""
    p = np.tile(np.asarray(ROUGH_PARAMS[name], float), (3, 1))
    for i, c in enumerate(colours):
        p[:, i] = c
    return p


def _mitsuba_dict(material):
    rgb = lambda x: {"type": "rgb", "value": x}  # noqa: E731
    out = {"type": material["model"], **{k: (rgb(x) if isinstance(x, list) else x) for k, x in material.items()
                                         if k != "model"}}
    return out


@pytest.mark.parametrize("name, alpha", [("roughconductor", 0.3), ("roughconductor-beckmann", 0.3),
                                         ("roughconductor", 0.02)])
def test_roughconductor_equals_mitsuba_eval(name, alpha):
    pytest.importorskip("mitsuba")
    from polyjax.render import mitsuba_bsdf_eval

    u, v = _hemi(60, 1), _hemi(60, 2)
    p = _rgb(name, [ETA, K])
    p[:, 2] = alpha
    theirs = mitsuba_bsdf_eval(_mitsuba_dict(bl.get_model(name).to_material(p)), u, v)
    ours = np.asarray(_evaluate(name, jnp.asarray(p), u, v)).T
    assert np.sum(theirs > 0) > 100
    np.testing.assert_allclose(ours, theirs, rtol=1e-5, atol=1e-7 * theirs.max())  # Mitsuba: float32


@pytest.mark.parametrize("alpha, eta", [(0.05, 1.5), (0.3, 1.3), (0.02, 2.5)])
def test_roughplastic_file_equals_mitsuba_eval(alpha, eta):
    """The material ``to_material`` writes, evaluated by Mitsuba's plugin (its transmittance table and internal
    reflectance computed by Mitsuba at load), against the model."""
    pytest.importorskip("mitsuba")
    from polyjax.render import mitsuba_bsdf_eval

    u, v = _hemi(60, 3), _hemi(60, 4)
    p = np.array([[c, alpha, eta] for c in (0.8, 0.5, 0.2)])
    material = bl.get_model("roughplastic").to_material(p)
    assert material["int_ior"] == eta and material["ext_ior"] == 1.0
    assert abs(material["diffuse_reflectance"][0] / 0.8 - 1) < 0.02  # the 32 vs 128 node internal reflectance
    theirs = mitsuba_bsdf_eval(_mitsuba_dict(material), u, v)
    ours = np.asarray(_evaluate("roughplastic", jnp.asarray(p), u, v)).T
    np.testing.assert_allclose(ours, theirs, rtol=2e-5)  # measured <= 8e-6 (float32)


@pytest.mark.parametrize("name", list(ROUGH_PARAMS))
def test_reciprocal_and_energy(name):
    """f(u, v) = f(v, u); the directional albedo at five view angles (a 48 x 96 midpoint grid over the light
    hemisphere) is at most 1 for a white material."""
    u, v = _hemi(100, 7), _hemi(100, 8)
    p = _rgb(name, [ETA, K] if name.startswith("roughconductor") else [[1.0, 1.0, 1.0]])
    np.testing.assert_allclose(_evaluate(name, jnp.asarray(p), u, v), _evaluate(name, jnp.asarray(p), v, u),
                               rtol=1e-12)
    th, ph = np.meshgrid((np.arange(48) + 0.5) / 48 * np.pi / 2, (np.arange(96) + 0.5) / 96 * 2 * np.pi,
                         indexing="ij")
    light = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1).reshape(-1, 3)
    dw = (np.sin(th) * (np.pi / 2 / 48) * (2 * np.pi / 96)).ravel()
    for tv in np.radians([0.0, 30.0, 50.0, 70.0, 80.0]):
        view = np.broadcast_to([np.sin(tv), 0.0, np.cos(tv)], light.shape)
        f = np.asarray(_evaluate(name, jnp.asarray(p[:1]), light, view))[0]
        albedo = np.sum(f * light[:, 2] * dw)
        assert 0.01 < albedo <= 1.0, (tv, albedo)


def test_roughconductor_joint_fit_recovers_parameters():
    """Noise-free synthetic data (300 pairs, 6 starts, tolerance 1e-12): every parameter to 1e-6, one alpha."""
    u, v = synthetic_geometry(300, seed=0)
    p = _rgb("roughconductor", [ETA, K])
    values = np.asarray(_evaluate("roughconductor", jnp.asarray(p), u, v))
    fit = bl.fit("roughconductor", u, v, values, n_starts=6, rtol=1e-12, atol=1e-14, max_steps=200)
    assert bool(jnp.all(fit.success)), fit.status
    np.testing.assert_allclose(np.asarray(fit.params), p, atol=1e-6)
    material = bl.standard_material(fit)
    assert material["model"] == "roughconductor" and material["distribution"] == "ggx"
    np.testing.assert_allclose(material["eta"], ETA, atol=1e-6)


def test_roughplastic_three_channels_at_once_equal_each_channel():
    """The record's ``evaluate_rgb`` (lobes and tables once), which the joint record uses, against the model channel by
    channel."""
    u, v = _hemi(50, 9), _hemi(50, 10)
    p = np.array([[c, 0.12, 1.6] for c in (0.7, 0.4, 0.15)])
    ours = jax.jit(bl.get_model("roughplastic").evaluate_rgb)(jnp.asarray(p), u, v)
    np.testing.assert_allclose(ours, _evaluate("roughplastic", jnp.asarray(p), u, v), rtol=1e-13, atol=1e-15)
    joint = bl.get_model("roughplastic:rgb")
    np.testing.assert_allclose(jax.jit(joint.evaluate)(jnp.asarray([0.12, 1.6, 0.7, 0.4, 0.15]), u, v),
                               np.asarray(ours).reshape(-1), rtol=1e-13, atol=1e-15)


@pytest.mark.slow  # the plastic's fit evaluates its tables at every step of every start: ~20 CPU-seconds
def test_roughplastic_joint_fit_recovers_parameters():
    u, v = synthetic_geometry(300, seed=0)
    p = np.array([[c, 0.12, 1.6] for c in (0.7, 0.4, 0.15)])
    values = np.asarray(_evaluate("roughplastic", jnp.asarray(p), u, v))
    fit = bl.fit("roughplastic", u, v, values, n_starts=4, rtol=1e-12, atol=1e-14, max_steps=200)
    assert bool(jnp.all(fit.success)), fit.status
    np.testing.assert_allclose(np.asarray(fit.params), p, atol=1e-6)


def test_roughplastic_tables_derivative_matches_finite_differences():
    """The derivative of ``roughplastic`` w.r.t. alpha and eta (its tables' own rule: a Jacobian times the tangent)
    is the same in forward and reverse mode and matches central differences part by part. With ``f = spec + rho D``,
    ``D = T(cos u) T(cos v) / ((1 - R_i) pi eta^2)``: the specular lobe ``f(rho = 0)`` and the transmittance table's
    part ``log D(u, v) - log D(u_0, v_0)`` to ~1e-8; the part common to every pair, ``log D(u_0, v_0)``, which holds
    the internal reflectance ``R_i``, only to 15% (its quadrature jumps where a node crosses the critical angle, by
    ~1e-6 as alpha moves by 1e-5: central differences see those steps)."""
    model = bl.get_model("roughplastic")
    u, v = _hemi(40, 1), _hemi(40, 2)
    x = jnp.array([0.12, 1.6])

    @jax.jit
    def parts(q):
        spec = model.evaluate(jnp.array([0.0, q[0], q[1]]), u, v)
        log_d = jnp.log(model.evaluate(jnp.array([1.0, q[0], q[1]]), u, v) - spec)
        return jnp.concatenate([spec, log_d[1:] - log_d[0], log_d[:1]])

    fwd = jax.jacfwd(parts)(x)
    np.testing.assert_allclose(jax.jacrev(parts)(x), fwd, rtol=1e-12, atol=1e-14)
    h = 1e-5
    fd = jnp.stack([(parts(x + h * e) - parts(x - h * e)) / (2 * h) for e in jnp.eye(2)], -1)
    smooth = len(u) + len(u) - 1  # the specular lobe and the transmittance part
    assert float(jnp.max(jnp.abs(fd[len(u):smooth]))) > 0.1
    np.testing.assert_allclose(fwd[:smooth], fd[:smooth], rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(fwd[smooth], fd[smooth], rtol=0.15)


def test_choose_plugin_rule():
    """The simplest plugin within the tolerance of principled's L2, else principled."""
    assert choose_plugin({"roughconductor": 0.104, "roughplastic": 0.09, "principled": 0.1}) == "roughconductor"
    assert choose_plugin({"roughconductor": 0.106, "roughplastic": 0.09, "principled": 0.1}) == "roughplastic"
    assert choose_plugin({"roughconductor": 0.2, "roughplastic": 0.106, "principled": 0.1}) == "principled"
    assert choose_plugin({"roughconductor": np.nan, "roughplastic": 0.2, "principled": 0.1}, 1.5) == "roughplastic"
    assert choose_plugin({"principled": 0.1}) == "principled"


def _saved_conductor(path):
    fit = baseline_fit_at("roughconductor", ROUGH_PARAMS["roughconductor"])
    p = jnp.asarray(_rgb("roughconductor", [ETA, K]))
    pj.save_model(path, fit.__class__(**{**{k: getattr(fit, k) for k in ("raw", "l2", "status", "steps", "success",
                                                                            "start_l2", "start_status", "best_start",
                                                                            "at_limit")},
                                         "params": p, "name": "roughconductor"}))
    return path


def test_export_mitsuba_xml_roughconductor_renders_as_polyjax(tmp_path, capsys):
    """``--plugin roughconductor`` on a saved conductor: the file holds its parameters, and Mitsuba renders it as
    polyjax renders the fit (PSNR >= 40 dB)."""
    mi = pytest.importorskip("mitsuba")
    src = _saved_conductor(tmp_path / "metal.npz")
    out = tmp_path / "metal.xml"
    assert main(["export", str(src), "--to", "mitsuba-xml", "--plugin", "roughconductor", "--out", str(out),
                 "--samples", "300"]) == 0
    printed = capsys.readouterr().out
    l2 = [float(x) for x in printed.split("L2 (eq. 11) R, G, B: ")[1].split("  (")[0].split(", ")]
    assert max(l2) < 1e-5, printed
    text = out.read_text()
    assert '<bsdf type="roughconductor" id="material">' in text and '"distribution" value="ggx"' in text
    fitted = pj.load_model(src)
    cam = pr.Camera(eye=(0.0, 0.0, 5.0), width=32, height=32, fov_deg=30.0)
    scene = pr.Scene(cam, [pr.Sphere(fitted)], [pr.PointLight((3.0, 2.0, 4.0), 30.0)])
    path = pj.export.mitsuba_xml(bl.standard_material(fitted), tmp_path / "scene.xml", scene=scene)
    mi.set_variant("scalar_rgb")
    theirs = np.asarray(mi.render(mi.load_file(str(path))), float)
    ours = np.asarray(pr.render(scene, dtype=jnp.float64).image)
    assert theirs.max() > 0.05
    assert float(pj.psnr(ours, theirs)) >= 40.0  # measured: 141.6 dB (float32 rounding in Mitsuba)
    with pytest.raises(pj.InputError, match="distribution"):
        pj.export.mitsuba_xml({"model": "principled", "distribution": "ggx", "base_color": [0.5] * 3,
                               "roughness": 0.3, "metallic": 0.0, "specular": 0.5}, tmp_path / "bad.xml")


@pytest.mark.slow  # fits all three candidates, each compiled: ~60 CPU-seconds
def test_export_mitsuba_xml_auto_picks_the_conductor(tmp_path, capsys):
    src = _saved_conductor(tmp_path / "metal.npz")
    out = tmp_path / "metal.xml"
    assert main(["export", str(src), "--to", "mitsuba-xml", "--out", str(out), "--samples", "300"]) == 0
    printed = capsys.readouterr().out
    assert "chosen: roughconductor" in printed and "roughconductor fitted to" in printed
    assert '<bsdf type="roughconductor"' in out.read_text()
