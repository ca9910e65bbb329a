"""What both Blender scripts set alike: a black world, Cycles on the CPU with direct light only, a box pixel filter
0.01 pixel wide (samples at the pixel centres, as polyjax), no denoising, no adaptive sampling, the Standard view
transform (linear values out), 32-bit OpenEXR RGB; and the read-back of a rendered image as a ``.npy`` beside it
(row 0 at the top). Named apart from Cycles' own ``_cycles`` module, which Blender has already imported."""

import bpy
import numpy as np


def set_up_cycles(scene, samples: int, width: int, height: int) -> None:
    """Black world and the render settings above on ``scene``, at ``width`` x ``height`` pixels."""
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
    scene.cycles.filter_width = 0.01
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.resolution_percentage = 100
    scene.render.film_transparent = False
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    scene.render.image_settings.color_mode = "RGB"


def render_to(scene, out: str, width: int, height: int) -> None:
    """Render ``scene`` to the OpenEXR file ``out`` and save its linear RGB as ``out + ".npy"``."""
    scene.render.filepath = out
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(out)
    px = np.asarray(img.pixels[:], dtype=np.float64).reshape(height, width, -1)[::-1, :, :3]
    np.save(out + ".npy", px)
    bpy.data.images.remove(img)
    print("polyjax-blender: wrote", out)
