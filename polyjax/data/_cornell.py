r"""Cornell gonioreflectometer BRDFs: the pbrt-v2 spectral text format and the ASTM E1392 text format.

**pbrt-v2 format** (the files below the data root: ``cornell/cayman.brdf``, ``garnet_red.brdf``,
``acryl_blue.brdf``): ASCII, ``#`` starts a comment to end of line; the rest is a flat list of numbers:
``n_wl``, then ``n_wl`` wavelengths in nm, then records of ``4 + n_wl`` numbers
``theta_i phi_i theta_s phi_s v_1 .. v_n_wl`` (angles in radians, values BRDF in 1/sr).

**ASTM format** (Cornell's ``*.astm`` files, ASTM E1392): header lines of a keyword and values, of which
two are used: ``NUM_POINTS <n>`` (optional; checked against the number of data lines) and
``VARS <name>,<name>,...`` (required): the column names, the first four being the angles
``theta_i, phi_i, theta_s, phi_s`` and the rest either ``R,G,B`` (linear RGB), ``X,Y,Z``, one column
(a single channel), or wavelengths such as ``400nm,410nm,...`` (spectral). Other header lines
(``NAME``, ``SOURCE``, ...) are ignored. Every line after the ``VARS`` line that is not blank is a data
line of comma- (or whitespace-) separated numbers, one column per name. Angles are in radians unless
``angle_unit="degrees"``.

Directions: ``u`` = light = ``(theta_i, phi_i)``, ``v`` = view = ``(theta_s, phi_s)`` as stored, both
pointing away from the surface; the mirror direction of ``u`` is ``phi_s = phi_i + pi``.

Colour (spectral files): see :mod:`polyjax.data._colour`: CIE 1931 2-degree observer, equal-energy
illuminant, luminance = CIE Y with ``Y = 1`` for a flat spectrum of 1; RGB = linear sRGB primaries
white-balanced so a flat spectrum of 1 gives ``(1, 1, 1)``.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Sequence

import numpy as np

from .._config import data_file
from .._errors import DataNotFoundError, InputError
from .._measurements import Measurements, make_measurements
from .._reading.bounded import read_bytes
from ._colour import spectral_to_luminance, spectral_to_rgb, spectral_to_xyz, xyz_to_rgb_matrix
from ._errors import (
    EmptyFileError,
    HeaderError,
    NonFiniteValueError,
    TruncatedFileError,
    UnknownMaterialError,
    WrongFormatError,
)

#: Cornell materials below the data root (``cornell/<name>.brdf``).
CORNELL_NAMES: tuple[str, ...] = ("cayman", "garnet_red", "acryl_blue")
CHANNEL_CHOICES = ("rgb", "luminance", "xyz", "spectral")


def _read_text(path: Path, expected: str) -> str:
    if not path.is_file():
        raise DataNotFoundError(f"Cornell BRDF file {str(path)!r}: no such file")
    data = read_bytes(path, None, expected)
    if not data.strip():
        raise EmptyFileError(path, expected, "an empty file" if not data else "only whitespace")
    if b"\x00" in data[:4096]:
        raise WrongFormatError(path, expected, "binary content (NUL bytes)")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        try:
            return data.decode("latin-1")
        except UnicodeDecodeError:  # pragma: no cover - latin-1 decodes every byte
            raise WrongFormatError(path, expected, "binary content") from None


def _to_float(tok: str, path: Path, line: int, expected: str) -> float:
    try:
        return float(tok)
    except ValueError:
        raise WrongFormatError(path, expected, f"the text {tok[:40]!r} on line {line}") from None


def _check_finite(arr: np.ndarray, path: Path, what: str, rows=None) -> None:
    bad = ~np.isfinite(arr)
    if bad.any():
        r, c = np.argwhere(bad)[0]
        where = f"record {r + 1}" if rows is None else f"line {rows[r]}"
        raise NonFiniteValueError(path, f"finite {what}",
                                  f"{int(bad.sum())} NaN/inf values (first: {arr[r, c]} in {where}, column {c + 1})")


def _check_angles(ang: np.ndarray, path: Path) -> None:
    th = ang[:, [0, 2]]
    if np.any(th < -1e-6) or np.any(th > np.pi / 2 + 1e-3) or np.any(np.abs(ang[:, [1, 3]]) > 2 * np.pi + 1e-3):
        raise HeaderError(
            path, "angles in radians (theta in [0, pi/2], phi in [-2 pi, 2 pi])",
            f"theta in [{th.min():.4g}, {th.max():.4g}], "
            f"phi in [{ang[:, [1, 3]].min():.4g}, {ang[:, [1, 3]].max():.4g}]",
        )


def read_cornell_pbrt(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Parse a pbrt-v2 spectral BRDF file.

    Returns:
        ``(angles, wavelengths, spectra)``: ``(n, 4)`` radians ``theta_i phi_i theta_s phi_s``,
        ``(n_wl,)`` nm, ``(n, n_wl)`` BRDF in 1/sr.

    Raises:
        EmptyFileError, WrongFormatError, HeaderError, TruncatedFileError, NonFiniteValueError.
    """
    path = Path(path)
    expected = "a pbrt-v2 spectral BRDF text file (n_wl, wavelengths, records of 4 + n_wl numbers)"
    text = _read_text(path, expected)
    toks: list[str] = []
    for line in text.splitlines():
        toks.extend(line.split("#", 1)[0].split())
    if not toks:
        raise EmptyFileError(path, expected, "only comments")
    if toks[0].upper() in ("VARS", "NUM_POINTS", "NAME") or any(t.upper() == "VARS" for t in toks[:200]):
        raise WrongFormatError(path, expected, "an ASTM file (VARS/NUM_POINTS header); use format='astm'")
    try:
        nums = np.array([float(t) for t in toks])
    except ValueError:
        bad = next(t for t in toks if not _is_number(t))
        line = next(i + 1 for i, ln in enumerate(text.splitlines()) if bad in ln.split("#", 1)[0].split())
        raise WrongFormatError(path, expected, f"the text {bad[:40]!r} on line {line}") from None
    n_wl = nums[0]
    if not (np.isfinite(n_wl) and n_wl == int(n_wl) and 1 <= n_wl <= 10000):
        raise HeaderError(path, "a positive integer number of wavelengths first", f"{toks[0]!r}")
    n_wl = int(n_wl)
    if nums.size < 1 + n_wl:
        raise TruncatedFileError(path, f"{n_wl} wavelengths after the count", f"{nums.size - 1} numbers")
    wl = nums[1 : 1 + n_wl]
    if not np.all(np.isfinite(wl)) or np.any(np.diff(wl) <= 0) or wl[0] < 100 or wl[-1] > 100000:
        raise HeaderError(path, "increasing wavelengths in nm", f"{wl[: min(6, n_wl)]}...")
    rest = nums[1 + n_wl :]
    rec = 4 + n_wl
    if rest.size == 0:
        raise TruncatedFileError(path, f"records of {rec} numbers after the header", "no records")
    if rest.size % rec:
        raise TruncatedFileError(
            path, f"records of {rec} numbers",
            f"{rest.size} numbers = {rest.size // rec} records + {rest.size % rec} left over",
        )
    rows = rest.reshape(-1, rec)
    _check_finite(rows, path, "angles and BRDF values")
    _check_angles(rows[:, :4], path)
    return rows[:, :4].copy(), wl.copy(), rows[:, 4:].copy()


