"""Fits from images: the rows of a fit from rendered or photographed images (:func:`image_rows`), the closed-form
polynomial fit from them (:func:`fit_polynomial_to_images`), and photographs of an object under several lights
(:class:`Capture`, :func:`relight`), their normals and spatially varying BRDF from the photographs alone
(:func:`fit_capture`, :class:`CaptureFit`). Built on :mod:`polyjax.render`, which it imports; loaded on first use,
like it (``polyjax.fit_polynomial_to_images`` and the other names are offered at the top level too)."""

from ._capture import Capture
from ._capture_fit import CaptureFit, fit_capture, relight
from ._fit import fit_polynomial_to_images
from ._rows import ImageRows, image_rows

__all__ = ["Capture", "CaptureFit", "ImageRows", "fit_capture", "fit_polynomial_to_images", "image_rows", "relight"]
