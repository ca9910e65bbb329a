"""Malformed and oversized input files: every loader checks declared sizes before it reads or inflates (a cap, the
file's own size), and every malformed file is a :class:`polyjax.PolyjaxError` naming the file and the fault.

One test per case: sizes (a neural-BRDF zip member inflating far past its size, a MAT-file's compressed normals,
a PNG's dimensions, a saved model's ``.npz`` members, a tensor file) are refused before the memory is spent
(tracemalloc measures it); faults (a zero-sized tensor dimension, a short MATLAB element, a 400-digit integer or
100,000 nested brackets in a model's JSON, a saved model whose arrays disagree, an ASTM header line of a lone comma,
a damaged shard manifest, a scene of the wrong types) are named errors. ``POLYJAX_MAX_INPUT_MB`` sets the cap.
"""

from __future__ import annotations

import json
import struct
import zipfile
import zlib

import numpy as np
import pytest
import scipy.io

import polyjax as pj

from _fuzz_problems import peak_bytes, small_model, write_diligent, write_nbrdf_zip, write_scene
from _rgl_problems import rgl_fields, write_tensor_file

MiB = 2**20


def _png_bytes(width: int, height: int, rows: bytes, colour: int = 0, bits: int = 8) -> bytes:
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    ihdr = struct.pack(">IIBBBBB", width, height, bits, colour, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(rows, 9)) + chunk(b"IEND", b"")


def _mat_file(elements: bytes) -> bytes:
    """A MATLAB 5 MAT-file of the given element bytes (little-endian header)."""
    text = b"MATLAB 5.0 MAT-file, written by the tests".ljust(116, b" ")
    return text + bytes(8) + struct.pack("<H", 0x0100) + b"IM" + elements


def _element(kind: int, data: bytes) -> bytes:
    return struct.pack("<II", kind, len(data)) + data + bytes(-len(data) % 8)


# ------------------------------------------------------------------------------------------ bounded reading


def test_nbrdf_zip_member_inflating_past_the_network_cap_is_refused_before_it_is_read(tmp_path):
    path = tmp_path / "bomb.zip"
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf, zf.open("set/bomb.h5", "w") as fh:
        for _ in range(24):
            fh.write(bytes(MiB))
    assert path.stat().st_size < 100_000  # 24 MiB of zeros in well under 1 MiB
    out, peak = peak_bytes(pj.data.load_nbrdf, path)
    assert isinstance(out, pj.DataFormatError), out
    assert "bomb.zip" in str(out) and "16.0 MiB" in str(out) and "24.0 MiB" in str(out)
    assert peak < 4 * MiB


def test_mat_normals_inflating_past_the_cap_are_refused_without_holding_them(tmp_path, monkeypatch):
    path = tmp_path / "Normal_gt.mat"
    scipy.io.savemat(path, {"Normal_gt": np.zeros((512, 512, 3))}, do_compression=True)  # 6 MiB in ~7 KB
    monkeypatch.setenv("POLYJAX_MAX_INPUT_MB", "1")
    out, peak = peak_bytes(pj.data.read_mat_array, str(path), "Normal_gt")
    assert isinstance(out, pj.DataFormatError), out
    assert "Normal_gt.mat" in str(out) and "POLYJAX_MAX_INPUT_MB" in str(out) and "inflating past it" in str(out)
    assert peak < 3 * MiB  # the array inflates to 6 MiB


def test_mask_png_declaring_more_pixels_than_the_cap_is_refused_before_decoding(tmp_path, monkeypatch):
    path = tmp_path / "mask.png"
    path.write_bytes(_png_bytes(4096, 4096, bytes(4097 * 4096)))  # 16 MiB of grey pixels in ~17 KB
    monkeypatch.setenv("POLYJAX_MAX_INPUT_MB", "16")  # decoded as 16-bit values: 32 MiB
    out, peak = peak_bytes(pj.data.read_png, str(path), None)
    assert isinstance(out, pj.DataFormatError), out
    assert "mask.png" in str(out) and "POLYJAX_MAX_INPUT_MB" in str(out) and "4096 x 4096" in str(out)
    assert peak < 2 * MiB


