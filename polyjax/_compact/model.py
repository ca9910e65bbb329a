r"""The fitted compact BRDF: one family's configuration and its parameters, for a batch of materials.

A :class:`CompactBRDF` is a model of at most ``N`` numbers per material chosen by :func:`polyjax.fit_compact`: the
family (``polyjax/_compact/families``) and its static configuration, the parameters the family's fit returned
(a pytree of arrays with leading axes ``(*batch)``, materials), and the held-out errors that chose it.
"""

from __future__ import annotations

import functools
from collections.abc import Hashable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._directions import call_directions, safe_normalize
from .._errors import UnknownNameError
from .._model import _from_key, _index_key
from .families import FAMILIES


def family_named(name: str):
    """The registered family ``name``; UnknownNameError naming the known ones."""
    if name not in FAMILIES:
        raise UnknownNameError(f"family {name!r}: expected one of {sorted(FAMILIES)}")
    return FAMILIES[name]


class CompactBRDF(eqx.Module):
    r"""A compact BRDF of RGB values: ``f(u, v) = F_c(theta; u, v)`` for the family ``F`` and configuration ``c``.

    Attributes:
        params: the family's parameters, a pytree of arrays with leading axes ``(*batch)`` (materials).
        l2, log: ``(*batch,)`` the held-out errors of the choice (cross-validation on the fitted data: the L2 of
            equation (11) and the log metric of :func:`polyjax.log_error`, each the root mean square over R, G, B
            and over the folds); NaN when the model was not chosen by cross-validation.
        family: the family's name (a key of the registry of families).
        config: the family's static configuration (hashable).

    Evaluating (``model(u, v)``) gives ``(*batch, 3, ...)``: finite, non-negative, bounded, 0 below the horizon;
    it is differentiable in the parameters and in the directions, and jitted (one program per family, config
    and shapes).
    """

    params: Any
    l2: Float[Array, "*batch"]
    log: Float[Array, "*batch"]
    family: str = eqx.field(static=True)
    config: Hashable = eqx.field(static=True)

    def __check_init__(self):
        family_named(self.family)

    @property
    def materials_shape(self) -> tuple[int, ...]:
        """The materials' axes ``(*batch)``."""
        return tuple(jnp.shape(self.l2))

    @property
    def batch_shape(self) -> tuple[int, ...]:
        """The leading axes of the model's values, ``(*batch, 3)`` (materials, then channels), as every fitted
        model's: one material is ``(3,)``, an RGB BRDF to the renderer, the exporters and the viewer."""
        return self.materials_shape + (3,)

    @property
    def n_numbers(self) -> int:
        """Numbers stored per material (every coefficient and value, all three channels counted)."""
        return int(family_named(self.family).n_numbers(self.config))

    def __getitem__(self, index) -> "CompactBRDF":
        """Select materials of the batch (``model[3]``, ``model[:2]``; the channel axis is not indexed)."""
        if not self.materials_shape:
            raise IndexError("this CompactBRDF has no batch axes")
        key = _index_key(index)
        if key is None:  # an array index
            return jax.tree.map(lambda a: a[index], self)
        return _select(self, key)

    def __call__(self, u: ArrayLike, v: ArrayLike) -> Float[Array, "*batch 3 ..."]:
        """Evaluate at light directions ``u`` and view directions ``v``.

        Args:
            u, v: ``(..., 3)`` directions (broadcast together; renormalised).

        Returns:
            ``(*batch, 3, ...)`` RGB values in 1/sr; 0 where ``u`` or ``v`` is below the horizon.
        """
        u, v = call_directions(u, v, jax.tree.leaves(self.params)[0].dtype)
        return _evaluate(self, u, v)


def evaluate_family(family: str, config, params, u, v):
    """``family``'s values ``(*batch, 3, ...)`` at directions ``(..., 3)`` (traceable; 0 below the horizon)."""
    dtype = jax.tree.leaves(params)[0].dtype
    u, ok_u = safe_normalize(jnp.asarray(u, dtype))
    v, ok_v = safe_normalize(jnp.asarray(v, dtype))
    u, v = jnp.broadcast_arrays(u, v)
    shape = u.shape[:-1]
    above = (ok_u & ok_v & (u[..., 2] > 0) & (v[..., 2] > 0)).reshape(-1)
    uf, vf = u.reshape(-1, 3), v.reshape(-1, 3)
    out = family_named(family).evaluate(config, params, uf, vf)
    out = jnp.where(above & jnp.isfinite(out), out, 0.0)
    return out.reshape(out.shape[:-1] + shape)


@jax.jit
def _evaluate(model: CompactBRDF, u, v):
    """:meth:`CompactBRDF.__call__` after its checks, one compiled program."""
    return evaluate_family(model.family, model.config, model.params, u, v)


@functools.partial(jax.jit, static_argnames=("key",))
def _select(model: CompactBRDF, key) -> CompactBRDF:
    index = _from_key(key)
    return jax.tree.map(lambda a: a[index], model)
