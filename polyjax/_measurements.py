"""The measurements pytree that every loader returns and every fitter takes."""

from __future__ import annotations

from typing import Sequence

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from ._arrays import device_array
from ._errors import InputError


class Measurements(eqx.Module):
    """Measured BRDF samples sharing one set of directions.

    Attributes:
        u: light (incoming) directions, unit vectors ``(n, 3)`` in the local frame (normal ``+z``).
        v: view (outgoing) directions ``(n, 3)``.
        values: BRDF values in 1/sr, shape ``(*batch, n)``: samples last, leading axes are
            materials and/or colour channels (see ``axes``).
        weights: solid-angle weights ``w_i`` of equation (11), shape ``(n,)`` or ``(*batch, n)``
            (1 where the data gives none).
        mask: True where a measurement is valid (e.g. MERL's negative entries are False): ``(n,)`` when every
            lane has the same valid samples (what the loaders return then), else ``(*batch, n)``.
        names: material (or sample) names: one per entry of the first batch axis when that axis is
            materials, or the one material's name when there is no material axis (e.g. a single file
            loaded by path: ``values (3, n)``, ``axes=("channel",)``, ``names=("<file stem>",)``).
        ids: sample numbers along the first batch axis (CUReT), if any.
        channels: channel labels, e.g. ``("avg",)`` or ``("R", "G", "B")``.
        axes: names of the batch axes, e.g. ``("material",)`` or ``("material", "channel")``.
        source: a one-line description of where the data came from.
    """

    u: Float[Array, "n 3"]
    v: Float[Array, "n 3"]
    values: Float[Array, "*batch n"]
    weights: Float[Array, "*wbatch n"]
    mask: Bool[Array, "*mbatch n"]
    names: tuple[str, ...] = eqx.field(static=True, default=())
    ids: tuple[int, ...] = eqx.field(static=True, default=())
    channels: tuple[str, ...] = eqx.field(static=True, default=())
    axes: tuple[str, ...] = eqx.field(static=True, default=())
    source: str = eqx.field(static=True, default="")

    @property
    def n_samples(self) -> int:
        """Number of (u, v) sample pairs."""
        return int(self.u.shape[0])

    @property
    def batch_shape(self) -> tuple[int, ...]:
        return tuple(self.values.shape[:-1])

    def __getitem__(self, index) -> "Measurements":
        """Select along the first batch axis (e.g. one material), keeping directions."""
        if not self.batch_shape:
            raise InputError("Measurements has no batch axis to index")
        idx = np.arange(self.batch_shape[0])[index]
        scalar = np.ndim(idx) == 0
        w, mask = self.weights, self.mask
        if w.ndim == self.values.ndim:
            w = w[idx]
        if mask.ndim == self.values.ndim:
            mask = mask[idx]
        names = self.names
        ids = self.ids
        per_entry = len(names) == self.batch_shape[0] and not (self.axes and self.axes[0] == "channel")
        if names and per_entry:
            names = (names[int(idx)],) if scalar else tuple(names[int(i)] for i in idx)
        if ids:
            ids = (ids[int(idx)],) if scalar else tuple(ids[int(i)] for i in idx)
        axes = self.axes[1:] if scalar else self.axes
        return Measurements(
            u=self.u, v=self.v, values=self.values[idx], weights=w, mask=mask,
            names=names, ids=ids, channels=self.channels, axes=axes, source=self.source,
        )

    def select(self, names: Sequence[str]) -> "Measurements":
        """Select materials along the first batch axis by name."""
        index = []
        for n in names:
            if n not in self.names:
                raise InputError(f"no material {n!r} in these measurements; have {list(self.names)}")
            index.append(self.names.index(n))
        return self[np.asarray(index)]

    def valid_fraction(self) -> float:
        return float(jnp.mean(jnp.broadcast_to(self.mask, self.values.shape)))


def check_samples(u, v, values, *, concrete: bool = True) -> int:
    """Check the shapes shared by every fitter: ``u``, ``v`` ``(n, 3)``, ``values`` ``(..., n)``.

    With ``concrete`` (arrays, not tracers) the directions must also be finite. Raises
    :class:`InputError` naming the argument, what was expected and what was found.

    Returns:
        ``n``, the number of samples.
    """
    for name, w in (("u", u), ("v", v)):
        if w.ndim != 2 or w.shape[-1] != 3:
            raise InputError(f"{name}: expected directions of shape (n, 3), found {w.shape}")
        if concrete and not np.all(np.isfinite(np.asarray(w))):
            raise InputError(f"{name}: expected finite direction vectors, found NaN or inf")
    if u.shape != v.shape:
        raise InputError(f"u and v: expected the same shape (n, 3), found {u.shape} and {v.shape}")
    n = u.shape[0]
    if values.ndim < 1 or values.shape[-1] != n:
        raise InputError(f"values: expected shape (..., {n}) with samples last (n = len(u)), found {values.shape}")
    return n


def lane_mask(valid: np.ndarray) -> np.ndarray:
    """A loader's mask from ``valid (*batch, n)``: its ``(n,)`` row when every lane (material, channel) has the
    same valid samples (the usual case; a fit then shares one design across the lanes), else a copy of ``valid``."""
    valid = np.asarray(valid, dtype=bool)
    flat = valid.reshape(-1, valid.shape[-1])
    return flat[0].copy() if bool(np.all(flat == flat[:1])) else valid.copy()


def make_measurements(
    u, v, values, *, weights=None, mask=None, names=(), ids=(), channels=(), axes=(), source="",
    dtype=None,
) -> Measurements:
    """Build a :class:`Measurements` after checking shapes; non-finite values are masked out.

    Args:
        u, v: ``(n, 3)`` directions (renormalised here).
        values: ``(*batch, n)``.
        weights: ``(n,)`` or ``(*batch, n)``; defaults to ones.
        mask: ``(n,)`` or ``(*batch, n)`` bool; defaults to ``isfinite(values)``. Stored as ``(n,)`` when every
            lane has the same valid samples, else ``(*batch, n)``.
    """
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    values = np.asarray(values, dtype=np.float64)
    n = check_samples(u, v, values)
    for name, w in (("u", u), ("v", v)):
        if np.any(np.linalg.norm(w, axis=-1) == 0):
            raise InputError(f"{name}: expected non-zero direction vectors, found a zero vector")
    finite = np.isfinite(values)
    m = finite if mask is None else (np.asarray(mask, dtype=bool) & finite)
    m = lane_mask(np.broadcast_to(m, values.shape))
    if weights is None:
        weights = np.ones(n)
    weights = np.asarray(weights, dtype=np.float64)
    if weights.shape[-1] != n:
        raise InputError(f"weights: expected shape (..., {n}), found {weights.shape}")
    u = u / np.linalg.norm(u, axis=-1, keepdims=True)
    v = v / np.linalg.norm(v, axis=-1, keepdims=True)
    values = np.where(finite, values, 0.0)
    return Measurements(
        u=device_array(u, dtype), v=device_array(v, dtype), values=device_array(values, dtype),
        weights=device_array(weights, dtype), mask=device_array(m),
        names=tuple(names), ids=tuple(int(i) for i in ids), channels=tuple(channels),
        axes=tuple(axes), source=source,
    )
