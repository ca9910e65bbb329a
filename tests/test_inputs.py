"""Bad arguments get clear polyjax errors naming the argument; nothing crashes inside XLA."""

import numpy as np
import pytest

import polyjax as pj

from _problems import random_hemisphere


@pytest.fixture(scope="module")
def problem():
    u, v = random_hemisphere(50)
    return u, v, 0.1 + u[:, 2] * v[:, 2] + 0.3 * np.sin(3 * u[:, 0] * v[:, 1])


def test_wrong_direction_shape(problem):
    u, v, b = problem
    with pytest.raises(pj.InputError, match=r"u: expected directions of shape \(n, 3\)"):
        pj.fit_polynomial(u[:, :2], v, b)
    with pytest.raises(pj.InputError, match="u and v"):
        pj.fit_polynomial(u, v[:10], b)


def test_values_must_end_with_the_sample_axis(problem):
    u, v, b = problem
    with pytest.raises(pj.InputError, match=r"values: expected shape \(\.\.\., 50\)"):
        pj.fit_polynomial(u, v, b[None, :-1])


def test_unknown_variables_and_bad_degree(problem):
    u, v, b = problem
    with pytest.raises(pj.UnknownNameError, match="variables 'phong'"):
        pj.fit_polynomial(u, v, b, variables="phong")
    with pytest.raises(pj.InputError, match="degree"):
        pj.fit_polynomial(u, v, b, degree=-1)
    with pytest.raises(pj.InputError, match="degree"):
        pj.fit_polynomial(u, v, b, degree=2.5)


def test_nan_values_error_by_default_and_mask_on_request(problem):
    u, v, b = problem
    bad = b.copy()
    bad[7] = np.nan
    with pytest.raises(pj.InputError,
                       match=r"values: expected finite numbers, found 1 NaN/inf \(first at index \(7,\)\)"):
        pj.fit_polynomial(u, v, bad)
    m = pj.fit_polynomial(u, v, bad, nonfinite="mask", degree=2, cutoff_deg=None)
    ref = pj.fit_polynomial(np.delete(u, 7, 0), np.delete(v, 7, 0), np.delete(b, 7), degree=2, cutoff_deg=None)
    assert int(m.n_used) == 49
    np.testing.assert_allclose(float(m.l2), float(ref.l2), rtol=1e-10)


def test_negative_weights_and_bad_cutoff(problem):
    u, v, b = problem
    with pytest.raises(pj.InputError, match="weights"):
        pj.fit_polynomial(u, v, b, weights=-np.ones(50))
    with pytest.raises(pj.InputError, match="cutoff_deg"):
        pj.fit_polynomial(u, v, b, cutoff_deg=120)


def test_missing_data_root_says_where_it_looked(tmp_path, monkeypatch):
    monkeypatch.delenv(pj.DATA_ENV, raising=False)
    with pytest.raises(pj.DataNotFoundError, match="POLYJAX_DATA"):
        pj.data.load_curet()
    (tmp_path / "curet").mkdir()
    with pytest.raises(pj.DataNotFoundError, match="curet/table.txt"):
        pj.data.load_curet(tmp_path)


@pytest.mark.data
def test_unknown_curet_sample(data_root):
    with pytest.raises(pj.UnknownNameError, match="CUReT sample 99"):
        pj.data.load_curet(data_root, [99])
    with pytest.raises(pj.UnknownNameError, match="'moon dust'"):
        pj.data.load_curet(data_root, ["moon dust"])


@pytest.mark.data
def test_truncated_curet_file(tmp_path, data_root):
    (tmp_path / "curet").mkdir()
    src = data_root / "curet"
    for f in ("table.txt", "sample_labels.txt"):
        (tmp_path / "curet" / f).write_text((src / f).read_text())
    lines = (src / "abrdf.dat").read_text().splitlines()
    (tmp_path / "curet" / "abrdf.dat").write_text("\n".join(lines[:3] + [lines[3][:200]]))
    with pytest.raises(pj.DataFormatError, match=r"abrdf.dat: expected 206 numbers per line"):
        pj.data.load_curet(tmp_path)
