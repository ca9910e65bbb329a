"""RGL-EPFL measured BSDFs (Mitsuba 3's ``measured`` format): ``load_rgl`` against Mitsuba's own plugin on the shared
files and on files the tests write (isotropic, anisotropic with each azimuthal reduction, spectral), a closed form,
the MERL grid, the ``rgl:`` spec, the MERL converter, bad files.

Directions are uniform on the hemisphere with ``cos theta >= 0.02``: Mitsuba computes in float32, and closer to the
horizon its rounding (not the evaluation) reaches 1e-4 of ``f = (f cos) / cos`` (polyjax's evaluation run in float32
agrees with it there to 3e-6).
"""

import jax
import numpy as np
import pytest

import polyjax as pj
from polyjax.data import HeaderError, NonFiniteValueError, TruncatedFileError, WrongFormatError

from _rgl_problems import RGL_FILES, WAVELENGTHS, hemisphere, mitsuba_measured, rgl_fields, write_tensor_file

N = 200
U, V = hemisphere(N, 1, 0.02), hemisphere(N, 2, 0.02)


def _relative(ours, ref, floor=1e-3):
    big = np.abs(ref) > floor
    assert big.sum() > 0.3 * ref.size
    return np.max(np.abs(ours[big] - ref[big]) / np.abs(ref[big]))


@pytest.mark.data
@pytest.mark.parametrize("name", RGL_FILES)
def test_equal_to_mitsuba_on_shared_files(name, data_root):
    pytest.importorskip("mitsuba")
    path = data_root / "rgl_epfl" / f"{name}.bsdf"
    m = pj.data.load_rgl(path, directions=(U, V))
    assert m.values.shape == (3, N) and m.channels == ("R", "G", "B") and m.names == (name,)
    assert m.values.dtype == np.float64 and bool(np.all(m.mask))
    ref = mitsuba_measured(path, U, V)
    assert _relative(np.asarray(m.values).T, np.maximum(ref, 0.0)) < 1e-4


LAYOUTS = {  # name: (rgl_fields options, Mitsuba variant, reduction)
    "isotropic": ({}, "scalar_rgb", 1),
    "anisotropic": ({"n_phi": 5}, "scalar_rgb", 1),
    "anisotropic-half": ({"n_phi": 4, "phi_range": (-np.pi, 0.0)}, "scalar_rgb", 2),
    "anisotropic-quarter": ({"n_phi": 3, "phi_range": (-np.pi, -np.pi / 2)}, "scalar_rgb", 4),
    "spectral": ({"spectral": True}, "scalar_spectral", 1),
    "no-jacobian-negative": ({"jacobian": 0, "negative": True}, "scalar_rgb", 1),  # flag off; RGB below 0 clipped
}


@pytest.mark.parametrize("layout", sorted(LAYOUTS))
def test_written_layouts_equal_to_mitsuba(layout, tmp_path):
    """A file of each layout written by the test, read by polyjax and by Mitsuba: the same values."""
    pytest.importorskip("mitsuba")
    opts, variant, reduction = LAYOUTS[layout]
    path = write_tensor_file(tmp_path / f"{layout}.bsdf", rgl_fields(seed=3, **opts))
    brdf = pj.data.read_rgl(path)
    assert brdf.reduction == reduction and brdf.isotropic == (layout in ("isotropic", "spectral",
                                                                           "no-jacobian-negative"))
    assert brdf.jacobian == (layout != "no-jacobian-negative")
    m = pj.data.load_rgl(path, directions=(U, V))
    spectral = layout == "spectral"
    assert m.channels == (tuple(f"{w:g}nm" for w in WAVELENGTHS) if spectral else ("R", "G", "B"))
    ref = mitsuba_measured(path, U, V, variant, WAVELENGTHS if spectral else None)
    if not spectral:  # the reference RGB code clips out-of-gamut values to 0; Mitsuba does not
        assert (ref < 0).any() == (layout == "no-jacobian-negative")
        ref = np.maximum(ref, 0.0)
    assert np.all(np.asarray(m.values)[:, ~(ref.T > 0).any(0)] == 0.0) or spectral
    # with signs mixed, small values are differences of larger ones, which Mitsuba rounds to float32: compared where
    # they are above 0.05 (the typical value is 0.1-1; the others are checked to be 0 where Mitsuba's are <= 0)
    floor, tol = (0.05, 1e-4) if layout == "no-jacobian-negative" else (1e-3, 1e-5)
    assert _relative(np.asarray(m.values).T, ref, floor) < tol


