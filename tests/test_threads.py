"""LAPACK's threads: one inside polyjax's calls, the user's own setting outside them (polyjax/_solve/threads.py).

Each check runs in a fresh process, so that the libraries start as a user's process starts them: OpenBLAS with
its default thread count (or the user's ``OPENBLAS_NUM_THREADS``) and jaxlib's LAPACK not yet loaded. Inside the
calls the count is read while the compiled program runs (a host callback in a variable set of the fit).
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
import json, sys
import jax, jax.numpy as jnp, numpy as np
jax.config.update("jax_enable_x64", True)
from threadpoolctl import threadpool_info, threadpool_limits
import baselines
import polyjax as pj

def blas():
    return sorted({i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"})

inside = []

def record(x):
    inside.append(blas())
    return x

def probe(u, v):
    x = jnp.stack([u[..., 2] * v[..., 2], u[..., 0] * v[..., 0] + u[..., 1] * v[..., 1]], axis=-1)
    return jax.pure_callback(record, jax.ShapeDtypeStruct(x.shape, x.dtype), x)

pj.register_variables("probe", probe, 2)
inside.clear()  # registering evaluates the variables once, eagerly, outside any fit
limit = None if sys.argv[1] == "none" else int(sys.argv[1])
data = pj.data.synthetic_default()
from scipy.linalg import cython_lapack  # the library jaxlib's LAPACK uses, loaded as a user's scipy call would
ctx = threadpool_limits(limits=limit, user_api="blas") if limit else None
before = blas()
fit = pj.fit_polynomial(data, variables="probe", degree=3)
after_fit = blas()
n_inside_fit = len(inside)
res = baselines.fit("blinn-phong", data[0], n_starts=2, key=jax.random.PRNGKey(0))
with pj.lapack_threads(2):
    nested = blas()
print(json.dumps({"before": before, "inside": inside, "n_inside_fit": n_inside_fit, "after_fit": after_fit,
                  "after": blas(), "nested": nested, "ok": bool(np.all(np.isfinite(np.asarray(fit.l2)))) and
                  bool(np.all(np.isfinite(np.asarray(res.l2))))}))
"""


def _probe(user_limit: str, **env):
    environ = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", pj.THREADS_ENV)}
    environ.update(env, PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, "-c", _PROBE, user_limit], cwd=ROOT, env=environ, capture_output=True,
                         text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_one_lapack_thread_inside_calls_and_the_users_setting_outside():
    r = _probe("2", OPENBLAS_NUM_THREADS="2")
    assert r["ok"]
    assert r["before"] == [2]  # the user's setting: the environment's, then their own threadpoolctl limit
    assert r["n_inside_fit"] > 0 and all(seen == [1] for seen in r["inside"])  # while the fit's program ran
    assert r["after_fit"] == [2] and r["after"] == [2]  # put back after the fit and after baselines.fit
    assert r["nested"] == [2]  # an explicit count in the caller's block


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
