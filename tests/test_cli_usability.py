"""What a new user of the command line ran into: lane labels, data roots, output paths, flags, warnings."""

import json

import numpy as np
import pytest

import polyjax as pj
from polyjax.cli import build_parser, main

from _data_problems import SMALL_RES, write_astm, write_small_merl


@pytest.fixture()
def two_merl(tmp_path):
    a, b = tmp_path / "alpha.binary", tmp_path / "beta.binary"
    write_small_merl(a, seed=0)
    write_small_merl(b, seed=1)
    return a, b


def _rows(out: str) -> list[str]:
    return [line for line in out.splitlines() if " L2 = " in line]


def test_fit_rows_one_per_material_and_channel_labelled_as_such(capsys, two_merl):
    a, b = two_merl
    spec = f"merl:{a},{b}"
    assert main(["fit", "--dataset", spec, "--variables", "ward", "--degree", "2"]) == 0
    rows = _rows(capsys.readouterr().out)
    assert len(rows) == 6
    labels = [r.split(" L2 = ")[0].strip() for r in rows]
    assert labels == ["alpha R", "alpha G", "alpha B", "beta R", "beta G", "beta B"]
    assert main(["fit", "--dataset", spec, "--variables", "ward", "--degree", "2", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    l2 = np.asarray(out["l2"]).ravel()
    printed = [float(r.split(" L2 = ")[1].split()[0]) for r in rows]
    np.testing.assert_allclose(printed, l2, atol=6e-6)
    assert out["labels"] == labels


def test_fit_degree_list_like_render_degrees(capsys, two_merl):
    a, _ = two_merl
    assert main(["fit", "--dataset", f"merl:{a}", "--variables", "ward", "--degree", "2,3"]) == 0
    rows = _rows(capsys.readouterr().out)
    labels = [r.split(" L2 = ")[0].strip() for r in rows]
    assert labels == [f"p={p} alpha {c}" for p in (2, 3) for c in "RGB"]
    assert main(["fit", "--dataset", f"merl:{a}", "--variables", "ward", "--degrees", "2,3", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["degree"] == [2, 3] and np.asarray(out["l2"]).shape == (2, 3)
    assert main(["fit", "--dataset", f"merl:{a}", "--degree", "two"]) == 2
    assert "--degree" in capsys.readouterr().err


def test_every_flag_has_help_text():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    missing = []
    for name, p in [("polyjax", parser), *sub.choices.items()]:
        for action in p._actions:
            if action.option_strings and action.help in (None, "") and action.dest != "help":
                missing.append(f"{name} {action.option_strings[0]}")
    assert missing == []


def test_missing_data_root_flag_is_an_error_not_the_synthetic_set(capsys, tmp_path):
    nope = tmp_path / "nope"
    assert main(["fit", "--data-root", str(nope), "--sample", "25"]) == 2
    err = capsys.readouterr().err
    assert str(nope) in err and "not a folder" in err


def test_missing_data_root_env_is_an_error_not_the_synthetic_set(capsys, tmp_path, monkeypatch):
    nope = tmp_path / "nope"
    monkeypatch.setenv(pj.DATA_ENV, str(nope))
    assert main(["fit", "--sample", "25"]) == 2
    assert str(nope) in capsys.readouterr().err
    assert main(["report"]) == 2
    assert str(nope) in capsys.readouterr().err
    monkeypatch.delenv(pj.DATA_ENV)
    assert main(["fit", "--sample", "25"]) == 0
    assert "SYNTHETIC" in capsys.readouterr().out


def test_save_into_missing_folder_fails_before_the_fit(capsys, tmp_path, monkeypatch):
    def no_fit(*a, **k):
        raise AssertionError("the fit ran before the output path was checked")

    monkeypatch.setattr(pj, "fit_polynomial", no_fit)
    target = tmp_path / "nonexistent_dir" / "m.npz"
    assert main(["fit", "--save", str(target)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "--save" in err and "nonexistent_dir" in err


def test_reproduce_out_not_creatable_fails_before_the_work(capsys, tmp_path, monkeypatch):
    from benchmarks.paper import run as rep

    monkeypatch.setattr(rep, "run", lambda *a, **k: (_ for _ in ()).throw(AssertionError("work started")))
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    assert rep.main(["--quick", "--out", str(blocker / "results")]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "--out" in err


def test_render_out_in_missing_folder_fails_before_rendering(capsys, tmp_path, monkeypatch):
    monkeypatch.delenv(pj.DATA_ENV, raising=False)
    assert main(["render", "--out", str(tmp_path / "missing" / "img"), "--size", "8"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "--out" in err


def test_load_merl_binary_of_missing_file_is_data_not_found(tmp_path):
    with pytest.raises(pj.DataNotFoundError, match="x.binary"):
        pj.data.load_merl_binary(tmp_path / "nope" / "x.binary")


def test_single_file_has_its_stem_as_material_name(tmp_path, capsys):
    a = tmp_path / "my-paint.binary"
    write_small_merl(a)
    d = pj.data.load_merl_binary(a)
    assert d.names == ("my-paint",) and d.axes == ("channel",) and d.values.shape[0] == 3
    assert d[1].names == ("my-paint",)  # indexing a channel keeps the material's name
    ang = np.array([[0.1, 0.0, 0.2, 3.0], [0.3, 0.5, 0.4, 2.0]])
    c = pj.data.load_cornell(write_astm(tmp_path / "my-sample.astm", ang, np.ones((2, 3)), ["R", "G", "B"]))
    assert c.names == ("my-sample",)
    assert main(["fit", "--dataset", f"merl:{a}", "--variables", "ward", "--degree", "1"]) == 0
    labels = [r.split(" L2 = ")[0].strip() for r in _rows(capsys.readouterr().out)]
    assert labels == ["my-paint R", "my-paint G", "my-paint B"]


def test_fit_report_warns_when_fit_barely_beats_zero(tmp_path, capsys):
    # a table that is 0 except for three huge spikes: no low-degree polynomial can follow them
    th, td, pd = pj.data.merl_bin_angles(SMALL_RES)
    u, v = pj.data.rusinkiewicz_to_directions(th, td, pd)
    vals = np.zeros((3, th.size))
    vals[:, (u[:, 2] <= 0) | (v[:, 2] <= 0)] = -1.0
    ok = np.flatnonzero((u[:, 2] > 0.5) & (v[:, 2] > 0.5))
    vals[:, ok[[3, 40, 90]]] = 1e3
    spiky = tmp_path / "spiky.binary"
    pj.data.write_merl_binary(spiky, vals, resolution=SMALL_RES, mask=vals >= 0)
    smooth = tmp_path / "smooth.binary"
    write_small_merl(smooth)
    assert main(["fit", "--dataset", f"merl:{spiky},{smooth}", "--variables", "ward", "--degree", "1"]) == 0
    out = capsys.readouterr().out
    warn = [line for line in out.splitlines() if line.startswith("WARNING")]
    assert len(warn) == 1 and "spiky" in warn[0] and "smooth" not in warn[0]
    assert main(["fit", "--dataset", f"merl:{spiky},{smooth}", "--variables", "ward", "--degree", "1", "--json"]) == 0
    js = json.loads(capsys.readouterr().out)
    ratio = np.asarray(js["l2"]) / np.asarray(js["l2_zero_model"])
    assert np.all(ratio[0] > 0.95) and np.all(ratio[1] < 0.8)
    assert len(js["warnings"]) == 1


@pytest.mark.data
def test_fit_report_warns_on_cornell_cayman(capsys, data_root):
    """Cayman's narrow peak: the Lafortune polynomial removes < 0.1% of the zero model's L2 at p = 1 (2.812 vs
    2.814)."""
    assert main(["fit", "--data-root", str(data_root), "--dataset", "cornell:cayman", "--degree", "1", "--json"]) == 0
    js = json.loads(capsys.readouterr().out)
    ratio = np.asarray(js["l2"]) / np.asarray(js["l2_zero_model"])
    assert np.all(ratio > 0.99) and np.all(ratio < 1.0)
    assert len(js["warnings"]) == 1 and "cayman R" in js["warnings"][0]


def _fitted_samples(capsys, args) -> tuple[int, str]:
    """``polyjax fit ... --json``'s sample count (from the data set's source) and source."""
    assert main(["fit", *args, "--variables", "ward", "--degree", "1", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    return out["n_samples"], out["source"]


def test_fit_subsamples_data_on_the_merl_grid_by_default_and_as_told(capsys, tmp_path):
    """``polyjax fit`` keeps 20,000 bins of a data set on the MERL grid unless ``--subsample`` says otherwise,
    as ``polyjax export`` does; ``all`` keeps every bin."""
    path = tmp_path / "big.binary"
    write_small_merl(path, resolution=(30, 30, 60))  # 54,000 bins, about half above the horizon
    every = pj.data.load(f"merl:{path}").values.shape[-1]
    assert every > 20000
    assert _fitted_samples(capsys, ["--dataset", f"merl:{path}"])[0] == 20000
    n, source = _fitted_samples(capsys, ["--dataset", f"merl:{path}", "--subsample", "500"])
    assert n == 500 and "subsample 500" in source
    n, source = _fitted_samples(capsys, ["--dataset", f"merl:{path}", "--subsample", "all"])
    assert n == every and "subsample" not in source


@pytest.mark.parametrize("value", ["5", "many", "0.5", "-300"])
def test_fit_subsample_bad_values_are_named_before_any_work(capsys, two_merl, value):
    a, _ = two_merl
    assert main(["fit", "--dataset", f"merl:{a}", "--subsample", value]) == 2
    err = capsys.readouterr().err
    assert "--subsample" in err and "expected an integer >= 100 or 'all'" in err and repr(value) in err


def test_fit_subsample_of_a_data_set_off_the_merl_grid_is_an_error(capsys, tmp_path):
    ang = np.array([[0.1, 0.0, 0.2, 3.0], [0.3, 0.5, 0.4, 2.0]])
    astm = write_astm(tmp_path / "s.astm", ang, np.ones((2, 3)), ["R", "G", "B"])
    assert main(["fit", "--dataset", f"cornell:{astm}", "--subsample", "500"]) == 2
    assert "--subsample: applies to data sets on the MERL grid" in capsys.readouterr().err
    assert main(["fit", "--sample", "25", "--subsample", "500"]) == 2
    assert "not to --sample" in capsys.readouterr().err


@pytest.mark.parametrize("to, good, bad", [("merl", "m.binary", "m.txt"), ("glsl", "m.frag", "m.brdf"),
                                           ("brdf-explorer", "m.brdf", "m.glsl"), ("mitsuba", "m.py", "m.txt"),
                                           ("rgl-bsdf", "m.bsdf", "m.binary")])
def test_export_out_must_end_in_the_target_s_suffix(capsys, tmp_path, two_merl, to, good, bad):
    """``export --to merl --out m.txt`` wrote a MERL table named ``.txt``; a file of the wrong suffix is now refused
    before the model is read, as the standard targets' writers and ``--save`` refuse theirs."""
    a, _ = two_merl
    saved = tmp_path / "fit.npz"
    assert main(["fit", "--dataset", f"merl:{a}", "--variables", "ward", "--degree", "1", "--save", str(saved)]) == 0
    capsys.readouterr()
    assert main(["export", str(saved), "--to", to, "--out", str(tmp_path / bad)]) == 2
    err = capsys.readouterr().err
    assert "--out: expected a file name ending in" in err and bad in err and not (tmp_path / bad).exists()
    assert main(["export", str(saved), "--to", to, "--out", str(tmp_path / good)]) == 0
    assert (tmp_path / good).stat().st_size > 0


def test_export_of_an_rgl_file_checks_the_out_suffix_too(capsys, tmp_path, data_root):
    """The RGL-EPFL route of ``export --to merl`` names its output through the same check: a ``.txt`` is refused
    before the file is read."""
    bad = tmp_path / "paper.txt"
    assert main(["export", "rgl:paper_white_rgb", "--to", "merl", "--out", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "--out: expected a file name ending in .binary for --to merl" in err and not bad.exists()
