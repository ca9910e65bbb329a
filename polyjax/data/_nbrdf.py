r"""Neural-BRDF fits of the 100 MERL materials (Sztrajman, Rainer, Ritschel, Weyrich 2021), in JAX.

File below the data root: ``nbrdf_sztrajman2021/merl_nbrdf.zip`` holding ``merl_nbrdf/<name>.h5``
(Keras weights) for every name of :data:`MERL_NAMES`. The network of each material is

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
import zipfile
from pathlib import Path
from typing import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._config import data_file
from .._errors import InputError
from .._measurements import Measurements
from ._errors import HeaderError, NonFiniteValueError, UnknownMaterialError, WrongFormatError
from ._merl import MERL_NAMES, MERL_RESOLUTION, TABLE3_MATERIALS, _choose_bins, merl_bin_angles, merl_grid

NBRDF_ZIP = "nbrdf_sztrajman2021/merl_nbrdf.zip"
_LAYERS = (("dense_1", (6, 21)), ("dense_2", (21, 21)), ("dense_3", (21, 3)))


def _mlp(params, x):
    """The network on inputs ``x (..., 6)``: raw RGB ``(..., 3)`` (may be negative)."""
    w1, b1, w2, b2, w3, b3 = (p.astype(x.dtype) for p in params)
    a = jax.nn.relu(x @ w1 + b1)
    a = jax.nn.relu(a @ w2 + b2)
    return jnp.expm1(a @ w3 + b3)


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
        valid = (u[..., 2] > 0) & (v[..., 2] > 0)
        y = _mlp(self.params, _half_diff_inputs(u, v))
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


def _read_weights(zf: zipfile.ZipFile, zpath: Path, name: str) -> tuple[np.ndarray, ...]:
    import h5py

    member = f"merl_nbrdf/{name}.h5"
    try:
        blob = zf.read(member)
    except KeyError:
        raise WrongFormatError(zpath, f"the member {member!r} in the neural-BRDF zip", "no such member") from None
    try:
        f = h5py.File(io.BytesIO(blob), "r")
    except OSError as e:
        raise WrongFormatError(zpath, f"an HDF5 file in {member!r}", f"unreadable content ({e})") from None
    out = []
    with f:
        for layer, shape in _LAYERS:
            for kind, shp in (("kernel:0", shape), ("bias:0", shape[1:])):
                key = f"{layer}/{layer}/{kind}"
                if key not in f:
                    raise HeaderError(zpath, f"dataset {key!r} in {member!r}", f"datasets {sorted(_h5_keys(f))}")
                a = np.asarray(f[key], dtype=np.float32)
                if a.shape != shp:
                    raise HeaderError(zpath, f"{key!r} of shape {shp} in {member!r}", f"shape {a.shape}")
                if not np.all(np.isfinite(a)):
                    raise NonFiniteValueError(zpath, f"finite weights in {member!r}/{key}", "NaN or inf")
                out.append(a)
    return tuple(out)


def _h5_keys(f) -> list[str]:
    keys = []
    f.visititems(lambda k, v: keys.append(k) if hasattr(v, "shape") else None)
    return keys


def _open_zip(root) -> tuple[zipfile.ZipFile, Path]:
    zpath = data_file(NBRDF_ZIP, root)
    try:
        return zipfile.ZipFile(zpath), zpath
    except zipfile.BadZipFile:
        raise WrongFormatError(zpath, "a zip archive of Keras .h5 networks", "a file that is not a zip archive") from None


def load_nbrdf(name: str, root: str | os.PathLike | None = None) -> NeuralBRDF:
    """The neural BRDF of one MERL material, read straight from the zip.

    Args:
        name: a MERL name, e.g. ``"yellow-plastic"`` (see :data:`MERL_NAMES`).
        root: data root (default ``$POLYJAX_DATA``).
    """
    name = resolve_merl_name(name)
    zf, zpath = _open_zip(root)
    with zf:
        w = _read_weights(zf, zpath, name)
    return NeuralBRDF(*(jnp.asarray(a) for a in w), name=name)


def _stacked_params(names: Sequence[str], root) -> tuple[np.ndarray, ...]:
    zf, zpath = _open_zip(root)
    with zf:
        ws = [_read_weights(zf, zpath, n) for n in names]
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
    return (jnp.asarray(x, jnp.float32), jnp.asarray(u[keep], dtype), jnp.asarray(v[keep], dtype),
            jnp.asarray(w[keep], dtype))


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
        One name: ``values (3, n)``, ``axes=("channel",)``; several: ``(m, 3, n)``,
        ``axes=("material", "channel")``; ``channels=("R", "G", "B")``, BRDF in 1/sr; mask all True.
    """
    names, single = _resolve_names(name_or_names)
    params = _stacked_params(names, root)
    if subsample is not None and not isinstance(subsample, (int, float, np.integer, np.floating)):
        raise InputError(f"subsample: expected None, a count or a fraction in (0, 1), found {subsample!r}")
    dtype = jnp.dtype(jnp.result_type(float))
    x, u, v, w = _grid_arrays(subsample, int(seed), dtype.name)
    vals = _eval_grid(tuple(jnp.asarray(p) for p in params), x).astype(dtype)
    if single:
        vals = vals[0]
    return Measurements(
        u=u, v=v, values=vals, weights=w, mask=jnp.ones(vals.shape, bool),
        names=() if single else tuple(names), channels=("R", "G", "B"),
        axes=("channel",) if single else ("material", "channel"),
        source=f"neural-BRDF fits (Sztrajman et al. 2021) of MERL {', '.join(names)} on the MERL grid, "
        f"{u.shape[0]} bins" + (f" (subsample {subsample}, seed {seed})" if subsample else ""),
    )
