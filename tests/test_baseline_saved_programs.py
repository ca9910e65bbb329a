"""Saved programs of ``baselines.fit`` (``baselines/_aot.py``): a second fresh process loads the first one's
executable (it neither traces, lowers nor compiles) and gets the same numbers bit for bit; a damaged file is
reported with its reason and replaced; the eager rules stay; and the plain numpy models of ``bench_latency.py``'s
comparison are the baselines' models. Saved programs are on whenever the compilation cache is
(``pj.enable_compilation_cache``); what a process compiled is counted from JAX's own events (:mod:`jax.monitoring`)."""

import dataclasses
import json
import os
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import jax
import numpy as np
import pytest

import baselines as bl
import polyjax as pj
from benchmarks import plain_models

from _problems import random_hemisphere

ROOT = Path(__file__).resolve().parents[1]
OPTIONS = dict(n_starts=4, max_steps=30)
#: the array fields of a fit (those a saved program returns)
FIELDS = tuple(f.name for f in dataclasses.fields(bl.BaselineFit) if not f.metadata.get("static", False))

_CHILD = r"""
import json, sys, warnings
import jax
jax.config.update("jax_enable_x64", True)
events = []
jax.monitoring.register_event_duration_secs_listener(lambda event, duration, **kw: events.append(event))
import numpy as np
import polyjax as pj
pj.enable_compilation_cache(sys.argv[1])
import baselines as bl
d = np.load(sys.argv[2])
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always", bl.SavedProgramWarning)
    f = bl.fit("ward", d["u"], d["v"], d["values"], n_starts=4, max_steps=30)
fields = sys.argv[4].split(",")
np.savez(sys.argv[3], **{k: np.asarray(getattr(f, k)) for k in fields})
print(json.dumps(dict(
    compiled=events.count("/jax/core/compile/backend_compile_duration"),
    built=events.count("/jax/core/compile/jaxpr_trace_duration")
    + events.count("/jax/core/compile/jaxpr_to_mlir_module_duration"),
    warnings=[str(w.message) for w in caught if issubclass(w.category, bl.SavedProgramWarning)],
    name=f.name, backend=f.backend)))
"""


@pytest.fixture(scope="module")
def problem():
    u, v = random_hemisphere(120, seed=5)
    h = (u + v) / np.linalg.norm(u + v, axis=1, keepdims=True)
    values = np.stack([0.2 + 0.8 * np.exp(-(1 / h[:, 2] ** 2 - 1) / 0.09), 0.1 + 0.3 * h[:, 2] ** 20])
    return u, v, values


def _child(folder, inputs, out):
    """A fresh process fitting Ward to ``inputs`` with the cache in ``folder``: what it compiled, traced or lowered
    (JAX's events), its SavedProgramWarnings, and the fit's arrays in ``out``."""
    env = {k: v for k, v in os.environ.items() if k not in ("POLYJAX_CACHE", "JAX_ENABLE_COMPILATION_CACHE",
                                                          "POLYJAX_SAVED_PROGRAMS")}
    env["PYTHONPATH"] = str(ROOT)
    proc = subprocess.run([sys.executable, "-c", _CHILD, str(folder), str(inputs), str(out), ",".join(FIELDS)],
                          cwd=ROOT, env=env, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _files(folder):
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file())


@pytest.fixture(scope="module")
def first_process(tmp_path_factory, problem):
    """The first process of a machine: ``(folder, inputs, its report, its arrays' file, the files it wrote)``."""
    tmp = tmp_path_factory.mktemp("saved")
    u, v, values = problem
    inputs, folder = tmp / "inputs.npz", tmp / "cache"
    np.savez(inputs, u=u, v=v, values=values)
    report = _child(folder, inputs, tmp / "first.npz")
    return folder, inputs, report, tmp / "first.npz", _files(folder)


