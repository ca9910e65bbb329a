r"""Neural BRDFs in the format of Sztrajman, Rainer, Ritschel, Weyrich 2021, in JAX.

A set of networks is a zip archive or a folder holding one Keras weights file ``<material>.h5`` per
material (:func:`load_nbrdf`, :func:`nbrdf_names`, ``load("nbrdf:<path>:<name>")``). The fits of the 100
MERL materials are below the data root: ``nbrdf_sztrajman2021/merl_nbrdf.zip`` holding
``merl_nbrdf/<name>.h5`` for every name of :data:`MERL_NAMES` (:func:`load_merl_nbrdf`). The network of
each material is

.. math::
    f(x) = \exp\big(W_3^\top \mathrm{relu}(W_2^\top \mathrm{relu}(W_1^\top x + b_1) + b_2) + b_3\big) - 1

with ``W1 (6, 21)``, ``W2 (21, 21)``, ``W3 (21, 3)``, output RGB BRDF in 1/sr (MERL's physical scale),
and input ``x = (h, d)``: the Rusinkiewicz half vector rotated to ``phi_h = 0``,
``h = (sin theta_h, 0, cos theta_h)``, and the difference vector
``d = (sin theta_d cos phi_d, sin theta_d sin phi_d, cos theta_d)`` of the light direction ``u``.
Outside the valid hemisphere (``cos theta_u <= 0`` or ``cos theta_v <= 0``) the network is meaningless
and the BRDF is set to 0; negative outputs inside (at most -0.0016 for most materials) are clamped to 0.

These are close approximations of the MERL measurements, not the measurements themselves. Cite
Matusik et al. 2003 (MERL, CC-BY-SA-4.0) and Sztrajman et al. 2021.
"""

from __future__ import annotations

import difflib
import functools
import io
import os
from pathlib import Path, PurePosixPath
from typing import Sequence

import equinox as eqx
import h5py
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._arrays import device_array
from .._config import data_file
from .._errors import DataNotFoundError, InputError, PolyjaxError
from .._measurements import Measurements
from .._reading.bounded import open_zip, read_bytes, read_zip_member, zip_members
from .._reading.limits import LIMIT_ENV, network_limit
from ._errors import HeaderError, NonFiniteValueError, UnknownMaterialError, WrongFormatError
from ._merl import MERL_NAMES, MERL_RESOLUTION, TABLE3_MATERIALS, _choose_bins, merl_bin_angles, merl_grid

NBRDF_ZIP = "nbrdf_sztrajman2021/merl_nbrdf.zip"
_LAYERS = (("dense_1", (6, 21)), ("dense_2", (21, 21)), ("dense_3", (21, 3)))


@jax.jit
def _mlp(params, x):
    """The network on inputs ``x (..., 6)``: raw RGB ``(..., 3)`` (may be negative)."""
    w1, b1, w2, b2, w3, b3 = (p.astype(x.dtype) for p in params)
    a = jax.nn.relu(x @ w1 + b1)
    a = jax.nn.relu(a @ w2 + b2)
    return jnp.expm1(a @ w3 + b3)


@jax.jit
def _half_diff_inputs(u, v):
    """Network inputs ``(h, d)`` (..., 6) from light/view directions (gradient-safe at the pole)."""
    s = u + v
    n2 = jnp.sum(s * s, axis=-1, keepdims=True)
    ok = n2 > 1e-24
    h = jnp.where(ok, s / jnp.sqrt(jnp.where(ok, n2, 1.0)), jnp.array([0.0, 0.0, 1.0], s.dtype))
    r2 = h[..., 0] ** 2 + h[..., 1] ** 2
    pole = r2 <= 1e-30
    sin_t = jnp.where(pole, 0.0, jnp.sqrt(jnp.where(pole, 1.0, r2)))
    cos_t = h[..., 2]
    safe = jnp.where(pole, 1.0, sin_t)
    cos_p = jnp.where(pole, 1.0, h[..., 0] / safe)
    sin_p = jnp.where(pole, 0.0, h[..., 1] / safe)
    # d = R_y(-theta_h) R_z(-phi_h) u
    x = cos_p * u[..., 0] + sin_p * u[..., 1]
    y = -sin_p * u[..., 0] + cos_p * u[..., 1]
    z = u[..., 2]
    d = jnp.stack([x * cos_t - z * sin_t, y, x * sin_t + z * cos_t], axis=-1)
    hh = jnp.stack([sin_t, jnp.zeros_like(sin_t), cos_t], axis=-1)
    return jnp.concatenate([hh, d], axis=-1)


