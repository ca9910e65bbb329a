"""Blender as a consumer of the glTF export: ``blender -b -P benchmarks/blender/render_glb.py`` imports the
``.glb`` sphere and renders it with Cycles on the CPU under one point light; polyjax renders the same scene with
the glTF BRDF (``gltf-pbr``).

Runs when ``blender`` is on the PATH and ``POLYJAX_BLENDER_PYTHONPATH`` names a folder holding numpy < 1.24 (Blender
3.4's glTF importer imports numpy from the system python3.11, and uses aliases numpy 1.24 removed); skipped
otherwise.

Where Blender's Principled BSDF (3.4) departs from the glTF BRDF: its diffuse is Burley's, with retro-reflection
(brighter than glTF's Lambertian by 4.7% in the median pixel at roughness 0.5), not weighted by ``1 - F``; its
metal (GGX, Schlick tint towards white) agrees with glTF's ``conductor_fresnel``.
"""

import os
import shutil
import subprocess
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

import baselines as bl
import polyjax as pj
import polyjax.render as pr

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "blender" / "render_glb.py"
SIZE, LIGHT, INTENSITY, FOV = 64, (3.0, 2.0, 4.0), 30.0, 30.0


def _blender(glb: Path, out: Path) -> np.ndarray:
    site = os.environ.get("POLYJAX_BLENDER_PYTHONPATH")
    if shutil.which("blender") is None or not site:
        (pytest.fail if os.environ.get("CI") else pytest.skip)(
            "blender, or POLYJAX_BLENDER_PYTHONPATH (a folder with numpy < 1.24 for its glTF importer), is missing")
    cmd = ["blender", "-b", "--factory-startup", "-P", str(SCRIPT), "--", str(glb), str(out), str(SIZE), "16",
           *map(str, LIGHT), str(INTENSITY), str(FOV)]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=dict(os.environ, PYTHONPATH=site))
    assert res.returncode == 0 and out.exists(), res.stdout[-2000:] + res.stderr[-2000:]
    return np.load(str(out) + ".npy")


@pytest.mark.parametrize("metallic, roughness, colour, min_psnr", [
    (1.0, 0.4, [0.9, 0.6, 0.3], 55.0),  # measured 63.9 dB
    (0.0, 0.5, [0.2, 0.5, 0.8], 30.0),  # measured 35.3 dB: Burley's diffuse against Lambert's
])
def test_blender_renders_the_glb_as_the_gltf_brdf(tmp_path, metallic, roughness, colour, min_psnr):
    material = {"model": "gltf-pbr", "baseColorFactor": colour, "metallicFactor": metallic,
                "roughnessFactor": roughness}
    theirs = _blender(pj.export.gltf(material, tmp_path / "sphere.glb", segments=96, rings=48),
                      tmp_path / "sphere.exr")
    p = jnp.asarray([[c, metallic, roughness] for c in colour])
    z = jnp.zeros((3,), jnp.int32)
    fit = bl.BaselineFit(params=p, raw=p, l2=jnp.zeros(3), status=z, steps=z, success=z == 0,
                         start_l2=jnp.zeros((3, 1)), start_status=z[:, None], best_start=z,
                         at_limit=jnp.zeros(p.shape, bool), name="gltf-pbr")
    cam = pr.Camera(eye=(0.0, 0.0, 5.0), width=SIZE, height=SIZE, fov_deg=FOV)
    ours = np.asarray(pr.render(pr.Scene(cam, [pr.Sphere(fit)], [pr.PointLight(LIGHT, INTENSITY)]),
                                dtype=jnp.float64).image)
    assert theirs.shape == ours.shape and theirs.max() > 0.1
    assert float(pj.psnr(ours, theirs)) >= min_psnr
