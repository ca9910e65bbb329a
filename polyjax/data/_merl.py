r"""MERL BRDF database: the ``.binary`` layout, the Rusinkiewicz grid and its solid-angle weights.

Layout of a MERL ``.binary`` file (Matusik, Pfister, Brand, McMillan 2003, ``readBRDF.cpp``):

- header: 3 x int32 little-endian ``(n_theta_h, n_theta_d, n_phi_d)`` = ``(90, 90, 180)``;
- then ``3 * n_theta_h * n_theta_d * n_phi_d`` float64 little-endian, channel-major (all R, all G, all B);
  within a channel ``idx = k + n_phi_d * (j + n_theta_d * i)`` for the bin ``(i, j, k)`` of
  ``(theta_h, theta_d, phi_d)``;
- scale to BRDF in 1/sr: R x 1/1500, G x 1.15/1500, B x 1.66/1500;
- negative entries mark missing measurements: they are masked out, never fitted.

Index mapping (with ``N_h, N_d, N_p`` the header dimensions)::

    i = floor(sqrt(theta_h / (pi/2)) * N_h),   j = floor(theta_d / (pi/2) * N_d),
    k = floor(phi_d / pi * N_p)  after phi_d -> phi_d + pi for phi_d < 0 (reciprocity),

clamped to the valid range, and bin centres (the directions a bin's value is attached to)
``theta_h = (i/N_h)^2 pi/2``, ``theta_d = j/N_d pi/2``, ``phi_d = k/N_p pi``. A value within
``1e-9`` (in index units) below a bin edge is taken to be on the edge, so the mapping inverts the bin
centres exactly despite round-off.

Directions of a bin, with ``phi_h = 0`` (isotropy): the difference vector
``d = (sin td cos pd, sin td sin pd, cos td)`` is rotated back by ``theta_h`` about ``y``:
``u = R_y(theta_h) d`` (light) and ``v = R_y(theta_h) (-d_x, -d_y, d_z)`` (view), so that
``cos theta_u = cos td cos th - sin td cos pd sin th`` and
``cos theta_v = cos td cos th + sin td cos pd sin th``, and ``(u + v) / |u + v| = (sin th, 0, cos th)``.

Solid-angle weight of a bin (its measure in the space of direction pairs ``(omega_u, omega_v)``).
Rusinkiewicz's change of variables has the Jacobian ``d omega_u d omega_v = 4 cos theta_d d omega_h
d omega_d`` (check: over ``omega_h`` in the sphere and ``theta_d <= pi/2`` it gives
``4 pi * 4 pi = 16 pi^2``). With ``d omega = sin theta d theta d phi``, integrating ``phi_h`` over
``2 pi`` (isotropy) and counting both halves ``phi_d`` and ``phi_d + pi`` of a bin (reciprocity)::

    w_ijk = 2 pi * 2 * 4 * [cos a_i - cos a_{i+1}] * [(sin^2 b_{j+1} - sin^2 b_j) / 2] * pi / N_p,

the exact integral of ``sin theta_h`` and ``cos theta_d sin theta_d`` over the quadrature cell of the
bin centre: in index units the centre ``i`` owns ``[i - 1/2, i + 1/2]`` (clipped to ``[0, N]``, the last
cell reaching ``N``), i.e. ``a_i = (max(i - 1/2, 0)/N_h)^2 pi/2`` and ``b_j = max(j - 1/2, 0)/N_d pi/2``.
(MERL's stored value averages the index cell ``[i, i + 1)``, but it is attached to the direction of
``i``; cells centred on the sample make the weights the quadrature weights of those directions.
Edge-anchored cells over-weight the horizon: their sums below come out 3-5 % high.) The weights of all
bins sum to ``8 pi^2`` (the pairs whose half vector is above the surface); over the bins with both
directions above the horizon they sum to ``(2 pi)^2`` and ``sum w cos theta_u cos theta_v`` to ``pi^2``
to within 0.1 % at MERL's resolution (the horizon cuts cells; checked in the tests).
"""

from __future__ import annotations

import functools
import os
import threading
from pathlib import Path
from typing import Sequence

import jax
import jax.numpy as jnp
import numpy as np

from .._cache.memo import grid_memo, remember_content, remember_unit_directions
from .._errors import DataNotFoundError, InputError
from .._files import check_output_path, write_bytes_atomically
from .._measurements import Measurements, lane_mask
from ._errors import EmptyFileError, HeaderError, NonFiniteValueError, TruncatedFileError, WrongFormatError