class NeuralBRDF(eqx.Module):
    """One MERL material's neural BRDF (Sztrajman et al. 2021) as a jittable, vmappable pytree.

    Call ``model(u, v)`` with light ``u`` and view ``v`` unit vectors ``(..., 3)`` (local frame,
    normal ``+z``) to get RGB BRDF values ``(..., 3)`` in 1/sr: 0 where either direction is at or
    below the horizon, negative network outputs clamped to 0.

    Attributes:
        w1, b1, w2, b2, w3, b3: the network's weights (float32 as stored).
        name: the MERL material name.
    """

    w1: Float[Array, "6 21"]
    b1: Float[Array, "21"]
    w2: Float[Array, "21 21"]
    b2: Float[Array, "21"]
    w3: Float[Array, "21 3"]
    b3: Float[Array, "3"]
    name: str = eqx.field(static=True, default="")

    @property
    def params(self):
        return (self.w1, self.b1, self.w2, self.b2, self.w3, self.b3)

    def network(self, x: Float[ArrayLike, "... 6"]) -> Float[Array, "... 3"]:
        """The raw network on inputs ``x = (h, d)`` (no mask, no clamping)."""
        x = jnp.asarray(x)
        if not jnp.issubdtype(x.dtype, jnp.floating):
            x = x.astype(jnp.result_type(float))
        return _mlp(self.params, x)

    def raw(self, u: Float[ArrayLike, "... 3"], v: Float[ArrayLike, "... 3"]) -> Float[Array, "... 3"]:
        """Network output at ``(u, v)`` without the hemisphere mask and clamping."""
        u, v = jnp.broadcast_arrays(jnp.asarray(u), jnp.asarray(v))
        if not jnp.issubdtype(u.dtype, jnp.floating):
            u, v = u.astype(jnp.result_type(float)), v.astype(jnp.result_type(float))
        return _mlp(self.params, _half_diff_inputs(u, v))

    def __call__(self, u: Float[ArrayLike, "... 3"], v: Float[ArrayLike, "... 3"]) -> Float[Array, "... 3"]:
        """RGB BRDF ``(..., 3)`` in 1/sr at light ``u`` and view ``v``."""
        u, v = jnp.broadcast_arrays(jnp.asarray(u), jnp.asarray(v))
        if not jnp.issubdtype(u.dtype, jnp.floating):
            u, v = u.astype(jnp.result_type(float)), v.astype(jnp.result_type(float))
        return _clamped(self.params, u, v)


@jax.jit
def _clamped(params, u, v):
    """:meth:`NeuralBRDF.__call__` in one compiled program (op by op, every operation compiles on its own)."""
    valid = (u[..., 2] > 0) & (v[..., 2] > 0)
    y = _mlp(params, _half_diff_inputs(u, v))
    return jnp.where(valid[..., None], jnp.maximum(y, 0.0), 0.0)


def resolve_merl_name(name: str) -> str:
    """The MERL spelling of ``name`` (case-insensitive, ``_`` or space for ``-``), or UnknownMaterialError."""
    key = str(name).strip().lower().replace("_", "-").replace(" ", "-")
    if key.endswith(".binary"):
        key = key[: -len(".binary")]
    if key in MERL_NAMES:
        return key
    close = difflib.get_close_matches(key, MERL_NAMES, n=3)
    hint = f"; did you mean {', '.join(close)}?" if close else ""
    raise UnknownMaterialError(f"MERL material {name!r}: not one of the 100 MERL names (polyjax.data.MERL_NAMES){hint}")


def _resolve_names(name_or_names) -> tuple[list[str], bool]:
    if isinstance(name_or_names, str):
        key = name_or_names.strip().lower()
        if key == "table3":
            return list(TABLE3_MATERIALS), False
        if key == "all":
            return list(MERL_NAMES), False
        return [resolve_merl_name(name_or_names)], True
    names = [resolve_merl_name(n) for n in name_or_names]
    if not names:
        raise InputError("name_or_names: expected at least one MERL material name")
    return names, False


def _norm_name(name: str) -> str:
    return str(name).strip().lower().replace("_", "-").replace(" ", "-")


