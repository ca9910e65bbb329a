"""Latency features: the persistent compilation cache across processes, the compile notice, the streamed tall fit."""

import io
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import jax
import numpy as np
import pytest

import polyjax as pj
import polyjax._cache as cache_mod
import polyjax._fit as fit_mod
import polyjax._stream as stream_mod

ROOT = Path(__file__).resolve().parents[1]


def _cli(args, env):
    return subprocess.run([sys.executable, "-m", "polyjax", *args], cwd=ROOT, env=env, capture_output=True, text=True)


def test_cli_cache_is_hit_by_a_second_process(tmp_path):
    """Two fresh processes: the first compiles (says so on stderr) and writes the cache; the second finds every
    program there (no file added) and prints the same fit."""
    env = {k: v for k, v in os.environ.items() if k not in ("POLYJAX_DATA", "POLYJAX_CACHE", "CI")}
    env.update(PYTHONPATH=str(ROOT), POLYJAX_COMPILE_NOTICE_SECS="0")
    folder = tmp_path / "jax-cache"
    args = ["fit", "--degree", "3", "--json", "--cache-dir", str(folder)]
    first = _cli(args, env)
    assert first.returncode == 0, first.stderr
    written = sorted(p.name for p in folder.iterdir())
    assert any(name.startswith("jit__fit_kernel") for name in written), written
    assert "polyjax: compiling the fit" in first.stderr
    second = _cli(args, env)
    assert second.returncode == 0, second.stderr
    assert sorted(p.name for p in folder.iterdir()) == written  # a compiled (missed) program would add a file
    assert json.loads(second.stdout)["l2"] == json.loads(first.stdout)["l2"]
    off = _cli(["fit", "--degree", "3", "--json", "--no-cache"], dict(env, XDG_CACHE_HOME=str(tmp_path / "xdg")))
    assert off.returncode == 0, off.stderr
    assert not (tmp_path / "xdg").exists()


def test_import_leaves_jax_config_alone():
    code = "import jax, polyjax; print(jax.config.jax_compilation_cache_dir)"
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                         env={**{k: v for k, v in os.environ.items() if not k.startswith("JAX_")},
                              "PYTHONPATH": str(ROOT)})  # without the test run's JAX_COMPILATION_CACHE_DIR
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "None"


