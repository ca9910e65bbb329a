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
import polyjax._cache.compilation as cache_mod
import polyjax._fit.closed_form as fit_mod
import polyjax._fit.stream as stream_mod
import polyjax.cli._progress as progress_mod

ROOT = Path(__file__).resolve().parents[1]


def _cli(args, env):
    return subprocess.run([sys.executable, "-m", "polyjax", *args], cwd=ROOT, env=env, capture_output=True, text=True)


def test_cli_cache_is_hit_by_a_second_process(tmp_path):
    """Two fresh processes: the first compiles (says so on stderr) and writes the fit's executable (the whole fit:
    one program, kept only as that file, not in JAX's cache: tests/test_saved_programs_rewritten.py); the second
    loads that executable (no file added anywhere) and prints the same fit as a process without any cache."""
    env = {k: v for k, v in os.environ.items() if k not in ("POLYJAX_DATA", "POLYJAX_CACHE", "CI")}
    env.update(PYTHONPATH=str(ROOT), POLYJAX_COMPILE_NOTICE_SECS="0")
    folder = tmp_path / "jax-cache"
    args = ["fit", "--degree", "3", "--json", "--cache-dir", str(folder)]
    first = _cli(args, env)
    assert first.returncode == 0, first.stderr
    written = sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))
    assert not any(name.startswith("jit_saved") for name in written), written
    assert len(list((folder / "polyjax-programs").glob("fit-*.bin"))) == 1, written
    assert "polyjax: compiling the fit" in first.stderr
    second = _cli(args, env)
    assert second.returncode == 0, second.stderr
    assert sorted(str(p.relative_to(folder)) for p in folder.rglob("*")) == written  # nothing compiled again
    assert "compiling" not in second.stderr
    assert json.loads(second.stdout)["l2"] == json.loads(first.stdout)["l2"]
    off = _cli(["fit", "--degree", "3", "--json", "--no-cache"], dict(env, XDG_CACHE_HOME=str(tmp_path / "xdg")))
    assert off.returncode == 0, off.stderr
    assert not (tmp_path / "xdg").exists()
    plain, warm = json.loads(off.stdout), json.loads(second.stdout)  # the eager fit of a process without a cache
    for key in ("l2", "l2_zero_model", "status", "rank"):
        assert warm[key] == plain[key], key
    np.testing.assert_allclose(warm["coefficients"], plain["coefficients"], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(warm["condition"], plain["condition"], rtol=1e-9)


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
    monkeypatch.setattr(progress_mod.compile_notice, "printed", False)
    quiet = io.StringIO()
    monkeypatch.setattr(cache_mod, "_counts", {"requests": 3, "answered": 3, "misses": 0})  # every look-up a hit
    with progress_mod.compile_notice("the fit", Path("/nowhere"), delay=0.0, stream=quiet):
        time.sleep(0.3)
    assert quiet.getvalue() == ""
    loud = io.StringIO()
    monkeypatch.setattr(cache_mod, "_counts", {"requests": 4, "answered": 3, "misses": 1})  # one being compiled
    with progress_mod.compile_notice("the fit", Path("/nowhere"), delay=0.0, stream=loud):
        time.sleep(0.3)
    assert loud.getvalue().count("\n") == 1 and loud.getvalue().startswith("polyjax: compiling the fit")
    again = io.StringIO()
    with progress_mod.compile_notice("the fit", None, delay=0.0, stream=again):  # at most one line per process
        time.sleep(0.2)
    assert again.getvalue() == ""
    fast = io.StringIO()
    monkeypatch.setattr(progress_mod.compile_notice, "printed", False)
    with progress_mod.compile_notice("the fit", None, delay=5.0, stream=fast):  # cache off, quick block: silence
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


@pytest.mark.parametrize("branch", ["auto", "one pass", "refined"])
@pytest.mark.parametrize("variables,degree", [("lafortune", [1, 3, 5]), ("ashikhmin-shirley", 4)])
def test_streamed_fit_equals_dense_fit(small_stream, monkeypatch, variables, degree, branch):
    """Both ways the streamed fit finishes (one pass over the values; a second, refining pass when the design is
    ill-conditioned or the residual is tiny) give the dense fit's numbers."""
    if branch == "one pass":
        monkeypatch.setattr(stream_mod, "SNE_CONDITION", np.inf)
        monkeypatch.setattr(stream_mod, "CANCELLATION", 0.0)
    if branch == "refined":
        monkeypatch.setattr(stream_mod, "SNE_CONDITION", 0.0)
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
    assert np.all(np.asarray(streamed.status) == pj.RESULTS.OK)


def test_streamed_fit_of_a_nearly_exact_polynomial_takes_the_refining_pass(small_stream):
    """Values that the model fits to 1e-5 of their size: ``b^T b - 2 beta^T A^T b + beta^T G beta`` would lose
    most digits of the residual, so the residual pass computes it; L2 and coefficients equal the dense fit's."""
    u, v, _, weights, mask = _tall_problem()
    x = np.asarray(pj.explanatory_variables("lafortune", u, v))
    rng = np.random.default_rng(3)
    values = np.stack([0.2 + 0.1 * x[:, 0] - 0.05 * x[:, 1] + 1e-6 * rng.normal(size=len(u)) for _ in range(2)])
    streamed = pj.fit_polynomial(u, v, values, "lafortune", 3, weights=weights, mask=mask)
    assert small_stream
    dense = jax.jit(lambda *a: pj.fit_polynomial(*a, "lafortune", 3, weights=weights, mask=mask))(u, v, values)
    assert np.all(np.asarray(streamed.l2) < 2e-6)
    np.testing.assert_allclose(streamed.l2, dense.l2, rtol=1e-8)
    np.testing.assert_allclose(streamed.coefficients, dense.coefficients, rtol=1e-9, atol=1e-12)


def test_streamed_fit_falls_back_on_a_rank_deficient_design(small_stream):
    """u = v everywhere: Lafortune's X_1 + X_2 = 1, one component is flat, the Cholesky factor breaks down and the
    dense path (inside the same program) flags the fit rank-deficient, as the dense fit does."""
    u, _, values, _, _ = _tall_problem()
    streamed = pj.fit_polynomial(u, u, values, "lafortune", 3)
    assert small_stream
    dense = jax.jit(lambda a, b, y: pj.fit_polynomial(a, b, y, "lafortune", 3))(u, u, values)
    np.testing.assert_array_equal(streamed.status, dense.status)
    assert np.all(np.asarray(streamed.status) == pj.RESULTS.RANK_DEFICIENT)
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


def test_fit_command_parser_leaves_the_other_commands_unimported():
    from polyjax.cli._main import _command_of

    assert _command_of(["--data-root", "fit", "--no-cache", "fit", "--degree", "3"]) == "fit"
    assert _command_of(["--cache-dir=x", "report"]) == "report"
    assert _command_of(["--help"]) is None
    code = ("import sys; from polyjax.cli._main import build_parser, _command_of; "
            "argv = ['--no-cache', 'fit', '--degree', '3']; a = build_parser(_command_of(argv)).parse_args(argv); "
            "print(a.degree, [m for m in ('polyjax.render', 'polyjax.svbrdf', 'polyjax.export') if m in sys.modules])")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                         env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["3", "[]"]
