"""Small valid input files of every loader, the damage the fuzz tests do to them, and a memory meter.

Each :class:`Problem` builds one small, synthetic, valid input in a folder (a MERL table of 6 x 5 x 8 bins, an RGL
tensor file, a neural-BRDF zip, Cornell ASTM and pbrt texts, a CUReT root, a DiLiGenT folder and its MAT-file, saved
models, a fit-images scene, a texture's shards) and loads it through the public API. The damage: truncations, bit
flips, huge declared sizes (integers written over binary fields, zip members' declared sizes, ``.npy`` shapes, PNG
dimensions with a correct CRC, numbers of a text replaced by huge ones) and wrong types (a JSON value replaced by one
of another type, deep nesting). ``peak_bytes`` measures the Python and numpy memory a load allocates (tracemalloc).
"""

from __future__ import annotations

import io
import json
import re
import struct
import tracemalloc
import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import h5py
import numpy as np
import scipy.io
from hypothesis import strategies as st

import polyjax as pj

from _data_problems import write_astm, write_small_merl
from _rgl_problems import rgl_fields, write_tensor_file

#: a load of these small files must allocate less than this (Python objects and numpy arrays, tracemalloc)
MEMORY_CAP = 64 * 2**20
HUGE_INTS = (2**31 - 1, 2**31, 2**32 - 1, 2**63 - 1, 2**64 - 1, 2**40, 10**12)
HUGE_TEXT = ("9" * 400, "1e999", "-1e999", "nan", "-1", "0", "4294967295", "1" + "0" * 30, ",", "", "x", "[[[")


def peak_bytes(fn: Callable, *args):
    """``(result or exception, peak bytes allocated during fn(*args))``."""
    tracemalloc.start()
    try:
        try:
            out = fn(*args)
        except BaseException as e:  # noqa: BLE001  (returned for the test to judge)
            out = e
        return out, tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


# ------------------------------------------------------------------------------------------- the damage


def damaged_bytes(data, raw: bytes) -> bytes:
    """``raw`` truncated, with bits flipped, or with a huge integer written over 2, 4 or 8 bytes."""
    kind = data.draw(st.sampled_from(["truncate", "flip", "huge"]), label="damage")
    if not raw:
        return raw
    if kind == "truncate":
        return raw[:data.draw(st.integers(0, len(raw) - 1), label="keep")]
    out = bytearray(raw)
    if kind == "flip":
        for _ in range(data.draw(st.integers(1, 8), label="flips")):
            i = data.draw(st.integers(0, len(out) - 1), label="at")
            out[i] ^= 1 << data.draw(st.integers(0, 7), label="bit")
        return bytes(out)
    width = data.draw(st.sampled_from([2, 4, 8]), label="width")
    value = data.draw(st.sampled_from(HUGE_INTS), label="value") % 2 ** (8 * width)
    at = data.draw(st.integers(0, max(len(out) - width, 0)), label="at")
    out[at:at + width] = value.to_bytes(width, data.draw(st.sampled_from(["little", "big"]), label="order"))
    return bytes(out[:len(raw)])


def damaged_text(data, text: str) -> str:
    """``text`` with a number (or token) replaced by a huge or wrong one, a line dropped or repeated, or its bytes
    damaged (:func:`damaged_bytes`, decoded as latin-1)."""
    kind = data.draw(st.sampled_from(["token", "line", "bytes"]), label="text damage")
    if kind == "bytes":
        return damaged_bytes(data, text.encode("latin-1", "replace")).decode("latin-1")
    if kind == "token":
        spans = [m.span() for m in re.finditer(r"[^\s,]+", text)]
        if not spans:
            return text
        a, b = spans[data.draw(st.integers(0, len(spans) - 1), label="token")]
        return text[:a] + data.draw(st.sampled_from(HUGE_TEXT), label="by") + text[b:]
    lines = text.splitlines(keepends=True)
    i = data.draw(st.integers(0, max(len(lines) - 1, 0)), label="line")
    return "".join(lines[:i] + (lines[i:i + 1] * 2 if data.draw(st.booleans(), label="twice") else []) + lines[i + 1:])


JSON_VALUES = st.one_of(
    st.none(), st.booleans(), st.integers(-2**70, 2**70), st.floats(), st.text(max_size=4),
    st.lists(st.integers(-3, 3), max_size=3), st.dictionaries(st.text(max_size=3), st.integers(), max_size=2),
    st.sampled_from([10**400, "[" * 5000, -1, 0, 2**63]),
)


def _paths(doc, prefix=()):
    yield prefix
    if isinstance(doc, dict):
        for k, v in doc.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(doc, list):
        for i, v in enumerate(doc[:6]):
            yield from _paths(v, prefix + (i,))