def test_second_process_loads_the_saved_program_bitwise(tmp_path, problem, first_process):
    """The first process compiles the whole fit once and writes it; the second loads it (nothing traced, lowered or
    compiled, no file added to the cache folder) and gets the first one's arrays bit for bit; both agree with the
    ordinary fit."""
    u, v, values = problem
    folder, inputs, first, first_out, written = first_process
    assert first["compiled"] >= 1 and first["warnings"] == []
    assert len([f for f in written if f.startswith("polyjax-programs/baseline-")]) == 1, written
    second = _child(folder, inputs, tmp_path / "second.npz")
    assert (second["compiled"], second["built"], second["warnings"]) == (0, 0, []) and _files(folder) == written
    a, b = np.load(first_out), np.load(tmp_path / "second.npz")
    assert sorted(a.files) == sorted(FIELDS)
    for name in a.files:
        assert a[name].dtype == b[name].dtype and np.array_equal(a[name], b[name]), name
    plain = bl.fit("ward", u, v, values, **OPTIONS)  # this process has no cache: the ordinary fit
    np.testing.assert_array_equal(a["status"], np.asarray(plain.status))
    np.testing.assert_allclose(a["l2"], np.asarray(plain.l2), rtol=1e-9)
    np.testing.assert_allclose(a["params"], np.asarray(plain.params), rtol=1e-6)


@pytest.mark.slow  # two fresh processes, one compiling the fit
def test_damaged_saved_program_is_reported_and_replaced(tmp_path, first_process):
    """A process finding a damaged file reports it once, with its reason, fits without it (the same numbers) and
    writes the program again; the next process loads that one, silently, compiling nothing."""
    folder, inputs, _, first_out, written = first_process
    cache = tmp_path / "cache"
    shutil.copytree(folder, cache)
    (path,) = (cache / "polyjax-programs").glob("baseline-*.bin")
    path.write_bytes(b"not a saved program")
    damaged = _child(cache, inputs, tmp_path / "damaged.npz")
    assert len(damaged["warnings"]) == 1 and damaged["compiled"] >= 1
    assert "expected a polyjax saved program, found another file" in damaged["warnings"][0]
    assert damaged["warnings"][0].endswith("; fitting without it")
    assert (damaged["name"], damaged["backend"]) == ("ward", "optimistix")
    first, again = np.load(first_out), np.load(tmp_path / "damaged.npz")
    for name in FIELDS:
        np.testing.assert_array_equal(again[name], first[name], name)
    programs = [f for f in written if f.startswith("polyjax-programs/")]
    assert [f for f in _files(cache) if f.startswith("polyjax-programs/")] == programs  # written again, in place
    assert path.read_bytes() != b"not a saved program"
    third = _child(cache, inputs, tmp_path / "third.npz")  # the file written again: loaded, nothing compiled
    assert (third["compiled"], third["built"], third["warnings"]) == (0, 0, [])
    assert np.array_equal(np.load(tmp_path / "third.npz")["l2"], first["l2"])


@pytest.fixture
def saved_here(tmp_path, monkeypatch):
    """Saved programs in this process: the compilation cache (its switch, and the environment variable the saved
    programs obey) in ``tmp_path``; returns the folder of the saved programs. The run's cache setting is put back
    after the test (tests/conftest.py)."""
    folder = tmp_path / "cache"
    monkeypatch.setenv(pj.CACHE_ENV, str(folder))
    monkeypatch.delenv("POLYJAX_SAVED_PROGRAMS", raising=False)
    pj.enable_compilation_cache(folder)
    return folder / "polyjax-programs"


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
    with warnings.catch_warnings():
        warnings.simplefilter("error", bl.SavedProgramWarning)
        short = bl.fit("ward", u, v, values, n_starts=2, max_steps=1, limit_steps=0)
    assert np.all(np.asarray(short.status) == pj.RESULTS.MAX_STEPS) and len(list(saved_here.glob("*.bin"))) == 1
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