def test_first_image_with_a_huge_header_chunk_length_is_refused_without_allocating_it(tmp_path):
    """A flipped bit of the first image's ``IHDR`` length (byte 8: 13 becomes 64 MiB + 13) is a named error before
    anything of that size is allocated (the bit-depth probe once read it from the file object, which allocates the
    whole chunk: 64 MiB for this 200-byte file, 2 GiB for bit 7)."""
    folder = write_diligent(tmp_path / "objPNG")
    pj.data.load_photometric(str(folder))
    raw = bytearray((folder / "001.png").read_bytes())
    raw[8] ^= 1 << 2
    (folder / "001.png").write_bytes(bytes(raw))
    out, peak = peak_bytes(pj.data.load_photometric, str(folder))
    assert isinstance(out, pj.DataFormatError), out
    assert "001.png" in str(out) and "IHDR" in str(out)
    assert peak < MiB


def test_png_declaring_more_pixels_than_its_bytes_can_hold_is_refused_before_decoding(tmp_path):
    path = tmp_path / "001.png"
    path.write_bytes(_png_bytes(30000, 30000, bytes(30001 * 3)))  # 900 M pixels declared in ~100 bytes
    with pytest.raises(pj.DataFormatError, match=r"001\.png.*30000 x 30000.*deflate"):
        pj.data.read_png(str(path), None)


def test_saved_model_npz_member_over_the_cap_is_refused_before_loading(tmp_path, monkeypatch):
    path = tmp_path / "m.npz"
    pj.save_model(path, small_model())
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["coefficients"] = np.zeros((2, 2**21))  # 32 MiB in ~32 KB
    np.savez_compressed(path, **arrays)
    monkeypatch.setenv("POLYJAX_MAX_INPUT_MB", "8")
    out, peak = peak_bytes(pj.load_model, path)
    assert isinstance(out, pj.DataFormatError), out
    assert "m.npz" in str(out) and "coefficients.npy" in str(out) and "8.0 MiB" in str(out)
    assert peak < 2 * MiB


def test_saved_model_npz_member_declaring_more_than_it_holds_is_refused_before_loading(tmp_path):
    path = tmp_path / "m.npz"
    pj.save_model(path, small_model())
    with zipfile.ZipFile(path) as zf:
        members = {i.filename: zf.read(i) for i in zf.infolist()}
    head = members["l2.npy"]  # its header's shape (2,) made (9999999,): 80 MB declared, 16 bytes held
    members["l2.npy"] = head[:head.index(b"(2,)")] + b"(9999999,)" + head[head.index(b"(2,)") + 4:]
    with zipfile.ZipFile(path, "w") as zf:
        for name, body in members.items():
            zf.writestr(name, body)
    out, peak = peak_bytes(pj.load_model, path)
    assert isinstance(out, pj.DataFormatError), out
    assert "m.npz" in str(out) and "l2.npy" in str(out) and "(9999999,)" in str(out)
    assert peak < 2 * MiB


def test_tensor_file_over_the_cap_is_refused_before_reading(tmp_path, monkeypatch):
    path = write_tensor_file(tmp_path / "big_rgb.bsdf", rgl_fields(res=(200, 400)))  # ~1.3 MB of VNDF
    monkeypatch.setenv("POLYJAX_MAX_INPUT_MB", "0.5")
    out, peak = peak_bytes(pj.data.read_rgl, path)
    assert isinstance(out, pj.DataFormatError), out
    assert "big_rgb.bsdf" in str(out) and "POLYJAX_MAX_INPUT_MB" in str(out)
    assert peak < MiB // 4


def test_input_cap_that_is_not_a_positive_number_is_an_input_error(tmp_path, monkeypatch):
    path = write_tensor_file(tmp_path / "a_rgb.bsdf", rgl_fields())
    monkeypatch.setenv("POLYJAX_MAX_INPUT_MB", "-3")
    with pytest.raises(pj.InputError, match="POLYJAX_MAX_INPUT_MB"):
        pj.data.read_rgl(path)


# ------------------------------------------------------------------------------------------- named errors


def test_tensor_file_with_a_zero_sized_dimension_is_a_header_error(tmp_path):
    name = b"vndf"
    head = b"tensor_file\0" + bytes((1, 0)) + struct.pack("<I", 1)
    offset = len(head) + 2 + len(name) + 2 + 1 + 8 + 16
    path = tmp_path / "zero_rgb.bsdf"
    path.write_bytes(head + struct.pack("<H", len(name)) + name + struct.pack("<HBQ", 2, 10, offset)
                     + struct.pack("<QQ", 0, 2**63))
    with pytest.raises(pj.data.HeaderError, match=r"zero_rgb\.bsdf.*'vndf'.*shape \(0, 9223372036854775808\)"):
        pj.data.read_rgl(path)


