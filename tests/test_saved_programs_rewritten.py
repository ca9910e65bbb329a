"""Saved programs written again while JAX's compilation cache still holds the program (the saved files removed, as
after ``polyjax cache clear`` of that folder or a new source stamp): the next process compiles afresh and the one
after loads what it wrote, with the first process's numbers, for ``polyjax fit`` and ``baselines.fit`` alike.

An executable that JAX's cache had loaded did not serialise whole: every later process failed when it ran it
(``NOT_FOUND: Function ..._kernel not found``). The first test is the same sequence within one process (the command
line's fit); the second, in three processes with ``baselines.fit`` too, is in the slow tier."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import polyjax as pj
from polyjax.cli import main

ROOT = Path(__file__).resolve().parents[1]

_CHILD = r"""
import contextlib, io, json, sys
import jax
jax.config.update("jax_enable_x64", True)
import numpy as np
import polyjax as pj
from polyjax.cli import main
folder = sys.argv[1]
out = io.StringIO()
with contextlib.redirect_stdout(out):
    code = main(["--cache-dir", folder, "fit", "--degree", "3", "--json"])
pj.enable_compilation_cache(folder)
import baselines as bl
u = np.array(pj.data.synthetic_default().u)
v = np.array(pj.data.synthetic_default().v)
values = np.array(pj.data.synthetic_default().values)
f = bl.fit("ward", u, v, values, n_starts=2, max_steps=20)
print(json.dumps(dict(code=code, fit=json.loads(out.getvalue())["l2"], ward=np.asarray(f.l2).tolist())))
"""


def test_a_removed_saved_fit_is_compiled_again_and_its_file_runs(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv(pj.DATA_ENV, raising=False)
    args = ["--cache-dir", str(tmp_path), "fit", "--degree", "3", "--json"]
    runs = []
    for removed in (False, True, False):  # written, written again after its removal, loaded
        if removed:
            shutil.rmtree(tmp_path / "polyjax-programs")
        assert main(args) == 0
        runs.append(json.loads(capsys.readouterr().out))
        assert len(list((tmp_path / "polyjax-programs").glob("fit-*.bin"))) == 1
    assert runs[0]["coefficients"] == runs[1]["coefficients"] == runs[2]["coefficients"]
    assert runs[0]["l2"] == runs[1]["l2"] == runs[2]["l2"]


def _child(folder: Path) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("POLYJAX_CACHE", "POLYJAX_SAVED_PROGRAMS", "POLYJAX_DATA")}
    env["PYTHONPATH"] = str(ROOT)
    proc = subprocess.run([sys.executable, "-c", _CHILD, str(folder)], cwd=ROOT, env=env, capture_output=True,
                          text=True)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_saved_programs_removed_are_written_again_and_run(tmp_path):
    folder = tmp_path / "cache"
    first = _child(folder)
    programs = folder / "polyjax-programs"
    assert sorted(p.name.split("-")[0] for p in programs.glob("*.bin")) == ["baseline", "fit"]
    shutil.rmtree(programs)  # JAX's cache folder kept
    again = _child(folder)  # compiles afresh and writes the saved programs
    assert len(list(programs.glob("*.bin"))) == 2
    loaded = _child(folder)  # loads them
    assert first["code"] == again["code"] == loaded["code"] == 0
    assert first == again == loaded
