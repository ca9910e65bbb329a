"""What a new user ran into, second round: one test per case (output paths, corrupt model files, absurd degrees,
strict JSON, model file suffixes, baseline exports and lane selection, lists as inputs, traced input rules, ...)."""

import json
import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _cli_problems import one_error_line

import baselines as bl
import polyjax as pj
from polyjax.cli import main

from _problems import random_hemisphere


@pytest.fixture(scope="module")
def problem():
    u, v = random_hemisphere(205, seed=3)
    return u, v, 0.1 + u[:, 2] * v[:, 2] + 0.2 * u[:, 0] * v[:, 0]


@pytest.fixture(scope="module")
def saved_fits(tmp_path_factory, problem):
    """A polynomial fit of two degrees x two materials and a Ward fit of two materials on 40 samples, saved."""
    u, v, b = problem
    folder = tmp_path_factory.mktemp("fits")
    poly = pj.fit_polynomial(u, v, np.stack([b, 0.5 * b + 0.05]), degree=[2, 3])
    ward = bl.fit("ward", u[:40], v[:40], np.stack([b[:40], 0.5 * b[:40] + 0.05]), n_starts=2)
    return pj.save_model(folder / "poly.npz", poly), pj.save_model(folder / "ward.json", ward), ward, poly


# ---------------------------------------------------------------- 3: output paths checked before any work, one rule
def test_export_out_in_missing_folder_is_refused_before_reading_the_model(capsys, tmp_path):
    missing_model = tmp_path / "not_read.npz"  # never read: the output path is checked first
    assert main(["export", str(missing_model), "--to", "glsl", "--out", str(tmp_path / "nonexistent" / "x.glsl")]) == 2
    one_error_line(capsys, "--out", "nonexistent")


def test_fit_images_save_in_missing_folder_is_refused_before_the_scene_is_read(capsys, tmp_path):
    assert main(["fit-images", str(tmp_path / "no_scene.json"), "--save", str(tmp_path / "nonexistent" / "x.npz")]) == 2
    one_error_line(capsys, "--save", "nonexistent")


def test_svbrdf_out_with_missing_parent_is_refused_not_created(capsys, tmp_path):
    target = tmp_path / "nonexistent" / "dir"
    assert main(["svbrdf", "--size", "2", "--lights", "8", "--out", str(target)]) == 2
    one_error_line(capsys, "--out", "nonexistent")
    assert not (tmp_path / "nonexistent").exists()


# ---------------------------------------------------------------- 4: corrupt model file
def test_truncated_npz_model_is_a_data_format_error_naming_the_file(capsys, tmp_path, saved_fits):
    cut = tmp_path / "cut.npz"
    cut.write_bytes(saved_fits[0].read_bytes()[:1000])
    with pytest.raises(pj.DataFormatError, match="cut.npz"):
        pj.load_model(cut)
    assert main(["export", str(cut), "--to", "glsl", "--out", str(tmp_path / "x.glsl")]) == 2
    one_error_line(capsys, "cut.npz")


# ---------------------------------------------------------------- 5: absurd degree refused at once
def test_fit_degree_500_is_refused_before_the_fit(capsys, no_data):
    assert main(["fit", "--degree", "500"]) == 2  # 1001 parameters, 302 samples used (synthetic set)
    one_error_line(capsys, "--degree 500", "1001 parameters", "302 samples used")


def test_render_degrees_500_is_refused_before_the_fit(capsys, no_data, tmp_path):
    assert main(["render", "--degrees", "3,500", "--size", "4", "--out", str(tmp_path / "r")]) == 2
    one_error_line(capsys, "--degrees 500")


def test_fit_polynomial_degree_500_on_205_samples_is_refused_in_the_api(problem):
    u, v, b = problem
    with pytest.raises(pj.InputError, match=r"degree=500.*expected at most 820 parameters for 205 samples"):
        pj.fit_polynomial(u, v, b, degree=500)


