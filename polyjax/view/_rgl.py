r"""An RGL-EPFL measured BSDF (``rgl:<file or name>``, :func:`polyjax.data.load_rgl`) on the page.

The file is a BRDF that evaluates anywhere, not a set of fixed samples: the page's table gets its values at the
centres of the table's own bins, ``pj.data.load("rgl:...", directions=...)`` at the directions of
:func:`polyjax.data.merl_grid` of the table's resolution (both above the horizon; 0 elsewhere), one sample per bin.
A coarse table is thus the BRDF at its bin centres, not an average of a finer grid's. The file is read at both
orders of each pair: a measured BSDF need not be reciprocal, and one that is not gets a table over the whole turn
of ``phi_d`` (:func:`polyjax.export._merl.whole_turn`).
"""

from __future__ import annotations

import numpy as np

import polyjax as pj

from .._errors import InputError
from ..export._merl import whole_turn
from ._items import MERL_RESOLUTION, ViewItem, _shown_as


def rgl_items(spec: str, root=None, resolution=MERL_RESOLUTION) -> list[ViewItem]:
    """The item of an ``rgl:`` spec: a table of the measured BSDF at the bin centres, bin ``i`` holding the value
    at direction pair ``i`` of :func:`polyjax.data.merl_grid` (not binned again: at ``theta_h = theta_d = 0``
    every ``phi_d`` bin has the same directions)."""
    resolution = tuple(int(n) for n in resolution)
    u, v, _, above = pj.data.merl_grid(resolution)
    a, b = u[above], v[above]
    n = len(a)
    # both orders of each pair in one read of the file, f(u, v) then f(v, u): it need not be reciprocal (whole_turn)
    data = pj.data.load(spec, root=root, directions=(np.concatenate([a, b]), np.concatenate([b, a])))
    if len(data.channels) != 3:
        raise InputError(f"{spec!r}: a spectral file ({len(data.channels)} wavelengths); the page shows RGB: use "
                         "the material's *_rgb.bsdf file")
    values = np.where(np.asarray(data.mask)[:, None], np.asarray(data.values).T, 0.0)
    tables = []
    for half in (slice(0, n), slice(n, 2 * n)):
        table = np.zeros((above.size, 3), np.float32)
        table[above] = values[half]
        tables.append(table.reshape(*resolution, 3))
    table, turn = whole_turn(*tables, axis=2)
    reciprocal = not turn
    info = {"model": "measured data", "source": data.source, "samples": int(np.asarray(data.mask)[:n].sum()),
            "channels": list(data.channels),
            "shown as": _shown_as(resolution, reciprocal, "the measured BSDF evaluated") + " above the horizon"}
    return [ViewItem(data.names[0], "table", info, table=table, model=data, reciprocal=reciprocal)]
