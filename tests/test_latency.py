"""Latency features: the persistent compilation cache across processes, the compile notice and the progress line,
the streamed tall fit."""

import json
import os
import pty
import re
import subprocess
import sys
from pathlib import Path

import jax
import numpy as np
import pytest

import polyjax as pj

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
    assert "polyjax: compiling the fit" in off.stderr and "the compilation cache is off" in off.stderr
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
    assert not pj.internal.cache_disabled_by_env()
    monkeypatch.setenv(pj.CACHE_ENV, str(tmp_path / "mine"))
    assert pj.default_cache_dir() == tmp_path / "mine"
    for off in ("", "off", "OFF", "0"):
        monkeypatch.setenv(pj.CACHE_ENV, off)
        assert pj.internal.cache_disabled_by_env()
    blocker = tmp_path / "a-file"
    blocker.write_text("x")
    with pytest.raises(pj.InputError, match="a-file"):
        pj.enable_compilation_cache(blocker)


def _cli_process(code: str, env: dict, terminal: bool) -> subprocess.CompletedProcess:
    """A fresh process running the Python ``code``, its stderr a pseudo-terminal (``terminal``) or a pipe."""
    if not terminal:
        return subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True)
    main, other = pty.openpty()
    proc = subprocess.Popen([sys.executable, "-c", code], cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=other)
    os.close(other)
    chunks = []
    while True:
        try:
            chunk = os.read(main, 65536)
        except OSError:  # the process closed the terminal
            break
        if not chunk:
            break
        chunks.append(chunk)
    out = proc.stdout.read()
    proc.wait()
    os.close(main)
    return subprocess.CompletedProcess(proc.args, proc.returncode, out.decode(), b"".join(chunks).decode())


_PROGRESS = re.compile(r"\rpolyjax: fitting polynomial: (\d+) s, (compiling \((\d+) programs? ready\)|running)\x1b\[K")


@pytest.mark.slow  # three fresh processes, the first compiling with XLA's full optimisation
def test_compile_notice_and_progress_line_say_what_is_happening(tmp_path):
    """What ``polyjax fit`` shows on stderr while it works, from outside (fresh processes, JAX's full optimisation,
    so that a compile lasts seconds).

    - A cold process on a terminal: one "compiling" line (at most one per process: its second fit compiles again,
      silently); the progress line, every second, names the stage: ``compiling (k programs ready)`` while XLA
      compiles, ``k`` counting up within the block; the line erased when the block ends.
    - A warm process on a terminal, the fit's saved executable loaded: no "compiling" line, and a progress line that
      says ``running`` (nothing is traced, lowered or compiled); none for a fit shorter than the line's delay.
    - A warm process in a pipe whose programs JAX's cache holds (saved executables off): no "compiling" line while
      the cache reads them; with the cache off, no line for a block shorter than the notice's delay; and no progress
      line in a pipe.
    """
    env = {k: v for k, v in os.environ.items() if k not in ("POLYJAX_DATA", "POLYJAX_CACHE", "CI", "XLA_FLAGS",
                                                            "JAX_DISABLE_MOST_OPTIMIZATIONS", "POLYJAX_PROGRESS")}
    env.update(PYTHONPATH=str(ROOT), POLYJAX_COMPILE_NOTICE_SECS="0", POLYJAX_PROGRESS_SECS="0")
    folder = str(tmp_path / "cache")
    fit = "main(['--cache-dir', {folder!r}, 'fit', '--degree', '{degree}', '--json'])"
    saved_off = "os.environ['POLYJAX_SAVED_PROGRAMS'] = 'off'"
    cold = _cli_process("\n".join(["import os", "from polyjax.cli import main", fit.format(folder=folder, degree=3),
                                   saved_off, fit.format(folder=folder, degree=3)]), env, terminal=True)
    assert cold.returncode == 0, cold.stderr
    assert cold.stderr.count("polyjax: compiling the fit") == 1
    blocks = cold.stderr.split("\r\x1b[K")  # each block's progress line is erased at its end
    assert len(blocks) == 3 and blocks[-1].strip() == ""
    for block in blocks[:2]:
        lines = _PROGRESS.findall(block)
        ready = [int(k) for _, stage, k in lines if stage.startswith("compiling")]
        seconds = [int(t) for t, _, _ in lines]
        assert lines and seconds[0] == 0 and seconds == sorted(seconds) and ready == sorted(ready)
    assert any(int(t) >= 1 and stage.startswith("compiling") for t, stage, _ in _PROGRESS.findall(blocks[0]))
    warm = _cli_process("\n".join(["import os", "from polyjax.cli import main", fit.format(folder=folder, degree=3),
                                   "os.environ['POLYJAX_PROGRESS_SECS'] = '60'", fit.format(folder=folder, degree=3)]),
                        env, terminal=True)
    assert warm.returncode == 0, warm.stderr
    assert "compiling" not in warm.stderr and _PROGRESS.findall(warm.stderr)[0][:2] == ("0", "running")
    assert warm.stderr.count("\r\x1b[K") == 1  # the second fit, shorter than the line's delay: no line
    assert json.loads(warm.stdout.splitlines()[0])["l2"] == json.loads(cold.stdout.splitlines()[0])["l2"]
    quiet = _cli_process("\n".join(["import os", "from polyjax.cli import main", saved_off,
                                    fit.format(folder=folder, degree=3),
                                    "os.environ['POLYJAX_COMPILE_NOTICE_SECS'] = '600'",
                                    "main(['--no-cache', 'fit', '--degree', '5', '--json'])"]), env, terminal=False)
    assert quiet.returncode == 0 and "polyjax:" not in quiet.stderr, quiet.stderr