#: The resolution of the MERL database ``(n_theta_h, n_theta_d, n_phi_d)``.
MERL_RESOLUTION: tuple[int, int, int] = (90, 90, 180)
#: Number of bins per channel (1,458,000).
MERL_N_BINS = 90 * 90 * 180
#: Multipliers from stored numbers to BRDF in 1/sr, per channel (R, G, B).
MERL_SCALE: tuple[float, float, float] = (1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0)
_HEADER_BYTES = 12
_MAX_BINS = 10**8  # a header announcing more bins than this is not a MERL header
_INDEX_TOL = 1e-9

#: All 100 MERL material names, as MERL spells them.
MERL_NAMES: tuple[str, ...] = (
    'alum-bronze', 'alumina-oxide', 'aluminium', 'aventurnine', 'beige-fabric', 'black-fabric', 'black-obsidian',
    'black-oxidized-steel', 'black-phenolic', 'black-soft-plastic', 'blue-acrylic', 'blue-fabric',
    'blue-metallic-paint', 'blue-metallic-paint2', 'blue-rubber', 'brass', 'cherry-235', 'chrome', 'chrome-steel',
    'colonial-maple-223', 'color-changing-paint1', 'color-changing-paint2', 'color-changing-paint3',
    'dark-blue-paint', 'dark-red-paint', 'dark-specular-fabric', 'delrin', 'fruitwood-241', 'gold-metallic-paint',
    'gold-metallic-paint2', 'gold-metallic-paint3', 'gold-paint', 'gray-plastic', 'grease-covered-steel',
    'green-acrylic', 'green-fabric', 'green-latex', 'green-metallic-paint', 'green-metallic-paint2',
    'green-plastic', 'hematite', 'ipswich-pine-221', 'light-brown-fabric', 'light-red-paint', 'maroon-plastic',
    'natural-209', 'neoprene-rubber', 'nickel', 'nylon', 'orange-paint', 'pearl-paint', 'pickled-oak-260',
    'pink-fabric', 'pink-fabric2', 'pink-felt', 'pink-jasper', 'pink-plastic', 'polyethylene', 'polyurethane-foam',
    'pure-rubber', 'purple-paint', 'pvc', 'red-fabric', 'red-fabric2', 'red-metallic-paint', 'red-phenolic',
    'red-plastic', 'red-specular-plastic', 'silicon-nitrade', 'silver-metallic-paint', 'silver-metallic-paint2',
    'silver-paint', 'special-walnut-224', 'specular-black-phenolic', 'specular-blue-phenolic',
    'specular-green-phenolic', 'specular-maroon-phenolic', 'specular-orange-phenolic', 'specular-red-phenolic',
    'specular-violet-phenolic', 'specular-white-phenolic', 'specular-yellow-phenolic', 'ss440', 'steel', 'teflon',
    'tungsten-carbide', 'two-layer-gold', 'two-layer-silver', 'violet-acrylic', 'violet-rubber', 'white-acrylic',
    'white-diffuse-bball', 'white-fabric', 'white-fabric2', 'white-marble', 'white-paint', 'yellow-matte-plastic',
    'yellow-paint', 'yellow-phenolic', 'yellow-plastic',
)
#: The six MERL materials of the paper's Table 3.
TABLE3_MATERIALS: tuple[str, ...] = (
    "beige-fabric", "blue-metallic-paint", "dark-blue-paint", "green-latex", "orange-paint", "yellow-plastic",
)


def _check_resolution(resolution) -> tuple[int, int, int]:
    res = tuple(int(r) for r in resolution)
    if len(res) != 3 or any(r <= 0 for r in res):
        raise InputError(
            f"resolution: expected three positive bin counts (n_theta_h, n_theta_d, n_phi_d), found {resolution!r}"
        )
    return res


