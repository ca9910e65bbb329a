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
