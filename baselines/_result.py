"""The result of :func:`baselines.fit`: :class:`BaselineFit`, evaluable at any directions, and the material of one
fitted lane of a standard model (:func:`standard_material`)."""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from polyjax import InputError, safe_normalize
from polyjax.internal import status_warnings

from ._models.common import BaselineModel
from ._models.materials import channel_parameters
from ._models.registry import get_model


class BaselineFit(eqx.Module):
    """The result of :func:`baselines.fit` for a batch of lanes (materials, channels).

    Attributes:
        params: ``(*batch, P)`` constrained (physical) parameters, see ``param_names``.
        raw: ``(*batch, P)`` the unconstrained parameters the optimiser worked on.
        l2: ``(*batch,)`` L2 of equation (11) (:func:`polyjax.l2_error`) of the kept start.
        status: ``(*batch,)`` :class:`polyjax.RESULTS` code of the kept start.
        steps: ``(*batch,)`` solver steps of the kept start (both stages).
        success: ``(*batch,)`` True when the kept start converged to a finite L2.
        start_l2: ``(*batch, S)`` final L2 of every start (``inf`` for non-finite ones).
        start_status: ``(*batch, S)`` code of every start.
        best_start: ``(*batch,)`` index of the kept start.
        at_limit: ``(*batch, P)`` True for a parameter on (within 0.01 in ``sin^2`` of) a limit of its
            range (e.g. ``F0 = 1``, an exponent at its lower bound): the data asks for a value the
            model's valid range excludes.
        name: model name; ``backend``: solver used.
    """

    params: Float[Array, "*batch P"]
    raw: Float[Array, "*batch P"]
    l2: Float[Array, "*batch"]
    status: Int[Array, "*batch"]
    steps: Int[Array, "*batch"]
    success: Bool[Array, "*batch"]
    start_l2: Float[Array, "*batch S"]
    start_status: Int[Array, "*batch S"]
    best_start: Int[Array, "*batch"]
    at_limit: Bool[Array, "*batch P"]
    name: str = eqx.field(static=True)
    backend: str = eqx.field(static=True, default="optimistix")

    @property
    def model(self) -> BaselineModel:
        return get_model(self.name)

    @property
    def param_names(self) -> tuple[str, ...]:
        if self.name == "zernike":
            return tuple(f"c{j}" for j in range(self.params.shape[-1]))
        return self.model.param_names

    @property
    def batch_shape(self) -> tuple[int, ...]:
        return tuple(self.l2.shape)

    @property
    def warnings(self) -> list[str]:
        """One line per result code other than ``OK`` among the lanes: how many lanes ended with it (e.g.
        ``MAX_STEPS``: the step limit reached before the tolerances; raise ``max_steps`` or ``n_starts``), which
        (their indices in the batch, the first ten), and what the code means; ``[]`` when every lane is ``OK``."""
        return status_warnings(np.asarray(self.status))

    def material(self, index=()) -> dict:
        """The fitted material ``index`` of a standard model, named as its specification names it
        (:func:`baselines.standard_material`; what :func:`polyjax.export.gltf` and ``mitsuba_xml`` take)."""
        return standard_material(self, index)

    def __getitem__(self, index) -> "BaselineFit":
        """Select lanes of the batch (``fit[3]``, ``fit[1, 0]``, ``fit[:, 0]``), as ``PolynomialBRDF[index]``."""
        if not self.batch_shape:
            raise IndexError("this BaselineFit has no batch axes")
        idx = index if isinstance(index, tuple) else (index,)
        if len(idx) > len(self.batch_shape):
            raise IndexError(f"too many indices ({len(idx)}) for a BaselineFit of batch shape {self.batch_shape}")
        return jax.tree.map(lambda a: a[idx], self)

    def __call__(self, u, v) -> Float[Array, "*batch ..."]:
        """Evaluate every fitted lane at directions ``u, v`` ``(..., 3)`` (broadcast together, e.g. ``(n, 3)``
        or an image's ``(h, w, 3)``): returns ``(*batch, ...)``, as :class:`polyjax.PolynomialBRDF` does.

        Directions are renormalised, as :func:`fit` does with its inputs (so a non-unit ``u`` gives
        the same value as ``u / |u|``); a zero vector has no direction and gives 0.
        """
        u = jnp.asarray(u, self.params.dtype)
        v = jnp.asarray(v, self.params.dtype)
        if u.ndim < 1 or v.ndim < 1 or u.shape[-1] != 3 or v.shape[-1] != 3:
            raise InputError(f"u, v: expected directions of shape (..., 3), found {u.shape} and {v.shape}")
        try:
            jnp.broadcast_shapes(u.shape, v.shape)
        except ValueError:
            raise InputError(f"u and v: expected shapes that broadcast together, found {u.shape} and "
                             f"{v.shape}") from None
        return _evaluate_batch(self.name, self.params, u, v)


@functools.partial(jax.jit, static_argnames=("name",))
def _evaluate_batch(name, params, u, v):
    """:meth:`BaselineFit.__call__` after its checks, in one compiled program: the directions broadcast and
    flattened to ``(N, 3)``, every lane evaluated there, the result shaped ``(*batch, *directions)``."""
    model = get_model(name)
    shape = jnp.broadcast_shapes(u.shape, v.shape)
    u, ok_u = safe_normalize(jnp.broadcast_to(u, shape).reshape(-1, 3))
    v, ok_v = safe_normalize(jnp.broadcast_to(v, shape).reshape(-1, 3))
    flat = params.reshape(-1, params.shape[-1])
    out = jax.vmap(lambda p: jnp.where(ok_u & ok_v, model.evaluate(p, u, v), 0.0))(flat)
    return out.reshape(params.shape[:-1] + shape[:-1])


def standard_material(fit, index=()) -> dict:
    """The material of one fitted material lane of a standard model, named as its specification names it.

    Args:
        fit: a :class:`baselines.BaselineFit` of a standard model (:data:`baselines.STANDARD_MODELS`), params
            ``(..., 3, P)``.
        index: the material's index in the batch axes before the channel axis (``()`` for one material).

    Returns:
        ``{"model": <name>, <parameter>: float or [r, g, b], ...}``, e.g. for ``gltf-pbr``
        ``{"model": "gltf-pbr", "baseColorFactor": [r, g, b], "metallicFactor": m, "roughnessFactor": r}``;
        ready for :func:`polyjax.export.gltf` and :func:`polyjax.export.mitsuba_xml`.

    Raises:
        InputError: ``fit`` is not a fit of a standard model, or ``index`` does not select one material.
    """
    name = getattr(fit, "name", None)
    model = get_model(name) if isinstance(name, str) else None
    if model is None or model.to_material is None:
        raise InputError(f"fit: expected a baselines fit of a standard material model, found {name!r}")
    index = index if isinstance(index, tuple) else (index,)
    params = np.asarray(fit.params)
    try:
        p = params[index]
    except IndexError as err:
        raise InputError(f"index: {index} is not a material of the fit's batch shape {params.shape[:-2]}") from err
    channel_parameters(p, model.n_params, f"index: expected one material's (3, {model.n_params}) parameters",
                       f"; the fit's batch shape is {params.shape[:-1]}")
    return model.to_material(p)