# ---------------------------------------------------------------- 6: strict JSON
def test_fit_json_of_a_rank_deficient_fit_is_strict_json(capsys, no_data):
    # monomials of degree 40 on 302 samples: numerically rank-deficient, condition inf
    assert main(["fit", "--degree", "40", "--basis", "monomial", "--json"]) == 0
    text = capsys.readouterr().out
    rec = json.loads(text, parse_constant=lambda c: pytest.fail(f"non-standard JSON constant {c}"))
    assert "Infinity" not in text and "NaN" not in text
    assert rec["condition"] == [None, None, None] and rec["rank"] == [69, 69, 69]


# ---------------------------------------------------------------- 8: model file suffixes
def test_save_model_with_foreign_suffix_is_refused_not_renamed(tmp_path, saved_fits):
    model = pj.load_model(saved_fits[0])
    with pytest.raises(pj.InputError, match=r"\.npz or \.json.*'\.txt'"):
        pj.save_model(tmp_path / "m.txt", model)
    assert not list(tmp_path.iterdir())


def test_fit_save_with_foreign_suffix_is_refused_before_the_fit(capsys, no_data, tmp_path):
    assert main(["fit", "--degree", "2", "--save", str(tmp_path / "m.txt")]) == 2
    one_error_line(capsys, "--save", ".npz or .json")
    assert not list(tmp_path.iterdir())


def test_fit_save_prints_the_written_line(capsys, no_data, tmp_path):
    assert main(["fit", "--degree", "2", "--save", str(tmp_path / "m.npz")]) == 0
    assert f"model written to {tmp_path / 'm.npz'}" in capsys.readouterr().out
    assert pj.load_model(tmp_path / "m.npz").batch_shape == (3,)


# ---------------------------------------------------------------- 1, 2: baseline exports, lane selection
def test_baseline_fit_evaluates_any_leading_direction_shape(saved_fits, problem):
    ward = saved_fits[2]
    u, v, _ = problem
    flat = np.asarray(ward(u[:12], v[:12]))
    grid = np.asarray(ward(u[:12].reshape(3, 4, 3), v[:12].reshape(3, 4, 3)))
    assert grid.shape == (2, 3, 4)
    np.testing.assert_array_equal(grid.reshape(2, 12), flat)
    np.testing.assert_array_equal(np.asarray(ward[1](u[:12], v[:12])), flat[1])


def test_export_baseline_fit_to_merl_selects_a_lane_and_tabulates_it(tmp_path, saved_fits):
    ward = pj.load_model(saved_fits[1])[1]
    out = pj.export.merl_binary(ward, tmp_path / "ward.binary", resolution=(6, 6, 12))
    back = pj.data.load_merl_binary(out)
    keep = np.all(np.broadcast_to(np.asarray(back.mask), np.shape(back.values)), axis=0)  # (n,) bins with a value
    u, v = np.asarray(back.u)[keep], np.asarray(back.v)[keep]
    got = np.asarray(back.values)[:, keep]  # (3 channels, bins)
    assert got.shape[1] > 50
    np.testing.assert_allclose(got, np.broadcast_to(np.maximum(np.asarray(ward(u, v)), 0), got.shape), rtol=1e-6)


def test_export_baseline_fit_to_mitsuba_script(capsys, tmp_path, saved_fits):
    out = tmp_path / "ward_plugin.py"
    assert main(["export", str(saved_fits[1]), "--to", "mitsuba", "--index", "0", "--out", str(out)]) == 0
    assert "INDEX = (0,)" in out.read_text()


def test_export_index_selects_degree_then_material(capsys, tmp_path, saved_fits):
    src = saved_fits[0]  # batch shape (2 degrees, 2 materials)
    a, b = tmp_path / "a.glsl", tmp_path / "b.glsl"
    assert main(["export", str(src), "--to", "glsl", "--index", "1,0", "--out", str(a)]) == 0
    assert main(["export", str(src), "--to", "glsl", "--index", "1", "--index", "0", "--out", str(b)]) == 0
    assert a.read_text() == b.read_text() == pj.export.glsl(pj.load_model(src)[1, 0])
    assert main(["export", str(src), "--to", "glsl", "--index", "1", "--out", str(a)]) == 2
    line = one_error_line(capsys, "--index")
    assert "model[i]" not in line


