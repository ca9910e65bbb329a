"""``polyjax view``: one self-contained interactive HTML page of fits and measured data (WebGL2).

Every fit or data set becomes a :class:`ViewItem`: a GLSL function printed by the expression builder of the GLSL
export (polynomial and neural models), a MERL-grid table shown through a 3D texture (dense measured data, and
models the expression builder does not cover, e.g. baseline fits, tabulated at the bin centres; RGL-EPFL files
evaluated at the bin centres), or scattered points (CUReT, Cornell, a photometric capture's BRDF samples, with
its photographs beside the fit relit under their lights). The page shows a lit sphere (point light moved by
dragging or the arrow keys, exposure), the lobe in the plane of incidence, the ``(theta_h, theta_d)`` slice and
the albedo against view elevation, two items side by side with their error image, and the numbers of each fit
(its fit time when the model file keeps it). ``docs/viewer.md``.

Typical use::

    pj.view.write_page([model, "curet:25"], "page.html")
    pj.view.serve_page("page.html")                    # http://127.0.0.1:<port>/ only
"""

from ._capture import MAX_PHOTO_SIZE, MAX_SAMPLES, capture_items
from ._environment import environment_map
from ._items import (
    DENSE_FRACTION,
    MERL_RESOLUTION,
    ViewItem,
    data_items,
    fit_time,
    model_items,
)
from ._page import ViewSettings, page_html, write_page
from ._rgl import rgl_items
from ._serve import open_server, serve_page
from ._sources import as_items, items_from_argument

__all__ = ["DENSE_FRACTION", "MAX_PHOTO_SIZE", "MAX_SAMPLES", "MERL_RESOLUTION", "ViewItem", "ViewSettings", "as_items",
           "capture_items", "data_items", "environment_map", "fit_time", "items_from_argument", "model_items",
           "open_server", "page_html", "rgl_items", "serve_page", "write_page"]
