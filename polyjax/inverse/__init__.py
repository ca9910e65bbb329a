"""Fits from images: the rows of a fit from rendered or photographed images (:func:`image_rows`), the closed-form
polynomial fit from them (:func:`fit_polynomial_to_images`), and photographs of an object under several lights
(:class:`Capture`, :func:`relight`). Built on :mod:`polyjax.render`, which it imports; loaded on first use, like it
(``polyjax.fit_polynomial_to_images`` and the other names are offered at the top level too)."""

from ._capture import Capture, relight
from ._fit import fit_polynomial_to_images
from ._rows import ImageRows, image_rows

__all__ = ["Capture", "ImageRows", "fit_polynomial_to_images", "image_rows", "relight"]