def merl_index(theta_h, theta_d, phi_d, resolution: Sequence[int] = MERL_RESOLUTION) -> np.ndarray:
    """Flat bin index ``k + N_p (j + N_d i)`` of Rusinkiewicz angles (radians), MERL's convention.

    Args:
        theta_h, theta_d, phi_d: arrays of the same shape; ``phi_d`` may be in ``(-pi, pi]``.
        resolution: ``(N_h, N_d, N_p)``.

    Returns:
        int64 array of flat indices into one channel.
    """
    nh, nd, npd = _check_resolution(resolution)
    th = np.asarray(theta_h, dtype=np.float64)
    td = np.asarray(theta_d, dtype=np.float64)
    pd = np.asarray(phi_d, dtype=np.float64)
    pd = np.where(pd < 0.0, pd + np.pi, pd)
    xi = np.sqrt(np.clip(th, 0.0, None) / (np.pi / 2)) * nh
    i = np.clip(np.floor(xi + _INDEX_TOL), 0, nh - 1).astype(np.int64)
    j = np.clip(np.floor(td / (np.pi / 2) * nd + _INDEX_TOL), 0, nd - 1).astype(np.int64)
    k = np.clip(np.floor(pd / np.pi * npd + _INDEX_TOL), 0, npd - 1).astype(np.int64)
    return k + npd * (j + nd * i)


def merl_bin_angles(resolution: Sequence[int] = MERL_RESOLUTION) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bin-centre angles ``(theta_h, theta_d, phi_d)`` of every bin, each ``(N_h N_d N_p,)`` in file order."""
    nh, nd, npd = _check_resolution(resolution)
    i, j, k = np.meshgrid(np.arange(nh), np.arange(nd), np.arange(npd), indexing="ij")
    th = (i.ravel() / nh) ** 2 * (np.pi / 2)
    td = j.ravel() / nd * (np.pi / 2)
    pd = k.ravel() / npd * np.pi
    return th, td, pd


def rusinkiewicz_to_directions(theta_h, theta_d, phi_d) -> tuple[np.ndarray, np.ndarray]:
    """Light ``u`` and view ``v`` unit vectors ``(..., 3)`` of Rusinkiewicz angles with ``phi_h = 0``."""
    th = np.asarray(theta_h, dtype=np.float64)
    td = np.asarray(theta_d, dtype=np.float64)
    pd = np.asarray(phi_d, dtype=np.float64)
    dx = np.sin(td) * np.cos(pd)
    dy = np.sin(td) * np.sin(pd)
    dz = np.cos(td)
    c, s = np.cos(th), np.sin(th)
    u = np.stack([dx * c + dz * s, dy, dz * c - dx * s], axis=-1)
    v = np.stack([-dx * c + dz * s, -dy, dz * c + dx * s], axis=-1)
    return u, v


def directions_to_rusinkiewicz(u, v) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rusinkiewicz angles ``(theta_h, theta_d, phi_d)`` of light/view unit vectors ``(..., 3)`` (numpy).

    ``phi_d`` is returned in ``(-pi, pi]``; :func:`merl_index` folds it into ``[0, pi)``.
    """
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    h = u + v
    hn = np.linalg.norm(h, axis=-1, keepdims=True)
    h = np.where(hn > 1e-12, h / np.where(hn > 1e-12, hn, 1.0), np.array([0.0, 0.0, 1.0]))
    th = np.arctan2(np.hypot(h[..., 0], h[..., 1]), h[..., 2])
    ph = np.arctan2(h[..., 1], h[..., 0])
    cp, sp = np.cos(ph), np.sin(ph)
    x = cp * u[..., 0] + sp * u[..., 1]
    y = -sp * u[..., 0] + cp * u[..., 1]
    z = u[..., 2]
    ct, st = np.cos(th), np.sin(th)
    dx = x * ct - z * st
    dz = x * st + z * ct
    td = np.arctan2(np.hypot(dx, y), dz)
    pd = np.arctan2(y, dx)
    return th, td, pd


def _cell_edges(n: int) -> np.ndarray:
    """Quadrature-cell edges in index units: sample ``i`` owns ``[i - 1/2, i + 1/2]``, clipped to ``[0, n]``
    (the last cell reaches ``n``)."""
    e = np.arange(n + 1) - 0.5
    e[0], e[-1] = 0.0, float(n)
    return e


def merl_bin_weights(resolution: Sequence[int] = MERL_RESOLUTION) -> np.ndarray:
    """Solid-angle weight of every bin in the space of direction pairs, ``(N_h N_d N_p,)`` in file order.

    ``w_ijk = 16 pi [cos a_i - cos a_{i+1}] [(sin^2 b_{j+1} - sin^2 b_j)/2] pi/N_p`` with the
    quadrature-cell edges ``a``, ``b`` of the module docstring; ``sum w = 8 pi^2``.
    """
    nh, nd, npd = _check_resolution(resolution)
    a = (_cell_edges(nh) / nh) ** 2 * (np.pi / 2)
    b = _cell_edges(nd) / nd * (np.pi / 2)
    wh = np.cos(a[:-1]) - np.cos(a[1:])
    wd = 0.5 * (np.sin(b[1:]) ** 2 - np.sin(b[:-1]) ** 2)
    w = 16.0 * np.pi * wh[:, None, None] * wd[None, :, None] * np.full((1, 1, npd), np.pi / npd)
    return w.ravel()


