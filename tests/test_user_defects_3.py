"""What a new user ran into, third round: one test per case (RGL files as standard materials, Ctrl-C, the default
subsample of standard exports, exporters that take what the others take, the Mitsuba plugin of another material
class, abbreviations of aliased flags, MAX_STEPS lanes in the warnings, ``curet:isotropic``, bare data paths)."""

import json

import numpy as np
import pytest

import baselines as bl
import polyjax as pj
from polyjax.cli import main

from _problems import random_hemisphere
from _rgl_problems import rgl_fields, write_tensor_file


@pytest.fixture()
def no_data(monkeypatch):
    monkeypatch.delenv(pj.DATA_ENV, raising=False)


def _one_error_line(capsys, *words):
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("polyjax: error:"), err
    for w in words:
        assert w in lines[0], (w, lines[0])
    return lines[0]


# ---------------------------------------------------------------- 6: aliases of one flag, one line per parse error
def test_abbreviation_of_a_flag_and_its_alias_is_that_flag(capsys, no_data):
    assert main(["fit", "--degre", "3", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["degree"] == 3


@pytest.mark.parametrize("argv, words", [
    (["fit", "--degree"], ["--degree", "expected one argument"]),
    (["fitt"], ["invalid choice", "'fitt'"]),
    (["fit", "--bogus", "1"], ["unrecognized arguments", "--bogus"]),
    (["export"], ["required", "--to"]),
    (["fit", "--cutoff", "x"], ["--cutoff", "invalid float"]),
])
def test_every_parse_error_is_one_line(capsys, argv, words):
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2
    _one_error_line(capsys, *words)


# ---------------------------------------------------------------- 8: the paper's 52 isotropic samples by name
@pytest.mark.data
def test_curet_isotropic_is_the_papers_52_samples(capsys, data_root):
    m = pj.data.load("curet:isotropic")
    assert m.batch_shape == (52,)
    assert list(m.values[:, 0]) == list(pj.data.load_curet(None, pj.data.ISOTROPIC_52).values[:, 0])
    assert main(["fit", "--dataset", "curet:isotropic", "--degree", "2", "--json"]) == 0
    assert len(json.loads(capsys.readouterr().out)["labels"]) == 52


def test_curet_isotropic_is_listed_in_the_data_docs():
    from pathlib import Path

    text = (Path(__file__).parents[1] / "docs" / "data.md").read_text()
    assert "curet:isotropic" in text and "ISOTROPIC_52" in text


# ---------------------------------------------------------------- 9: one rule for data paths; --data-root's help
def test_view_takes_the_bare_bsdf_path_that_export_takes(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    write_tensor_file(tmp_path / "half.bsdf", rgl_fields(seed=3))
    assert pj.data.dataset_spec("half.bsdf") == "rgl:half.bsdf"
    assert pj.data.dataset_spec("x/satin.binary") == "merl:x/satin.binary"
    assert pj.data.dataset_spec("curet:25") == "curet:25"
    assert main(["view", "half.bsdf", "--table-resolution", "6,6,12", "--out", "half.html"]) == 0
    assert (tmp_path / "half.html").stat().st_size > 1000
    bare, spec = pj.data.load("half.bsdf", subsample=300), pj.data.load("rgl:half.bsdf", subsample=300)
    np.testing.assert_array_equal(np.asarray(bare.values), np.asarray(spec.values))


def test_data_root_help_lists_every_folder_read(capsys):
    with pytest.raises(SystemExit):
        main(["fit", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    for folder in ("curet/", "cornell/", "nbrdf_sztrajman2021/", "rgl_epfl/", "published_fits/"):
        assert folder in text, folder
