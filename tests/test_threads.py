"""LAPACK's threads: one in a process that runs polyjax, set at its first call and kept (polyjax/_solve/threads.py).

Each check runs in a fresh process, so that the libraries start as a user's process starts them: OpenBLAS with
the user's ``OPENBLAS_NUM_THREADS`` and jaxlib's LAPACK either not loaded yet or loaded by the user's own scipy
call. Inside the calls the count is read while the compiled program runs (a host callback in a variable set of
the fit). Counts are reported per library folder: ``scipy.libs`` (the OpenBLAS jaxlib's LAPACK calls) and
``numpy.libs`` (numpy's own, left alone).
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import pytest

import polyjax as pj

ROOT = Path(__file__).resolve().parents[1]

_PROBE = r"""
import json, os, sys
import jax, jax.numpy as jnp, numpy as np
jax.config.update("jax_enable_x64", True)
from threadpoolctl import threadpool_info, threadpool_limits
import polyjax as pj

def counts():
    return {os.path.basename(os.path.dirname(i["filepath"])): i["num_threads"] for i in threadpool_info()
            if i["user_api"] == "blas"}

inside = []

def record(x):
    inside.append(counts().get("scipy.libs"))
    return x

def probe(u, v):
    x = jnp.stack([u[..., 2] * v[..., 2], u[..., 0] * v[..., 0] + u[..., 1] * v[..., 1]], axis=-1)
    return jax.pure_callback(record, jax.ShapeDtypeStruct(x.shape, x.dtype), x)

pj.register_variables("probe", probe, 2)
inside.clear()  # registering evaluates the variables once, eagerly, outside any fit
data = pj.data.synthetic_default()
if sys.argv[1] == "loaded":  # the user's scipy call loaded jaxlib's LAPACK library first, and set its own limit
    from scipy.linalg import cython_lapack
    threadpool_limits(limits=2, user_api="blas")
before = counts()
fit = pj.fit_polynomial(data, variables="probe", degree=3)
after_fit, inside_fit = counts(), list(inside)
res = pj.fit_log_polynomial(data, variables="probe", degree=2)
after_log = counts()
inside.clear()
with pj.lapack_threads(2):
    nested = counts()
    pj.fit_polynomial(data, variables="probe", degree=3).l2.block_until_ready()
print(json.dumps({"before": before, "inside_fit": inside_fit,
                  "after_fit": after_fit, "after_log": after_log, "nested": nested,
                  "inside_block": inside, "after": counts(), "env": os.environ.get("OPENBLAS_NUM_THREADS"),
                  "ok": bool(np.all(np.isfinite(np.asarray(fit.l2))) and np.all(np.isfinite(np.asarray(res.l2))))}))
"""


def _probe(mode: str, **env):
    environ = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", pj.THREADS_ENV)}
    environ.update(env, PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, "-c", _PROBE, mode], cwd=ROOT, env=environ, capture_output=True,
                         text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("mode", ["fresh", "loaded"])
def test_one_lapack_thread_from_the_first_call_on_and_numpys_left_alone(mode):
    r = _probe(mode, OPENBLAS_NUM_THREADS="2")
    assert r["ok"]
    assert r["before"]["numpy.libs"] == 2  # the user's environment
    if mode == "loaded":
        assert r["before"]["scipy.libs"] == 2  # the user's own load and limit, before polyjax's first call
    else:
        assert "scipy.libs" not in r["before"]  # not loaded until polyjax's first factorisation
    assert r["inside_fit"] and all(seen == 1 for seen in r["inside_fit"])  # while the fit's program ran
    assert r["after_fit"]["scipy.libs"] == 1 and r["after_log"]["scipy.libs"] == 1  # set once, kept
    assert r["after_fit"]["numpy.libs"] == 2 and r["after"]["numpy.libs"] == 2  # numpy's own is not polyjax's
    assert r["env"] == "2"  # the environment is the user's again after loading
    assert r["nested"]["scipy.libs"] == 2  # an explicit count for the caller's block ...
    assert r["inside_block"] and all(seen == 2 for seen in r["inside_block"])  # ... which polyjax's calls keep
    assert r["after"]["scipy.libs"] == 1  # and the block's end puts the previous count back


def test_the_count_while_the_fit_runs_is_one():
    """Read inside the compiled fit (the probe's host callback), in this process: scipy's OpenBLAS has one
    thread while the program runs, even after the user raised it."""
    from threadpoolctl import threadpool_info, threadpool_limits

    seen = []

    def probe(u, v):
        x = jnp.stack([u[..., 2] * v[..., 2], u[..., 0] * v[..., 0] + u[..., 1] * v[..., 1]], axis=-1)

        def record(x):
            return seen.append({i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas" and
                                "scipy" in i["filepath"] and "numpy" not in i["filepath"]}) or x
        return jax.pure_callback(record, jax.ShapeDtypeStruct(x.shape, x.dtype), x)

    pj.register_variables("threads-probe-on", probe, 2, overwrite=True)
    with threadpool_limits(limits=2, user_api="blas"):
        seen.clear()
        pj.fit_polynomial(pj.data.synthetic_default(), variables="threads-probe-on", degree=2).l2.block_until_ready()
    assert seen and all(s == {1} for s in seen)


def test_switch_off_leaves_the_libraries_alone(monkeypatch):
    from scipy.linalg import cython_lapack  # noqa: F401 - jaxlib's LAPACK library loaded before the user's limit
    from threadpoolctl import threadpool_info, threadpool_limits

    seen = []

    def probe(u, v):
        x = jnp.stack([u[..., 2] * v[..., 2], u[..., 0] * v[..., 0] + u[..., 1] * v[..., 1]], axis=-1)
        def record(x):
            return seen.append({i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"}) or x
        return jax.pure_callback(record, jax.ShapeDtypeStruct(x.shape, x.dtype), x)

    pj.register_variables("threads-probe", probe, 2, overwrite=True)
    monkeypatch.setenv(pj.THREADS_ENV, "off")
    with threadpool_limits(limits=2, user_api="blas"):
        seen.clear()
        pj.fit_polynomial(pj.data.synthetic_default(), variables="threads-probe", degree=2).l2.block_until_ready()
    assert seen and all(s == {2} for s in seen)


def test_bad_switch_is_a_clear_error(monkeypatch):
    monkeypatch.setenv(pj.THREADS_ENV, "many")
    with pytest.raises(pj.InputError, match="POLYJAX_LAPACK_THREADS"):
        with pj.lapack_threads():
            pass
    with pytest.raises(pj.InputError, match="positive integer"):
        pj.lapack_threads(0)