def _grid_tables(resolution: tuple[int, int, int]):
    """``cos theta_h``, ``sin theta_h`` ``(N_h,)`` and the difference vector ``d`` (``dx``, ``dy``, ``dz``, each
    ``(N_d, N_p)``) of the bin centres: the factors of every direction of the grid."""
    nh, nd, npd = resolution
    th = (np.arange(nh) / nh) ** 2 * (np.pi / 2)
    td = np.arange(nd) / nd * (np.pi / 2)
    pd = np.arange(npd) / npd * np.pi
    dx = np.sin(td)[:, None] * np.cos(pd)[None, :]
    dy = np.sin(td)[:, None] * np.sin(pd)[None, :]
    dz = np.broadcast_to(np.cos(td)[:, None], dx.shape)
    return np.cos(th), np.sin(th), dx, dy, dz


def _grid_directions(resolution: tuple[int, int, int]) -> tuple[np.ndarray, np.ndarray]:
    """:func:`rusinkiewicz_to_directions` of every bin centre, in file order, by the grid's separable form: the sines
    and cosines of the ``N_h + N_d + N_p`` bin angles, then the products of :func:`rusinkiewicz_to_directions`
    (the same operations on the same numbers, so the same bits) written straight into the ``(N, 3)`` arrays, with
    no full-size angle or temporary arrays (a tenth of the time of the elementwise form)."""
    nh, nd, npd = resolution
    c, s, dx, dy, dz = _grid_tables(resolution)
    c, s, dx, dy, dz = c[:, None, None], s[:, None, None], dx[None], dy[None], dz[None]
    u = np.empty((nh, nd, npd, 3))
    v = np.empty((nh, nd, npd, 3))
    _fill_directions(u, v, c, s, dx, dy, dz)
    return u.reshape(-1, 3), v.reshape(-1, 3)


def _fill_directions(u, v, c, s, x, y, z) -> None:
    """Write into ``u``, ``v`` (``(..., 3)``) the light and view directions of the half-vector elevation with cosine
    ``c`` and sine ``s`` and the difference vector ``(x, y, z)`` (broadcast against ``u[..., 0]``): the rotation of
    :func:`rusinkiewicz_to_directions` (the same operations on the same numbers, so the same bits)."""
    xc, zs, zc, xs = x * c, z * s, z * c, x * s  # each product once (-a + b and b - a are the same double)
    np.add(xc, zs, out=u[..., 0])
    u[..., 1] = y
    np.subtract(zc, xs, out=u[..., 2])
    np.subtract(zs, xc, out=v[..., 0])
    np.negative(y, out=v[..., 1])
    np.add(zc, xs, out=v[..., 2])


@functools.lru_cache(maxsize=4)
def merl_grid(resolution: tuple[int, int, int] = MERL_RESOLUTION):
    """``(u, v, weights, above)`` for every bin in file order; ``above`` is True where both directions
    are above the horizon (``cos theta_u > 0`` and ``cos theta_v > 0``). Cached; arrays are read-only."""
    u, v = _grid_directions(_check_resolution(resolution))
    w = merl_bin_weights(resolution)
    above = (u[:, 2] > 0) & (v[:, 2] > 0)
    for a in (u, v, w, above):
        a.setflags(write=False)
    return u, v, w, above


def _looks_like_text(head: bytes) -> bool:
    if not head:
        return False
    printable = sum(32 <= c < 127 or c in (9, 10, 13) for c in head)
    return printable == len(head)


_SIGNATURES = {b"\x89HDF": "an HDF5 file", b"PK\x03\x04": "a zip archive", b"\x89PNG": "a PNG image",
               b"\x76\x2f\x31\x01": "an OpenEXR image"}


