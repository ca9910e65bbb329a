"""The streamed fit's geometry (``polyjax/_fit/stream.py``): a QR of the weighted design as accurate as Householder's,
whichever way its preconditioner was found (a sample of the rows, every row, or a further pass), and the geometry
kept on disk beside the compilation cache (``polyjax/_cache/geometry.py``), found again, checked, never trusted.

Observed from outside: fits stream from :data:`STREAM_FROM` samples on (``$POLYJAX_STREAM_ROWS``), and with the
compilation cache on every streamed fit keeps its geometry in ``<cache>/polyjax-geometry/geometry-<key>.npz`` (its
factors, and how many passes over the rows they took): a file written is a geometry computed, a file left as it was
is a geometry loaded (a computed one is always written)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import polyjax as pj

N = 9000  # in the streamed fit's blocks of 4096 rows: two blocks and a remainder
STREAM_FROM = 5000
STRIDE = 8  # the preconditioner's sample: every N // 1024 = 8th row (at most every 16th, at least 1024 rows)


def _directions(rng, n, narrow=False):
    w = rng.normal(size=(n, 3))
    if narrow:  # within about 15 degrees of the normal
        w[:, :2] *= 0.15
    w[:, 2] = np.abs(w[:, 2])
    return w / np.linalg.norm(w, axis=1, keepdims=True)


def _problem(seed=0, narrow_sample=False):
    rng = np.random.default_rng(seed)
    u, v = _directions(rng, N), _directions(rng, N)
    if narrow_sample:  # the sampled rows unlike the whole: the preconditioner is poor
        n = len(u[::STRIDE])
        u[::STRIDE], v[::STRIDE] = _directions(rng, n, True), _directions(rng, n, True)
    weights = rng.uniform(0.5, 1.5, N)
    return u, v, weights


def _values(u, v, seed=0):
    h = u + v
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    rng = np.random.default_rng(seed)
    return np.stack([0.1 + c * h[:, 2] ** (8 * c + 2) + 0.01 * rng.normal(size=len(u)) for c in range(3)])


@pytest.fixture
def kept(monkeypatch, tmp_path):
    """Streamed fits from :data:`STREAM_FROM` samples on, the compilation cache (and so the kept geometries) in
    ``tmp_path``: returns the folder of the geometries. Every in-process memo forgotten before and after."""
    monkeypatch.setenv("POLYJAX_STREAM_ROWS", str(STREAM_FROM))
    folder = tmp_path / "cache"
    monkeypatch.setenv(pj.CACHE_ENV, str(folder))
    pj.enable_compilation_cache(folder)
    pj.internal.forget_memos()
    yield folder / "polyjax-geometry"
    pj.internal.forget_memos()


def _files(folder) -> dict:
    """The kept geometries: file name -> (inode, modification time); a file written again (atomically, by a rename)
    gets a new inode."""
    return {p.name: (p.stat().st_ino, p.stat().st_mtime_ns) for p in sorted(folder.glob("geometry-*.npz"))}


def _read(path) -> dict:
    with np.load(path) as f:
        return {name: f[name] for name in f.files}


def _fit_fresh(u, v, values, weights, degree=4, variables="lafortune"):
    """A fit as the first one of a process: every in-process memo forgotten."""
    pj.internal.forget_memos()
    return pj.fit_polynomial(u, v, values, variables, degree, weights=weights)


def _geometry(folder, u, v, weights, variables="lafortune", degree=4):
    """The geometry a streamed fit keeps (read from its file), and the dense, equilibrated weighted design it stands
    for."""
    _fit_fresh(u, v, _values(u, v), weights, degree, variables)
    (path,) = folder.glob("geometry-*.npz")
    x = pj.explanatory_variables(variables, u, v)
    w, wc2 = pj.internal.fit_weights(u, v, weights, None, 80.0)
    _, _, _, d = pj.fitted_design(x, w > 0, degree)
    return _read(path), np.asarray(d) * np.sqrt(np.asarray(wc2))[:, None]


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


@pytest.mark.parametrize("variables,degree", [("lafortune", 4), ("ashikhmin-shirley", 3)])
def test_geometry_from_a_sample_of_the_rows_is_a_householder_grade_qr(kept, variables, degree):
    geo, a = _geometry(kept, *_problem(), variables, degree)
    assert int(geo["passes"]) == 1 and bool(geo["sampled"])  # the sample preconditions well: one pass, every row
    _check_qr(geo, a)


def test_a_sample_without_full_rank_falls_back_to_every_row(kept):
    u, v, weights = _problem(1)
    weights[::STRIDE] = 0.0  # the sampled rows carry no weight: their Gram matrix is zero, its Cholesky factor fails
    geo, a = _geometry(kept, u, v, weights)
    assert int(geo["passes"]) == 2 and not bool(geo["sampled"])  # CholeskyQR2 itself: G of every row, then Q_1
    _check_qr(geo, a)


@pytest.mark.parametrize("variables,degree", [("lafortune", 5), ("ashikhmin-shirley", 3)])
def test_a_sample_unlike_the_whole_gets_a_further_pass(kept, variables, degree):
    """``Q_1`` far from orthogonal: a further pass, ``Q_1 R_2^{-1}`` once more, gives the factor of Householder QR."""
    geo, a = _geometry(kept, *_problem(2, narrow_sample=True), variables, degree)
    assert int(geo["passes"]) == 2 and bool(geo["sampled"])
    _check_qr(geo, a)


# the geometry kept on disk (polyjax/_cache/geometry.py)

@pytest.mark.parametrize("variables,degrees", [("lafortune", 4), ("ashikhmin-shirley", [1, 3])])
def test_kept_geometry_is_loaded_and_gives_the_same_fit(kept, variables, degrees):
    """A later process's first fit on the same samples loads the kept geometry (its shapes and dtypes, for one
    degree or several, are those it is checked against) and makes its per-sample rows, block by block, inside the
    fit: the same fit as the cold one to rounding, on samples some of which a zero weight or the mask drops."""
    u, v, weights = _problem(4)
    weights[::7] = 0.0
    mask = np.ones(N, bool)
    mask[3::11] = False
    values = _values(u, v)

    def fit():
        pj.internal.forget_memos()
        return pj.fit_polynomial(u, v, values, variables, degrees, weights=weights, mask=mask)

    cold = fit()
    written = _files(kept)
    assert len(written) == 1
    warm = fit()
    assert _files(kept) == written  # loaded, not computed (a computed geometry is written)
    for field in ("l2", "coefficients", "condition", "mean", "rotation", "centre", "halfwidth", "n_used"):
        np.testing.assert_allclose(getattr(warm, field), getattr(cold, field), rtol=1e-13, atol=1e-14)  # rounding
    dense = jax.jit(lambda y: pj.fit_polynomial(u, v, y, variables, degrees, weights=weights, mask=mask))(values)
    np.testing.assert_allclose(warm.l2, dense.l2, rtol=1e-10)


def test_kept_geometry_is_not_used_when_its_inputs_differ(kept):
    u, v, weights = _problem(5)
    values = _values(u, v)
    _fit_fresh(u, v, values, weights)
    other_w = weights.copy()
    other_w[1234] *= 1.0 + 1e-15  # one weight, in its last bits
    changed = _fit_fresh(u, v, values, other_w)
    other_v = v.copy()
    other_v[[7, 8]] = other_v[[8, 7]]  # two view directions swapped
    swapped = _fit_fresh(u, other_v, values, weights)
    _fit_fresh(u, v, values, weights, degree=3)  # other options
    assert len(_files(kept)) == 4  # four geometries computed
    dense = jax.jit(lambda v, y, w: pj.fit_polynomial(u, v, y, "lafortune", 4, weights=w))
    np.testing.assert_allclose(changed.l2, dense(v, values, other_w).l2, rtol=1e-10)
    np.testing.assert_allclose(swapped.l2, dense(other_v, values, weights).l2, rtol=1e-10)


def test_damaged_or_foreign_kept_geometry_is_ignored(kept):
    u, v, weights = _problem(6)
    values = _values(u, v)
    reference = _fit_fresh(u, v, values, weights)
    (path,) = kept.glob("geometry-*.npz")
    size = path.stat().st_size

    def computed_again() -> bool:
        before = path.stat().st_ino
        np.testing.assert_allclose(_fit_fresh(u, v, values, weights).l2, reference.l2, rtol=1e-14)
        return path.stat().st_ino != before and path.stat().st_size == size

    path.write_bytes(path.read_bytes()[:-100])  # truncated
    assert computed_again()
    arrays = _read(path)  # a changed factor under the old checksum
    arrays["r2"] = arrays["r2"] * 1.01
    np.savez(path, **arrays)
    assert computed_again()
    # another grid's geometry, with a valid checksum, written under this key: its samples and weight do not match
    u2, v2, w2 = _problem(7)
    w2[:100] = 0.0
    other = _fit_fresh(u2, v2, _values(u2, v2), w2)
    assert np.all(np.asarray(other.status) == pj.RESULTS.OK)
    (foreign,) = set(kept.glob("geometry-*.npz")) - {path}
    np.savez(path, **dict(_read(foreign), key=_read(path)["key"]))
    assert computed_again()
    assert computed_again() is False  # the geometry written again is loaded again (the check itself can fail)


def test_kept_geometry_of_a_loader_grid_serves_a_later_process(kept, tmp_path):
    """Every MERL file on one grid has the same directions, weights and mask: the geometry kept by the first fit is
    found by a later process's fit of another material on that grid (its own load of the grid), and gives the fit of
    a geometry computed for it."""
    resolution = (24, 24, 48)
    rng = np.random.default_rng(3)
    paths = [pj.data.write_merl_binary(tmp_path / f"m{i}.binary", rng.uniform(0.1, 1.0, (3, int(np.prod(resolution)))),
                                       resolution=resolution) for i in range(2)]
    first = pj.data.load_merl_binary(paths[0])
    assert first.n_samples >= STREAM_FROM
    pj.fit_polynomial(first, variables="lafortune", degree=2)
    kept_files = _files(kept)
    assert len(kept_files) == 1
    pj.internal.forget_memos()  # a later process
    second = pj.data.load_merl_binary(paths[1])
    assert second.u is not first.u
    fit = pj.fit_polynomial(second, variables="lafortune", degree=2)
    assert _files(kept) == kept_files  # loaded, not computed
    dense = jax.jit(lambda d: pj.fit_polynomial(d, variables="lafortune", degree=2))(second)
    np.testing.assert_allclose(fit.l2, dense.l2, rtol=1e-10)


def test_fit_after_a_kept_geometry_reuses_its_rows(kept):
    """The first fit on a kept geometry makes its rows inside the fit's program; the next fit on the same samples
    uses that completed geometry (nothing computed, nothing read: the files are gone) and agrees with a fit on the
    cold geometry."""
    u, v, weights = _problem(10)
    values = _values(u, v)
    u, v = jnp.asarray(u), jnp.asarray(v)  # the same device arrays for every fit (as a loader's grid)
    cold = _fit_fresh(u, v, values, weights)
    warm = _fit_fresh(u, v, values, weights)
    assert len(_files(kept)) == 1
    for path in kept.glob("geometry-*.npz"):
        path.unlink()  # the memo, not the disk, serves the next fit
    later = pj.fit_polynomial(u, v, values * 2.0, "lafortune", 4, weights=weights)
    assert _files(kept) == {}  # nothing computed (a computed geometry would be written)
    np.testing.assert_allclose(warm.l2, cold.l2, rtol=1e-14)
    np.testing.assert_allclose(later.l2, 2.0 * cold.l2, rtol=1e-13)
    np.testing.assert_allclose(later.coefficients, 2.0 * cold.coefficients, rtol=1e-12, atol=1e-14)
