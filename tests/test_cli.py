"""The command line: ``polyjax fit --json`` and the main job on the synthetic default."""

import json

import numpy as np
import pytest

import polyjax as pj
from polyjax.cli import main


@pytest.mark.data
def test_fit_json_matches_api(capsys, data_root):
    assert main(["fit", "--data-root", str(data_root), "--sample", "25", "--variables", "lafortune", "--degree", "7",
                 "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    d = pj.data.load_curet(data_root, [25])
    m = pj.fit_polynomial(d, variables="lafortune", degree=7)
    assert out["n_params"] == 15
    assert out["l2"] == pytest.approx(np.asarray(m.l2).tolist(), rel=1e-12)
    np.testing.assert_allclose(out["coefficients"], m.paper_coefficients(), rtol=1e-12)


def test_main_job_runs_on_synthetic_default_and_says_so(capsys, monkeypatch):
    monkeypatch.delenv(pj.DATA_ENV, raising=False)
    assert main(["report"]) == 0
    out = capsys.readouterr().out
    assert "SYNTHETIC" in out and "not measured data" in out


def test_cli_reports_errors_cleanly(capsys, tmp_path):
    assert main(["fit", "--data-root", str(tmp_path / "nowhere"), "--dataset", "curet:25"]) == 2
    assert "is not a folder" in capsys.readouterr().err


def test_damaged_saved_program_is_logged_once_and_the_fit_still_answers(capsys, caplog, tmp_path, monkeypatch):
    """A kept executable that cannot be read is reported once (naming the file and the reason) and the fit runs
    without it, with the same numbers as the first run."""
    monkeypatch.delenv(pj.DATA_ENV, raising=False)
    args = ["--cache-dir", str(tmp_path), "fit", "--degree", "3", "--json"]
    assert main(args) == 0
    first = json.loads(capsys.readouterr().out)
    (program,) = (tmp_path / "polyjax-programs").glob("fit-*.bin")
    for _ in range(2):
        program.write_bytes(b"not a program")
        with caplog.at_level("WARNING", logger="polyjax"):
            assert main(args) == 0
        again = json.loads(capsys.readouterr().out)
        assert again["coefficients"] == first["coefficients"] and again["l2"] == first["l2"]
    logged = [r.getMessage() for r in caplog.records if r.name == "polyjax"]
    assert len(logged) == 1 and program.name in logged[0] and "reading the kept program failed" in logged[0]