def damaged_json(data, text: str) -> str:
    """``text`` (a JSON document) with one value replaced by another of any type, one key removed, the document
    nested 100,000 deep, or its text damaged (:func:`damaged_text`)."""
    kind = data.draw(st.sampled_from(["retype", "drop", "nest", "text"]), label="json damage")
    if kind == "text":
        return damaged_text(data, text)
    if kind == "nest":
        return "[" * 100_000 + text + "]" * 100_000
    doc = json.loads(text)
    paths = [p for p in _paths(doc) if p]
    path = paths[data.draw(st.integers(0, len(paths) - 1), label="path")]
    parent = doc
    for k in path[:-1]:
        parent = parent[k]
    if kind == "drop":
        del parent[path[-1]]
    else:
        value = data.draw(JSON_VALUES, label="value")
        parent[path[-1]] = value
    return json.dumps(doc).replace('"' + "[" * 5000 + '"', "[" * 5000 + "]" * 5000)


def damaged_zip(data, raw: bytes, member_damage=damaged_bytes, kinds=("container", "declared", "member")) -> bytes:
    """A zip archive's bytes damaged (:func:`damaged_bytes`), a member's declared size made huge (local header and
    central directory), or one member damaged by ``member_damage`` and stored again with a correct CRC."""
    kind = data.draw(st.sampled_from(kinds), label="zip damage")
    if kind == "container":
        return damaged_bytes(data, raw)
    if kind == "declared":
        out = bytearray(raw)
        size = data.draw(st.sampled_from([2**32 - 1, 2**31, 2**28, 10**6]), label="declared")
        for sig, at in ((b"PK\x03\x04", 22), (b"PK\x01\x02", 24)):
            for m in re.finditer(re.escape(sig), raw):
                out[m.start() + at:m.start() + at + 4] = struct.pack("<I", size)
        return bytes(out)
    with zipfile.ZipFile(io.BytesIO(raw)) as zf:
        members = {i.filename: (i, zf.read(i)) for i in zf.infolist()}
    names = sorted(members)
    chosen = names[data.draw(st.integers(0, len(names) - 1), label="member")]
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as out:
        for name in names:
            info, body = members[name]
            out.writestr(info, member_damage(data, body) if name == chosen else body)
    return buf.getvalue()


def damaged_npy(data, body: bytes) -> bytes:
    """An ``.npy`` member with its shape's numbers replaced by huge ones or zero, or its bytes damaged."""
    if data.draw(st.booleans(), label="shape"):
        head_end = body.find(b"\n") + 1
        head = body[:head_end].decode("latin-1")
        big = data.draw(st.sampled_from(["2000000000", "0", "9" * 30, "-1", "3"]), label="dim")
        head = re.sub(r"\d+(?=[,)])", big, head, count=1)
        return head.encode("latin-1") + body[head_end:]
    return damaged_bytes(data, body)


def png_with_dimensions(raw: bytes, width: int, height: int) -> bytes:
    """The PNG ``raw`` with its IHDR's width and height replaced (and its CRC recomputed)."""
    ihdr = bytearray(raw[12:29])  # type + 13 data bytes
    ihdr[4:12] = struct.pack(">II", width, height)
    return raw[:12] + bytes(ihdr) + struct.pack(">I", zlib.crc32(bytes(ihdr))) + raw[33:]


def damaged_png(data, raw: bytes) -> bytes:
    if data.draw(st.booleans(), label="dimensions"):
        dims = st.sampled_from([1, 3, 2**16, 2**24, 2**31 - 1])
        return png_with_dimensions(raw, data.draw(dims, label="w"), data.draw(dims, label="h"))
    return damaged_bytes(data, raw)


# ------------------------------------------------------------------------------------------ valid files


def write_png(path: Path, pixels: np.ndarray, bits: int) -> Path:
    import png

    rows = pixels.reshape(pixels.shape[0], -1)
    greyscale = pixels.ndim == 2
    with open(path, "wb") as fh:
        png.Writer(pixels.shape[1], pixels.shape[0], greyscale=greyscale, bitdepth=bits).write(fh, rows)
    return path


def network_h5(seed: int = 0) -> bytes:
    """A Keras-style weights file of a 6-21-21-3 network (small random weights)."""
    rng = np.random.default_rng(seed)
    buf = io.BytesIO()
    with h5py.File(buf, "w") as f:
        for i, (a, b) in enumerate(((6, 21), (21, 21), (21, 3)), 1):
            g = f.create_group(f"dense_{i}/dense_{i}")
            g["kernel:0"] = (0.1 * rng.normal(size=(a, b))).astype(np.float32)
            g["bias:0"] = (0.01 * rng.normal(size=b)).astype(np.float32)
    return buf.getvalue()


