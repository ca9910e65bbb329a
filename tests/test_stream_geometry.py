"""The streamed fit's geometry (``polyjax/_fit/stream.py``): a QR of the weighted design as accurate as Householder's,
whichever way its preconditioner was found (a sample of the rows, every row, or a further pass)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import polyjax as pj
import polyjax._cache.keys as keys
import polyjax._cache.memo as memo
import polyjax._fit.stream as stream_mod
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
    w, wc2 = pj.internal.fit_weights(u, v, weights, None, 80.0)
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


# the geometry kept on disk (polyjax/_cache/geometry.py)

@pytest.fixture
def kept(monkeypatch, tmp_path):
    """Streamed fits from 2000 rows on (blocks of 512) with the geometry kept in ``tmp_path``; counts the geometries
    computed (not loaded)."""
    import polyjax._cache.geometry as store
    import polyjax._fit.closed_form as fit_mod

    monkeypatch.setattr(stream_mod, "STREAM_ROWS", 2000)
    monkeypatch.setattr(stream_mod, "BLOCK", 512)
    monkeypatch.setattr(store, "store_folder", lambda: tmp_path)
    computed = []
    original = fit_mod._geometry_kernel

    def counting(*args, **kwargs):
        if not any(isinstance(a, jax.core.Tracer) for a in jax.tree.leaves(args)):  # not jax.eval_shape's call
            computed.append(1)
        return original(*args, **kwargs)

    monkeypatch.setattr(fit_mod, "_geometry_kernel", counting)
    for kernel in (fit_mod._fit_kernel, original):
        kernel.clear_cache()  # BLOCK is read when a kernel is traced
    memo._GEOMETRY_MEMO.clear()
    yield computed, tmp_path
    memo._GEOMETRY_MEMO.clear()
    for kernel in (fit_mod._fit_kernel, original):
        kernel.clear_cache()


def _fit_fresh(u, v, values, weights, degree=4):
    """A fit as the first one of a process: the in-process geometry memo forgotten."""

    memo._GEOMETRY_MEMO.clear()
    return pj.fit_polynomial(u, v, values, "lafortune", degree, weights=weights)


def _values(u, v, seed=0):
    h = u + v
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    rng = np.random.default_rng(seed)
    return np.stack([0.1 + c * h[:, 2] ** (8 * c + 2) + 0.01 * rng.normal(size=len(u)) for c in range(3)])


def test_kept_geometry_is_loaded_and_gives_the_same_fit(kept):
    computed, folder = kept
    u, v, weights = _problem(4)
    values = _values(u, v)
    cold = _fit_fresh(u, v, values, weights)
    assert len(computed) == 1 and len(list(folder.glob("geometry-*.npz"))) == 1
    warm = _fit_fresh(u, v, values, weights)
    assert len(computed) == 1  # loaded, not computed
    for field in ("l2", "coefficients", "condition", "mean", "rotation", "centre", "halfwidth"):
        np.testing.assert_allclose(getattr(warm, field), getattr(cold, field), rtol=1e-14, atol=1e-15)
    dense = jax.jit(lambda y: pj.fit_polynomial(u, v, y, "lafortune", 4, weights=weights))(values)
    np.testing.assert_allclose(warm.l2, dense.l2, rtol=1e-10)


def test_kept_geometry_is_not_used_when_its_inputs_differ(kept):
    computed, folder = kept
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
    assert len(computed) == 4 and len(list(folder.glob("geometry-*.npz"))) == 4
    dense = jax.jit(lambda v, y, w: pj.fit_polynomial(u, v, y, "lafortune", 4, weights=w))
    np.testing.assert_allclose(changed.l2, dense(v, values, other_w).l2, rtol=1e-10)
    np.testing.assert_allclose(swapped.l2, dense(other_v, values, weights).l2, rtol=1e-10)


def test_damaged_or_foreign_kept_geometry_is_ignored(kept):
    import polyjax._cache.geometry as store

    computed, folder = kept
    u, v, weights = _problem(6)
    values = _values(u, v)
    reference = _fit_fresh(u, v, values, weights)
    (path,) = folder.glob("geometry-*.npz")
    key = path.stem.removeprefix("geometry-")
    path.write_bytes(path.read_bytes()[:-100])  # truncated
    np.testing.assert_allclose(_fit_fresh(u, v, values, weights).l2, reference.l2, rtol=1e-14)
    assert len(computed) == 2
    with np.load(path) as f:  # a changed factor under the old checksum
        arrays = {name: f[name] for name in f.files}
    arrays["r2"] = arrays["r2"] * 1.01
    np.savez(path, **arrays)
    np.testing.assert_allclose(_fit_fresh(u, v, values, weights).l2, reference.l2, rtol=1e-14)
    assert len(computed) == 3
    # another grid's geometry written under this key, with a valid checksum: its samples and weight do not match

    u2, v2, w2 = _problem(7)
    w2[:100] = 0.0
    memo._GEOMETRY_MEMO.clear()
    other = pj.fit_polynomial(u2, v2, _values(u2, v2), "lafortune", 4, weights=w2)
    assert np.all(np.asarray(other.status) == pj.RESULTS.OK)
    foreign = memo._GEOMETRY_MEMO["last"]["geo"]
    store.save(folder, key, foreign)
    n_computed = len(computed)
    np.testing.assert_allclose(_fit_fresh(u, v, values, weights).l2, reference.l2, rtol=1e-14)
    assert len(computed) == n_computed + 1


def test_loader_grid_directions_are_named_not_checksummed():
    """The MERL loader's grid directions are fingerprinted by name (made by polyjax's code, which is in the key);
    any other array, a copy of them included, by the CRC-32 of its bytes."""
    from polyjax.data import _merl

    u, v, w, _ = _merl._device_grid(pj.data.MERL_RESOLUTION, "float64")
    assert keys.fingerprint(u) == "merl-grid:(90, 90, 180):float64:u"
    assert keys.fingerprint(v) == "merl-grid:(90, 90, 180):float64:v"
    copy = jnp.array(u)
    assert keys.fingerprint(copy) == keys.fingerprint(np.asarray(u)) != keys.fingerprint(u)
    changed = np.asarray(u).copy()
    changed[12345, 1] = np.nextafter(changed[12345, 1], 2.0)
    assert keys.fingerprint(changed) != keys.fingerprint(copy)


@pytest.mark.parametrize("variables,degrees", [("lafortune", [4]), ("ashikhmin-shirley", [1, 3])])
def test_kept_fields_template_is_the_geometry_shape(variables, degrees):
    """The shapes and dtypes a kept geometry is checked against are those the geometry has."""
    import polyjax._cache.geometry as store
    import polyjax._fit.closed_form as fit_mod
    from polyjax import n_terms
    from polyjax.internal import prepare_inputs

    u, v, weights = _problem(8)
    inp, _ = prepare_inputs("fit_polynomial", u, v, _values(u, v), weights, None, cutoff_deg=80.0)
    static = dict(variables=variables, max_degree=max(degrees), basis="legendre", interactions=False,
                  cutoff_deg=80.0)
    shapes = jax.eval_shape(lambda i: fit_mod._geometry_kernel(i, np.asarray(degrees, np.int32), **static), inp)
    k = pj.get_variables(variables).k
    want = store.template(k, n_terms(k, max(degrees), False), len(degrees), inp.u.dtype)
    assert {f: (shapes[f].shape, shapes[f].dtype) for f in store.FIELDS} == {
        f: (want[f].shape, want[f].dtype) for f in store.FIELDS}


def test_kept_rows_block_by_block_are_the_whole_rows():
    """The rows of a kept transform made block by block (5 blocks and a remainder) are those made over the whole
    arrays at once: ``t`` and ``w cos^2 theta_u`` bit for bit, the samples used exactly, the total weight to
    rounding (summed in another order)."""
    u, v, weights = _problem(9)
    weights[::7] = 0.0
    mask = np.ones(N, bool)
    mask[3::11] = False
    geo, _ = _geometry(u, v, weights)
    transform = [geo[f] for f in ("mean", "rotation", "centre", "halfwidth")]

    def sample(u, v, w, m):
        wl, wc2l = pj.internal.fit_weights(u, v, w, m, 80.0)
        return pj.explanatory_variables("lafortune", u, v), wl, wc2l

    whole = jax.jit(lambda *a: stream_mod.stream_rows(*sample(*a), *transform))(u, v, weights, mask)
    blocks = jax.jit(lambda *a: stream_mod.kept_rows(sample, a, *transform, block=512))(u, v, weights, mask)
    assert np.array_equal(blocks["t"], whole["t"]) and np.array_equal(blocks["wc2"], whole["wc2"])
    assert int(blocks["n_used"]) == int(whole["n_used"]) == int(np.sum((weights > 0) & mask
                                                                      & (np.asarray(whole["wc2"]) > 0)))
    np.testing.assert_allclose(blocks["den"], whole["den"], rtol=1e-14)


def test_fit_after_a_kept_geometry_reuses_its_rows(kept):
    """The first fit on a kept geometry makes its rows inside the fit's program; the next fit on the same samples
    uses that completed geometry (nothing computed or read again) and agrees with a fit on the cold geometry."""

    computed, folder = kept
    u, v, weights = _problem(10)
    values = _values(u, v)
    u, v = jnp.asarray(u), jnp.asarray(v)  # the same device arrays for every fit (as a loader's grid)
    cold = _fit_fresh(u, v, values, weights)
    warm = _fit_fresh(u, v, values, weights)
    geo = memo._GEOMETRY_MEMO["last"]["geo"]
    assert len(computed) == 1 and set(geo) >= {"t", "wc2"} and "sw" not in geo
    for path in folder.glob("geometry-*.npz"):
        path.unlink()  # the memo, not the disk, serves the next fit
    later = pj.fit_polynomial(u, v, values * 2.0, "lafortune", 4, weights=weights)
    assert len(computed) == 1 and memo._GEOMETRY_MEMO["last"]["geo"] is geo
    np.testing.assert_allclose(warm.l2, cold.l2, rtol=1e-14)
    np.testing.assert_allclose(later.l2, 2.0 * cold.l2, rtol=1e-13)
    np.testing.assert_allclose(later.coefficients, 2.0 * cold.coefficients, rtol=1e-12, atol=1e-14)
