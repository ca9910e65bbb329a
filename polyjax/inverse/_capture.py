r"""A photometric capture: photographs of one object under calibrated directional lights, its mask and normals.

Image ``l`` of a :class:`Capture` is modelled as the render of a scene (:attr:`Capture.scenes`): the measured normal
map (:class:`polyjax.render.NormalMap`) seen by an orthographic camera looking along ``-z`` (view direction
``(0, 0, 1)`` at every pixel, the frame of the normals and lights), lit by one directional light of direction
``d_l`` and irradiance ``E_l`` (the light's RGB intensity), direct lighting only:

.. math:: I_{l,c}(x) = E_{l,c}\, \max(0, n(x) \cdot d_l)\, f_c(u, v),

``u``, ``v`` the light and view in the local frame of ``n(x)``. The scenes are what
:func:`polyjax.fit_polynomial_to_images`, ``baselines.fit_to_images`` and :func:`polyjax.render.render` take, and
:func:`relight` renders a fitted model under the capture's lights in the images' own units.
"""

from __future__ import annotations

from typing import Sequence

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from .._errors import InputError
from ..render import Camera, DirectionalLight, Lambertian, NormalMap, Scene, render, rgb_brdf
from ..render._integrator import _replaced


class Capture(eqx.Module):
    """Photographs of one object under ``L`` directional lights (:func:`polyjax.data.load_photometric`).

    Attributes:
        images: ``(L, H, W, 3)`` linear camera values (a 16-bit PNG's value / 65535: 1.0 is saturation).
        mask: ``(H, W)`` True on the object.
        normals: ``(H, W, 3)`` unit normals in the camera frame (view ``(0, 0, 1)``), or None when the capture
            has none (then :func:`polyjax.fit_capture` estimates them; :attr:`scenes` needs them).
        light_directions: ``(L, 3)`` unit directions towards the lights, camera frame.
        light_intensities: ``(L, 3)`` RGB intensity of each light (the irradiance of its scene).
        names: the ``L`` image names.
        saturation: the camera value at which a pixel is clipped (1.0 for 16-bit PNGs).
        quantisation: the step between two camera values (``1 / 65535`` for 16-bit PNGs, ``1 / 255`` for 8-bit
            ones; 0 when unknown): the noise floor of the images.
    """

    images: Float[Array, "l h w 3"]
    mask: Bool[Array, "h w"]
    normals: Float[Array, "h w 3"] | None
    light_directions: Float[Array, "l 3"]
    light_intensities: Float[Array, "l 3"]
    names: tuple = eqx.field(static=True)
    saturation: float = eqx.field(static=True, default=1.0)
    quantisation: float = eqx.field(static=True, default=0.0)

    def __check_init__(self):
        n_l = len(self.names)
        shapes = {"images": (n_l,) + tuple(np.shape(self.mask)) + (3,), "normals": tuple(np.shape(self.mask)) + (3,),
                  "light_directions": (n_l, 3), "light_intensities": (n_l, 3)}
        for field, shape in shapes.items():
            if getattr(self, field) is None and field == "normals":
                continue
            if tuple(np.shape(getattr(self, field))) != shape:
                raise InputError(f"{field}: expected shape {shape} ({n_l} lights, mask {np.shape(self.mask)}), "
                                 f"found {tuple(np.shape(getattr(self, field)))}")

    @property
    def n_lights(self) -> int:
        return len(self.names)

    @property
    def scenes(self) -> tuple:
        """One :class:`polyjax.render.Scene` per light (module notes): the normal map (a placeholder BRDF) seen by
        an orthographic camera along ``-z``, lit by that light alone."""
        if self.normals is None:
            raise InputError("capture.normals: expected normals to make the capture's scenes, found None (fit them "
                             "with polyjax.fit_capture, then relight that fit)")
        h, w = np.shape(self.mask)
        camera = Camera(eye=(0.0, 0.0, 2.0), target=(0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0), width=w, height=h,
                        ortho_height=2.0)
        surface = NormalMap(Lambertian(1.0), self.normals, self.mask)
        return tuple(Scene(camera, [surface], [DirectionalLight(d, e)])
                     for d, e in zip(self.light_directions, self.light_intensities))

    def select(self, lights: Sequence[int]) -> "Capture":
        """The capture under the lights ``lights`` (indices into this capture's lights) only."""
        idx = np.asarray(lights, dtype=int).reshape(-1)
        if idx.size == 0 or np.any((idx < 0) | (idx >= self.n_lights)):
            raise InputError(f"lights: expected indices in [0, {self.n_lights}), found {np.asarray(lights).tolist()}")
        return Capture(self.images[idx], self.mask, self.normals, self.light_directions[idx],
                       self.light_intensities[idx], tuple(self.names[i] for i in idx), self.saturation,
                       self.quantisation)

    def cropped(self, margin: int = 2) -> "Capture":
        """The capture cropped to the mask's bounding box plus ``margin`` pixels (the same fits, fewer pixels to
        trace); its images are no longer the camera's full frame."""
        mask = np.asarray(self.mask)
        if not mask.any():
            raise InputError("mask: expected at least one object pixel to crop to")
        ys, xs = np.nonzero(mask)
        h, w = mask.shape
        r = slice(max(ys.min() - margin, 0), min(ys.max() + margin + 1, h))
        c = slice(max(xs.min() - margin, 0), min(xs.max() + margin + 1, w))
        normals = None if self.normals is None else self.normals[r, c]
        return Capture(self.images[:, r, c], self.mask[r, c], normals, self.light_directions,
                       self.light_intensities, self.names, self.saturation, self.quantisation)

    def strided(self, step: int) -> "Capture":
        """Every ``step``-th pixel in each direction (a smaller capture of the same object, for fast fits)."""
        if int(step) != step or int(step) < 1:
            raise InputError(f"step: expected a positive integer, found {step!r}")
        s = int(step)
        normals = None if self.normals is None else self.normals[::s, ::s]
        return Capture(self.images[:, ::s, ::s], self.mask[::s, ::s], normals, self.light_directions,
                       self.light_intensities, self.names, self.saturation, self.quantisation)


def relight(model, capture: Capture, *, dtype=None) -> Float[Array, "l h w 3"]:
    """The images ``(L, H, W, 3)`` that ``model`` predicts under the lights of ``capture``, in its units.

    Each is :func:`polyjax.render.render` of the capture's scene with ``model`` on the normal map (module notes:
    ``E_l max(0, n . d_l) f(u, v)``, 0 off the mask); differentiable with respect to the model's arrays.

    Args:
        model: a fitted model of batch shape ``()``, ``(1,)`` or ``(3,)`` (:func:`polyjax.render.rgb_brdf`), or
            any BRDF callable.
        capture: the :class:`Capture` whose lights and normals are used (its images are not).
        dtype: the render's floating-point type (default: the default float, float64 under x64).
    """
    if not isinstance(capture, Capture):
        raise InputError(f"capture: expected a polyjax.Capture, found {type(capture).__name__}")
    brdf = rgb_brdf(model)
    dtype = jnp.result_type(float) if dtype is None else dtype
    out = []
    for scene in capture.scenes:
        surface = scene.objects[0]
        assert isinstance(surface, NormalMap)
        lit = _replaced(scene, objects=(_replaced(surface, brdf=brdf),))
        out.append(render(lit, dtype=dtype).image)
    return jnp.stack(out)


__all__ = ["Capture", "relight"]
