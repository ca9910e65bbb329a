"""Cornell pbrt-v2 spectral files, the ASTM format, colour conversion, the load() entry point."""

import numpy as np
import pytest

import polyjax as pj
from polyjax.data import (
    EmptyFileError,
    HeaderError,
    NonFiniteValueError,
    TruncatedFileError,
    UnknownMaterialError,
    WrongFormatError,
)

from _data_problems import write_astm

WL = pj.data.CMF_WAVELENGTHS


def test_colour_conventions():
    flat = np.ones(31)
    np.testing.assert_allclose(pj.data.spectral_to_rgb(2.0 * flat, WL), [2.0, 2.0, 2.0], rtol=1e-12)
    assert pj.data.spectral_to_luminance(flat, WL) == pytest.approx(1.0, rel=1e-12)
    # the embedded CIE 1931 table: ybar peaks at 1 near 555 nm, xbar's long-wave peak 1.0622 at 600 nm
    assert pj.data.CIE1931_CMF[:, 1].max() == pytest.approx(0.995)
    assert pj.data.CIE1931_CMF[20, 0] == pytest.approx(1.0622)
    # a red spectrum is red, a blue one blue
    red = (WL >= 600).astype(float)
    blue = (WL <= 470).astype(float)
    r, b = pj.data.spectral_to_rgb(red, WL), pj.data.spectral_to_rgb(blue, WL)
    assert r[0] > 3 * r[2] and b[2] > 3 * b[0]


def _tiny_pbrt(tmp_path, body=None, n_wl=3):
    text = f"# comment\n{n_wl}\n" + " ".join(str(500 + 10 * i) for i in range(n_wl)) + "\n"
    text += body if body is not None else "0.1 0 0.2 3.14159 0.5 0.6 0.7\n0.3 0 0.3 3.0 1 1 1\n"
    p = tmp_path / "tiny.brdf"
    p.write_text(text)
    return p


def test_pbrt_parser_small(tmp_path):
    ang, wl, spectra = pj.data.read_cornell_pbrt(_tiny_pbrt(tmp_path))
    np.testing.assert_allclose(wl, [500, 510, 520])
    np.testing.assert_allclose(spectra[0], [0.5, 0.6, 0.7])
    np.testing.assert_allclose(ang[1], [0.3, 0, 0.3, 3.0])
    d = pj.data.load_cornell(tmp_path / "tiny.brdf", channels="spectral")
    assert d.channels == ("500nm", "510nm", "520nm") and d.values.shape == (3, 2)
    np.testing.assert_allclose(np.asarray(d.v[1]), pj.spherical_to_cartesian(0.3, 3.0), atol=1e-12)


@pytest.mark.data
def test_cayman_has_1439_samples_and_its_peak_at_the_mirror_direction():
    d = pj.data.load("cornell:cayman")
    assert d.n_samples == 1439 and d.values.shape == (3, 1439) and d.channels == ("R", "G", "B")
    spec = pj.data.load_cornell("cayman", channels="spectral")
    assert spec.values.shape == (31, 1439)
    assert float(spec.values.max()) == pytest.approx(645.8, rel=1e-3)
    i = int(np.argmax(np.asarray(spec.values).mean(0)))
    assert float(np.asarray(spec.values)[:, i].mean()) == pytest.approx(622, rel=2e-3)
    u, v = np.asarray(d.u[i]), np.asarray(d.v[i])
    # the mirror direction of u is reflect(u): the peak's v is within a degree of it
    angle = np.degrees(np.arccos(np.clip(np.dot(np.asarray(pj.reflect(u)), v), -1, 1)))
    assert angle < 1.0
    assert np.degrees(np.arccos(u[2])) == pytest.approx(80.0, abs=1e-3)
    lum = pj.data.load_cornell("cayman", channels="luminance")
    assert lum.channels == ("Y",) and int(np.argmax(np.asarray(lum.values[0]))) == i
    both = pj.data.load("cornell:cayman,garnet_red")
    assert both.values.shape == (2, 3, 1439) and both.names == ("cayman", "garnet_red")


