"""Blender script: import a capture's ``.glb`` card (``polyjax.export.gltf_card``) and render it with Cycles on the
CPU under directional (sun) lights, one image per light, through an orthographic camera matching the capture's
(the image spans ``y`` in ``[-1, 1]``, ``x`` in ``[-W/H, W/H]``), direct light only, a box pixel filter 0.01 pixel
wide (the pixel centres, which are the texel centres), no denoising, Standard view transform; writes each linear
image as OpenEXR and ``.npy`` (row 0 at the top).

    blender -b --factory-startup -P render_card.py -- IN.glb OUT_PREFIX W H SAMPLES DX DY DZ R G B [DX ...]

Each light is a direction ``(DX, DY, DZ)`` towards it in the capture's camera frame (glTF's frame) and an RGB
irradiance; Blender's glTF importer turns glTF's ``+y`` up into Blender's ``+z`` (``(x, y, z) -> (x, -z, y)``), the
lights and camera are placed in the same turned frame. A sun of strength ``S`` W/m^2 gives irradiance ``S`` on a
surface facing it, the capture's model ``E max(0, n . d) f``. Blender's glTF importer needs numpy < 1.24 on
PYTHONPATH (Blender 3.4 with the system python3.11).
"""

import math
import os
import sys

import bpy
from mathutils import Vector

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _polyjax_cycles import render_to, set_up_cycles  # noqa: E402

args = sys.argv[sys.argv.index("--") + 1:]
src, prefix = args[0], args[1]
width, height, samples = int(args[2]), int(args[3]), int(args[4])
lights = [tuple(float(x) for x in args[i:i + 6]) for i in range(5, len(args), 6)]

bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=src)
scene = bpy.context.scene
for obj in list(scene.objects):  # the card's own camera is replaced by one placed explicitly
    if obj.type == "CAMERA":
        bpy.data.objects.remove(obj, do_unlink=True)
cam_data = bpy.data.cameras.new("camera")
cam_data.type = "ORTHO"
cam_data.sensor_fit = "AUTO"
cam_data.ortho_scale = 2.0 * max(width / height, 1.0)  # the larger side of the image
cam_data.clip_start, cam_data.clip_end = 0.01, 10.0
cam = bpy.data.objects.new("camera", cam_data)
cam.location = (0.0, -2.0, 0.0)  # glTF (0, 0, 2)
cam.rotation_euler = (math.pi / 2, 0.0, 0.0)  # looking along Blender +y (glTF -z), Blender +z (glTF +y) up
scene.collection.objects.link(cam)
scene.camera = cam
set_up_cycles(scene, samples, width, height)
sun_data = bpy.data.lights.new("sun", type="SUN")
sun_data.angle = 0.0
sun = bpy.data.objects.new("sun", sun_data)
scene.collection.objects.link(sun)
for i, (dx, dy, dz, r, g, b) in enumerate(lights):
    strength = max(r, g, b, 1e-12)
    sun_data.energy = strength
    sun_data.color = (r / strength, g / strength, b / strength)
    towards = Vector((dx, -dz, dy)).normalized()  # glTF -> Blender
    sun.rotation_euler = towards.to_track_quat("Z", "Y").to_euler()  # the sun shines along its local -z
    render_to(scene, f"{prefix}{i}.exr", width, height)