def test_closed_form_of_a_uniform_table(tmp_path):
    """Uniform VNDF (its warp is the identity), values ``(c + 1) x``, ``ndf / (4 sigma) = 2``: then
    ``f cos theta_u = 2 (c + 1) sqrt(2 theta_m / pi)`` with ``theta_m`` the half vector's elevation."""
    path = write_tensor_file(tmp_path / "uniform.bsdf", rgl_fields(constant=True))  # nodes k/4: exact in float32
    m = pj.data.load_rgl(path, directions=(U, V))
    h = (U + V) / np.linalg.norm(U + V, axis=1, keepdims=True)
    want = 2 * np.arange(1, 4)[:, None] * np.sqrt(2 * np.arccos(h[:, 2]) / np.pi) / U[:, 2]
    np.testing.assert_allclose(np.asarray(m.values), want, rtol=1e-12)


def test_jit_vmap_and_below_horizon(tmp_path):
    path = write_tensor_file(tmp_path / "a.bsdf", rgl_fields(seed=3, n_phi=5))  # the anisotropic layout's file
    brdf = pj.data.read_rgl(path)
    direct = pj.data.load_rgl(path, directions=(U, V)).values[:, :8]
    mapped = jax.vmap(brdf, in_axes=(0, 0), out_axes=1)(jax.numpy.asarray(U[:8]), jax.numpy.asarray(V[:8]))
    np.testing.assert_allclose(np.asarray(mapped), np.asarray(direct), rtol=1e-14)
    below = V * [1.0, 1.0, -1.0]
    m = pj.data.load_rgl(path, directions=(U, below))
    assert not np.any(np.asarray(m.mask)) and np.all(np.asarray(m.values) == 0.0)


@pytest.mark.data
def test_merl_grid_subsample_and_spec(data_root):
    """A subsample of the MERL grid: the grid's directions and solid-angle weights, the values at those
    directions; ``load("rgl:<name>")`` is the same."""
    m = pj.data.load_rgl("paper_white_rgb", subsample=500, seed=4, root=data_root)
    u, v, w, above = pj.data.merl_grid()
    idx = np.flatnonzero(above)
    rows = np.array([np.flatnonzero((u[idx] == x).all(1) & (v[idx] == y).all(1))[0]
                     for x, y in zip(np.asarray(m.u)[:20], np.asarray(m.v)[:20])])
    np.testing.assert_array_equal(np.asarray(m.weights)[:20], w[idx][rows])
    at = pj.data.load_rgl(data_root / "rgl_epfl" / "paper_white_rgb.bsdf", directions=(m.u, m.v))
    # rtol: the directions are normalised again, and near the horizon f = (f cos) / cos magnifies the last bits
    np.testing.assert_allclose(np.asarray(m.values), np.asarray(at.values), rtol=1e-8)
    again = pj.data.load("rgl:paper_white_rgb", root=data_root, subsample=500, seed=4)
    np.testing.assert_array_equal(np.asarray(again.values), np.asarray(m.values))
    assert m.values.shape == (3, 500) and float(np.asarray(m.values).min()) >= 0.0


@pytest.mark.data
def test_cosine_convention_white_paper_albedo_and_near_reciprocity(data_root):
    """The reference ``eval(wi, wo)`` is ``f cos theta_o`` with ``wi`` the view: ``load_rgl`` divides by the
    light's cosine. Dividing by the view's instead (or swapping light and view) gives ``f`` times
    ``(cos theta_v / cos theta_u)^{+-1}``. Two checks that would see it: the near-Lambertian white paper's albedo
    ``int f(u, v) cos theta_u du`` is the same for every view (within 10 %; the other cosine makes it vary as
    ``1 / cos theta_v``, 2.9x from 0 to 70 degrees), and ``log(f(u, v) / f(v, u))`` has no trend in
    ``log(cos theta_u / cos theta_v)`` (slope near 0; the other cosine gives a slope of 2)."""
    path = data_root / "rgl_epfl" / "paper_white_rgb.bsdf"
    n_t, n_p = 60, 120  # midpoint rule over the light's hemisphere
    t, p = np.meshgrid((np.arange(n_t) + 0.5) * (np.pi / 2) / n_t, (np.arange(n_p) + 0.5) * 2 * np.pi / n_p,
                       indexing="ij")
    u = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1).reshape(-1, 3)
    dw = (np.sin(t) * (np.pi / 2 / n_t) * (2 * np.pi / n_p)).ravel()
    views = np.deg2rad([0.0, 30.0, 50.0, 70.0])
    v = np.concatenate([np.tile([np.sin(a), 0.0, np.cos(a)], (u.shape[0], 1)) for a in views])
    f = np.asarray(pj.data.load_rgl(path, directions=(np.tile(u, (len(views), 1)), v)).values)
    albedo = (f.reshape(3, len(views), -1) * (u[:, 2] * dw)).sum(-1)  # (3, views)
    assert np.all((albedo > 0.7) & (albedo < 1.05)), albedo
    assert np.all(albedo.max(1) / albedo.min(1) < 1.1), albedo
    a, b = hemisphere(4000, 5, 0.1), hemisphere(4000, 6, 0.1)
    fab = np.asarray(pj.data.load_rgl(path, directions=(a, b)).values).mean(0)
    fba = np.asarray(pj.data.load_rgl(path, directions=(b, a)).values).mean(0)
    x, y = np.log(a[:, 2] / b[:, 2]), np.log(fab / fba)
    slope = float(x @ y / (x @ x))
    assert abs(slope) < 0.3, slope