def test_cache_folder_settings(tmp_path, monkeypatch):
    monkeypatch.delenv(pj.CACHE_ENV, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert pj.default_cache_dir() == tmp_path / "xdg" / "polyjax" / "jax"
    assert not cache_mod.cache_disabled_by_env()
    monkeypatch.setenv(pj.CACHE_ENV, str(tmp_path / "mine"))
    assert pj.default_cache_dir() == tmp_path / "mine"
    for off in ("", "off", "OFF", "0"):
        monkeypatch.setenv(pj.CACHE_ENV, off)
        assert cache_mod.cache_disabled_by_env()
    blocker = tmp_path / "a-file"
    blocker.write_text("x")
    with pytest.raises(pj.InputError, match="a-file"):
        pj.enable_compilation_cache(blocker)


def test_compile_notice_one_line_only_while_compiling(monkeypatch):
    monkeypatch.setattr(cache_mod.compile_notice, "printed", False)
    quiet = io.StringIO()
    monkeypatch.setattr(cache_mod, "_counts", {"requests": 3, "answered": 3})  # the cache answered every look-up
    with cache_mod.compile_notice("the fit", Path("/nowhere"), delay=0.0, stream=quiet):
        time.sleep(0.3)
    assert quiet.getvalue() == ""
    loud = io.StringIO()
    monkeypatch.setattr(cache_mod, "_counts", {"requests": 4, "answered": 3})  # one program being compiled
    with cache_mod.compile_notice("the fit", Path("/nowhere"), delay=0.0, stream=loud):
        time.sleep(0.3)
    assert loud.getvalue().count("\n") == 1 and loud.getvalue().startswith("polyjax: compiling the fit")
    again = io.StringIO()
    with cache_mod.compile_notice("the fit", None, delay=0.0, stream=again):  # at most one line per process
        time.sleep(0.2)
    assert again.getvalue() == ""
    fast = io.StringIO()
    monkeypatch.setattr(cache_mod.compile_notice, "printed", False)
    with cache_mod.compile_notice("the fit", None, delay=5.0, stream=fast):  # cache off, quick block: silence
        pass
    assert fast.getvalue() == ""


def _tall_problem(n=2600, seed=0):
    rng = np.random.default_rng(seed)

    def dirs():
        w = rng.normal(size=(n, 3))
        w[:, 2] = np.abs(w[:, 2])
        return w / np.linalg.norm(w, axis=1, keepdims=True)

    u, v = dirs(), dirs()
    h = u + v
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    values = np.stack([0.1 + c * h[:, 2] ** (8 * c + 2) + 0.01 * rng.normal(size=n) for c in range(3)])
    weights = rng.uniform(0.5, 1.5, n)
    mask = rng.uniform(size=n) > 0.1
    return u, v, values, weights, mask


@pytest.fixture
def small_stream(monkeypatch):
    """Stream from 2000 rows on, in blocks of 512 (so 2600 rows are 5 blocks and a remainder); count the calls."""
    monkeypatch.setattr(stream_mod, "STREAM_ROWS", 2000)
    monkeypatch.setattr(stream_mod, "BLOCK", 512)
    calls = []
    original = fit_mod.streamed_lane

    def counting(*args, **kwargs):
        calls.append(1)
        return original(*args, **kwargs)

    monkeypatch.setattr(fit_mod, "streamed_lane", counting)
    fit_mod._fit_kernel.clear_cache()  # calls are counted when the kernel is traced: trace it again here
    yield calls
    fit_mod._fit_kernel.clear_cache()


@pytest.mark.parametrize("variables,degree", [("lafortune", [1, 3, 5]), ("ashikhmin-shirley", 4)])
def test_streamed_fit_equals_dense_fit(small_stream, variables, degree):
    u, v, values, weights, mask = _tall_problem()

    def fit(u, v, values, weights, mask):
        return pj.fit_polynomial(u, v, values, variables, degree, weights=weights, mask=mask)

    streamed = fit(u, v, values, weights, mask)
    assert small_stream, "the eager call should have been streamed"
    n_streamed = len(small_stream)
    dense = jax.jit(fit)(u, v, values, weights, mask)  # traced inputs: the dense path
    assert len(small_stream) == n_streamed
    np.testing.assert_allclose(streamed.l2, dense.l2, rtol=1e-10)
    np.testing.assert_allclose(streamed.coefficients, dense.coefficients, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(streamed.condition, dense.condition, rtol=1e-8)
    for field in ("rank", "status", "n_used"):
        np.testing.assert_array_equal(getattr(streamed, field), getattr(dense, field))
    assert np.all(np.asarray(streamed.status) == pj.Result.OK)


def test_streamed_fit_falls_back_on_a_rank_deficient_design(small_stream):
    """u = v everywhere: Lafortune's X_1 + X_2 = 1, one component is flat, the Cholesky factor breaks down and the
    dense path (inside the same program) flags the fit rank-deficient, as the dense fit does."""
    u, _, values, _, _ = _tall_problem()
    streamed = pj.fit_polynomial(u, u, values, "lafortune", 3)
    assert small_stream
    dense = jax.jit(lambda a, b, y: pj.fit_polynomial(a, b, y, "lafortune", 3))(u, u, values)
    np.testing.assert_array_equal(streamed.status, dense.status)
    assert np.all(np.asarray(streamed.status) == pj.Result.RANK_DEFICIENT)
    np.testing.assert_allclose(streamed.l2, dense.l2, rtol=1e-10)


def test_gradient_of_a_tall_fit_takes_the_dense_path(small_stream):
    u, v, values, weights, _ = _tall_problem()
    loss = lambda y: pj.fit_polynomial(u, v, y, "lafortune", 3, weights=weights).l2.sum()  # noqa: E731
    g = jax.grad(loss)(values)
    assert not small_stream
    eps = 1e-6
    direction = np.random.default_rng(1).normal(size=values.shape)
    fd = (loss(values + eps * direction) - loss(values - eps * direction)) / (2 * eps)  # eager: streamed
    assert small_stream
    np.testing.assert_allclose(float(np.sum(np.asarray(g) * direction)), float(fd), rtol=1e-6)
