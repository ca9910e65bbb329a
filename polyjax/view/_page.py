r"""One self-contained HTML page: the template ``page.html`` with the scripts ``photos.js`` (a capture's
photographs) and ``viewer.js``, the items' GLSL (:mod:`polyjax.view._glsl`) and their data (JSON; tables as base64
float16, points, photographs and normals as base64 float32) inlined. Nothing is fetched: no network, no CDN, no
other file.

The page's sphere is :func:`polyjax.render.render`'s scene ``Scene(Camera(eye, target, up, fov_deg, size, size),
[Sphere(brdf)], [PointLight(position, intensity)])`` with background 0, shaded per pixel centre exactly as the
renderer does (the same ray, sphere frame and ``f(u, v) I cos / r^2``; ``docs/conventions.md``), then
``to_srgb(image, exposure)`` (``2^exposure L`` clipped to ``[0, 1]``, the sRGB transfer function) and 8 bits.
"""

from __future__ import annotations

import base64
import dataclasses
import html
import json
import os
import re
from importlib import resources
from pathlib import Path

import numpy as np

from .._config import check_output_file
from .._errors import InputError
from .._files import write_bytes_atomically
from ._capture import capture_json
from ._environment import environment_json
from ._glsl import brdf_functions
from ._items import MERL_RESOLUTION, ViewItem
from ._sources import as_items


@dataclasses.dataclass(frozen=True)
class ViewSettings:
    """The page's initial camera, light and canvas size (the renderer's :class:`polyjax.render.Camera` and
    :class:`polyjax.render.PointLight` defaults).

    Attributes:
        size: canvas width and height in pixels.
        eye, target, up, fov_deg: the perspective camera (vertical field of view in degrees).
        light: the point light's position (world, ``+y`` up); dragging moves it on the sphere of its radius.
        intensity: its radiant intensity (W/sr), grey.
        exposure: ``2^exposure`` before sRGB encoding.
        title: the page title.
        text: optional preformatted text shown under the views (e.g. a report).
        environment: optional environment map lighting the sphere besides the light: an
            ``polyjax.render.EnvironmentLight``, an ``(H, W, 3)`` latitude-longitude map, ``"sky"`` or an OpenEXR
            path (:func:`polyjax.view._environment.environment_map`: averaged down to 16 x 32 texels).
    """

    size: int = 256
    eye: tuple = (0.0, 0.0, 4.0)
    target: tuple = (0.0, 0.0, 0.0)
    up: tuple = (0.0, 1.0, 0.0)
    fov_deg: float = 30.0
    light: tuple = (2.0, 2.0, 4.0)
    intensity: float = 24.0
    exposure: float = 0.0
    title: str = "polyjax view"
    text: str = ""
    environment: object = None


def _check_settings(s: ViewSettings) -> None:
    if not 8 <= int(s.size) <= 4096:
        raise InputError(f"size: expected a canvas size in [8, 4096] pixels, found {s.size}")
    if not 0.0 < float(s.fov_deg) < 180.0:
        raise InputError(f"fov_deg: expected a field of view in (0, 180) degrees, found {s.fov_deg}")
    for name in ("eye", "target", "up", "light"):  # tuples of floats (JSON)
        a = np.asarray(getattr(s, name), float)
        if a.shape != (3,) or not np.all(np.isfinite(a)):
            raise InputError(f"{name}: expected a finite 3-vector, found {getattr(s, name)!r}")
    if np.linalg.norm(np.asarray(s.eye, float)) <= 1.0 or np.linalg.norm(np.asarray(s.light, float)) <= 1.0:
        raise InputError("eye, light: expected positions outside the unit sphere")


def _b64(a: np.ndarray, dtype) -> str:
    return base64.b64encode(np.ascontiguousarray(a, dtype=dtype).tobytes()).decode("ascii")


def _item_json(i: int, item: ViewItem) -> dict:
    out = {"index": i, "name": item.name, "kind": item.kind, "info": item.info}
    if item.kind == "table":
        table = np.nan_to_num(np.asarray(item.table, np.float64), nan=0.0, posinf=0.0, neginf=0.0)
        out["resolution"] = list(item.table.shape[:3])
        out["table"] = _b64(np.clip(table, 0.0, 65000.0), np.float16)  # RGB16F texels, MERL file order
    elif item.kind == "points":
        out["n"] = int(item.u.shape[0])
        out["u"], out["v"], out["values"] = (_b64(a, np.float32) for a in (item.u, item.v, item.values))
    if item.capture is not None:
        out["capture"] = capture_json(item.capture)
    if "fit time" in item.info:  # a model's item
        out["fit_seconds"] = item.fit_seconds
    return out


def _template(name: str) -> str:
    return resources.files(__package__).joinpath(name).read_text(encoding="utf-8")


def page_html(items: list[ViewItem], settings: ViewSettings = ViewSettings()) -> str:
    """The page's HTML text for ``items`` (:class:`polyjax.view.ViewItem`) and ``settings``."""
    _check_settings(settings)
    data = {"settings": {f.name: getattr(settings, f.name) for f in dataclasses.fields(settings)
                         if f.name not in ("text", "environment")},
            "environment": environment_json(settings.environment),
            "items": [_item_json(i, it) for i, it in enumerate(items)]}
    parts = {
        "TITLE": html.escape(settings.title),
        "TEXT": html.escape(settings.text),
        "DATA": json.dumps(data, allow_nan=False).replace("<", "\\u003c"),
        "GLSL": brdf_functions(items),
        "SCRIPT": _template("photos.js") + _template("viewer.js"),
    }
    return re.sub(r"__POLYJAX_([A-Z]+)__", lambda m: parts[m.group(1)], _template("page.html"))


def write_page(objects, path: str | os.PathLike, *, settings: ViewSettings = ViewSettings(),
               resolution=MERL_RESOLUTION, root=None, lights=None) -> Path:
    """Write the page of ``objects`` (fits, data sets, captures, their file names, folders or specs:
    :func:`as_items`; ``lights``: the lights to load of capture folders, None for all) to ``path``.

    The text is built completely before the file is opened (no half-written page). Returns the path written.
    """
    path = check_output_file(path, "out")
    _check_settings(settings)  # before the items' work
    text = page_html(as_items(objects, resolution, root, lights), settings)
    return write_bytes_atomically(path, text.encode("utf-8"))