@pytest.mark.data
def test_astm_file_matches_pbrt_data(tmp_path):
    """An RGB ASTM file written from Cayman's RGB loads to the same measurements (radians and degrees)."""
    d = pj.data.load_cornell("cayman")
    ang, _, _ = pj.data.read_cornell_pbrt(pj.data_root() / "cornell" / "cayman.brdf")
    rgb = np.asarray(d.values).T
    p = write_astm(tmp_path / "cayman_RGB.astm", ang, rgb, ["R", "G", "B"])
    a = pj.data.load_cornell(p)
    np.testing.assert_allclose(np.asarray(a.values), np.asarray(d.values), rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(np.asarray(a.u), np.asarray(d.u), atol=1e-8)
    pdeg = write_astm(tmp_path / "deg.astm", ang, rgb, ["R", "G", "B"], degrees=True)
    b = pj.data.load_cornell(pdeg, angle_unit="degrees")
    np.testing.assert_allclose(np.asarray(b.v), np.asarray(d.v), atol=1e-8)
    lum = pj.data.load_cornell(p, channels="luminance")
    np.testing.assert_allclose(
        np.asarray(lum.values[0]), np.asarray(pj.data.load_cornell("cayman", channels="luminance").values[0]),
        rtol=1e-6, atol=1e-9,
    )


def test_astm_spectral_and_single_column(tmp_path):
    ang = np.array([[0.1, 0.0, 0.2, 3.0], [0.2, 0.0, 0.4, 1.0]])
    p = write_astm(tmp_path / "s.astm", ang, np.ones((2, 31)), [f"{w:g}nm" for w in WL])
    d = pj.data.load_cornell(p)
    np.testing.assert_allclose(np.asarray(d.values), 1.0, rtol=1e-12)
    q = write_astm(tmp_path / "y.astm", ang, np.array([[0.5], [0.25]]), ["Y"])
    y = pj.data.load_cornell(q, channels="luminance")
    np.testing.assert_allclose(np.asarray(y.values), [[0.5, 0.25]])


# ---------- bad files ----------

def test_bad_pbrt_files(tmp_path):
    p = tmp_path / "bad.brdf"
    p.write_text("")
    with pytest.raises(EmptyFileError):
        pj.data.load_cornell(p)
    p.write_text("# only a comment\n\n")
    with pytest.raises(EmptyFileError, match="comments"):
        pj.data.load_cornell(p)
    with pytest.raises(TruncatedFileError, match="left over"):
        pj.data.load_cornell(_tiny_pbrt(tmp_path, body="0.1 0 0.2 3.14 0.5 0.6 0.7\n0.3 0 0.3 3.0 1\n"))
    with pytest.raises(HeaderError, match="wavelengths"):
        pj.data.load_cornell(_tiny_pbrt(tmp_path, n_wl=0, body="1 2 3\n"))
    bad_wl = tmp_path / "wl.brdf"
    bad_wl.write_text("3\n500 490 520\n0.1 0 0.2 3.1 1 1 1\n")
    with pytest.raises(HeaderError, match="increasing"):
        pj.data.load_cornell(bad_wl)
    with pytest.raises(NonFiniteValueError, match="NaN"):
        pj.data.load_cornell(_tiny_pbrt(tmp_path, body="0.1 0 0.2 3.14 0.5 nan 0.7\n"))
    with pytest.raises(NonFiniteValueError, match="inf"):
        pj.data.load_cornell(_tiny_pbrt(tmp_path, body="0.1 0 0.2 3.14 0.5 inf 0.7\n"))
    with pytest.raises(WrongFormatError, match="abc"):
        pj.data.load_cornell(_tiny_pbrt(tmp_path, body="0.1 0 0.2 3.14 0.5 abc 0.7\n"))
    binary = tmp_path / "merl.binary"
    binary.write_bytes(np.array([90, 90, 180], "<i4").tobytes() + np.zeros(8).tobytes())
    with pytest.raises(WrongFormatError, match="binary"):
        pj.data.load_cornell(binary)
    with pytest.raises(HeaderError, match="radians"):
        pj.data.load_cornell(_tiny_pbrt(tmp_path, body="10 0 20 180 0.5 0.6 0.7\n"))


def test_bad_astm_files(tmp_path):
    ang = np.array([[0.1, 0.0, 0.2, 3.0], [0.2, 0.0, 0.4, 1.0]])
    with pytest.raises(TruncatedFileError, match="NUM_POINTS 5"):
        pj.data.load_cornell(write_astm(tmp_path / "a.astm", ang, np.ones((2, 3)), ["R", "G", "B"], n_points=5))
    p = write_astm(tmp_path / "b.astm", ang, np.ones((2, 3)), ["R", "G", "B"])
    p.write_text(p.read_text() + "0.3,0,0.1\n")
    with pytest.raises(TruncatedFileError, match="7 columns"):
        pj.data.load_cornell(p)
    q = tmp_path / "c.astm"
    q.write_text("NUM_POINTS 1\n0.1,0,0.2,3.0,1,1,1\n")
    with pytest.raises(HeaderError, match="VARS"):
        pj.data.load_cornell(q, format="astm")
    r = write_astm(tmp_path / "d.astm", ang, np.array([[1, np.nan, 1], [1, 1, 1]]), ["R", "G", "B"])
    with pytest.raises(NonFiniteValueError, match="line 6"):
        pj.data.load_cornell(r)
    s = write_astm(tmp_path / "e.astm", ang, np.ones((2, 2)), ["U", "W"])
    with pytest.raises(HeaderError, match="R,G,B"):
        pj.data.load_cornell(s)
    t = tmp_path / "f.astm"
    t.write_text("")
    with pytest.raises(EmptyFileError):
        pj.data.load_cornell(t, format="astm")


def test_unknown_names_and_kinds(tmp_path):
    with pytest.raises(UnknownMaterialError, match="cayman"):
        pj.data.load_cornell("caymen", root=tmp_path)
    with pytest.raises(pj.UnknownNameError, match="merl-nbrdf"):
        pj.data.load("mystery:thing")
    with pytest.raises(pj.InputError, match="channels"):
        pj.data.load_cornell(_tiny_pbrt(tmp_path), channels="cmyk")
    with pytest.raises(pj.DataNotFoundError, match="no such file"):
        pj.data.load_cornell(tmp_path / "missing.brdf")


def test_missing_data_says_where_it_looked(tmp_path):
    with pytest.raises(pj.DataNotFoundError, match="cornell/cayman.brdf"):
        pj.data.load("cornell:cayman", root=tmp_path)
    with pytest.raises(pj.DataNotFoundError, match="merl_nbrdf.zip"):
        pj.data.load("merl-nbrdf:green-latex", root=tmp_path)


@pytest.mark.data
def test_load_entry_point_curet():
    d = pj.data.load("curet:25")
    assert d.values.shape == (1, 205) and d.names == ("Quarry Tile",)
