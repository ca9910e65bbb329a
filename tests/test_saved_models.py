"""Saved models of every kind (polynomial and baseline fits), old file versions, kinds found through entry points;
baseline fits in the renderer and on the command line; the renderer's clamp of negative BRDF values."""

import json
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import baselines
import polyjax as pj
import polyjax.render as pr
from polyjax.cli import main

from _data_problems import write_small_merl


@pytest.fixture(scope="module")
def rgb_data(tmp_path_factory):
    path = tmp_path_factory.mktemp("merl") / "paint.binary"
    write_small_merl(path)
    return path, pj.data.load_merl_binary(path)


@pytest.fixture(scope="module")
def ward_fit(rgb_data):
    return baselines.fit("ward", rgb_data[1], n_starts=4)


def _same_fields(a, b):
    la, ta = jax.tree.flatten(a)
    lb, tb = jax.tree.flatten(b)
    assert ta == tb
    for x, y in zip(la, lb):
        assert np.asarray(x).dtype == np.asarray(y).dtype
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


@pytest.mark.parametrize("suffix", [".npz", ".json"])
def test_baseline_fit_saves_and_loads_like_a_polynomial_fit(tmp_path, ward_fit, rgb_data, suffix):
    path = pj.save_model(tmp_path / f"ward{suffix}", ward_fit)
    back = pj.load_model(path)
    assert type(back) is baselines.BaselineFit and back.name == "ward" and back.backend == ward_fit.backend
    _same_fields(back, ward_fit)
    d = rgb_data[1]
    np.testing.assert_array_equal(np.asarray(back(d.u, d.v)), np.asarray(ward_fit(d.u, d.v)))


def test_saved_file_declares_format_version_and_kind(tmp_path, ward_fit):
    doc = json.loads(pj.save_model(tmp_path / "w.json", ward_fit).read_text())
    assert doc["format"] == "polyjax.model" and doc["version"] == 2 and doc["kind"] == "baselines.BaselineFit"
    assert doc["static"] == {"name": "ward", "backend": "optimistix"}
    assert set(doc["arrays"]) >= {"params", "raw", "l2", "status"}
    with np.load(pj.save_model(tmp_path / "w.npz", ward_fit)) as z:
        meta = json.loads(str(z["__meta__"]))
    assert meta == {k: doc[k] for k in ("format", "version", "kind", "static")}


def test_old_version_1_files_still_load(tmp_path):
    d = pj.data.synthetic_default()
    m = pj.fit_polynomial(d, variables="ward", degree=3)
    names = ("coefficients", "degree", "mean", "rotation", "centre", "halfwidth", "l2", "rank", "condition",
             "n_used", "status")
    meta = {"format": "polyjax.PolynomialBRDF", "version": 1, "variables": "ward", "basis": "legendre",
            "interactions": False, "max_degree": 3}
    arrays = {k: np.asarray(getattr(m, k)) for k in names}
    np.savez(tmp_path / "old.npz", __meta__=np.asarray(json.dumps(meta)), **arrays)
    doc = dict(meta, arrays={k: {"dtype": str(a.dtype), "shape": list(a.shape), "data": a.ravel().tolist()}
                             for k, a in arrays.items()})
    (tmp_path / "old.json").write_text(json.dumps(doc))
    for name in ("old.npz", "old.json"):
        back = pj.load_model(tmp_path / name)
        _same_fields(back, m)


def test_newer_version_and_unknown_kind_are_clear_errors(tmp_path, ward_fit):
    doc = json.loads(pj.save_model(tmp_path / "w.json", ward_fit).read_text())
    (tmp_path / "new.json").write_text(json.dumps(dict(doc, version=4)))
    with pytest.raises(pj.DataFormatError, match="version 4"):
        pj.load_model(tmp_path / "new.json")
    (tmp_path / "other.json").write_text(json.dumps(dict(doc, kind="someone.Else")))
    with pytest.raises(pj.UnknownNameError, match="someone.Else.*polyjax.models"):
        pj.load_model(tmp_path / "other.json")
    with pytest.raises(pj.UnknownNameError, match="register_model_kind"):
        pj.save_model(tmp_path / "x.npz", object())