class _NetworkSet:
    """A zip archive or a folder holding ``<name>.h5`` networks (in any sub-folder); names are the file stems."""

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path).expanduser()
        self.zip = None
        if self.path.is_dir():
            found = [(p.stem, p.relative_to(self.path).as_posix()) for p in sorted(self.path.rglob("*.h5"))]
        elif self.path.is_file():
            try:
                self.zip = open_zip(self.path, "a zip archive (or folder) of Keras .h5 networks")
            except PolyjaxError as e:
                raise WrongFormatError(self.path, "a zip archive (or folder) of Keras .h5 networks",
                                       getattr(e, "found", str(e))) from None
            try:
                self.infos = {i.filename: i for i in zip_members(self.zip, self.path, "a zip archive of Keras .h5 "
                                                                                     "networks")}
            except PolyjaxError:
                self.zip.close()
                raise
            found = [(PurePosixPath(i.filename).stem, i.filename) for i in self.infos.values()
                     if not i.is_dir() and i.filename.lower().endswith(".h5")]
        else:
            raise DataNotFoundError(f"neural-BRDF set {str(self.path)!r}: no such zip file or folder")
        self.members: dict[str, str] = {}
        for stem, member in found:
            if stem in self.members:
                raise HeaderError(self.path, "one network per material name",
                                  f"{stem!r} twice: {self.members[stem]!r} and {member!r}")
            self.members[stem] = member
        if not self.members:
            raise WrongFormatError(self.path, "Keras networks <material>.h5 (the neural-BRDF format)", "no .h5 member")

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if self.zip is not None:
            self.zip.close()

    def resolve(self, name: str) -> str:
        """The stored name of ``name`` (exact, else case and ``-``/``_``/space insensitive)."""
        if name in self.members:
            return name
        by_key = {_norm_name(n): n for n in self.members}
        key = _norm_name(name)
        if key in by_key:
            return by_key[key]
        close = difflib.get_close_matches(key, list(by_key), n=3)
        hint = f"; did you mean {', '.join(by_key[c] for c in close)}?" if close else ""
        raise UnknownMaterialError(f"material {name!r}: not in the neural-BRDF set {str(self.path)!r} "
                                   f"({len(self.members)} networks){hint}")

    def read(self, name: str) -> tuple[np.ndarray, ...]:
        """The network's six arrays; the member (or file) is read only when its size is within
        :func:`polyjax._reading.limits.network_limit`, and inflated in bounded chunks."""
        member = self.members[name]
        if self.zip is not None:
            blob = read_zip_member(self.zip, self.infos[member], self.path, network_limit(),
                                   f"of one network, 16 MiB or {LIMIT_ENV}")
        else:
            blob = read_bytes(self.path / member, network_limit(), "a Keras .h5 network")
        return _parse_weights(blob, self.path, member)


def _parse_weights(blob: bytes, path: Path, member: str) -> tuple[np.ndarray, ...]:
    """The six arrays ``W1, b1, W2, b2, W3, b3`` of a Keras weights file.

    Layers are recognised by their kernels' shapes (6, 21), (21, 21), (21, 3), whatever Keras named them
    (``dense_1``, ``dense_4`` ...); each bias is the ``bias`` dataset beside its kernel. Every dataset's shape is
    checked before it is read; a file h5py cannot read is a :class:`WrongFormatError` naming the member.
    """
    try:
        with h5py.File(io.BytesIO(blob), "r") as f:
            return _layer_weights(f, path, member)
    except PolyjaxError:
        raise
    except (OSError, KeyError, ValueError, TypeError, RuntimeError, AttributeError, OverflowError) as e:
        raise WrongFormatError(path, f"an HDF5 file in {member!r}", f"unreadable content ({e})") from None


def _layer_weights(f, path: Path, member: str) -> tuple[np.ndarray, ...]:
    """The kernels and biases of :func:`_parse_weights` from the open HDF5 file ``f``."""
    out = []
    keys = _h5_keys(f)
    kernels = [k for k in keys if k.rsplit("/", 1)[-1].split(":")[0] == "kernel"]
    for shape in (shp for _, shp in _LAYERS):
        hits = [k for k in kernels if tuple(f[k].shape) == shape]
        if len(hits) != 1:
            found = {k: tuple(f[k].shape) for k in kernels}
            raise HeaderError(path, f"one kernel of shape {shape} in {member!r} (layers 6-21-21-3)",
                              f"kernels {found}" if found else f"datasets {sorted(keys)}")
        key = hits[0]
        bias = key.rsplit("/", 1)[0] + "/" + key.rsplit("/", 1)[-1].replace("kernel", "bias")
        if bias not in f or not hasattr(f[bias], "shape"):
            raise HeaderError(path, f"dataset {bias!r} in {member!r}", f"datasets {sorted(keys)}")
        for k, shp in ((key, shape), (bias, shape[1:])):
            if tuple(f[k].shape) != shp:  # the declared shape, before any data is read
                raise HeaderError(path, f"{k!r} of shape {shp} in {member!r}", f"shape {tuple(f[k].shape)}")
            a = np.asarray(f[k], dtype=np.float32)
            if not np.all(np.isfinite(a)):
                raise NonFiniteValueError(path, f"finite weights in {member!r}/{k}", "NaN or inf")
            out.append(a)
    return tuple(out)