def test_mat_file_with_a_short_element_is_a_data_format_error(tmp_path):
    path = tmp_path / "Normal_gt.mat"
    matrix = (_element(6, b"") + _element(5, struct.pack("<ii", 1, 3)) + _element(1, b"Normal_gt")
              + _element(9, np.zeros(3).tobytes()))  # an array flags element of 0 bytes (8 expected)
    path.write_bytes(_mat_file(_element(14, matrix)))
    with pytest.raises(pj.DataFormatError, match=r"Normal_gt\.mat"):
        pj.data.read_mat_array(str(path), "Normal_gt")


def test_mat_file_cut_inside_an_element_is_a_data_format_error(tmp_path):
    path = tmp_path / "Normal_gt.mat"
    scipy.io.savemat(path, {"Normal_gt": np.ones((3, 4, 3))})
    path.write_bytes(path.read_bytes()[:200])
    with pytest.raises(pj.DataFormatError, match=r"Normal_gt\.mat"):
        pj.data.read_mat_array(str(path), "Normal_gt")


def test_model_json_with_a_400_digit_integer_is_a_data_format_error(tmp_path):
    path = pj.save_model(tmp_path / "m.json", small_model())
    doc = json.loads(path.read_text())
    text = json.dumps(doc).replace('"data": [2, 2]', '"data": [' + "9" * 400 + ", 2]", 1)
    assert "9" * 400 in text
    path.write_text(text)
    with pytest.raises(pj.DataFormatError, match=r"m\.json.*400 digits"):
        pj.load_model(path)


def test_model_json_with_100000_nested_brackets_is_a_data_format_error(tmp_path):
    path = pj.save_model(tmp_path / "m.json", small_model())
    doc = path.read_text()
    path.write_text(doc[:-1] + ', "metadata": ' + "[" * 100_000 + "]" * 100_000 + "}")
    with pytest.raises(pj.DataFormatError, match=r"m\.json.*nested"):
        pj.load_model(path)


@pytest.mark.parametrize("suffix", [".npz", ".json"])
def test_saved_model_whose_arrays_disagree_is_refused_at_load(tmp_path, suffix):
    good = small_model()
    fields = {k: getattr(good, k) for k in good.__dataclass_fields__}
    bad = pj.PolynomialBRDF(**{**fields, "mean": np.zeros((2, 3))})  # three components beside two
    path = pj.save_model(tmp_path / f"m{suffix}", bad)
    with pytest.raises(pj.DataFormatError, match=rf"m\{suffix}.*'centre' of shape \(2, 3\)"):
        pj.load_model(path)
    path = pj.save_model(tmp_path / f"d{suffix}", pj.PolynomialBRDF(**{**fields, "degree": np.array([2, 7])}))
    with pytest.raises(pj.DataFormatError, match=r"degrees in \[0, max_degree = 2\]"):
        pj.load_model(path)
    assert pj.load_model(pj.save_model(tmp_path / f"g{suffix}", good)).batch_shape == (2,)


def test_astm_header_line_of_a_lone_comma_is_a_header_error(tmp_path):
    path = tmp_path / "lone.astm"
    path.write_text("NAME sample\n,\nVARS theta_i,phi_i,theta_s,phi_s,R\n0.1,0,0.2,3.1,0.5\n")
    with pytest.raises(pj.data.HeaderError, match=r"lone\.astm.*','.*line 2"):
        pj.data.read_cornell_astm(path)


def _shards(tmp_path):
    d = tmp_path / "tex"
    pj.svbrdf.write_texture_shards(d, small_model((3, 2)))
    return d, json.loads((d / "manifest.json").read_text())


@pytest.mark.parametrize("damage", ["truncated", "no shards", "rows of text", "rows past the height", "gap",
                                    "no file", "height as text"])
