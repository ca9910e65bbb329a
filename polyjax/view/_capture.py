r"""A photometric capture on the page (:class:`polyjax.Capture`, e.g. a DiLiGenT folder loaded by
:func:`polyjax.data.load_photometric`): its measurements as data, and its photographs beside a fit relit under the
same lights.

The capture is cropped to its mask (:meth:`polyjax.Capture.cropped`) and, when larger than
:data:`MAX_PHOTO_SIZE` pixels on a side, strided (:meth:`polyjax.Capture.strided`). It becomes one ``"points"``
item whose samples are the BRDF samples the fits from images use (:mod:`polyjax._image_samples`): for every kept
pixel of every photograph (on the mask, no channel at or above the capture's saturation, lit: ``E cos > 0``;
:func:`polyjax.image_rows` without a cutoff)

.. math:: b = I / (E \max(0, n \cdot d)), \quad u, v \text{ the light and view in the pixel's frame},

a seeded subsample of at most :data:`MAX_SAMPLES` of them. The item also carries the photographs (the masked
pixels, float32), the normals and the lights (:func:`capture_json`), from which the page relights the other item
exactly as :func:`polyjax.relight` does: ``E max(0, n . d) max(f(u, v), 0)`` with the normal map's frame
(tangent ``(0, 1, 0) x n`` normalised, ``+x`` where ``n`` is along ``+-y``; view ``(0, 0, 1)``).
"""

from __future__ import annotations

import base64

import numpy as np

import polyjax as pj

from .._errors import InputError
from ..inverse._capture import Capture
from ._items import ViewItem

#: the longest side, in pixels, of the photographs on the page (larger ones are strided)
MAX_PHOTO_SIZE = 128
#: at most this many BRDF samples are plotted (a seeded subsample beyond)
MAX_SAMPLES = 16384


def shown_capture(capture: Capture, max_size: int = MAX_PHOTO_SIZE) -> tuple[Capture, int]:
    """``(capture cropped to its mask and strided to at most max_size pixels a side, the stride)``."""
    if int(max_size) < 1:
        raise InputError(f"max_size: expected a positive number of pixels, found {max_size}")
    cropped = capture.cropped()
    step = max(1, -(-max(np.shape(cropped.mask)) // int(max_size)))
    return (cropped.strided(step) if step > 1 else cropped), step


def capture_samples(capture: Capture) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The BRDF samples ``(u (n, 3), v (n, 3), b (n, 3))`` of the capture's kept pixels (module notes)."""
    rows = pj.image_rows(capture.scenes, capture.images, saturation=capture.saturation, cutoff_deg=None)
    c = np.asarray(rows.weight)[:, 0]
    lit = np.all(c > 0, axis=-1)
    values = np.asarray(rows.values)[lit] / c[lit]
    return np.asarray(rows.u)[lit, 0], np.asarray(rows.v)[lit], values


def capture_items(capture: Capture, name: str, *, source: str = "", max_size: int = MAX_PHOTO_SIZE,
                  max_samples: int = MAX_SAMPLES, seed: int = 0) -> list[ViewItem]:
    """The item of a capture: its BRDF samples as points, its photographs, normals and lights (module notes).

    Args:
        capture: the :class:`polyjax.Capture`.
        name: the item's label.
        source: where it came from (shown among its numbers).
        max_size: the longest side of the photographs shown (:func:`shown_capture`).
        max_samples: at most this many samples plotted (seeded subsample).
        seed: seed of that subsample.
    """
    if not isinstance(capture, Capture):
        raise InputError(f"{name}: expected a polyjax.Capture, found {type(capture).__name__}")
    if int(max_samples) < 1:
        raise InputError(f"max_samples: expected a positive count, found {max_samples}")
    shown, step = shown_capture(capture, max_size)
    u, v, b = capture_samples(shown)
    n = u.shape[0]
    if n == 0:
        raise InputError(f"{name}: no pixel of the capture is on the mask, lit and unsaturated")
    pick = np.arange(n) if n <= max_samples else np.sort(np.random.default_rng(seed).choice(n, max_samples,
                                                                                                replace=False))
    h, w = np.shape(shown.mask)
    info = {"model": "photometric capture (photographs under calibrated lights)", "source": source,
            "lights": shown.n_lights,
            "photographs": f"{w} x {h} pixels (cropped to the mask" + (f"; one pixel in {step} along each axis)"
                                                                     if step > 1 else ")"),
            "samples": f"{pick.size} of the {n} BRDF samples I / (E cos) of the pixels shown"
                       + (f" (seeded subsample, seed {seed})" if pick.size < n else ""),
            "shown as": "points: the BRDF samples; the photographs beside the other item relit under their lights"}
    return [ViewItem(name, "points", info, u=u[pick].astype(np.float32), v=v[pick].astype(np.float32),
                     values=b[pick].astype(np.float32), model=shown, capture=shown)]


def _b64(a, dtype) -> str:
    return base64.b64encode(np.ascontiguousarray(a, dtype=dtype).tobytes()).decode("ascii")


def capture_json(capture: Capture) -> dict:
    """The page's data of a capture: size, light names, unit light directions, irradiances, saturation, and as
    base64 the row-major indices of the mask's pixels (int32), their normals (float32 ``(P, 3)``) and the
    photographs at them (float32 ``(L, P, 3)``)."""
    mask = np.asarray(capture.mask)
    h, w = mask.shape
    index = np.flatnonzero(mask.ravel())
    d = np.asarray(capture.light_directions, np.float64)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)  # as polyjax.render.DirectionalLight
    images = np.asarray(capture.images, np.float64).reshape(capture.n_lights, h * w, 3)[:, index]
    return {"width": int(w), "height": int(h), "names": list(capture.names), "saturation": float(capture.saturation),
            "light_directions": d.tolist(), "light_intensities": np.asarray(capture.light_intensities).tolist(),
            "pixels": int(index.size), "index": _b64(index, np.int32),
            "normals": _b64(np.asarray(capture.normals).reshape(-1, 3)[index], np.float32),
            "images": _b64(images, np.float32)}
