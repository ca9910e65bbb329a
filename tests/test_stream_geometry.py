"""The streamed fit's geometry (``polyjax/_stream.py``): a QR of the weighted design as accurate as Householder's,
whichever way its preconditioner was found (a sample of the rows, every row, or a further pass)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import polyjax as pj
import polyjax._stream as stream_mod
from polyjax._basis import term_degrees

N = 2600  # with blocks of 512 rows: 5 blocks and a remainder; the sample is every 2nd row (n // 1024 = 2)


def _directions(rng, n, narrow=False):
    w = rng.normal(size=(n, 3))
    if narrow:  # within about 15 degrees of the normal
        w[:, :2] *= 0.15
    w[:, 2] = np.abs(w[:, 2])
    return w / np.linalg.norm(w, axis=1, keepdims=True)


def _problem(seed=0, narrow_sample=False):
    rng = np.random.default_rng(seed)
    u, v = _directions(rng, N), _directions(rng, N)
    if narrow_sample:  # the sampled rows (even ones) unlike the whole: the preconditioner is poor
        u[::2], v[::2] = _directions(rng, N // 2, True), _directions(rng, N // 2, True)
    weights = rng.uniform(0.5, 1.5, N)
    return u, v, weights


def _geometry(u, v, weights, variables="lafortune", degree=4):
    x = pj.explanatory_variables(variables, u, v)
    w, wc2 = pj.fit_weights(u, v, weights, None, 80.0)
    k = x.shape[1]
    active = jnp.asarray(term_degrees(k, degree, False))[None, :] <= jnp.asarray([degree])[:, None]
    geo = jax.jit(lambda x, w, wc2: stream_mod.stream_geometry(
        x, w, wc2, active, max_degree=degree, basis="legendre", interactions=False, block=512))(x, w, wc2)
    # the dense, equilibrated weighted design the geometry stands for
    _, _, _, d = pj.fitted_design(x, w > 0, degree)
    a = np.asarray(d) * np.sqrt(np.asarray(wc2))[:, None]
    return geo, a


def _check_qr(geo, a):
    """``R`` (from its SVD) is the R of Householder QR of ``A E^{-1}`` up to row signs, ``Q = A E^{-1} R^{-1}`` is
    orthogonal to rounding, and the column norms and ``G`` are those of ``A``."""
    e = np.linalg.norm(a, axis=0)
    np.testing.assert_allclose(geo["scale"][0], e, rtol=1e-13)
    r = np.asarray(geo["u"][0] * geo["s"][0][None, :] @ geo["vt"][0])
    q = np.linalg.solve(r.T, (a / e).T).T
    np.testing.assert_allclose(q.T @ q, np.eye(a.shape[1]), atol=1e-13)
    r_householder = np.linalg.qr(a / e, mode="r")
    np.testing.assert_allclose(np.abs(r), np.abs(r_householder), atol=1e-12)
    np.testing.assert_allclose(geo["g"], a.T @ a, rtol=1e-12, atol=1e-12 * np.max(e) ** 2)
    assert bool(geo["ok"])


def test_geometry_from_a_sample_of_the_rows_is_a_householder_grade_qr():
    geo, a = _geometry(*_problem())
    assert int(geo["passes"]) == 1 and bool(geo["sampled"])  # the sample preconditions well: one pass, every row
    _check_qr(geo, a)


def test_a_sample_without_full_rank_falls_back_to_every_row():
    u, v, weights = _problem(1)
    weights[::2] = 0.0  # the sampled rows carry no weight: their Gram matrix is zero, its Cholesky factor fails
    geo, a = _geometry(u, v, weights)
    assert int(geo["passes"]) == 2 and not bool(geo["sampled"])  # CholeskyQR2 itself: G of every row, then Q_1
    _check_qr(geo, a)


def test_a_sample_unlike_the_whole_gets_a_further_pass():
    geo, a = _geometry(*_problem(2, narrow_sample=True), degree=5)
    assert int(geo["passes"]) == 2 and bool(geo["sampled"])  # Q_1 far from orthogonal: Q_1 R_2^{-1} once more
    _check_qr(geo, a)


@pytest.mark.parametrize("variables,degree", [("lafortune", 5), ("ashikhmin-shirley", 3)])
def test_forced_further_pass_gives_the_same_factor(monkeypatch, variables, degree):
    u, v, weights = _problem(3)
    geo, a = _geometry(u, v, weights, variables, degree)
    monkeypatch.setattr(stream_mod, "PRECONDITION_CONDITION", 1.0)  # every Q_1 counts as far from orthogonal
    geo3, _ = _geometry(u, v, weights, variables, degree)
    assert int(geo["passes"]) == 1 and int(geo3["passes"]) == 2 and bool(geo3["sampled"])
    _check_qr(geo3, a)
    np.testing.assert_allclose(geo3["s"], geo["s"], rtol=1e-13)