def test_damaged_shard_manifest_is_a_data_format_error(tmp_path, damage):
    d, meta = _shards(tmp_path)
    text = json.dumps(meta)
    if damage == "truncated":
        text = text[: len(text) // 2]
    else:
        shard = meta["shards"][0]
        if damage == "no shards":
            del meta["shards"]
        elif damage == "rows of text":
            shard["rows"] = "0-3"
        elif damage == "rows past the height":
            shard["rows"] = [0, 7]
        elif damage == "gap":
            shard["rows"] = [1, 3]
        elif damage == "no file":
            shard.pop("file")
            shard.pop("files")
        else:
            meta["height"] = "3"
        text = json.dumps(meta)
    (d / "manifest.json").write_text(text)
    with pytest.raises(pj.DataFormatError, match=r"manifest\.json"):
        pj.svbrdf.read_texture_shards(d)


def test_shard_npz_whose_arrays_disagree_with_the_manifest_is_a_data_format_error(tmp_path):
    d, meta = _shards(tmp_path)
    meta["max_degree"] = 5  # the coefficients hold 5 per texel, degree 5 would need 11
    (d / "manifest.json").write_text(json.dumps(meta))
    with pytest.raises(pj.DataFormatError, match=r"manifest\.json.*'coefficients' of shape \(3, 2, 11\)"):
        pj.svbrdf.read_texture_shards(d)


@pytest.mark.parametrize("damage", ["nested", "image as text", "lights as object", "target as text",
                                    "huge integer"])
def test_scene_json_of_the_wrong_shape_is_an_input_error(tmp_path, damage):
    path = write_scene(tmp_path / "scene")
    spec = json.loads(path.read_text())
    if damage == "nested":
        text = "[" * 100_000 + "]" * 100_000
    else:
        if damage == "image as text":
            spec["images"][0] = "a.exr"
        elif damage == "lights as object":
            spec["images"][0]["lights"] = {"type": "point"}
        elif damage == "target as text":
            spec["target"] = "zero"
        text = json.dumps(spec)
        if damage == "huge integer":
            text = text.replace('"target": 0', '"target": ' + "9" * 400)
    path.write_text(text)
    with pytest.raises(pj.InputError, match=r"scene\.json"):
        pj.cli.load_scene_json(path)


def test_small_valid_inputs_still_load(tmp_path):
    nets = pj.data.load_nbrdf(write_nbrdf_zip(tmp_path / "set.zip"))
    assert sorted(nets) == ["alpha", "beta"] and nets["alpha"].w2.shape == (21, 21)
    path = tmp_path / "Normal_gt.mat"
    normals = np.random.default_rng(0).normal(size=(3, 4, 3))
    scipy.io.savemat(path, {"Normal_gt": normals}, do_compression=True)
    np.testing.assert_array_equal(pj.data.read_mat_array(str(path), "Normal_gt"), normals)


@pytest.mark.parametrize("damage", ["data type 0", "flags of every bit"])
def test_mat_file_that_crashes_scipy_is_a_data_format_error(tmp_path, damage):
    """Two damaged MAT-files on which ``scipy.io.loadmat`` itself crashes the process (a segmentation fault): a
    value element of the undefined type 0, array flags with the complex bit (and undefined ones) set."""
    path = tmp_path / "Normal_gt.mat"
    scipy.io.savemat(path, {"Normal_gt": np.ones((3, 4, 3))})
    raw = bytearray(path.read_bytes())
    if damage == "data type 0":
        raw[200] = 0  # the values' element: miDOUBLE (9) -> 0
    else:
        raw[145:149] = b"\xff\xff\xff\xff"  # the array flags' upper bytes
    path.write_bytes(bytes(raw))
    with pytest.raises(pj.DataFormatError, match=r"Normal_gt\.mat.*(MAT data type|array flags)"):
        pj.data.read_mat_array(str(path), "Normal_gt")


@pytest.mark.parametrize("reader", ["load_model", "load_nbrdf"])
def test_a_zip_member_without_a_name_is_a_named_error(tmp_path, reader):
    """A damaged central directory can give a member an empty name (found by fuzzing a saved model): zipfile's own
    ``is_dir`` then fails with an IndexError; the readers name the file and the member instead."""
    path = tmp_path / ("m.npz" if reader == "load_model" else "nets.zip")
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr(zipfile.ZipInfo(""), b"abc")
    load = pj.load_model if reader == "load_model" else pj.data.load_nbrdf
    with pytest.raises(pj.DataFormatError, match=r"member 0 without a name") as e:
        load(path)
    assert path.name in str(e.value)