def write_nbrdf_zip(path: Path) -> Path:
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("set/alpha.h5", network_h5(0))
        zf.writestr("set/beta.h5", network_h5(1))
    return path


def write_curet_root(root: Path) -> Path:
    """A CUReT root of 205 geometries and two samples."""
    d = root / "curet"
    d.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(0)
    th = rng.uniform(0.1, 1.4, (205, 2))
    ph = rng.uniform(-3.0, 3.0, (205, 2))
    (d / "table.txt").write_text("".join(f"{i + 1} {th[i, 0]:.6f} {ph[i, 0]:.6f} {th[i, 1]:.6f} {ph[i, 1]:.6f}\n"
                                         for i in range(205)))
    (d / "sample_labels.txt").write_text("# number<TAB>name\n1\tFelt\n2\tPolyester\n")
    (d / "abrdf.dat").write_text("".join(f"{s} " + " ".join(f"{x:.3f}" for x in rng.uniform(0.05, 0.5, 205)) + "\n"
                                         for s in (1, 2)))
    return root


def write_diligent(folder: Path, h: int = 4, w: int = 5, lights: int = 3) -> Path:
    """A DiLiGenT folder of ``lights`` 16-bit images of ``h x w`` pixels, a mask and a compressed MAT-file."""
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(0)
    names = [f"{i + 1:03d}.png" for i in range(lights)]
    dirs = rng.normal(size=(lights, 3)) + [0, 0, 3]
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    (folder / "filenames.txt").write_text("".join(n + "\n" for n in names))
    (folder / "light_directions.txt").write_text("".join(" ".join(repr(float(x)) for x in d) + "\n" for d in dirs))
    (folder / "light_intensities.txt").write_text("1 1 1\n" * lights)
    for n in names:
        write_png(folder / n, rng.integers(0, 65535, (h, w, 3)).astype(np.uint16), 16)
    write_png(folder / "mask.png", np.full((h, w), 255, np.uint8), 8)
    normals = np.zeros((h, w, 3))
    normals[..., 2] = 1.0
    scipy.io.savemat(folder / "Normal_gt.mat", {"Normal_gt": normals}, do_compression=True)
    return folder


def small_model(batch=(2,), seed: int = 0) -> pj.PolynomialBRDF:
    """A hand-made polynomial model (Lafortune variables, k = 2, degree 2, m = 5) of batch shape ``batch``."""
    rng = np.random.default_rng(seed)
    k, p = 2, 2
    fields = dict(
        coefficients=rng.normal(size=batch + (k * p + 1,)), degree=np.full(batch, p, np.int32),
        mean=rng.normal(size=batch + (k,)), rotation=np.broadcast_to(np.eye(k), batch + (k, k)).copy(),
        centre=np.zeros(batch + (k,)), halfwidth=np.ones(batch + (k,)), l2=np.full(batch, 0.1),
        rank=np.full(batch, k * p + 1, np.int32), condition=np.full(batch, 3.0),
        n_used=np.full(batch, 100, np.int32), status=np.zeros(batch, np.int32),
    )
    return pj.PolynomialBRDF(**fields, variables="lafortune", basis="legendre", interactions=False, max_degree=p)


def write_scene(folder: Path) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    pj.render.write_exr(folder / "a.exr", np.full((4, 4, 3), 0.25, np.float32))
    spec = {"camera": {"eye": [0.0, 0.0, 5.0], "target": [0.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0], "fov_deg": 30.0},
            "objects": [{"type": "sphere", "center": [0.0, 0.0, 0.0], "radius": 1.0}], "target": 0,
            "images": [{"file": "a.exr", "lights": [{"type": "point", "position": [2.0, 2.0, 5.0], "intensity": 30.0},
                                                    {"type": "directional", "direction": [0.0, 0.0, 1.0]}]}]}
    path = folder / "scene.json"
    path.write_text(json.dumps(spec))
    return path


# ----------------------------------------------------------------------------------------------- problems


@dataclass(frozen=True)
class Problem:
    """One loader: ``build(folder) -> path`` of a valid input, ``file(path) -> the file damaged`` (``path`` itself
    or a file inside a folder input), ``damage(data, bytes) -> bytes``, ``load(path)``."""

    build: Callable[[Path], Path]
    damage: Callable
    load: Callable[[Path], object]
    files: Callable[[Path], list] = lambda p: [p]


