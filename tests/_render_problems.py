"""Shared scenes for the rendering tests."""

import numpy as np

import polyjax.render as pr

SIZE = 48
LIGHT_DIR = np.array([1.0, 1.0, 1.5]) / np.linalg.norm([1.0, 1.0, 1.5])


def ortho_camera(size=SIZE):
    return pr.Camera(eye=(0.0, 0.0, 5.0), width=size, height=size, ortho_height=2.1)


def lone_sphere(brdf, lights=None, size=SIZE, **kw):
    lights = [pr.DirectionalLight(direction=LIGHT_DIR, irradiance=np.pi)] if lights is None else lights
    return pr.Scene(ortho_camera(size), [pr.Sphere(brdf)], lights, **kw)


def sphere_on_plane(brdf, lights=None, size=SIZE, **kw):
    cam = pr.Camera(eye=(0.0, 1.5, 6.0), target=(0.0, -0.3, 0.0), width=size, height=size)
    lights = [pr.PointLight(position=(2.0, 4.0, 2.0), intensity=30.0)] if lights is None else lights
    return pr.Scene(cam, [pr.Sphere(brdf), pr.Plane(pr.Lambertian(0.5), height=-1.0)], lights, **kw)


def sphere_normals(size=SIZE, height=2.1):
    """Analytic normals of the unit sphere seen by :func:`ortho_camera` (pixel centres) and the hit mask."""
    half = height / 2
    c = ((np.arange(size) + 0.5) / size * 2 - 1) * half
    x, y = np.meshgrid(c, -c)
    r2 = x**2 + y**2
    hit = r2 < 1.0
    z = np.sqrt(np.clip(1 - r2, 0.0, None))
    return np.stack([x, y, z], -1), hit