#: samples of the tall problems: with ``$POLYJAX_STREAM_ROWS`` at :data:`STREAM_FROM` an eager fit streams them, in
#: the streamed fit's blocks of 4096 rows: two blocks and a remainder
TALL = 9000
STREAM_FROM = 5000
#: the equilibrated design's condition number up to which a streamed fit keeps its one-pass solution (residuals not
#: tiny), above which it refines it with a second pass over the values (``polyjax/_fit/stream.py``)
ONE_PASS_CONDITION = 30.0


def _tall_problem(n=TALL, seed=0):
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
def streamed(monkeypatch, tmp_path):
    """Fits stream from :data:`STREAM_FROM` samples on (``$POLYJAX_STREAM_ROWS``), with the compilation cache in
    ``tmp_path``, where every streamed fit keeps its geometry (``polyjax-geometry/``): returns the number of
    geometries kept so far, so the number of streamed fits of different samples (every memo forgotten first)."""
    monkeypatch.setenv("POLYJAX_STREAM_ROWS", str(STREAM_FROM))
    folder = tmp_path / "cache"
    monkeypatch.setenv(pj.CACHE_ENV, str(folder))
    pj.enable_compilation_cache(folder)
    pj.internal.forget_memos()
    yield lambda: len(list((folder / "polyjax-geometry").glob("geometry-*.npz")))
    pj.internal.forget_memos()


@pytest.mark.parametrize("variables,degree,basis,refined", [
    ("lafortune", [1, 3, 5], "legendre", False), ("ashikhmin-shirley", [1, 2], "legendre", False),
    ("lafortune", [3, 5], "monomial", True), ("ashikhmin-shirley", 5, "legendre", True)])