def _text(fn):
    return lambda data, raw: fn(data, raw.decode("latin-1")).encode("latin-1", "replace")


def _pbrt(folder: Path) -> Path:
    rng = np.random.default_rng(0)
    rows = np.column_stack([rng.uniform(0, 1.4, 6), rng.uniform(-3, 3, 6), rng.uniform(0, 1.4, 6),
                            rng.uniform(-3, 3, 6), rng.uniform(0.1, 1, (6, 3))])
    text = "# pbrt-v2 spectral BRDF\n3\n450 550 650\n" + "".join(" ".join(f"{x:.6g}" for x in r) + "\n" for r in rows)
    (folder / "m.brdf").write_text(text)
    return folder / "m.brdf"


def _astm(folder: Path) -> Path:
    rng = np.random.default_rng(0)
    ang = np.column_stack([rng.uniform(0, 1.4, 6), rng.uniform(-3, 3, 6), rng.uniform(0, 1.4, 6),
                           rng.uniform(-3, 3, 6)])
    return write_astm(folder / "m.astm", ang, rng.uniform(0.1, 1, (6, 3)), ["R", "G", "B"])


def _merl(folder: Path) -> Path:
    write_small_merl(folder / "m.binary")
    return folder / "m.binary"


def _tensor(folder: Path) -> Path:
    return write_tensor_file(folder / "m.bsdf", rgl_fields(res=(3, 4), s=3))


def _model(suffix: str):
    def build(folder: Path) -> Path:
        return pj.save_model(folder / f"m{suffix}", small_model())
    return build


def _shards(folder: Path) -> Path:
    pj.svbrdf.write_texture_shards(folder / "tex", small_model((3, 2)))
    return folder / "tex"


def _diligent_files(folder: Path) -> list:
    return [folder / n for n in ("filenames.txt", "light_directions.txt", "light_intensities.txt", "mask.png",
                                 "001.png", "Normal_gt.mat")]


def _diligent_damage(data, raw: bytes) -> bytes:
    if raw.startswith(b"\x89PNG"):
        return damaged_png(data, raw)
    if raw.startswith(b"MATLAB"):
        return damaged_bytes(data, raw)
    return _text(damaged_text)(data, raw)


def _plain_mat(folder: Path) -> Path:
    """An uncompressed MAT-file of normals (its elements' sizes in plain sight of the damage)."""
    normals = np.zeros((3, 4, 3))
    normals[..., 2] = 1.0
    scipy.io.savemat(folder / "Normal_gt.mat", {"Normal_gt": normals, "other": np.arange(3.0)})
    return folder / "Normal_gt.mat"


def _curet_files(root: Path) -> list:
    return [root / "curet" / n for n in ("table.txt", "sample_labels.txt", "abrdf.dat")]


PROBLEMS = {
    "merl-binary": Problem(_merl, damaged_bytes, pj.data.read_merl_binary),
    "tensor-file": Problem(_tensor, damaged_bytes, pj.data.read_rgl),
    "nbrdf-zip": Problem(lambda d: write_nbrdf_zip(d / "set.zip"),
                         lambda data, raw: damaged_zip(data, raw, kinds=("container", "declared")), pj.data.load_nbrdf),
    "nbrdf-h5": Problem(lambda d: write_nbrdf_zip(d / "set.zip"),
                        lambda data, raw: damaged_zip(data, raw, kinds=("member",)), pj.data.load_nbrdf),
    "cornell-astm": Problem(_astm, _text(damaged_text), pj.data.read_cornell_astm),
    "cornell-pbrt": Problem(_pbrt, _text(damaged_text), pj.data.read_cornell_pbrt),
    "curet": Problem(lambda d: write_curet_root(d / "root"), _text(damaged_text),
                     lambda p: pj.data.load_curet(root=p), _curet_files),
    "diligent-folder": Problem(lambda d: write_diligent(d / "objPNG"), _diligent_damage, pj.data.load_photometric,
                               _diligent_files),
    "diligent-mat": Problem(_plain_mat, damaged_bytes,
                            lambda p: pj.data.read_mat_array(str(p), "Normal_gt")),
    "model-npz": Problem(_model(".npz"), lambda data, raw: damaged_zip(data, raw, damaged_npy), pj.load_model),
    "model-json": Problem(_model(".json"), _text(damaged_json), pj.load_model),
    "scene-json": Problem(lambda d: write_scene(d / "scene"), _text(damaged_json), lambda p: pj.cli.load_scene_json(p)),
    "shard-manifest": Problem(_shards, _text(damaged_json), pj.svbrdf.read_texture_shards,
                              lambda p: [p / "manifest.json"]),
}
