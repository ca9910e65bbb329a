"""``polyjax export FIT_OR_DATA --to gltf|mitsuba-xml``: the standard model fitted to a saved model (tabulated) or a
data set, written, with the projection's error printed; the file holds exactly the fitted material."""

import json
import struct

import jax.numpy as jnp
import numpy as np
import pytest

import baselines as bl
import polyjax as pj
from polyjax.cli import main

PARAMS = [[c, 0.3, 0.4] for c in (0.2, 0.5, 0.8)]


def _saved_gltf_fit(path):
    p = jnp.asarray(PARAMS)
    z = jnp.zeros((3,), jnp.int32)
    fit = bl.BaselineFit(params=p, raw=bl.get_model("gltf-pbr").to_raw(p), l2=jnp.zeros(3), status=z, steps=z,
                         success=z == 0, start_l2=jnp.zeros((3, 1)), start_status=z[:, None], best_start=z,
                         at_limit=jnp.zeros(p.shape, bool), name="gltf-pbr")
    pj.save_model(path, fit)
    return path


def test_export_gltf_of_a_saved_model_fits_it_back_exactly(tmp_path, capsys):
    """A saved glTF model tabulated and projected onto glTF: the glb holds its parameters, the printed L2 is ~0
    (300 samples: the shapes of ``test_standard_models``' one-material fit, so one compiled program)."""
    src = _saved_gltf_fit(tmp_path / "fit.npz")
    out = tmp_path / "fit.glb"
    assert main(["export", str(src), "--to", "gltf", "--out", str(out), "--samples", "300"]) == 0
    printed = capsys.readouterr().out
    assert "L2 (eq. 11) R, G, B:" in printed and "log-space L2 R, G, B:" in printed and f"wrote {out}" in printed
    l2 = [float(x) for x in printed.split("L2 (eq. 11) R, G, B: ")[1].split("  (")[0].split(", ")]
    assert max(l2) < 1e-6
    data = out.read_bytes()
    n = struct.unpack("<I", data[12:16])[0]
    pbr = json.loads(data[20:20 + n])["materials"][0]["pbrMetallicRoughness"]
    np.testing.assert_allclose(pbr["baseColorFactor"][:3], [0.2, 0.5, 0.8], atol=1e-6)
    np.testing.assert_allclose([pbr["metallicFactor"], pbr["roughnessFactor"]], [0.3, 0.4], atol=1e-6)


def test_export_standard_bad_source_and_folder(tmp_path, capsys):
    assert main(["export", "merl-nbrdf:no-such-material", "--to", "mitsuba-xml", "--out", str(tmp_path / "m.xml"),
                 "--data-root", str(tmp_path)]) != 0
    assert main(["export", "cornell:cayman", "--to", "gltf", "--out", str(tmp_path / "missing" / "m.glb")]) == 2
    err = capsys.readouterr().err
    assert "--out" in err and "the folder" in err and "does not exist" in err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.data
@pytest.mark.slow  # a second standard model's fit compiled: about 15 CPU-seconds
def test_export_mitsuba_xml_of_measured_data(tmp_path, capsys, data_root):
    out = tmp_path / "bronze.xml"
    assert main(["export", "merl-nbrdf:alum-bronze", "--to", "mitsuba-xml", "--plugin", "principled", "--subsample",
                 "2000", "--out", str(out), "--data-root", str(data_root)]) == 0
    assert '<bsdf type="principled" id="material">' in out.read_text()
    assert "principled fitted to merl-nbrdf:alum-bronze" in capsys.readouterr().out