def _starts_with_number(line: str) -> bool:
    """Whether the first comma- or space-separated token of ``line`` is a number (False for a line of only
    separators, such as a lone comma)."""
    toks = line.replace(",", " ").split()
    return bool(toks) and _is_number(toks[0])


def _is_number(t: str) -> bool:
    try:
        float(t)
    except ValueError:
        return False
    return True


def read_cornell_astm(path: str | os.PathLike, *, angle_unit: str = "radians"
                      ) -> tuple[np.ndarray, list[str], np.ndarray]:
    """Parse an ASTM E1392 BRDF text file (format in the module docstring).

    Returns:
        ``(angles, names, values)``: ``(n, 4)`` radians, the value-column names (after the four angles),
        ``(n, k)`` values.
    """
    path = Path(path)
    expected = "an ASTM BRDF file (header with 'VARS theta_i,phi_i,theta_s,phi_s,...', then comma-separated rows)"
    if angle_unit not in ("radians", "degrees"):
        raise InputError(f"angle_unit: expected 'radians' or 'degrees', found {angle_unit!r}")
    text = _read_text(path, expected)
    lines = text.splitlines()
    names = None
    n_points = None
    data_rows, row_lines = [], []
    for no, line in enumerate(lines, 1):
        s = line.strip()
        if not s:
            continue
        if names is None:
            key, _, val = s.partition(" ")
            key = key.upper()
            if key == "NUM_POINTS":
                try:
                    n_points = int(val.strip())
                except ValueError:
                    raise HeaderError(path, "'NUM_POINTS <integer>'", repr(s)) from None
            elif key == "VARS" or s.upper().startswith("VARS,"):
                cols = [c.strip() for c in re.split(r"[,\s]+", s[4:].strip(" ,")) if c.strip()]
                if len(cols) < 5:
                    raise HeaderError(path, "VARS with 4 angle columns and at least one value column", repr(s))
                names = cols
            elif _starts_with_number(s):
                raise HeaderError(path, "a 'VARS ...' line naming the columns before the data",
                                  f"data on line {no} first")
            elif not s.replace(",", " ").split():
                raise HeaderError(path, "header lines of a keyword and its values (NAME, NUM_POINTS, VARS ...)",
                                  f"the line {s!r} (line {no})")
            continue
        toks = [t for t in re.split(r"[,\s]+", s) if t]
        if len(toks) != len(names):
            raise TruncatedFileError(path, f"{len(names)} columns per row ({', '.join(names)})",
                                     f"{len(toks)} on line {no}")
        data_rows.append([_to_float(t, path, no, expected) for t in toks])
        row_lines.append(no)
    if names is None:
        if not any(_starts_with_number(ln) for ln in lines):
            raise WrongFormatError(path, expected, "no VARS header and no numeric rows")
        raise HeaderError(path, "a 'VARS ...' header line", "none")
    if not data_rows:
        raise TruncatedFileError(path, "data rows after the header", "none")
    arr = np.array(data_rows)
    if n_points is not None and arr.shape[0] != n_points:
        cls = TruncatedFileError if arr.shape[0] < n_points else HeaderError
        raise cls(path, f"NUM_POINTS {n_points} data rows", f"{arr.shape[0]}")
    _check_finite(arr, path, "angles and values", row_lines)
    ang = arr[:, :4].copy()
    if angle_unit == "degrees":
        ang = np.deg2rad(ang)
    _check_angles(ang, path)
    return ang, names[4:], arr[:, 4:].copy()