def test_model_kind_found_through_an_entry_point(tmp_path):
    """A package that polyjax never imports provides its kind through the entry point group polyjax.models: a fresh
    process that has not imported it loads a model of that kind (found through the entry point), as it was saved."""
    import os
    import subprocess
    from pathlib import Path

    (tmp_path / "toykinds.py").write_text(textwrap.dedent('''
        import equinox as eqx
        import jax.numpy as jnp
        from polyjax.internal import module_kind

        class Toy(eqx.Module):
            scale: jnp.ndarray
            label: str = eqx.field(static=True)

            def __call__(self, u, v):
                return self.scale * u[..., 2] * v[..., 2]

        KIND = module_kind(Toy, "toykinds.Toy")
    '''))
    dist = tmp_path / "toykinds-1.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: toykinds\nVersion: 1.0\n")
    (dist / "entry_points.txt").write_text("[polyjax.models]\ntoykinds.Toy = toykinds:KIND\n")
    root = Path(__file__).resolve().parents[1]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), str(root)])}
    path = tmp_path / "toy.npz"
    save = ("import sys, jax.numpy as jnp, polyjax, toykinds\n"
            f"polyjax.save_model({str(path)!r}, toykinds.Toy(jnp.asarray([1.5, 2.5]), label='t'))\n")
    load = ("import sys, numpy as np, polyjax\n"
            "assert 'toykinds' not in sys.modules\n"
            f"back = polyjax.load_model({str(path)!r})\n"
            "print(type(back).__module__, type(back).__name__, back.label, *np.asarray(back.scale))\n")
    for code in (save, load):
        out = subprocess.run([sys.executable, "-c", code], cwd=root, env=env, capture_output=True, text=True)
        assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["toykinds", "Toy", "t", "1.5", "2.5"]


def test_polyjax_does_not_import_baselines():
    import subprocess

    code = "import polyjax, sys; polyjax.save_model; assert 'baselines' not in sys.modules"
    assert subprocess.run([sys.executable, "-c", code], check=False, capture_output=True).returncode == 0


def test_baseline_fit_renders_without_channels_first_wrapper(ward_fit):
    scene = pr.sphere_scene(16)
    direct = pr.render_grid([[ward_fit]], scene, dtype=jnp.float64)
    wrapped = pr.render_grid([[pr.ChannelsFirst(ward_fit)]], scene, dtype=jnp.float64)
    img = np.asarray(direct.images)
    assert img.max() > 0
    np.testing.assert_allclose(img, np.asarray(wrapped.images), rtol=1e-12, atol=0)
    res = pr.render(pr.Scene(scene.camera, [pr.Sphere(ward_fit)], list(scene.lights)), dtype=jnp.float64)
    np.testing.assert_allclose(np.asarray(res.image), img[0, 0], rtol=1e-9, atol=1e-12)


def test_renderer_never_emits_negative_radiance():
    class Negative(pr.Phong):
        def __call__(self, u, v):
            return super().__call__(u, v) - 0.2  # negative away from the highlight

    brdf = Negative(kd=0.1, ks=0.5, exponent=20.0)
    scene = pr.sphere_scene(24)
    grid = np.asarray(pr.render_grid([[brdf, pr.Phong(kd=0.1, ks=0.5, exponent=20.0)]], scene,
                                     dtype=jnp.float64).images)
    assert grid[0, 0].min() == 0.0 and grid[0, 0].max() > 0
    clamped = np.asarray(pr.render(pr.Scene(scene.camera, [pr.Sphere(brdf)], list(scene.lights)),
                                   dtype=jnp.float64).image)
    assert clamped.min() == 0.0
    np.testing.assert_allclose(clamped, grid[0, 0], atol=1e-12)
    # where the BRDF is positive, the clamp changes nothing
    u = jnp.asarray([[0.0, 0.0, 1.0]])
    np.testing.assert_allclose(np.asarray(pr.evaluate_rgb(brdf, u, u)), np.asarray(brdf(u, u)), rtol=1e-15)
    assert np.all(np.asarray(pr.evaluate_rgb(brdf, u, jnp.asarray([[0.8, 0.0, 0.6]]))) == 0.0)


