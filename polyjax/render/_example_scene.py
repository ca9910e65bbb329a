"""A ready example for ``polyjax fit-images``: a scene description and the EXR photographs it lists, rendered from a
known BRDF, to start from (``polyjax fit-images --example DIR``, then ``polyjax fit-images DIR/scene.json``).

The scene is the format of ``docs/fit-images.md``: a camera on the +z axis looking at a unit sphere at the origin,
three point lights, one image per light, rendered with a Phong BRDF (``kd = (0.3, 0.5, 0.7)``, ``ks = 0.4``, exponent
20) in float64 and written as linear-RGB OpenEXR.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import jax.numpy as jnp

from .._files import write_bytes_atomically
from ._brdf import Phong
from ._image import write_exr
from ._integrator import render
from ._scene import Camera, PointLight, Scene, Sphere

#: the three point lights of the example: position (x, y, z) and intensity
LIGHTS = (((3.0, 2.0, 4.0), 30.0), ((-3.0, 1.0, 3.0), 30.0), ((0.0, -3.0, 4.0), 30.0))


def write_example_scene(folder: str | os.PathLike, size: int = 64) -> Path:
    """Render the example's images into ``folder`` (an existing folder) and write its ``scene.json`` there.

    Args:
        folder: where ``scene.json`` and ``light0.exr`` .. ``light2.exr`` are written.
        size: image width and height in pixels.

    Returns:
        The path of ``scene.json``.
    """
    folder = Path(folder)
    camera = {"eye": [0.0, 0.0, 5.0], "target": [0.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0], "fov_deg": 30.0,
              "width": int(size), "height": int(size)}
    cam = Camera(**camera)
    brdf = Phong(kd=(0.3, 0.5, 0.7), ks=0.4, exponent=20.0)
    entries = []
    for i, (position, intensity) in enumerate(LIGHTS):
        image = render(Scene(cam, [Sphere(brdf)], [PointLight(position, intensity)]), dtype=jnp.float64).image
        write_exr(folder / f"light{i}.exr", image)
        entries.append({"file": f"light{i}.exr",
                        "lights": [{"type": "point", "position": list(position), "intensity": intensity}]})
    spec = {"camera": camera, "objects": [{"type": "sphere", "center": [0.0, 0.0, 0.0], "radius": 1.0}],
            "target": 0, "images": entries}
    path = folder / "scene.json"
    return write_bytes_atomically(path, (json.dumps(spec, indent=2) + "\n").encode())


__all__ = ["LIGHTS", "write_example_scene"]
