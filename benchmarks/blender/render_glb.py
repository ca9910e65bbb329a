"""Blender script: import a ``.glb`` sphere and render it with Cycles on the CPU under one point light, camera and
light placed as polyjax's scene (camera at (0, 0, 5) looking at the origin, vertical field of view ``FOV``, point
light of radiant intensity ``I`` W/sr at ``LIGHT``), direct light only, a box pixel filter 0.01 pixel wide (the
pixel centres, as polyjax), no denoising, Standard view transform; writes the linear image as OpenEXR and as
``.npy`` (row 0 at the top).

    blender -b --factory-startup -P render_glb.py -- IN.glb OUT.exr SIZE SAMPLES LX LY LZ I FOV

Blender's glTF importer needs numpy < 1.24 on PYTHONPATH (Blender 3.4 with the system python3.11).
Cycles' point light of power ``P`` watts has radiant intensity ``P / (4 pi)`` W/sr: the power is set to ``4 pi I``
(checked by the metal sphere, which agrees with polyjax to 64 dB).
"""

import math
import os
import sys

import bpy

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _polyjax_cycles import render_to, set_up_cycles  # noqa: E402

args = sys.argv[sys.argv.index("--") + 1:]
src, out = args[0], args[1]
size, samples = int(args[2]), int(args[3])
light_pos = tuple(float(x) for x in args[4:7])
intensity, fov = float(args[7]), float(args[8])

bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=src)
scene = bpy.context.scene
cam_data = bpy.data.cameras.new("camera")
cam_data.sensor_fit = "VERTICAL"
cam_data.angle = math.radians(fov)
cam = bpy.data.objects.new("camera", cam_data)
cam.location = (0.0, 0.0, 5.0)  # Blender's camera looks along its -z with +y up: polyjax's frame
cam.rotation_euler = (0.0, 0.0, 0.0)
scene.collection.objects.link(cam)
scene.camera = cam
light_data = bpy.data.lights.new("light", type="POINT")
light_data.energy = 4.0 * math.pi * intensity
light_data.shadow_soft_size = 0.0
light = bpy.data.objects.new("light", light_data)
light.location = light_pos
scene.collection.objects.link(light)
set_up_cycles(scene, samples, size, size)
render_to(scene, out, size, size)