def read_merl_binary(
    path: str | os.PathLike, *, scaled: bool = True, copy: bool = True
) -> tuple[np.ndarray, tuple[int, int, int]]:
    """Read a MERL ``.binary`` file completely and check it.

    The header and the file's size are checked first, from its first bytes and its size on disk; then the body is
    read straight into the float64 array returned (one read, no intermediate copy).

    Args:
        path: the file.
        scaled: multiply by :data:`MERL_SCALE` (BRDF in 1/sr); False returns the stored numbers.
        copy: kept for compatibility: the array returned is always a fresh, writable array of its own.

    Returns:
        ``(values, resolution)`` with ``values`` float64 ``(3, N_h N_d N_p)`` in file order
        (negative entries = missing data, kept negative) and the header's resolution.

    Raises:
        DataNotFoundError (no such file), EmptyFileError, TruncatedFileError, HeaderError, WrongFormatError,
        NonFiniteValueError.
    """
    del copy
    raw, res = _read_raw(path, None)
    if scaled:
        raw *= np.asarray(MERL_SCALE)[:, None]
    return raw, res


def _read_raw(path, scratch: dict | None, on_header=None) -> tuple[np.ndarray, tuple[int, int, int]]:
    """The checked ``(3, N)`` stored numbers of a ``.binary`` file: a fresh array, or, with ``scratch`` (a dict
    holding a reusable buffer, see :data:`_SCRATCH`), read into that buffer (no fresh pages to fault in).
    ``on_header(resolution)`` is called once the header and size are checked, before the body is read."""
    path = Path(path)
    if not path.is_file():
        raise DataNotFoundError(f"MERL .binary file {str(path)!r}: no such file")
    with open(path, "rb", buffering=0) as f:
        size = os.fstat(f.fileno()).st_size
        head = f.read(256)
        res, n = _check_header(path, head, size)
        if on_header is not None:
            on_header(res)
        f.seek(_HEADER_BYTES)
        if scratch is None:
            raw = np.fromfile(f, dtype="<f8", count=3 * n)
            got = raw.size
        else:
            if scratch.get("buffer") is None or scratch["buffer"].size != 3 * n:
                scratch["buffer"] = np.empty(3 * n, "<f8")
            raw = scratch["buffer"]
            view = memoryview(raw).cast("B")
            got = 0
            while got < view.nbytes:  # readinto may return less than asked for
                k = f.readinto(view[got:])
                if not k:
                    break
                got += k
            got //= 8
    if got != 3 * n:  # the file shrank while being read
        raise TruncatedFileError(path, f"{3 * n} float64 values", f"{got}")
    raw = raw.reshape(3, n)
    with np.errstate(invalid="ignore", over="ignore"):  # inf - inf or an overflowing sum: then look entry by entry
        total = np.sum(raw)
    if not np.isfinite(total):  # a finite sum means every entry is finite; else find the culprits
        finite = np.isfinite(raw)
        if not finite.all():
            c, idx = np.argwhere(~finite)[0]
            raise NonFiniteValueError(
                path, "finite numbers (negative = missing)",
                f"{int((~finite).sum())} NaN/inf values (first: channel {'RGB'[c]}, bin {idx}: {raw[c, idx]})",
            )
    return raw, res


#: the buffer a single-file :func:`load_merl_binary` reads into (the file's numbers are only gathered from, so
#: one 35 MB buffer serves every load of a process instead of fresh memory each time), with its lock
_SCRATCH: dict = {}
_SCRATCH_LOCK = threading.Lock()


def _check_header(path: Path, head: bytes, size: int) -> tuple[tuple[int, int, int], int]:
    """The resolution and bin count of a ``.binary`` file from its first bytes and its size, or the error."""
    expected_header = "a MERL .binary file: int32 header (90, 90, 180) then 3 x N float64"
    if size == 0:
        raise EmptyFileError(path, expected_header, "an empty file (0 bytes)")
    for sig, what in _SIGNATURES.items():
        if head.startswith(sig):
            raise WrongFormatError(path, expected_header, what)
    if _looks_like_text(head):
        raise WrongFormatError(path, expected_header, f"a text file (starts with {head[:40]!r})")
    if size < _HEADER_BYTES:
        raise TruncatedFileError(path, "a 12-byte header (3 x int32)", f"only {size} bytes")
    dims = np.frombuffer(head, dtype="<i4", count=3)
    if np.any(dims <= 0) or int(np.prod(dims.astype(np.int64))) > _MAX_BINS:
        raise HeaderError(path, "3 positive int32 bin counts such as (90, 90, 180)", f"{tuple(int(d) for d in dims)}")
    res = tuple(int(d) for d in dims)
    n = int(np.prod(res))
    want = _HEADER_BYTES + 3 * 8 * n
    if size < want:
        raise TruncatedFileError(
            path, f"{want} bytes for the header {res} (3 x {n} float64)", f"{size} bytes ({want - size} missing)",
        )
    if size > want:
        raise HeaderError(path, f"{want} bytes for the header {res}", f"{size} bytes ({size - want} extra)")
    return res, n