def test_fit_cli_fits_a_baseline_with_the_same_output_forms(tmp_path, capsys, rgb_data):
    path, d = rgb_data
    assert main(["fit", "--model", "ward", "--dataset", f"merl:{path}", "--json", "--save",
                 str(tmp_path / "w.npz")]) == 0
    out = json.loads(capsys.readouterr().out)
    ref = baselines.fit("ward", d)
    assert out["model"] == "ward" and out["labels"] == ["paint R", "paint G", "paint B"]
    np.testing.assert_allclose(out["l2"], np.asarray(ref.l2), rtol=1e-10)
    assert out["status"] == ["OK"] * 3 and out["coefficient_form"].startswith("parameters: ")
    assert type(pj.load_model(tmp_path / "w.npz")) is baselines.BaselineFit
    assert main(["fit", "--model", "Ward", "--dataset", f"merl:{path}"]) == 0
    text = capsys.readouterr().out
    assert "model: ward" in text and sum(" L2 = " in line for line in text.splitlines()) == 3
    assert main(["fit", "--model", "coook-torrance", "--dataset", f"merl:{path}"]) == 2
    assert "cook-torrance" in capsys.readouterr().err


def test_render_cli_model_fitted_to_other_materials_is_an_error(tmp_path, capsys):
    paths = []
    for i, name in enumerate(("felt", "polyester", "terry")):
        paths.append(tmp_path / f"{name}.binary")
        write_small_merl(paths[-1], seed=i)
    one = pj.fit_polynomial(pj.data.load_merl_binary(paths[0]), variables="ward", degree=2)
    pj.save_model(tmp_path / "one.npz", one)
    spec = "merl:" + ",".join(map(str, paths))
    out = str(tmp_path / "img")
    assert main(["render", "--model", str(tmp_path / "one.npz"), "--dataset", spec, "--size", "8", "--out", out]) == 2
    err = capsys.readouterr().err
    assert "1 material" in err and "has 3" in err
    assert main(["render", "--model", str(tmp_path / "one.npz"), "--dataset", f"merl:{paths[0]}", "--size", "8",
                 "--out", out]) == 0
    assert "columns: felt" in capsys.readouterr().out


def test_render_cli_renders_a_saved_baseline_fit(tmp_path, capsys, ward_fit, rgb_data):
    pj.save_model(tmp_path / "ward.npz", ward_fit)
    out = tmp_path / "img"
    assert main(["render", "--model", str(tmp_path / "ward.npz"), "--dataset", f"merl:{rgb_data[0]}", "--size", "8",
                 "--out", str(out)]) == 0
    assert "rows: ward; columns: paint" in capsys.readouterr().out
    img = pr.read_exr(out.with_suffix(".exr"))
    assert np.asarray(img).max() > 0 and np.asarray(img).min() >= 0


def test_render_cli_model_flag_takes_a_baseline_name_like_fit(tmp_path, capsys, rgb_data):
    out = tmp_path / "img"
    assert main(["render", "--model", "ward", "--dataset", f"merl:{rgb_data[0]}", "--size", "8", "--out",
                 str(out)]) == 0
    assert "rows: ward; columns: paint" in capsys.readouterr().out
    assert main(["render", "--model", "nope", "--dataset", f"merl:{rgb_data[0]}", "--size", "8",
                 "--out", str(out)]) == 2
    assert "cook-torrance" in capsys.readouterr().err
