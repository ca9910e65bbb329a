"""Saved programs of ``baselines.fit`` (``baselines/_aot.py``): a second fresh process loads the first one's
executable and gets the same numbers bit for bit; a damaged file is reported with its reason and replaced; the
eager rules stay; and the plain numpy models of ``bench_latency.py``'s comparison are the baselines' models."""

import json
import os
import subprocess
import sys
import warnings
from pathlib import Path

import jax
import numpy as np
import pytest

import baselines as bl
import baselines._aot as aot
import polyjax as pj
from benchmarks import plain_models

from _problems import random_hemisphere

ROOT = Path(__file__).resolve().parents[1]
OPTIONS = dict(n_starts=4, max_steps=30)

_CHILD = r"""
import json, sys
import jax
jax.config.update("jax_enable_x64", True)
import numpy as np
import polyjax as pj
pj.enable_compilation_cache(sys.argv[1])
import baselines as bl
import baselines._aot as aot
compiled = []
original = aot._compile
aot._compile = lambda *a: compiled.append(1) or original(*a)
d = np.load(sys.argv[2])
f = bl.fit("ward", d["u"], d["v"], d["values"], n_starts=4, max_steps=30)
np.savez(sys.argv[3], **{k: np.asarray(getattr(f, k)) for k in aot._FIELDS})
print(json.dumps(dict(compiled=len(compiled))))
"""


@pytest.fixture(scope="module")
def problem():
    u, v = random_hemisphere(120, seed=5)
    h = (u + v) / np.linalg.norm(u + v, axis=1, keepdims=True)
    values = np.stack([0.2 + 0.8 * np.exp(-(1 / h[:, 2] ** 2 - 1) / 0.09), 0.1 + 0.3 * h[:, 2] ** 20])
    return u, v, values


def _child(folder, inputs, out):
    env = {k: v for k, v in os.environ.items() if k not in ("POLYJAX_CACHE", "JAX_ENABLE_COMPILATION_CACHE",
                                                          "POLYJAX_SAVED_PROGRAMS")}
    env["PYTHONPATH"] = str(ROOT)
    proc = subprocess.run([sys.executable, "-c", _CHILD, str(folder), str(inputs), str(out)], cwd=ROOT, env=env,
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _files(folder):
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file())


def test_second_process_loads_the_saved_program_bitwise(tmp_path, problem):
    """The first process compiles the whole fit once and writes it; the second loads it (nothing compiled, no file
    added to the cache folder) and gets the first one's arrays bit for bit; both agree with the ordinary fit."""
    u, v, values = problem
    inputs, folder = tmp_path / "inputs.npz", tmp_path / "cache"
    np.savez(inputs, u=u, v=v, values=values)
    first = _child(folder, inputs, tmp_path / "first.npz")
    written = _files(folder)
    assert first["compiled"] == 1
    assert len([f for f in written if f.startswith("polyjax-programs/baseline-")]) == 1, written
    second = _child(folder, inputs, tmp_path / "second.npz")
    assert second["compiled"] == 0 and _files(folder) == written
    a, b = np.load(tmp_path / "first.npz"), np.load(tmp_path / "second.npz")
    assert sorted(a.files) == sorted(aot._FIELDS)
    for name in a.files:
        assert a[name].dtype == b[name].dtype and np.array_equal(a[name], b[name]), name
    plain = bl.fit("ward", u, v, values, **OPTIONS)  # this process has no cache: the ordinary fit
    np.testing.assert_array_equal(a["status"], np.asarray(plain.status))
    np.testing.assert_allclose(a["l2"], np.asarray(plain.l2), rtol=1e-9)
    np.testing.assert_allclose(a["params"], np.asarray(plain.params), rtol=1e-6)


@pytest.fixture
def saved_here(tmp_path, monkeypatch):
    """Saved programs in this process, kept in ``tmp_path``; the process's memo and reports emptied."""
    folder = tmp_path / "polyjax-programs"
    monkeypatch.setattr(aot, "saved_folder", lambda: folder)
    monkeypatch.setattr(aot, "_LOADED", {})
    monkeypatch.setattr(aot, "_REPORTED", set())
    return folder


def test_damaged_saved_program_is_reported_and_replaced(saved_here, problem, monkeypatch):
    u, v, values = problem
    first = bl.fit("ward", u, v, values, **OPTIONS)
    (path,) = saved_here.glob("baseline-*.bin")
    path.write_bytes(b"not a saved program")
    monkeypatch.setattr(aot, "_LOADED", {})  # a fresh process: read from the file
    with pytest.warns(aot.SavedProgramWarning, match=r"could not be read \(UnpicklingError: .*\); fitting without"):
        again = bl.fit("ward", u, v, values, **OPTIONS)
    for name in aot._FIELDS:
        np.testing.assert_array_equal(np.asarray(getattr(again, name)), np.asarray(getattr(first, name)), name)
    assert again.name == "ward" and again.backend == "optimistix"
    monkeypatch.setattr(aot, "_LOADED", {})
    calls = []
    monkeypatch.setattr(aot, "_compile", lambda *a: calls.append(1))
    with warnings.catch_warnings():
        warnings.simplefilter("error", aot.SavedProgramWarning)
        third = bl.fit("ward", u, v, values, **OPTIONS)  # the file written again: loaded, nothing compiled
    assert calls == [] and np.array_equal(np.asarray(third.l2), np.asarray(first.l2))


def test_saved_programs_keep_the_eager_rules(saved_here, problem):
    """NaN values and negative weights raise as an eager call does (a traced program would flag the lane), before
    any program is compiled or written; throw=True raises on a lane that is not OK."""
    u, v, values = problem
    bad = values.copy()
    bad[1, 7] = np.nan
    with pytest.raises(pj.InputError, match="values: expected finite numbers"):
        bl.fit("ward", u, v, bad, **OPTIONS)
    with pytest.raises(pj.InputError, match="weights"):
        bl.fit("ward", u, v, values, weights=-np.ones(len(u)), **OPTIONS)
    assert not saved_here.exists()
    short = bl.fit("ward", u, v, values, n_starts=2, max_steps=1, limit_steps=0)
    assert np.all(np.asarray(short.status) == pj.Result.MAX_STEPS) and len(list(saved_here.glob("*.bin"))) == 1
    with pytest.raises(pj.FitError):
        bl.fit("ward", u, v, values, n_starts=2, max_steps=1, limit_steps=0, throw=True)


@pytest.mark.parametrize("name", sorted(plain_models.MODELS))
def test_plain_numpy_models_are_the_baselines_models(name):
    model = bl.get_model(name)
    u, v = random_hemisphere(300, seed=2, min_cos=0.01)
    rng = np.random.default_rng(7)
    for _ in range(4):
        raw = rng.normal(size=model.n_params)
        want = np.asarray(model.evaluate(model.to_params(jax.numpy.asarray(raw)), u, v))
        np.testing.assert_allclose(plain_models.evaluate(name, raw, u, v), want, rtol=1e-9, atol=1e-300)