# ---------------------------------------------------------------- 14: lists as inputs
def test_fit_polynomial_accepts_python_lists(problem, saved_fits):
    u, v, b = problem
    a = pj.fit_polynomial(u.tolist(), v.tolist(), [b.tolist(), (0.5 * b + 0.05).tolist()], degree=[2, 3])
    np.testing.assert_array_equal(np.asarray(a.coefficients), np.asarray(saved_fits[3].coefficients))


def test_baselines_fit_accepts_python_lists(problem, saved_fits):
    u, v, b = problem
    values = [b[:40].tolist(), (0.5 * b[:40] + 0.05).tolist()]
    a = bl.fit("ward", u[:40].tolist(), v[:40].tolist(), values, n_starts=2)
    np.testing.assert_array_equal(np.asarray(a.params), np.asarray(saved_fits[2].params))


def test_ragged_list_is_an_input_error_naming_the_argument(problem):
    u, v, b = problem
    with pytest.raises(pj.InputError, match="values: expected an array or a nested list"):
        pj.fit_polynomial(u[:2], v[:2], [[0.1, 0.2], [0.3]], degree=1)


# ---------------------------------------------------------------- 7: the "compiling" line only when compiling:
# tests/test_latency.py::test_compile_notice_and_progress_line_say_what_is_happening


# ---------------------------------------------------------------- 9: one rule eager and traced
def test_grad_of_a_fit_with_nan_values_raises_the_eager_input_error(problem):
    u, v, b = problem
    y = np.array(b)
    y[7] = np.nan
    with pytest.raises(pj.InputError, match=r"values: expected finite numbers, found 1 NaN/inf \(first at index \(7"):
        jax.grad(lambda y: pj.fit_polynomial(u, v, y, degree=2).l2)(jnp.asarray(y))
    with pytest.raises(pj.InputError, match=r"found 1 NaN/inf \(first at index \(7,\)"):
        pj.fit_polynomial(u, v, y, degree=2)


def test_negative_weights_refused_eagerly_and_flagged_under_jit_never_clipped(problem):
    u, v, b = problem
    w = np.ones(205)
    w[3] = -1.0
    with pytest.raises(pj.InputError, match="weights: expected finite, non-negative"):
        pj.fit_polynomial(u, v, b, weights=w, degree=2)
    m = jax.jit(lambda w: pj.fit_polynomial(u, v, b, weights=w, degree=2))(jnp.asarray(w))
    assert int(m.status) == pj.RESULTS.NONFINITE and np.isinf(float(m.l2))
    ok = jax.jit(lambda w: pj.fit_polynomial(u, v, b, weights=w, degree=2))(jnp.ones(205))
    assert int(ok.status) == pj.RESULTS.OK and np.isfinite(float(ok.l2))


# ---------------------------------------------------------------- 12: every variable set in --help, a --link flag
def test_fit_help_lists_every_variable_set_and_a_link_flag(monkeypatch):
    import subprocess
    import sys
    from pathlib import Path

    from polyjax.cli import build_parser

    monkeypatch.setenv("COLUMNS", "2000")  # one line per option: names are not wrapped at their hyphens
    sub = build_parser("fit")._subparsers._group_actions[0].choices["fit"]
    text = sub.format_help().replace("\n", " ")
    text = " ".join(text.split())
    # the built-in sets: those of a fresh process (other tests of this one register their own)
    root = Path(__file__).resolve().parents[1]
    fresh = subprocess.run([sys.executable, "-c", "import polyjax; print(*polyjax.variable_sets())"], cwd=root,
                           capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(root)})
    builtin = fresh.stdout.split()
    assert fresh.returncode == 0 and "lafortune" in builtin and len(builtin) >= 6, fresh.stderr
    for name in builtin:
        assert name in text, name
    assert "--link {identity,log}" in text


def test_fit_link_log_on_the_command_line_is_the_api_log_fit(capsys, no_data):
    assert main(["fit", "--degree", "2", "--link", "log", "--json"]) == 0
    rec = json.loads(capsys.readouterr().out)
    api = pj.fit_polynomial(pj.data.synthetic_default(), variables="lafortune", degree=2, link="log")
    assert rec["link"] == "log"
    np.testing.assert_allclose(rec["l2"], np.asarray(api.l2), rtol=1e-12)