def _directions(ang: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    def d(th, ph):
        return np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)

    return d(ang[:, 0], ang[:, 1]), d(ang[:, 2], ang[:, 3])


def _spectral_channels(spectra, wl, channels: str, path) -> tuple[np.ndarray, tuple[str, ...]]:
    if channels == "spectral":
        return spectra.T, tuple(f"{w:g}nm" for w in wl)
    try:
        if channels == "rgb":
            return spectral_to_rgb(spectra, wl).T, ("R", "G", "B")
        if channels == "xyz":
            return spectral_to_xyz(spectra, wl).T, ("X", "Y", "Z")
        return spectral_to_luminance(spectra, wl)[None], ("Y",)
    except InputError as e:
        raise HeaderError(path, "wavelengths within 400..700 nm for colour conversion", str(e)) from None


def _astm_channels(names, vals, channels: str, path) -> tuple[np.ndarray, tuple[str, ...]]:
    up = [n.upper() for n in names]
    wl = [re.fullmatch(r"([\d.]+)\s*NM", n) for n in up]
    if all(wl) and len(wl) > 1:
        return _spectral_channels(vals, np.array([float(m.group(1)) for m in wl]), channels, path)
    if channels == "spectral":
        raise HeaderError(path, "wavelength columns such as 400nm,410nm,... for channels='spectral'", ",".join(names))
    if up == ["R", "G", "B"]:
        rgb = vals
        if channels == "rgb":
            return rgb.T, ("R", "G", "B")
        # RGB -> XYZ with the same white balance as spectral data (equal-energy white at R = G = B)
        xyz = rgb @ np.linalg.inv(xyz_to_rgb_matrix()).T
        return (xyz.T, ("X", "Y", "Z")) if channels == "xyz" else (xyz[:, 1][None], ("Y",))
    if up == ["X", "Y", "Z"]:
        if channels == "xyz":
            return vals.T, ("X", "Y", "Z")
        if channels == "rgb":
            return (vals @ xyz_to_rgb_matrix().T).T, ("R", "G", "B")
        return vals[:, 1][None], ("Y",)
    if len(names) == 1:
        if channels == "luminance":
            return vals.T, (names[0],)
        raise HeaderError(path, f"R,G,B / X,Y,Z / wavelength columns for channels={channels!r}",
                          f"one column {names[0]!r}")
    raise HeaderError(path, "value columns R,G,B or X,Y,Z or <wavelength>nm,...", ",".join(names))