def _h5_keys(f) -> list[str]:
    keys = []
    f.visititems(lambda k, v: keys.append(k) if hasattr(v, "shape") else None)
    return keys


def merl_nbrdf_path(root: str | os.PathLike | None = None) -> Path:
    """The zip of the 100 MERL networks below the data root (``nbrdf_sztrajman2021/merl_nbrdf.zip``)."""
    return data_file(NBRDF_ZIP, root)


def nbrdf_names(path: str | os.PathLike) -> tuple[str, ...]:
    """The material names of a neural-BRDF set (zip or folder): the stems of its ``.h5`` members, in order."""
    with _NetworkSet(path) as nets:
        return tuple(nets.members)


def _is_merl_name(text) -> bool:
    if not isinstance(text, str) or Path(text).expanduser().exists():
        return False
    return "/" not in text and os.sep not in text and not Path(text).suffix


def load_nbrdf(
    path: str | os.PathLike,
    names: str | Sequence[str] | None = None,
    *,
    root: str | os.PathLike | None = None,
) -> NeuralBRDF | dict[str, NeuralBRDF]:
    """Neural BRDFs of any set in the published format (Sztrajman et al. 2021): a zip archive or folder
    holding one Keras weights file ``<material>.h5`` per material, in any sub-folder (e.g. the MERL set,
    the RGL-EPFL isotropic materials, the Nielsen et al. materials, or your own trained networks).

    Args:
        path: the zip or folder. For compatibility, a MERL material name that is not an existing path
            (``load_nbrdf("yellow-plastic")``) reads that material from the data root's MERL zip
            (:func:`merl_nbrdf_path`).
        names: None (every network of the set), one name, or a sequence of names; names match the file
            stems exactly or up to case and ``-``/``_``/space.
        root: data root for the MERL-name form (default ``$POLYJAX_DATA``).

    Returns:
        One name: a :class:`NeuralBRDF`; None or a sequence: ``{name: NeuralBRDF}`` in the set's order
        (or the order asked for).

    Raises:
        DataNotFoundError (no such path), WrongFormatError (not a zip, no ``.h5`` member), HeaderError
        (duplicate names, a network without the 6-21-21-3 layers), UnknownMaterialError (a name not in the set,
        with suggestions).
    """
    if names is None and _is_merl_name(path):
        name = resolve_merl_name(path)
        with _NetworkSet(merl_nbrdf_path(root)) as nets:
            w = nets.read(nets.resolve(name))
        return NeuralBRDF(*(device_array(a) for a in w), name=name)
    with _NetworkSet(path) as nets:
        single = isinstance(names, str)
        if names is None:
            wanted = list(nets.members)
        elif single:
            wanted = [nets.resolve(names)]
        else:
            wanted = [nets.resolve(n) for n in names]
            if not wanted:
                raise InputError("names: expected at least one material name (or None for all)")
        out = {n: NeuralBRDF(*(device_array(a) for a in nets.read(n)), name=n) for n in wanted}
    return out[wanted[0]] if single else out


def _stacked_params(names: Sequence[str], path) -> tuple[np.ndarray, ...]:
    with _NetworkSet(path) as nets:
        ws = [nets.read(nets.resolve(n)) for n in names]
    return tuple(np.stack(parts) for parts in zip(*ws))


@jax.jit
def _eval_grid(params, x):
    """params stacked over materials (m, ...); x (n, 6) -> (m, 3, n), clamped at 0."""
    y = jax.vmap(lambda p: _mlp(p, x))(params)
    return jnp.swapaxes(jnp.maximum(y, 0.0), 1, 2)


