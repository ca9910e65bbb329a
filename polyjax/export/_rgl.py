"""RGL-EPFL measured BSDFs to MERL ``.binary``: the converter behind ``polyjax export <file.bsdf> --to merl``.

Every bin of the 90 x 90 x 180 MERL grid gets the measured BRDF at its bin centre, evaluated as
:func:`polyjax.data.load_rgl` evaluates it (the authors' reference evaluation; the same numbers, so reading the
file back with :func:`polyjax.data.load_merl_binary` returns them to float64 rounding). Bins that ``load_rgl``
masks (a direction at or within float32's resolution of the horizon) are written as -1, MERL's "missing". The
file holds RGB: a spectral file is refused (convert its spectra to RGB first).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .._errors import InputError
from .._files import check_output_path
from ..data._merl import MERL_N_BINS, MERL_RESOLUTION, _above_index, write_merl_binary
from ..data._rgl import load_rgl


def is_rgl_source(model: str) -> bool:
    """True for an ``rgl:<file or name>`` spec or a ``.bsdf`` file name (an RGL-EPFL file, not a saved model)."""
    s = str(model)
    return s.lower().startswith("rgl:") or s.lower().endswith(".bsdf")


def rgl_to_merl(source: str | os.PathLike, path: str | os.PathLike, *, root=None) -> Path:
    """Write the RGL-EPFL file ``source`` (a path, a name in ``<root>/rgl_epfl/`` or ``rgl:<either>``) as a MERL
    ``.binary`` file at ``path`` (module docstring).

    Returns:
        The path written.

    Raises:
        DataNotFoundError, DataFormatError: as :func:`polyjax.data.load_rgl`. InputError: a spectral file.
    """
    path = check_output_path(path, "path")
    s = str(source)
    name = s[4:] if s.lower().startswith("rgl:") else s
    m = load_rgl(name, root=root)
    if m.channels != ("R", "G", "B"):
        raise InputError(f"{name}: expected an RGB file for MERL's three channels, found {len(m.channels)} "
                         f"spectral channels ({m.channels[0]}..{m.channels[-1]})")
    values = np.full((3, MERL_N_BINS), -1.0)
    keep = np.asarray(m.mask)
    values[:, _above_index(MERL_RESOLUTION)[keep]] = np.asarray(m.values, np.float64)[:, keep]
    return write_merl_binary(path, values, mask=values >= 0.0)


__all__ = ["is_rgl_source", "rgl_to_merl"]
