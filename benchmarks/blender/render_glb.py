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
import sys

import bpy
import numpy as np

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
world = bpy.data.worlds.new("black")
world.color = (0.0, 0.0, 0.0)
scene.world = world
scene.render.engine = "CYCLES"
scene.cycles.device = "CPU"
scene.cycles.samples = samples
scene.cycles.use_denoising = False
scene.cycles.use_adaptive_sampling = False
scene.cycles.max_bounces = 0
scene.cycles.pixel_filter_type = "BOX"
scene.cycles.filter_width = 0.01  # samples at the pixel centres, as polyjax
scene.view_settings.view_transform = "Standard"
scene.view_settings.look = "None"
scene.render.resolution_x = scene.render.resolution_y = size
scene.render.resolution_percentage = 100
scene.render.image_settings.file_format = "OPEN_EXR"
scene.render.image_settings.color_depth = "32"
scene.render.image_settings.color_mode = "RGB"
scene.render.filepath = out
bpy.ops.render.render(write_still=True)
img = bpy.data.images.load(out)
px = np.asarray(img.pixels[:], dtype=np.float64).reshape(size, size, -1)[::-1, :, :3]
np.save(out + ".npy", px)
print("polyjax-blender: wrote", out)