@pytest.mark.data
def test_export_to_merl_round_trip(data_root, tmp_path, capsys):
    """``polyjax export rgl:<name> --to merl``: read back by ``load_merl_binary``, the same values at the bin
    centres as ``load_rgl`` on the MERL grid."""
    from polyjax.cli import main

    out = tmp_path / "paper.binary"
    assert main(["export", "rgl:paper_white_rgb", "--to", "merl", "--out", str(out),
                 "--data-root", str(data_root)]) == 0
    assert "wrote" in capsys.readouterr().out
    back = pj.data.load_merl_binary(out, subsample=3000, seed=1)
    at = pj.data.load_rgl("paper_white_rgb", root=data_root, directions=(back.u, back.v))
    keep = np.asarray(at.mask)
    assert keep.all()
    np.testing.assert_allclose(np.asarray(back.values), np.asarray(at.values), rtol=1e-8, atol=0)  # as above


def _bad(tmp_path, name, fields=None, data=None):
    p = tmp_path / name
    if data is not None:
        p.write_bytes(data)
        return p
    return write_tensor_file(p, fields)


def _without(fields, name):
    return {k: v for k, v in fields.items() if k != name}


@pytest.mark.parametrize("case", ["truncated", "foreign", "version", "missing-field", "dtype", "shape", "nan",
                                  "spectral-without-spectra"])
def test_bad_files_name_the_file(case, tmp_path):
    good = rgl_fields()
    raw = write_tensor_file(tmp_path / "good.bsdf", good).read_bytes()
    spec = rgl_fields(spectral=True)
    made = {
        "truncated": (TruncatedFileError, dict(data=raw[: len(raw) // 2]), "missing"),
        "foreign": (WrongFormatError, dict(data=b"\x89PNG\r\n\x1a\n" + bytes(40)), "tensor_file"),
        "version": (HeaderError, dict(data=raw[:12] + bytes((2, 0)) + raw[14:]), "version (1, 0)"),
        "missing-field": (HeaderError, dict(fields=_without(good, "vndf")), "'vndf'"),
        "dtype": (HeaderError, dict(fields={**good, "theta_i": good["theta_i"].astype(np.float64)}), "float32"),
        "shape": (HeaderError, dict(fields={**good, "rgb": good["rgb"][:, :, :2]}), "3 channels"),
        "nan": (NonFiniteValueError, dict(fields={**good, "vndf": good["vndf"] * np.float32("nan")}), "finite"),
        "spectral-without-spectra": (HeaderError, dict(fields=_without(spec, "spectra")), "'spectra'"),
    }
    error, kw, words = made[case]
    path = _bad(tmp_path, f"{case}.bsdf", **kw)
    with pytest.raises(error) as e:
        pj.data.load_rgl(path, directions=(U[:4], V[:4]))
    assert isinstance(e.value, pj.DataFormatError)
    assert str(path) in str(e.value) and words in str(e.value)


def test_missing_file_and_bad_arguments(tmp_path):
    with pytest.raises(pj.DataNotFoundError, match="nothing.bsdf"):
        pj.data.load_rgl(tmp_path / "nothing.bsdf")
    path = write_tensor_file(tmp_path / "ok.bsdf", rgl_fields())
    with pytest.raises(pj.InputError, match="directions"):
        pj.data.load_rgl(path, directions=(U[:4], V[:3]))
    with pytest.raises(pj.InputError, match="subsample"):
        pj.data.load_rgl(path, subsample=-2)
    with pytest.raises(pj.InputError, match="subsample"):
        pj.data.load_rgl(path, subsample=10, directions=(U, V))


def test_command_line_names_a_missing_rgl_file(tmp_path, capsys):
    from polyjax.cli import main

    missing = tmp_path / "nothing.bsdf"
    assert main(["fit", "--dataset", f"rgl:{missing}"]) == 2
    assert main(["export", str(missing), "--to", "merl", "--out", str(tmp_path / "x.binary")]) == 2
    err = capsys.readouterr().err
    assert err.count("nothing.bsdf") >= 2 and not (tmp_path / "x.binary").exists()