@functools.lru_cache(maxsize=2)
def _grid_arrays(subsample, seed: int, dtype_name: str):
    """Device arrays of the kept MERL bins: network inputs (float32), u, v, weights; cached."""
    u, v, w, above = merl_grid(MERL_RESOLUTION)
    keep = _choose_bins(above, subsample, seed, "merl-nbrdf")
    th, td, pd = (a[keep] for a in merl_bin_angles(MERL_RESOLUTION))
    x = np.stack([np.sin(th), np.zeros_like(th), np.cos(th),
                  np.sin(td) * np.cos(pd), np.sin(td) * np.sin(pd), np.cos(td)], axis=-1)
    dtype = np.dtype(dtype_name)
    return (device_array(x, np.float32), device_array(u[keep], dtype), device_array(v[keep], dtype),
            device_array(w[keep], dtype))


def load_merl_nbrdf(
    name_or_names: str | Sequence[str],
    root: str | os.PathLike | None = None,
    subsample: int | float | None = None,
    seed: int = 0,
) -> Measurements:
    """MERL data from the neural fits, evaluated on the MERL grid (90 x 90 x 180 bin centres).

    The samples are the bins with both directions above the horizon (1,111,432 of 1,458,000), or a random
    subset of them reproducible from ``seed``; weights are the bins' solid-angle weights
    (:func:`polyjax.data.merl_bin_weights`). The networks are evaluated in float32, the precision they were
    trained and stored in (relative differences to a float64 evaluation ~1e-6, far below the fit's own
    error), then returned in JAX's default float type.

    Args:
        name_or_names: a MERL name, a sequence of names, ``"table3"`` (:data:`TABLE3_MATERIALS`) or ``"all"``.
        root: data root (default ``$POLYJAX_DATA``).
        subsample: None (all valid bins), a count, or a fraction in (0, 1).
        seed: seed of the subsample.

    Returns:
        One name: ``values (3, n)``, ``axes=("channel",)``, ``names=(name,)``; several: ``(m, 3, n)``,
        ``axes=("material", "channel")``; ``channels=("R", "G", "B")``, BRDF in 1/sr; mask ``(n,)``, all True.
    """
    names, single = _resolve_names(name_or_names)
    return _grid_measurements(merl_nbrdf_path(root), names, single, subsample, seed,
                              "neural-BRDF fits (Sztrajman et al. 2021) of MERL")


def load_nbrdf_measurements(
    path: str | os.PathLike,
    names: str | Sequence[str] | None = None,
    subsample: int | float | None = None,
    seed: int = 0,
) -> Measurements:
    """Any neural-BRDF set (see :func:`load_nbrdf`) evaluated on the MERL grid, as :func:`load_merl_nbrdf` does.

    Args:
        path: zip or folder of ``<material>.h5`` networks.
        names: None (all), one name, or a sequence of names.
        subsample, seed: as in :func:`load_merl_nbrdf`.

    Returns:
        One name: ``values (3, n)``, ``axes=("channel",)``, ``names=(name,)``; None or a sequence:
        ``(m, 3, n)``, ``axes=("material", "channel")``.
    """
    with _NetworkSet(path) as nets:
        if names is None:
            wanted, single = list(nets.members), False
        elif isinstance(names, str):
            wanted, single = [nets.resolve(names)], True
        else:
            wanted, single = [nets.resolve(n) for n in names], False
    if not wanted:
        raise InputError("names: expected at least one material name (or None for all)")
    return _grid_measurements(path, wanted, single, subsample, seed, f"neural BRDFs of {Path(path).name}:")


def _grid_measurements(path, names, single, subsample, seed, what) -> Measurements:
    params = _stacked_params(names, path)
    if subsample is not None and not isinstance(subsample, (int, float, np.integer, np.floating)):
        raise InputError(f"subsample: expected None, a count or a fraction in (0, 1), found {subsample!r}")
    dtype = jnp.dtype(jnp.result_type(float))
    x, u, v, w = _grid_arrays(subsample, int(seed), dtype.name)
    vals = _eval_grid(tuple(device_array(p) for p in params), x).astype(dtype)
    if single:
        vals = vals[0]
    return Measurements(
        u=u, v=v, values=vals, weights=w, mask=jnp.ones(vals.shape[-1:], bool),
        names=tuple(names), channels=("R", "G", "B"),
        axes=("channel",) if single else ("material", "channel"),
        source=f"{what} {', '.join(names)} on the MERL grid, "
        f"{u.shape[0]} bins" + (f" (subsample {subsample}, seed {seed})" if subsample else ""),
    )
