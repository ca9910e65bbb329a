"""The weighted least-squares solver: tall (CholeskyQR2) path against SVD, and batched factorisations
that never deadlock XLA's CPU thread pool."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import jax.numpy as jnp
import numpy as np
import pytest

import polyjax as pj
from polyjax.internal import TALL_ROWS


def _tall_problem(seed=0, m=12):
    rng = np.random.default_rng(seed)
    n = TALL_ROWS + 5000
    d = rng.normal(size=(n, m))
    d[:, 0] = 1.0
    beta = rng.normal(size=m)
    y = d @ beta + 0.01 * rng.normal(size=n)
    w = rng.uniform(0.0, 1.0, n)
    w[:100] = 0.0  # masked samples
    return d, y, w, beta


@pytest.mark.parametrize("active", [None, "last3off"])
def test_tall_cholesky_qr2_matches_svd(active):
    d, y, w, _ = _tall_problem()
    act = None if active is None else jnp.arange(d.shape[1]) < d.shape[1] - 3
    a = pj.weighted_lstsq(jnp.asarray(d), jnp.asarray(y), jnp.asarray(w), act)
    b = pj.weighted_lstsq(jnp.asarray(d), jnp.asarray(y), jnp.asarray(w), act, method="svd")
    np.testing.assert_allclose(np.asarray(a.coefficients), np.asarray(b.coefficients), rtol=0, atol=1e-12)
    assert int(a.rank) == int(b.rank) == int(a.n_active)
    np.testing.assert_allclose(float(a.condition), float(b.condition), rtol=1e-9)
    if act is not None:
        assert np.all(np.asarray(a.coefficients)[-3:] == 0.0)


def test_tall_exact_data_recovered():
    d, _, w, beta = _tall_problem(1)
    sol = pj.weighted_lstsq(jnp.asarray(d), jnp.asarray(d @ beta), jnp.asarray(w))
    np.testing.assert_allclose(np.asarray(sol.coefficients), beta, rtol=0, atol=1e-12)


def test_tall_duplicated_column_falls_back_to_minimum_norm():
    """Hard case: a duplicated column makes the Gram matrix singular; Householder takes over."""
    d, y, w, _ = _tall_problem(2)
    d[:, 5] = d[:, 4]
    a = pj.weighted_lstsq(jnp.asarray(d), jnp.asarray(y), jnp.asarray(w))
    b = pj.weighted_lstsq(jnp.asarray(d), jnp.asarray(y), jnp.asarray(w), method="svd")
    assert int(a.rank) == int(b.rank) == d.shape[1] - 1
    assert np.isinf(float(a.condition))
    np.testing.assert_allclose(np.asarray(a.coefficients), np.asarray(b.coefficients), rtol=0, atol=1e-10)
    np.testing.assert_allclose(a.coefficients[4], a.coefficients[5], rtol=1e-10)  # minimum norm splits evenly


def test_several_fits_in_one_jit_do_not_deadlock():
    """Hard case: three batched fits compiled into one program and run repeatedly.

    jaxlib schedules batched LAPACK calls onto XLA's intra-op pool and blocks; two such calls
    running concurrently on a 2-thread pool used to wait on each other forever (205 samples, as in
    CUReT, hung within two calls). Run in a subprocess with a time limit so a regression fails
    instead of hanging the suite.
    """
    script = textwrap.dedent(
        """
        import jax
        jax.config.update("jax_enable_x64", True)
        import numpy as np
        import polyjax as pj
        rng = np.random.default_rng(0)
        z = rng.normal(size=(205, 3)); z[:, 2] = np.abs(z[:, 2]) + 0.2
        u = z / np.linalg.norm(z, axis=1, keepdims=True)
        z = rng.normal(size=(205, 3)); z[:, 2] = np.abs(z[:, 2]) + 0.2
        v = z / np.linalg.norm(z, axis=1, keepdims=True)
        b = rng.uniform(0.1, 1.0, size=(52, 205))
        f = jax.jit(lambda u, v, b: [pj.fit_polynomial(u, v, b, variables=s, degree=tuple(range(1, 9))).l2
                                     for s in ("ashikhmin-shirley", "lafortune", "ward")])
        for _ in range(30):
            out = jax.block_until_ready(f(u, v, b))
        print("ok", all(bool(np.all(np.isfinite(o))) for o in out))
        """
    )
    res = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=240)
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.strip().endswith("ok True")
