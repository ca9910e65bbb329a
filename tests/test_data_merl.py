"""MERL .binary layout, Rusinkiewicz grid and index mapping, solid-angle weights, bad files."""

import warnings

import numpy as np
import pytest

import polyjax as pj
from polyjax.data import (
    EmptyFileError,
    HeaderError,
    NonFiniteValueError,
    TruncatedFileError,
    WrongFormatError,
)

from _data_problems import SMALL_RES, smooth_table, write_small_merl


def test_round_trip_small(tmp_path):
    vals = write_small_merl(tmp_path / "small.binary")
    back, res = pj.data.read_merl_binary(tmp_path / "small.binary")
    assert res == SMALL_RES
    np.testing.assert_allclose(back[vals >= 0], vals[vals >= 0], rtol=1e-15)
    assert np.all(back[vals < 0] < 0)
    raw, _ = pj.data.read_merl_binary(tmp_path / "small.binary", scaled=False)
    np.testing.assert_allclose(raw[0, vals[0] >= 0] / 1500.0, vals[0, vals[0] >= 0], rtol=1e-15)
    np.testing.assert_allclose(raw[2, vals[2] >= 0] * 1.66 / 1500.0, vals[2, vals[2] >= 0], rtol=1e-15)


def test_full_layout_bytes_and_measurements(tmp_path):
    """A file of the real 90 x 90 x 180 layout: size, header, channel-major order, masking."""
    n = pj.data.MERL_N_BINS
    vals = np.zeros((3, n))
    vals[0, 7] = 1.0
    vals[1, 123456] = 2.0
    vals[2, n - 1] = 3.0
    vals[1, 5] = -1.0  # missing
    p = pj.data.write_merl_binary(tmp_path / "full.binary", vals, mask=vals >= 0)
    data = p.read_bytes()
    assert len(data) == 34_992_012
    assert np.frombuffer(data[:12], "<i4").tolist() == [90, 90, 180]
    body = np.frombuffer(data[12:], "<f8")
    assert body[7] == pytest.approx(1500.0)
    assert body[n + 123456] == pytest.approx(2.0 * 1500 / 1.15)
    assert body[n + 5] == -1.0
    m = pj.data.load_merl_binary(p)
    assert m.axes == ("channel",) and m.channels == ("R", "G", "B")
    _, _, _, above = pj.data.merl_grid()
    assert m.n_samples == int(above.sum()) == 1_111_432
    kept = np.flatnonzero(above)
    j = np.searchsorted(kept, 123456)
    if kept[j] == 123456:
        assert float(m.values[1, j]) == pytest.approx(2.0)
    j5 = np.searchsorted(kept, 5)
    if kept[j5] == 5:
        assert not bool(m.mask[1, j5]) and bool(m.mask[0, j5])


def test_load_several_and_subsample(tmp_path):
    a = write_small_merl(tmp_path / "a.binary", seed=1)
    b = write_small_merl(tmp_path / "b.binary", seed=2)
    m = pj.data.load_merl_binary([tmp_path / "a.binary", tmp_path / "b.binary"])
    assert m.axes == ("material", "channel") and m.names == ("a", "b")
    assert m.values.shape == (2, 3, m.n_samples)
    # every value equals the table entry of its bin; masked exactly where the table is negative
    u, v, w, above = pj.data.merl_grid(SMALL_RES)
    idx = np.flatnonzero(above & ((a >= 0) | (b >= 0)).any(0))
    np.testing.assert_allclose(np.asarray(m.u), u[idx], atol=1e-15)
    np.testing.assert_allclose(np.asarray(m.weights), w[idx], rtol=1e-15)
    for k, t in enumerate((a, b)):
        np.testing.assert_array_equal(np.asarray(m.mask[k]), t[:, idx] >= 0)
        ok = t[:, idx] >= 0
        np.testing.assert_allclose(np.asarray(m.values[k])[ok], t[:, idx][ok], rtol=1e-14)
    s1 = pj.data.load_merl_binary(tmp_path / "a.binary", subsample=20, seed=3)
    s2 = pj.data.load_merl_binary(tmp_path / "a.binary", subsample=20, seed=3)
    s3 = pj.data.load_merl_binary(tmp_path / "a.binary", subsample=20, seed=4)
    assert s1.n_samples == 20
    np.testing.assert_array_equal(np.asarray(s1.u), np.asarray(s2.u))
    assert not np.array_equal(np.asarray(s1.u), np.asarray(s3.u))
    half = pj.data.load_merl_binary(tmp_path / "a.binary", subsample=0.5)
    assert half.n_samples == round(0.5 * m.n_samples)
    with pytest.raises(pj.InputError):
        pj.data.load_merl_binary(tmp_path / "a.binary", subsample=-3)