# ---------------------------------------------------------------- 13: svbrdf arguments
def test_svbrdf_degree_beyond_the_samples_of_a_texel_is_refused_at_once(capsys, tmp_path):
    assert main(["svbrdf", "--size", "8", "--degree", "9", "--lights", "8", "--out", str(tmp_path / "t")]) == 2
    one_error_line(capsys, "--degree 9", "19 parameters", "--lights 8")
    assert not (tmp_path / "t").exists()


def test_svbrdf_zero_lights_names_the_flag(capsys, tmp_path):
    assert main(["svbrdf", "--lights", "0", "--out", str(tmp_path / "t")]) == 2
    line = one_error_line(capsys, "--lights")
    assert " k" not in line.split("error:")[1]


@pytest.mark.data
def test_svbrdf_warns_when_texel_fits_are_not_ok(capsys, tmp_path, monkeypatch):
    """Texels whose fits are not OK (here one channel of one texel marked RANK_DEFICIENT after the fit, as a texel
    with too few lit samples gets) are reported: the summary's WARNING line with the count, and in --json the count
    and the warning."""
    import equinox as eqx

    from polyjax import svbrdf

    fit_rows = svbrdf.fit_rows_distributed

    def one_not_ok(*args, **kwargs):
        model = fit_rows(*args, **kwargs)
        status = np.array(model.status)
        status[1, 0, 2] = pj.RESULTS.RANK_DEFICIENT
        return eqx.tree_at(lambda m: m.status, model, jax.device_put(status, model.status.sharding))

    monkeypatch.setattr(svbrdf, "fit_rows_distributed", one_not_ok)
    args = ["svbrdf", "--size", "2", "--lights", "8", "--degree", "1", "--format", "npz"]
    assert main(args + ["--out", str(tmp_path / "text")]) == 0
    out = capsys.readouterr().out
    assert "WARNING: 1 of 12 texel fits here are not OK" in out and "for degree 1" in out.split("WARNING")[1]
    assert main(args + ["--out", str(tmp_path / "json"), "--json"]) == 0
    rec = json.loads(capsys.readouterr().out)
    assert rec["not_ok_local"] == 1 and rec["warnings"] == ["1 texel fits not OK"]


# ---------------------------------------------------------------- 15: conditioning with interactions
@pytest.mark.data
def test_interactions_p7_on_curet_25_is_reported_ill_conditioned_in_both_bases(capsys, data_root):
    """CUReT 25 (205 samples), Lafortune, p = 7 with interactions (36 terms): the design is nearly singular in any
    basis of that space (condition ~1e8 with Legendre and with monomials, the same L2): a property of the samples,
    reported as a warning, not a claim of a small condition number."""
    conds, l2s = [], []
    for basis in ("legendre", "monomial"):
        assert main(["--data-root", str(data_root), "fit", "--dataset", "curet:25", "--degree", "7",
                     "--interactions", "--basis", basis, "--json"]) == 0
        rec = json.loads(capsys.readouterr().out)
        conds.append(rec["condition"][0])
        l2s.append(rec["l2"][0])
        assert any("ill-conditioned" in w for w in rec["warnings"]), rec["warnings"]
    assert min(conds) > 1e7 and abs(l2s[0] - l2s[1]) < 1e-9
    assert main(["--data-root", str(data_root), "fit", "--dataset", "curet:25", "--degree", "7", "--json"]) == 0
    rec = json.loads(capsys.readouterr().out)
    assert rec["condition"][0] < 100 and not any("ill-conditioned" in w for w in rec["warnings"])