def write_merl_binary(
    path: str | os.PathLike,
    values,
    *,
    resolution: Sequence[int] | None = None,
    mask=None,
    scaled: bool = True,
) -> Path:
    """Write a MERL ``.binary`` file.

    Args:
        path: the file to write.
        values: ``(3, N_h N_d N_p)`` or ``(3, N_h, N_d, N_p)`` BRDF values in file order (in 1/sr when
            ``scaled``: divided by :data:`MERL_SCALE` before writing).
        resolution: ``(N_h, N_d, N_p)``; default :data:`MERL_RESOLUTION`, or the shape of a 4-d ``values``.
        mask: optional bool array of the same shape as ``values``; False entries (and NaN) are written as -1
            (MERL's "missing").
        scaled: see ``values``.

    Returns:
        The path written.
    """
    vals = np.array(values, dtype=np.float64)
    if resolution is None:
        resolution = vals.shape[1:] if vals.ndim == 4 else MERL_RESOLUTION
    res = _check_resolution(resolution)
    n = int(np.prod(res))
    if vals.size != 3 * n or vals.shape[0] != 3:
        raise InputError(f"values: expected shape (3, {n}) or (3, {res[0]}, {res[1]}, {res[2]}) for resolution "
                         f"{res}, found {vals.shape}")
    vals = vals.reshape(3, n)
    bad = ~np.isfinite(vals)
    if mask is not None:
        m = np.asarray(mask, dtype=bool)
        if m.size != vals.size:
            raise InputError(f"mask: expected {vals.size} entries like values, found shape {m.shape}")
        bad |= ~m.reshape(3, n)
    if scaled:
        vals = vals / np.asarray(MERL_SCALE)[:, None]
    vals = np.where(bad, -1.0, vals)
    return write_bytes_atomically(check_output_path(path, "path"),
                                  np.asarray(res, dtype="<i4").tobytes() + vals.astype("<f8").tobytes())


def _choose_bins(valid: np.ndarray, subsample, seed: int, what: str) -> np.ndarray:
    """Indices of the kept bins: all ``valid`` ones, or a reproducible random subset (sorted)."""
    idx = np.flatnonzero(valid)
    if subsample is None:
        return idx
    if isinstance(subsample, (bool, np.bool_)) or not isinstance(subsample, (int, float, np.integer, np.floating)):
        raise InputError(f"subsample: expected None, a count or a fraction in (0, 1), found {subsample!r}")
    if isinstance(subsample, (float, np.floating)) and 0.0 < subsample < 1.0:
        count = max(1, int(round(float(subsample) * idx.size)))
    elif float(subsample) >= 1 and float(subsample).is_integer():
        count = int(subsample)
    else:
        raise InputError(f"subsample: expected None, a positive count or a fraction in (0, 1), found {subsample!r}")
    if count >= idx.size:
        return idx
    rng = np.random.default_rng(seed)
    return np.sort(rng.choice(idx, size=count, replace=False))


@grid_memo(maxsize=2)
def _device_grid(resolution: tuple[int, int, int], dtype_name: str):
    """Device arrays ``(u, v, w)`` of all bins above the horizon (the usual sample set) and an all-True ``(n,)``
    mask; cached: every file on this grid hands out the same arrays (what a fit keeps for the grid is found
    again by identity). :func:`load_merl_binary` starts it in a thread (``_device_grid.start``) as soon as a file's
    header is read, so a process's first load makes the grid while the file is read and its values gathered."""
    idx = _above_index(resolution)
    u, v = _above_directions(resolution, idx, dtype_name)
    w = _aligned_empty(idx.shape, dtype_name)  # aligned: jax.device_put takes it over without a copy
    weights = merl_bin_weights(resolution)
    if w.dtype == weights.dtype:  # gathered in place (numpy buffers a take into another dtype)
        np.take(weights, idx, out=w, mode="clip")
    else:
        np.copyto(w, weights[idx])
    grid = tuple(jax.device_put(a) for a in (u, v, w)) + (jax.device_put(np.ones(idx.size, bool)),)
    # unit by construction (to rounding): not normalised again
    remember_unit_directions(grid[0], grid[1], (grid[0], grid[1], grid[3]))
    for a, what in zip(grid[:2], "uv"):  # named for the geometry kept on disk: no checksum of their bytes needed
        remember_content(a, f"merl-grid:{resolution}:{dtype_name}:{what}")
    return grid


