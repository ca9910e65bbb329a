"""The ``polyjax fit-images`` command: EXR images and a JSON scene description."""

import json

import jax.numpy as jnp
import numpy as np

import polyjax as pj
import polyjax.render as pr
from polyjax.cli import main

SIZE = 32
LIGHTS = [(3.0, 2.0, 4.0), (-3.0, 1.0, 3.0), (0.0, -3.0, 4.0)]


def _write_scene(tmp_path, brdf):
    cam = pr.Camera(eye=(0.0, 0.0, 5.0), width=SIZE, height=SIZE, fov_deg=30.0)
    entries = []
    for i, p in enumerate(LIGHTS):
        img = pr.render(pr.Scene(cam, [pr.Sphere(brdf)], [pr.PointLight(p, 30.0)]), dtype=jnp.float64).image
        pr.write_exr(tmp_path / f"light{i}.exr", img)
        entries.append({"file": f"light{i}.exr", "lights": [{"type": "point", "position": list(p), "intensity": 30}]})
    spec = {"camera": {"eye": [0, 0, 5], "fov_deg": 30}, "objects": [{"type": "sphere", "radius": 1}],
            "images": entries}
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(spec))
    return path


def test_fit_images_command_recovers_the_api_fit(tmp_path, capsys):
    path = _write_scene(tmp_path, pr.Phong(kd=(0.3, 0.5, 0.7), ks=0.4, exponent=20.0))
    assert main(["fit-images", str(path), "--variables", "lafortune", "--degree", "4", "--save",
                 str(tmp_path / "m.npz"), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["images"] == 3 and out["status_rgb"] == ["OK", "OK", "OK"]
    # the scene the JSON describes, built with the API, and the images as the command reads them
    cam = pr.Camera(eye=(0.0, 0.0, 5.0), width=SIZE, height=SIZE, fov_deg=30.0)
    sphere = pr.Sphere(pr.Lambertian(0.5), radius=1.0)  # a placeholder BRDF: the fit replaces it
    scenes = [pr.Scene(cam, [sphere], [pr.PointLight(p, 30.0)]) for p in LIGHTS]
    images = [pr.read_exr(tmp_path / f"light{i}.exr") for i in range(len(LIGHTS))]
    api = pj.fit_polynomial_to_images(scenes, images, variables="lafortune", degree=4, interactions=False,
                                      link="identity", clamp=False, weighting="radiance", cutoff_deg=80.0)
    saved = pj.load_model(tmp_path / "m.npz")
    np.testing.assert_allclose(np.asarray(saved.coefficients), np.asarray(api.coefficients), rtol=1e-12)
    assert out["pixels_used"] == int(api.n_used[0]) > 500


def test_fit_images_command_names_bad_input(tmp_path, capsys):
    path = _write_scene(tmp_path, pr.Lambertian(0.5))
    spec = json.loads(path.read_text())
    spec["images"][1]["file"] = "missing.exr"
    path.write_text(json.dumps(spec))
    assert main(["fit-images", str(path)]) == 2
    assert "images[1]: file" in capsys.readouterr().err
    spec["images"][1] = {"file": "light1.exr", "lights": [{"type": "spot"}]}
    path.write_text(json.dumps(spec))
    assert main(["fit-images", str(path)]) == 2
    assert "images[1].lights[0]: expected type 'point', 'directional' or 'environment'" in capsys.readouterr().err