# ---------------------------------------------------------------- 16: README's code blocks run
@pytest.mark.data
@pytest.mark.slow
def test_readme_code_blocks_run_as_written(tmp_path, monkeypatch, data_root):
    """Every Python block of README's tour, in order and in one scope (a block uses the names of those before it),
    in an empty folder: the tour's names find the data under the data root (``catPNG``: DiLiGenT's cat)."""
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    blocks = [part.split("```", 1)[0] for part in text.split("```python\n")[1:]]
    assert len(blocks) == 4, "README's tour has changed: say here what each block must give"
    monkeypatch.chdir(tmp_path)  # the tour writes fits.npz, gold.npz and cat.glb
    scope = {}
    for block in blocks:
        exec(compile(block, "README.md", "exec"), scope)  # noqa: S102 - the documentation's own example
    assert scope["model"].l2.shape == (61,) and scope["models"].l2.shape == (5, 61)
    assert scope["grads"].shape == scope["data"].values.shape
    best = scope["best"]
    assert best.n_numbers <= 33 and float(best.log) < 0.05
    assert pj.load_model(tmp_path / "gold.npz").n_numbers == best.n_numbers
    cat = scope["cat"]
    assert cat.normals.shape == (*cat.diffuse.shape[:2], 3) and (tmp_path / "cat.glb").stat().st_size > 10_000
    assert scope["image"].shape == (128, 128, 3) and np.all(np.isfinite(np.asarray(scope["image"])))


def test_multi_degree_header_gives_the_degrees_then_their_parameter_counts(capsys, no_data):
    assert main(["fit", "--degree", "2,3"]) == 0
    assert "p=2,3 (5, 7 parameters)" in capsys.readouterr().out