def _resolve_cornell(path_or_name, root) -> Path:
    s = str(path_or_name)
    p = Path(s).expanduser()
    if p.suffix or os.sep in s or "/" in s or p.is_file():
        if not p.is_file():
            raise DataNotFoundError(f"Cornell BRDF file {s!r}: no such file")
        return p
    key = s.strip().lower().replace("-", "_").replace(" ", "_")
    if key not in CORNELL_NAMES:
        raise UnknownMaterialError(f"Cornell material {s!r}: expected a file path or one of {list(CORNELL_NAMES)}")
    return data_file(f"cornell/{key}.brdf", root)


def _detect_format(path: Path) -> str:
    head = path.read_bytes()[:8192].decode("latin-1", errors="replace")
    for line in head.splitlines():
        t = line.strip().upper()
        if t.startswith("VARS") or t.startswith("NUM_POINTS"):
            return "astm"
    return "pbrt"


def load_cornell(
    path_or_name: str | os.PathLike | Sequence[str | os.PathLike],
    root: str | os.PathLike | None = None,
    *,
    channels: str = "rgb",
    format: str = "auto",
    angle_unit: str = "radians",
) -> Measurements:
    """Load Cornell BRDF measurements (a file anywhere on disk, or a name below the data root).

    Args:
        path_or_name: a file path, a name of :data:`CORNELL_NAMES` (e.g. ``"cayman"``: 1439 samples,
            31 wavelengths), or a sequence of them sharing the same directions.
        root: data root for names (default ``$POLYJAX_DATA``).
        channels: ``"rgb"`` (white-balanced linear sRGB, channels R, G, B), ``"luminance"`` (CIE Y),
            ``"xyz"`` or ``"spectral"`` (one channel per wavelength); see the module docstring for the
            illuminant and RGB space.
        format: ``"auto"`` (ASTM if the header has ``VARS``/``NUM_POINTS``, else pbrt), ``"pbrt"`` or ``"astm"``.
        angle_unit: angle unit of ASTM files (``"radians"`` or ``"degrees"``).

    Returns:
        :class:`polyjax.Measurements`: one file ``values (C, n)``, ``axes=("channel",)``,
        ``names=(<file stem>,)``; several
        ``(m, C, n)``, ``axes=("material", "channel")``. Weights are 1 (the data give no solid angles).
    """
    if channels not in CHANNEL_CHOICES:
        raise InputError(f"channels: expected one of {CHANNEL_CHOICES}, found {channels!r}")
    if format not in ("auto", "pbrt", "astm"):
        raise InputError(f"format: expected 'auto', 'pbrt' or 'astm', found {format!r}")
    single = isinstance(path_or_name, (str, os.PathLike))
    items = [path_or_name] if single else list(path_or_name)
    if not items:
        raise InputError("path_or_name: expected at least one Cornell file or name")
    angles, tables, labels, names = None, [], None, []
    for item in items:
        path = _resolve_cornell(item, root)
        fmt = _detect_format(path) if format == "auto" else format
        if fmt == "pbrt":
            ang, wl, spectra = read_cornell_pbrt(path)
            vals, labs = _spectral_channels(spectra, wl, channels, path)
        else:
            ang, cols, raw = read_cornell_astm(path, angle_unit=angle_unit)
            vals, labs = _astm_channels(cols, raw, channels, path)
        if angles is not None and (ang.shape != angles.shape or not np.allclose(ang, angles)):
            raise HeaderError(path, f"the same directions as {names[0]!r} to load them together",
                              "different directions")
        if labels is not None and labs != labels:
            raise HeaderError(path, f"channels {labels}", f"{labs}")
        angles, labels = ang, labs
        tables.append(vals)
        names.append(path.stem)
    u, v = _directions(angles)
    values = tables[0] if single else np.stack(tables)
    return make_measurements(
        u, v, values, names=names, channels=labels,
        axes=("channel",) if single else ("material", "channel"),
        source=f"Cornell gonioreflectometer {', '.join(names)} ({channels}), {angles.shape[0]} samples",
    )