def _above_directions(resolution, idx, dtype_name):
    """``merl_grid``'s ``u[idx]``, ``v[idx]`` (the same bits) in aligned ``(len(idx), 3)`` buffers, computed one
    ``theta_h`` slab at a time from :func:`_grid_tables` (no full-grid arrays: a fresh process's first load); the
    slabs of the first half of the bins in a second thread (numpy releases the interpreter lock in its loops)."""
    nh, nd, npd = resolution
    c, s, dx, dy, dz = (a.ravel() if a.ndim > 1 else a for a in _grid_tables(resolution))
    u = _aligned_empty((idx.size, 3), dtype_name)
    v = _aligned_empty((idx.size, 3), dtype_name)
    bounds = np.searchsorted(idx, np.arange(nh + 1) * (nd * npd))

    def fill(first, last):
        for i in range(first, last):
            a, b = bounds[i], bounds[i + 1]
            sel = idx[a:b] - i * (nd * npd)
            _fill_directions(u[a:b], v[a:b], c[i], s[i], dx[sel], dy[sel], dz[sel])

    half = int(np.searchsorted(bounds, idx.size // 2))
    _in_two_threads(lambda: fill(0, half), lambda: fill(half, nh))
    return u, v


def _in_two_threads(first, second) -> None:
    """``first()`` in a new thread while ``second()`` runs in this one; the first error of either is raised."""
    errors = []

    def run():
        try:
            first()
        except BaseException as e:  # noqa: BLE001 - raised in the caller's thread below
            errors.append(e)

    thread = threading.Thread(target=run, name="polyjax-grid-half", daemon=True)
    thread.start()
    try:
        second()
    finally:
        thread.join()
    if errors:
        raise errors[0]


@grid_memo(maxsize=4)
def _above_index(resolution: tuple[int, int, int]) -> np.ndarray:
    """File-order indices of the bins with both directions above the horizon.

    ``merl_grid`` computes the z components ``dz c - dx s`` (light) and ``dz c + dx s`` (view) of a bin; for finite
    doubles ``a - b > 0`` iff ``a > b`` and ``a + b > 0`` iff ``a > -b`` (IEEE subtraction is exact in sign,
    subnormals included), so both are positive iff ``dz c > |dx s|``: the same bins from one ``(N_h, N_d)`` table
    of ``dz c`` (``dz`` does not depend on ``phi_d``) and one full-size product, a fifth of the work."""
    c, s, dx, _, dz = _grid_tables(resolution)
    zc = (c[:, None] * dz[None, :, 0])[:, :, None]  # (N_h, N_d, 1): dz c, the same product as merl_grid's
    xs = dx[None] * s[:, None, None]  # (N_h, N_d, N_p)
    idx = np.flatnonzero(zc > np.abs(xs, out=xs))
    idx.setflags(write=False)
    return idx


def _aligned_empty(shape, dtype) -> np.ndarray:
    """An uninitialised array on a 64-byte boundary: :func:`jax.device_put` then takes it over without a copy
    (on the CPU); the loaders hand such an array, never touched again, to the device."""
    dtype = np.dtype(dtype)
    count = int(np.prod(shape))
    buf = np.empty(count * dtype.itemsize + 64, np.uint8)
    start = -buf.ctypes.data % 64
    return buf[start:start + count * dtype.itemsize].view(dtype).reshape(shape)


def _default_float_name() -> str:
    """The name of JAX's default float dtype (``float64`` with x64 on), the dtype of the loaders' arrays."""
    return jnp.dtype(jnp.result_type(float)).name


def _merl_measurements(values, resolution, *, subsample, seed, names, source, scale=None) -> Measurements:
    """values ``(m, 3, N)`` (negative = missing) -> Measurements over the kept bins; ``scale`` ``(3,)`` multiplies
    the kept values (the stored numbers of a ``.binary`` file are scaled after the gather). The mask is ``(n,)``
    when every lane has the same valid bins (:func:`lane_mask`)."""
    resolution = tuple(resolution)
    dtype = jnp.dtype(_default_float_name())
    if subsample is None:  # the usual case: gather the bins above the horizon once, then look at validity
        keep = _above_index(resolution)
        # mode="clip" (the indices are in range): with the default mode numpy gathers into a buffer, then copies
        vals = np.take(values, keep, axis=-1, out=_aligned_empty(values.shape[:-1] + keep.shape, values.dtype),
                       mode="clip")
        if vals.min() >= 0.0:  # every kept bin valid in every lane
            valid = None
        else:
            valid = vals >= 0.0
            some = valid.any(axis=(0, 1))
            if not some.all():
                keep, vals, valid = keep[some], vals[..., some], valid[..., some]
    else:
        valid_all = values >= 0.0
        keep = _choose_bins(merl_grid(resolution)[3] & valid_all.any(axis=(0, 1)), subsample, seed, source)
        vals, valid = values[..., keep], valid_all[..., keep]
    if scale is not None:
        vals *= np.asarray(scale)[:, None]
    if valid is not None:
        np.copyto(vals, 0.0, where=~valid)
    single = vals.shape[0] == 1
    if single:
        vals = vals[0]
        valid = None if valid is None else valid[0]
    if keep.size == _above_index(resolution).size:  # all bins above the horizon: the cached device arrays
        du, dv, dw, all_true = _device_grid(resolution, dtype.name)
    else:
        du, dv, dw = (jax.device_put(np.asarray(a[keep], dtype)) for a in merl_grid(resolution)[:3])
        all_true = None
    mask = lane_mask(valid) if valid is not None else all_true
    mask = jax.device_put(np.ones(keep.size, bool)) if mask is None else mask
    return Measurements(
        u=du, v=dv, values=jax.device_put(vals if vals.dtype == dtype else np.asarray(vals, dtype)), weights=dw,
        mask=mask if isinstance(mask, jax.Array) else jax.device_put(mask),
        names=tuple(names), channels=("R", "G", "B"),
        axes=("channel",) if single else ("material", "channel"), source=source,
    )


def load_merl_binary(
    paths: str | os.PathLike | Sequence[str | os.PathLike],
    *,
    subsample: int | float | None = None,
    seed: int = 0,
    names: Sequence[str] | None = None,
) -> Measurements:
    """Load MERL ``.binary`` files (anywhere on disk) as :class:`polyjax.Measurements`.

    Every bin with both directions above the horizon and a non-negative value in some file is a sample
    (about 1.1 million of 1,458,000 for real MERL files); directions from the Rusinkiewicz bin centres,
    weights = the bins' solid-angle measure (module docstring). Negative entries are masked out.

    Args:
        paths: one file or a sequence of files of the same resolution.
        subsample: None (all valid bins), a count, or a fraction in (0, 1): a random subset of the bins,
            reproducible from ``seed``.
        seed: seed of the subsample.
        names: material names (default: the file names without extension).

    Returns:
        One file: ``values`` ``(3, n)`` with ``axes=("channel",)`` and ``names=(<its stem>,)``; several:
        ``(m, 3, n)`` with ``axes=("material", "channel")``; ``channels=("R", "G", "B")``, BRDF in 1/sr.
    """
    single = isinstance(paths, (str, os.PathLike))
    plist = [Path(paths)] if single else [Path(p) for p in paths]
    if not plist:
        raise InputError("paths: expected at least one MERL .binary file")
    names = tuple(names) if names is not None else tuple(p.stem for p in plist)
    if len(names) != len(plist):
        raise InputError(f"names: expected {len(plist)} names, found {len(names)}")
    source = (f"MERL .binary {', '.join(p.name for p in plist)}"
              + (f" (subsample {subsample}, seed {seed})" if subsample else ""))
    # the grid's bins, directions and weights (the first load of a process) made in a thread while the file is read;
    # files with bins missing in every lane use other arrays (merl_grid's), and the grid made is kept for later loads
    dtype_name = _default_float_name()
    on_header = None if subsample is not None else lambda r: _device_grid.start(r, dtype_name)
    if len(plist) == 1:  # read into the reused buffer, gathered from before the lock is released
        with _SCRATCH_LOCK:
            raw, res = _read_raw(plist[0], _SCRATCH, on_header)
            return _merl_measurements(raw[None], res, subsample=subsample, seed=seed, names=names,
                                      scale=MERL_SCALE, source=source)
    tables = []
    res = None
    for p in plist:
        vals, r = _read_raw(p, None, on_header if res is None else None)
        if res is not None and r != res:
            raise HeaderError(p, f"the resolution {res} of {plist[0]}", f"{r}")
        res = r
        tables.append(vals)
    return _merl_measurements(np.stack(tables), res, subsample=subsample, seed=seed, names=names, scale=MERL_SCALE,
                              source=source)