def test_index_mapping_inverts_every_bin_centre():
    n = pj.data.MERL_N_BINS
    th, td, pd = pj.data.merl_bin_angles()
    np.testing.assert_array_equal(pj.data.merl_index(th, td, pd), np.arange(n))
    # through the directions and back: identical except at theta_d = 0, where phi_d is undefined
    u, v, _, _ = pj.data.merl_grid()
    idx = pj.data.merl_index(*pj.data.directions_to_rusinkiewicz(u, v))
    j = (np.arange(n) // 180) % 90
    np.testing.assert_array_equal(idx[j > 0], np.arange(n)[j > 0])
    assert np.all(idx[j == 0] // 180 == np.arange(n)[j == 0] // 180)
    # negative phi_d folds by reciprocity; clamping at the top of the range
    assert pj.data.merl_index(0.3, 0.4, 0.5 - np.pi) == pj.data.merl_index(0.3, 0.4, 0.5)
    assert pj.data.merl_index(np.pi / 2, np.pi / 2, np.pi) == n - 1


def test_directions_match_the_half_difference_frame():
    th, td, pd = pj.data.merl_bin_angles((9, 9, 18))
    u, v = pj.data.rusinkiewicz_to_directions(th, td, pd)
    np.testing.assert_allclose(u[:, 2], np.cos(td) * np.cos(th) - np.sin(td) * np.cos(pd) * np.sin(th), atol=1e-15)
    np.testing.assert_allclose(v[:, 2], np.cos(td) * np.cos(th) + np.sin(td) * np.cos(pd) * np.sin(th), atol=1e-15)
    h = (u + v) / np.linalg.norm(u + v, axis=1, keepdims=True)
    np.testing.assert_allclose(h, np.stack([np.sin(th), 0 * th, np.cos(th)], 1), atol=1e-15)
    np.testing.assert_allclose(np.sum(u * h, 1), np.cos(td), atol=1e-15)


def test_weights_integrate_the_pair_measure():
    u, v, w, above = pj.data.merl_grid()
    assert w.sum() == pytest.approx(8 * np.pi**2, rel=1e-12)
    # over pairs with both directions above the horizon: (2 pi)^2, and int cos cos = pi^2
    assert w[above].sum() == pytest.approx(4 * np.pi**2, rel=2e-3)
    assert np.sum((w * u[:, 2] * v[:, 2])[above]) == pytest.approx(np.pi**2, rel=1e-3)


def test_weights_against_monte_carlo():
    """Uniform pairs on the two hemispheres binned with the index mapping: the measure per theta_h
    and per theta_d slab agrees with the weights (a coarse grid, so edge effects are visible but small)."""
    res = (6, 6, 12)
    rng = np.random.default_rng(0)
    n = 2_000_000

    def hemi():
        z = rng.uniform(0, 1, n)
        p = rng.uniform(-np.pi, np.pi, n)
        s = np.sqrt(1 - z * z)
        return np.stack([s * np.cos(p), s * np.sin(p), z], 1)

    a, b = hemi(), hemi()
    th, td, pd = pj.data.directions_to_rusinkiewicz(a, b)
    # weights are quadrature cells centred on the bin centres: bin MC samples by the nearest centre
    nh, nd, npd = res
    i = np.clip(np.floor(np.sqrt(th / (np.pi / 2)) * nh + 0.5), 0, nh - 1).astype(int)
    j = np.clip(np.floor(td / (np.pi / 2) * nd + 0.5), 0, nd - 1).astype(int)
    mc = np.bincount(i * nd + j, minlength=nh * nd) * (2 * np.pi) ** 2 / n
    w = pj.data.merl_bin_weights(res).reshape(nh, nd, npd).sum(-1).ravel()
    # cells entirely above the horizon (all pairs valid): theta_h upper edge + theta_d upper edge < pi/2
    # upper cell edges: i + 1/2, the last cell reaching N (theta_u, theta_v <= theta_h + theta_d)
    ea = (np.r_[np.arange(nh - 1) + 0.5, nh] / nh) ** 2 * np.pi / 2
    eb = np.r_[np.arange(nd - 1) + 0.5, nd] / nd * np.pi / 2
    inside = (ea[:, None] + eb[None, :] < np.pi / 2).ravel() & (w > 0.3)  # big cells: MC noise < 1 %
    assert inside.sum() >= 8
    np.testing.assert_allclose(mc[inside], w[inside], rtol=0.03)


# ---------- bad files: each its own exception, raised before any JAX work ----------

def test_empty_file(tmp_path):
    p = tmp_path / "e.binary"
    p.write_bytes(b"")
    with pytest.raises(EmptyFileError, match="empty"):
        pj.data.load_merl_binary(p)


def test_truncated_file(tmp_path):
    p = tmp_path / "t.binary"
    write_small_merl(p)
    data = p.read_bytes()
    p.write_bytes(data[:-100])
    with pytest.raises(TruncatedFileError, match="100 missing") as e:
        pj.data.load_merl_binary(p)
    assert e.value.path == str(p)
    p.write_bytes(data[:7])
    with pytest.raises(TruncatedFileError):
        pj.data.read_merl_binary(p)


def test_wrong_header(tmp_path):
    p = tmp_path / "h.binary"
    p.write_bytes(np.array([90, -90, 180], "<i4").tobytes() + np.zeros(10).tobytes())
    with pytest.raises(HeaderError, match=r"\(90, -90, 180\)"):
        pj.data.load_merl_binary(p)
    p.write_bytes(np.array([2, 2, 2], "<i4").tobytes() + np.zeros(3 * 8 + 5).tobytes())
    with pytest.raises(HeaderError, match="extra"):
        pj.data.load_merl_binary(p)


def test_wrong_format(tmp_path):
    p = tmp_path / "cornell_like.binary"
    p.write_text("# num wls\n31\n400 410 420\n")
    with pytest.raises(WrongFormatError, match="text file"):
        pj.data.load_merl_binary(p)
    p.write_bytes(b"\x89HDF\r\n\x1a\n" + bytes(100))
    with pytest.raises(WrongFormatError, match="HDF5"):
        pj.data.load_merl_binary(p)


def test_nan_values(tmp_path):
    p = tmp_path / "n.binary"
    vals = smooth_table()
    pj.data.write_merl_binary(p, vals, resolution=SMALL_RES)
    raw = bytearray(p.read_bytes())
    raw[12 + 8 * 4 : 12 + 8 * 5] = np.array([np.nan], "<f8").tobytes()
    p.write_bytes(bytes(raw))
    with pytest.raises(NonFiniteValueError, match="NaN"):
        pj.data.load_merl_binary(p)
    raw[12 + 8 * 4 : 12 + 8 * 5] = np.array([np.inf], "<f8").tobytes()
    p.write_bytes(bytes(raw))
    with pytest.raises(NonFiniteValueError):
        pj.data.read_merl_binary(p)


def test_opposite_infinities_and_huge_values_are_checked_without_a_numpy_warning(tmp_path):
    """The finiteness check sums the body first: ``+inf`` and ``-inf`` together (a NaN sum) are a named error,
    finite values whose sum overflows load, and neither lets numpy warn."""
    p = tmp_path / "n.binary"
    pj.data.write_merl_binary(p, smooth_table(), resolution=SMALL_RES)
    raw = bytearray(p.read_bytes())
    raw[12 + 8 * 4: 12 + 8 * 6] = np.array([np.inf, -np.inf], "<f8").tobytes()
    p.write_bytes(bytes(raw))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(NonFiniteValueError, match="2 NaN/inf"):
            pj.data.read_merl_binary(p)
        raw[12 + 8 * 4: 12 + 8 * 6] = np.array([1e308, 1e308], "<f8").tobytes()
        p.write_bytes(bytes(raw))
        values, _ = pj.data.read_merl_binary(p, scaled=False)
    assert values[0, 4] == 1e308 and np.all(np.isfinite(values))


def test_errors_are_polyjax_errors():
    for cls in (EmptyFileError, HeaderError, NonFiniteValueError, TruncatedFileError, WrongFormatError):
        assert issubclass(cls, pj.DataFormatError)
    assert issubclass(pj.data.UnknownMaterialError, pj.UnknownNameError)


def test_write_rejects_wrong_shape(tmp_path):
    with pytest.raises(pj.InputError, match="values"):
        pj.data.write_merl_binary(tmp_path / "x.binary", np.zeros((3, 10)), resolution=SMALL_RES)


def test_loaders_return_one_mask_row_when_every_lane_has_the_same_valid_bins(tmp_path):
    """Bins missing in every channel (as in MERL's files) are no samples, and the mask is ``(n,)``: the fit shares
    one design across the channels and equals a fit given the mask per lane; a bin missing in one channel only
    keeps the mask ``(3, n)``."""
    vals = np.abs(smooth_table(SMALL_RES, 0))  # every bin valid ...
    vals[:, ::7] = -1.0  # ... but these, missing in every channel
    pj.data.write_merl_binary(tmp_path / "same.binary", vals, resolution=SMALL_RES, mask=vals >= 0)
    same = pj.data.load_merl_binary(tmp_path / "same.binary")
    assert same.mask.shape == (same.n_samples,)
    _, _, _, above = pj.data.merl_grid(SMALL_RES)
    kept = np.flatnonzero(above & (vals[0] >= 0))  # a bin missing in every lane is no sample at all
    assert same.n_samples == kept.size < int(above.sum())
    assert same.mask.dtype == bool and bool(np.all(np.asarray(same.mask)))
    fit = pj.fit_polynomial(same, degree=3)
    explicit = pj.fit_polynomial(same.u, same.v, same.values, degree=3, weights=same.weights,
                                 mask=np.broadcast_to(np.asarray(same.mask), same.values.shape))
    np.testing.assert_allclose(fit.l2, explicit.l2, rtol=1e-12)
    assert np.all(np.asarray(fit.status) == pj.RESULTS.OK)

    vals[1, 3] = -1.0  # one more bin, missing in G only
    pj.data.write_merl_binary(tmp_path / "differ.binary", vals, resolution=SMALL_RES, mask=vals >= 0)
    differ = pj.data.load_merl_binary(tmp_path / "differ.binary")
    assert differ.mask.shape == differ.values.shape == (3, differ.n_samples)
    assert pj.data.load_merl_binary([tmp_path / "same.binary"] * 2).mask.shape == (same.n_samples,)
    assert pj.data.load_merl_binary([tmp_path / "same.binary", tmp_path / "differ.binary"]).mask.ndim == 3
    assert same[1].mask.shape == (same.n_samples,) and differ[1].mask.shape == (differ.n_samples,)


def test_loads_in_a_row_keep_their_own_values(tmp_path):
    """Single-file loads read into one reused buffer: what a load returned never changes with the next load."""
    a = write_small_merl(tmp_path / "a.binary", seed=1)
    b = write_small_merl(tmp_path / "b.binary", seed=2)
    first = pj.data.load_merl_binary(tmp_path / "a.binary")
    kept = np.asarray(first.values).copy()
    second = pj.data.load_merl_binary(tmp_path / "b.binary")
    np.testing.assert_array_equal(np.asarray(first.values), kept)
    _, _, _, above = pj.data.merl_grid(SMALL_RES)
    for m, t in ((first, a), (second, b)):
        idx = np.flatnonzero(above & (t >= 0).any(0))
        ok = t[:, idx] >= 0
        np.testing.assert_allclose(np.asarray(m.values)[ok], t[:, idx][ok], rtol=1e-14)


def test_grid_directions_are_the_elementwise_formula_bit_for_bit():
    """``merl_grid`` builds the directions from the grid's separable form: the same numbers as
    ``rusinkiewicz_to_directions`` of every bin's angles, to the last bit."""
    u, v, _, above = pj.data.merl_grid()
    u0, v0 = pj.data.rusinkiewicz_to_directions(*pj.data.merl_bin_angles())
    assert np.array_equal(u, u0) and np.array_equal(v, v0)
    assert np.array_equal(above, (u0[:, 2] > 0) & (v0[:, 2] > 0))
    np.testing.assert_allclose(np.linalg.norm(u, axis=1), 1.0, atol=4e-16)


def test_loaded_grid_directions_are_taken_as_unit(tmp_path):
    """The loader's device directions of the full grid are remembered as unit vectors when it makes them (no
    normalising pass in the first fit: a fit's prepared inputs are those very arrays, all valid): they are, to
    rounding, what normalising gives. Other arrays, a copy of them included, are normalised."""
    import jax.numpy as jnp

    pj.internal.forget_memos()  # the grid made again by the next load, as in a fresh process
    vals = np.zeros((3, pj.data.MERL_N_BINS))
    m = pj.data.load_merl_binary(pj.data.write_merl_binary(tmp_path / "zero.binary", vals))
    inp, _ = pj.internal.prepare_inputs("fit_polynomial", m, None, None)
    assert inp.u is m.u and inp.v is m.v and bool(jnp.all(inp.mask))
    np.testing.assert_allclose(np.asarray(m.u), np.asarray(pj.safe_normalize(m.u)[0]), rtol=0, atol=1e-15)  # 2 ulp
    copy = jnp.array(m.u)
    assert pj.internal.prepare_inputs("fit_polynomial", copy, m.v, m.values)[0].u is not copy


def test_first_load_makes_the_grid_beside_the_read_with_the_same_bits(tmp_path):
    """The first load of a process (every memo forgotten) makes the grid in a thread while the file is read, slab
    by slab without the full grid: the Measurements are those of a later load, bit for bit, the directions and
    weights ``merl_grid``'s above the horizon, every bin valid; a later load hands out the same device arrays."""
    rng = np.random.default_rng(3)
    path = pj.data.write_merl_binary(tmp_path / "r.binary", rng.uniform(0.0, 1.0, (3, pj.data.MERL_N_BINS)))
    pj.internal.forget_memos()
    first = pj.data.load_merl_binary(path)
    later = pj.data.load_merl_binary(path)
    u, v, w, above = pj.data.merl_grid()
    assert first.u is later.u and first.v is later.v and first.weights is later.weights
    for got, want in ((first.u, u[above]), (first.v, v[above]), (first.weights, w[above])):
        assert np.array_equal(np.asarray(got), want)
    assert np.shape(first.mask) == (int(above.sum()),) and bool(np.all(np.asarray(first.mask)))
    raw, _ = pj.data.read_merl_binary(path)
    assert np.array_equal(np.asarray(first.values), raw[:, above]) and first.n_samples == int(above.sum())


@pytest.mark.parametrize("resolution", [(7, 5, 12), (16, 11, 9)])
def test_loaded_bins_are_the_grid_above_the_horizon(tmp_path, resolution):
    """At odd small resolutions too, the loader's bins above the horizon (``dz c > |dx s|``, computed slab by slab)
    are exactly ``merl_grid``'s (both z components positive), with its directions and weights, bit for bit."""
    n = int(np.prod(resolution))
    path = pj.data.write_merl_binary(tmp_path / "s.binary", np.full((3, n), 0.5), resolution=resolution)
    pj.internal.forget_memos()
    m = pj.data.load_merl_binary(path)
    u, v, w, above = pj.data.merl_grid(resolution)
    assert m.n_samples == int(above.sum()) < n
    for got, want in ((m.u, u[above]), (m.v, v[above]), (m.weights, w[above])):
        assert np.array_equal(np.asarray(got), want)


def test_grid_memo_waits_for_the_work_under_way_and_raises_its_error():
    """A call while the background computation of the same arguments is under way waits for it (the work is done
    once, the same value returned); an error there is raised by the caller's call, and not remembered."""
    import threading

    calls, started, release = [], threading.Event(), threading.Event()

    def slow(x):
        calls.append(x)
        started.set()
        assert release.wait(10.0)
        if x < 0:
            raise ValueError(f"x: expected >= 0, found {x}")
        return [x]

    def under_way(x):  # start x in the background and wait until its work has begun
        started.clear()
        release.clear()
        memo.start(x)
        memo.start(x)  # under way: not started again
        assert started.wait(10.0)
        threading.Timer(0.1, release.set).start()

    memo = pj.internal.grid_memo(maxsize=2)(slow)
    under_way(1)
    value = memo(1)
    assert value == [1] and memo(1) is value and calls == [1]
    under_way(-1)
    with pytest.raises(ValueError, match="x: expected >= 0"):
        memo(-1)
    assert calls.count(-1) == 1
    with pytest.raises(ValueError):
        memo(-1)  # computed again, not a remembered failure
    assert calls.count(-1) == 2
    memo(2), memo(3)  # at most maxsize values kept: the oldest dropped
    assert memo(1) is not value and calls.count(1) == 2


def test_first_load_in_float32_is_the_grid_rounded(tmp_path):
    """Without x64 the grid is made in float32 (its own cached arrays): the float64 grid rounded once, weights
    included, and no warning from the gathers."""
    import warnings

    import jax

    path = pj.data.write_merl_binary(tmp_path / "h.binary", np.full((3, pj.data.MERL_N_BINS), 0.25))
    pj.internal.forget_memos()
    with jax.enable_x64(False), warnings.catch_warnings():
        warnings.simplefilter("error")
        m = pj.data.load_merl_binary(path)
    u, v, w, above = pj.data.merl_grid()
    assert m.u.dtype == np.float32 and m.weights.dtype == np.float32
    for got, want in ((m.u, u[above]), (m.v, v[above]), (m.weights, w[above])):
        assert np.array_equal(np.asarray(got), want.astype(np.float32))
    pj.internal.forget_memos()