# ---------------------------------------------------------------- 11: a foreign package named baselines
def test_a_foreign_baselines_package_is_named_in_the_error(tmp_path):
    import os
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    fake = tmp_path / "site" / "baselines"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text('"""An unrelated package that happens to be called baselines."""\n')
    env = dict(os.environ, PYTHONPATH=f"{tmp_path / 'site'}{os.pathsep}{root}")
    env.pop(pj.DATA_ENV, None)
    out = subprocess.run([sys.executable, "-W", "ignore", "-m", "polyjax", "--no-cache", "fit", "--model", "ward"],
                         cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 2, out.stderr
    assert str(fake) in out.stderr and "shadows it" in out.stderr, out.stderr


# ---------------------------------------------------------------- 10: the fit-images example and its format
def test_fit_images_example_is_written_and_fits(capsys, tmp_path):
    folder = tmp_path / "example"
    assert main(["fit-images", "--example", str(folder)]) == 0
    assert "example written to" in capsys.readouterr().out
    assert main(["fit-images", str(folder / "scene.json"), "--degree", "3", "--json"]) == 0
    rec = json.loads(capsys.readouterr().out)
    assert rec["images"] == 3 and rec["status_rgb"] == ["OK", "OK", "OK"] and rec["pixels_used"] > 1000
    spec = json.loads((folder / "scene.json").read_text())
    spec["camera"]["fov_deg"] = "wide"
    (folder / "scene.json").write_text(json.dumps(spec))
    assert main(["fit-images", str(folder / "scene.json")]) == 2
    one_error_line(capsys, "camera.fov_deg", "expected a number", "'wide'")


# ---------------------------------------------------------------- 17: cache info|clear, a size cap (the progress line:
# tests/test_latency.py::test_compile_notice_and_progress_line_say_what_is_happening)
def test_cache_info_and_clear_commands(capsys, tmp_path):
    folder = pj.internal.make_cache_folder(tmp_path / "cache")  # polyjax's own: marked
    (folder / "polyjax-programs").mkdir(parents=True)
    (folder / f"jit_fit-{'ab' * 32}-cache").write_bytes(b"x" * 2048)
    (folder / "polyjax-programs" / f"fit-{'1' * 32}.bin").write_bytes(b"y" * 1024)
    assert main(["--cache-dir", str(folder), "cache", "info"]) == 0
    out = capsys.readouterr().out
    assert "remove 2 file(s)" in out and "polyjax-programs: 1 file(s)" in out and "cap 2048 MiB" in out
    assert main(["--cache-dir", str(folder), "cache", "clear"]) == 0
    assert "removed 2 file(s)" in capsys.readouterr().out
    assert folder.is_dir() and [p.name for p in folder.rglob("*") if p.is_file()] == ["POLYJAX-CACHE"]


def test_cache_folder_is_trimmed_to_its_cap_after_a_run_oldest_first(capsys, tmp_path, monkeypatch, no_data):
    import os

    folder = pj.internal.make_cache_folder(tmp_path / "cache")
    for i in range(4):  # 4 x 0.4 MiB, oldest first
        p = folder / f"jit_old{i}-{'0' * 64}-cache"
        p.write_bytes(b"z" * (400 * 1024))
        os.utime(p, (1000 + i, 1000 + i))
    monkeypatch.setenv("POLYJAX_CACHE_MAX_MB", "1")
    monkeypatch.setenv("POLYJAX_SAVED_PROGRAMS", "off")
    assert main(["--cache-dir", str(folder), "fit", "--degree", "2", "--json"]) == 0
    left = sorted(p.name for p in folder.rglob("*") if p.is_file())
    assert sum(p.stat().st_size for p in folder.rglob("*") if p.is_file()) <= 0.8 * 2**20
    assert not {f"jit_old{i}-{'0' * 64}-cache" for i in (0, 1)} & set(left)


# ---------------------------------------------------------------- 1: every export target for a baseline fit
def test_export_baseline_fit_to_glsl_and_brdf_explorer_by_a_table(capsys, tmp_path, saved_fits):
    import re
    import shutil
    import subprocess

    for target, suffix in (("glsl", ".glsl"), ("brdf-explorer", ".brdf")):
        out = tmp_path / f"ward{suffix}"
        assert main(["export", str(saved_fits[1]), "--to", target, "--index", "1", "--out", str(out)]) == 0
        assert "tabulated BRDF" in out.read_text()
    # the shader's table: max(f, 0) per channel at the nodes of a coarse MERL grid (file order), then 1 where both
    # directions of the node are above the horizon
    text = (tmp_path / "ward.glsl").read_text()
    resolution = tuple(int(re.search(rf"const int {n} = (\d+);", text).group(1)) for n in ("NH", "ND", "NP"))
    numbers = re.search(r"const float TABLE\[(\d+)\] = float\[\d+\]\(([^)]*)\);", text)
    table = np.array([float(x) for x in numbers.group(2).split(",")]).reshape(4, -1)
    assert int(numbers.group(1)) == table.size == 4 * int(np.prod(resolution))
    ward = pj.load_model(saved_fits[1])[1]
    u, v, _, above = pj.data.merl_grid(resolution)
    np.testing.assert_array_equal(table[3], above.astype(float))
    want = np.maximum(np.asarray(ward(np.asarray(u)[above], np.asarray(v)[above])), 0.0)
    assert want.max() > 10 * want.min() >= 0  # a lobe: the table is not a constant
    np.testing.assert_allclose(table[:3, above], np.broadcast_to(want, (3, want.size)), rtol=1e-6, atol=1e-9)
    assert np.all(table[:3, ~above] == 0.0)
    if shutil.which("glslangValidator"):
        frag = tmp_path / "ward.frag"
        frag.write_text("#version 120\n" + (tmp_path / "ward.glsl").read_text()
                        + "void main() { gl_FragColor = vec4(BRDF(vec3(0.3, 0.2, 0.9), vec3(-0.1, 0.4, 0.8), "
                        "vec3(0, 0, 1), vec3(1, 0, 0), vec3(0, 1, 0)), 1.0); }\n")
        res = subprocess.run(["glslangValidator", str(frag)], capture_output=True, text=True)
        assert res.returncode == 0, res.stdout + res.stderr


def test_saved_json_model_is_strict_json_and_round_trips_inf(tmp_path, saved_fits):
    import equinox as eqx

    model = pj.load_model(saved_fits[0])
    l2 = np.array(model.l2)
    l2[0, 1], l2[1, 0] = np.inf, np.nan  # as a lane without samples / a flagged lane holds
    model = eqx.tree_at(lambda m: m.l2, model, jnp.asarray(l2))
    text = pj.save_model(tmp_path / "m.json", model).read_text()
    json.loads(text, parse_constant=lambda c: pytest.fail(f"non-standard JSON constant {c}"))
    back = pj.load_model(tmp_path / "m.json")
    np.testing.assert_array_equal(np.asarray(back.l2), l2)
