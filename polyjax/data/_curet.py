"""CUReT BRDF measurements (Dana, van Ginneken, Nayar, Koenderink 1999).

Files below the data root (format in ``curet/SOURCE.md`` of the data folder):

- ``curet/abrdf.dat``: 61 lines ``sample meas_1 .. meas_205``, BRDF in 1/sr averaged over RGB;
- ``curet/table.txt``: 205 lines ``index theta_v phi_v theta_i phi_i`` (radians), ``i`` = light
  = the BRDF's incoming ``u``, ``v`` = camera = outgoing ``v``;
- ``curet/sample_labels.txt``: ``number<TAB>name``.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Iterable

import numpy as np

from .._config import data_file
from .._errors import DataFormatError, UnknownNameError
from .._measurements import Measurements, make_measurements
from .._reading.bounded import read_text

N_GEOMETRIES = 205

#: The five samples of the paper's Table 2 and Fig. 3 (number -> name).
TABLE2_SAMPLES: dict[int, str] = {1: "Felt", 55: "Orange Peel", 25: "Quarry Tile", 33: "Slate_a", 34: "Slate_b"}

#: Zoomed duplicates left out of the isotropic set.
ZOOMED_DUPLICATES = (29, 30, 31, 32)
#: Visibly anisotropic samples left out of the isotropic set.
ANISOTROPIC_SAMPLES = (38, 40, 42, 51, 57)
#: The 52 isotropic samples of Figs. 6-7 and Table 4 (all 61 minus the nine above).
ISOTROPIC_52: tuple[int, ...] = tuple(
    s for s in range(1, 62) if s not in ZOOMED_DUPLICATES and s not in ANISOTROPIC_SAMPLES
)


def _read_numbers(path: Path, n_cols: int, what: str) -> np.ndarray:
    text = read_text(path, None, f"a text file of {what}")
    rows = [ln.split() for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if not rows:
        raise DataFormatError(path, f"{what}", "an empty file")
    for i, r in enumerate(rows):
        if len(r) != n_cols:
            raise DataFormatError(path, f"{n_cols} numbers per line ({what})", f"{len(r)} on line {i + 1}")
    try:
        arr = np.array(rows, dtype=np.float64)
    except ValueError as e:
        raise DataFormatError(path, f"numbers ({what})", f"text that is not a number ({e})") from None
    if not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise DataFormatError(path, "finite numbers", f"{arr[tuple(bad)]} on line {bad[0] + 1}")
    return arr


def read_curet_geometry(root: str | os.PathLike | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The 205 (light, view) direction pairs as unit vectors ``(u, v)``, each ``(205, 3)``."""
    path = data_file("curet/table.txt", root)
    t = _read_numbers(path, 5, "index theta_v phi_v theta_i phi_i")
    if t.shape[0] != N_GEOMETRIES:
        raise DataFormatError(path, f"{N_GEOMETRIES} geometry rows", f"{t.shape[0]}")
    order = np.argsort(t[:, 0])
    t = t[order]

    def d(th, ph):
        return np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)

    return d(t[:, 3], t[:, 4]), d(t[:, 1], t[:, 2])


def curet_sample_names(root: str | os.PathLike | None = None) -> dict[int, str]:
    """Sample number -> material name, from ``curet/sample_labels.txt``."""
    path = data_file("curet/sample_labels.txt", root)
    names = {}
    for line in read_text(path, None, "a text file of 'number<TAB>name' lines").splitlines():
        if not line.strip() or line.startswith("#"):
            continue
        parts = line.split("\t") if "\t" in line else line.split(None, 1)
        if len(parts) != 2 or not (parts[0].strip().isascii() and parts[0].strip().isdigit()):
            raise DataFormatError(path, "'number<TAB>name' lines", repr(line[:80]))
        names[int(parts[0])] = parts[1].strip()
    return names


def resolve_curet_sample(key: int | str, names: dict[int, str]) -> int:
    """A sample number from a number or a (case-insensitive) name such as ``"quarry tile"``."""
    if isinstance(key, (int, np.integer)) or (isinstance(key, str) and key.strip().isdigit()):
        k = int(key)
        if k not in names:
            raise UnknownNameError(f"CUReT sample {k}: expected a number from 1 to 61")
        return k
    norm = str(key).strip().lower().replace("-", " ").replace("_", " ")
    for k, n in names.items():
        if n.lower().replace("-", " ").replace("_", " ") == norm:
            return k
    raise UnknownNameError(f"CUReT sample {key!r}: not a sample number or name; names are {sorted(names.values())}")


def load_curet(
    root: str | os.PathLike | None = None,
    samples: Iterable[int | str] | int | str | None = None,
) -> Measurements:
    """Load CUReT BRDF measurements.

    Args:
        root: data root (default: ``$POLYJAX_DATA``).
        samples: sample numbers or names (e.g. ``25`` or ``"Quarry Tile"``), a single one, or None
            for all 61. Use :data:`ISOTROPIC_52` or :data:`TABLE2_SAMPLES` for the paper's sets.

    Returns:
        :class:`Measurements` with ``u, v`` ``(205, 3)``, ``values`` ``(n_samples, 205)`` (RGB average, 1/sr),
        weights 1, axes ``("material",)``. The 29 slightly negative values (and 14 zeros) are kept.
    """
    u, v = read_curet_geometry(root)
    names = curet_sample_names(root)
    path = data_file("curet/abrdf.dat", root)
    a = _read_numbers(path, N_GEOMETRIES + 1, "sample_number and 205 measurements")
    rows = {int(r[0]): r[1:] for r in a}
    if samples is None:
        wanted = sorted(rows)
    else:
        if isinstance(samples, (int, str, np.integer)):
            samples = [samples]
        wanted = [resolve_curet_sample(s, names) for s in samples]
    missing = [s for s in wanted if s not in rows]
    if missing:
        raise DataFormatError(path, f"rows for samples {missing}", "no such rows")
    values = np.stack([rows[s] for s in wanted])
    return make_measurements(
        u, v, values, names=[names.get(s, str(s)) for s in wanted], ids=wanted, channels=("avg",),
        axes=("material",), source="CUReT abrdf.dat (RGB average), 205 geometries",
    )