def test_streamed_fit_equals_dense_fit(streamed, variables, degree, basis, refined):
    """Both ways the streamed fit finishes give the dense fit's numbers: one pass over the values (every degree's
    design well-conditioned), or a second, refining pass (an ill-conditioned design; the residual tiny: the next
    test). The dense fit: the same call traced (``jit``), which never streams."""
    u, v, values, weights, mask = _tall_problem()

    def fit(u, v, values, weights, mask):
        return pj.fit_polynomial(u, v, values, variables, degree, weights=weights, mask=mask, basis=basis)

    streamed_fit = fit(u, v, values, weights, mask)
    assert streamed() == 1, "the eager call should have been streamed"
    dense = jax.jit(fit)(u, v, values, weights, mask)
    assert streamed() == 1
    assert bool(np.any(np.asarray(dense.condition) > ONE_PASS_CONDITION)) is refined  # the branch under test
    np.testing.assert_allclose(streamed_fit.l2, dense.l2, rtol=1e-10)
    np.testing.assert_allclose(streamed_fit.coefficients, dense.coefficients, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(streamed_fit.condition, dense.condition, rtol=1e-8)
    for field in ("rank", "status", "n_used"):
        np.testing.assert_array_equal(getattr(streamed_fit, field), getattr(dense, field))
    assert np.all(np.asarray(streamed_fit.status) == pj.RESULTS.OK)


def test_streamed_fit_of_a_nearly_exact_polynomial_takes_the_refining_pass(streamed):
    """Values that the model fits to 1e-5 of their size: ``b^T b - 2 beta^T A^T b + beta^T G beta`` would lose
    most digits of the residual, so the residual pass computes it; L2 and coefficients equal the dense fit's."""
    u, v, _, weights, mask = _tall_problem()
    x = np.asarray(pj.explanatory_variables("lafortune", u, v))
    rng = np.random.default_rng(3)
    values = np.stack([0.2 + 0.1 * x[:, 0] - 0.05 * x[:, 1] + 1e-6 * rng.normal(size=len(u)) for _ in range(2)])
    streamed_fit = pj.fit_polynomial(u, v, values, "lafortune", 3, weights=weights, mask=mask)
    assert streamed() == 1
    dense = jax.jit(lambda *a: pj.fit_polynomial(*a, "lafortune", 3, weights=weights, mask=mask))(u, v, values)
    assert np.all(np.asarray(dense.condition) <= ONE_PASS_CONDITION)  # refined for the residual's sake alone
    assert np.all(np.asarray(streamed_fit.l2) < 2e-6)
    np.testing.assert_allclose(streamed_fit.l2, dense.l2, rtol=1e-8)
    np.testing.assert_allclose(streamed_fit.coefficients, dense.coefficients, rtol=1e-9, atol=1e-12)


def test_streamed_fit_falls_back_on_a_rank_deficient_design(streamed):
    """u = v everywhere: Lafortune's X_1 + X_2 = 1, one component is flat, the Cholesky factor breaks down and the
    dense path (inside the same program) flags the fit rank-deficient, as the dense fit does."""
    u, _, values, _, _ = _tall_problem()
    streamed_fit = pj.fit_polynomial(u, u, values, "lafortune", 3)
    assert streamed() == 1
    dense = jax.jit(lambda a, b, y: pj.fit_polynomial(a, b, y, "lafortune", 3))(u, u, values)
    np.testing.assert_array_equal(streamed_fit.status, dense.status)
    assert np.all(np.asarray(streamed_fit.status) == pj.RESULTS.RANK_DEFICIENT)
    np.testing.assert_allclose(streamed_fit.l2, dense.l2, rtol=1e-10)


def test_gradient_of_a_tall_fit_takes_the_dense_path(streamed):
    u, v, values, weights, _ = _tall_problem()
    loss = lambda y: pj.fit_polynomial(u, v, y, "lafortune", 3, weights=weights).l2.sum()  # noqa: E731
    g = jax.grad(loss)(values)
    assert streamed() == 0
    eps = 1e-6
    direction = np.random.default_rng(1).normal(size=values.shape)
    fd = (loss(values + eps * direction) - loss(values - eps * direction)) / (2 * eps)  # eager: streamed
    assert streamed() == 1
    np.testing.assert_allclose(float(np.sum(np.asarray(g) * direction)), float(fd), rtol=1e-6)


def test_tall_fits_stream_from_the_number_of_samples_the_switch_names(streamed, monkeypatch):
    """``$POLYJAX_STREAM_ROWS``, read at every fit: below it the eager fit is dense (no geometry kept), from it
    streamed; a value that is not a positive number of samples is an error naming the variable."""
    u, v, values, weights, _ = _tall_problem(n=STREAM_FROM + 10)
    monkeypatch.setenv("POLYJAX_STREAM_ROWS", str(STREAM_FROM + 11))
    dense = pj.fit_polynomial(u, v, values, "lafortune", 2, weights=weights)
    assert streamed() == 0
    monkeypatch.setenv("POLYJAX_STREAM_ROWS", str(STREAM_FROM + 10))
    tall = pj.fit_polynomial(u, v, values, "lafortune", 2, weights=weights)
    assert streamed() == 1
    np.testing.assert_allclose(tall.l2, dense.l2, rtol=1e-10)
    for bad in ("0", "many", "-5"):
        monkeypatch.setenv("POLYJAX_STREAM_ROWS", bad)
        with pytest.raises(pj.InputError, match="POLYJAX_STREAM_ROWS"):
            pj.fit_polynomial(u, v, values, "lafortune", 2, weights=weights)


def test_fit_command_parser_leaves_the_other_commands_unimported():
    """The command line finds its command past the global options and their values (a value may look like a
    command), and builds that command's parser alone: ``fit`` imports none of the heavy subpackages."""
    code = ("import sys\nfrom polyjax.cli import main\n"
            "def run(argv):\n    try:\n        main(argv)\n    except SystemExit as e:\n        print('exit', e.code)\n"
            "run(['--data-root', 'report', '--no-cache', 'fit', '--degree', '3', '--help'])\n"
            "print([m for m in ('polyjax.render', 'polyjax.svbrdf', 'polyjax.export') if m in sys.modules])\n"
            "run(['--cache-dir=x', 'report', '--help'])\n")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                         env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert out.returncode == 0, out.stderr
    fit, report = out.stdout.split("\n[]\n")  # the fit's help, no heavy subpackage imported, the report's help
    assert fit.startswith("usage: polyjax fit ") and "--degree" in fit and fit.rstrip().endswith("exit 0")
    assert report.startswith("usage: polyjax report ") and report.rstrip().endswith("exit 0")
