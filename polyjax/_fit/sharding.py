"""Fits of inputs sharded over their lanes: each device fits its own lanes, the result stays where it was computed.

A fit's lanes (materials, channels, texels) are independent, so a batch sharded over its leading axis with a
:class:`jax.sharding.NamedSharding` needs no communication at all. It is run under :func:`jax.shard_map` rather
than handed to the partitioner: the per-lane path loops over blocks of lanes (:func:`jax.lax.map`) and maps its
factorisations one matrix at a time (``custom_vmap`` in :mod:`polyjax._solve.linalg`), and neither partitions along
the mapped axis. With ``Explicit`` mesh axes (the default of :func:`jax.make_mesh`) ``vmap`` refuses a batch
sharded differently from the replicated design ("Mapped away dimension ... should be sharded the same"); inputs
on a mesh with ``Auto`` axes take the same path. Under ``shard_map`` every
device runs the unsharded program on its own block of lanes, so the numbers are those of an unsharded fit.

Rule: only the leading batch axis of ``values`` (and of per-lane ``u``, ``v``, ``weights``, ``mask``) may be
sharded, over any mesh axes (``P("x")``, ``P(("x", "y"))``); the sample axis and the other batch axes must be
replicated, and the leading axis must divide evenly among the devices.
"""

from __future__ import annotations

import functools

import jax
import numpy as np
from jax.sharding import NamedSharding
from jax.sharding import PartitionSpec as P

from .._arrays import is_traced
from .._errors import InputError


def _named_sharding(a):
    """The :class:`NamedSharding` of ``a`` (concrete or traced), or None."""
    if is_traced(a):
        try:
            sh = jax.typeof(a).sharding
        except Exception:  # noqa: BLE001 - a tracer without a sharding in its type
            return None
    else:
        sh = getattr(a, "sharding", None)
    if not isinstance(sh, NamedSharding) or sh.mesh.empty:
        return None
    return sh


def _axes(entry) -> tuple[str, ...]:
    if entry is None:
        return ()
    return tuple(entry) if isinstance(entry, tuple) else (entry,)


def lane_sharding(batch_ndim: int, named: dict):
    """``(mesh, lane_axes)`` when the inputs are sharded over their leading batch axis, else None.

    Args:
        batch_ndim: number of batch axes of ``values``.
        named: ``{argument name: (array, number of trailing unbatched axes)}``.

    Raises:
        InputError: a sharded sample axis or a non-leading batch axis, or arguments sharded differently.
    """
    found = None
    for name, (a, trailing) in named.items():
        if a is None:
            continue
        sh = _named_sharding(a)
        if sh is None:
            continue
        spec = tuple(sh.spec) + (None,) * (np.ndim(a) - len(sh.spec))
        lead = np.ndim(a) - trailing
        if any(_axes(e) for e in spec[1:]) or (lead == 0 and _axes(spec[0])):
            raise InputError(
                f"{name}: expected a sharding over the leading batch axis only (e.g. PartitionSpec('x')), found "
                f"{sh.spec} for shape {np.shape(a)}; the sample axis and other batch axes must be replicated")
        axes = _axes(spec[0])
        if not axes:
            continue
        if found is not None and (found[0] != sh.mesh or found[1] != axes):
            raise InputError(f"{name}: expected the sharding of the other inputs ({found[1]} on {found[0]}), found "
                             f"{axes} on {sh.mesh}")
        found = (sh.mesh, axes)
    if found is None:
        return None
    mesh, axes = found
    size = int(np.prod([mesh.shape[ax] for ax in axes]))
    lead = next(np.shape(a)[0] for a, t in named.values() if a is not None and np.ndim(a) > t)
    if batch_ndim == 0 or lead % size:
        raise InputError(f"values: expected a leading batch axis divisible by the {size} devices it is sharded "
                         f"over, found {lead}")
    return found


def _place(a, mesh, spec):
    """``a`` laid out as ``spec`` on ``mesh``: moves blocks between devices when needed, never gathers a batch."""
    target = NamedSharding(mesh, spec)
    if is_traced(a):
        return jax.sharding.reshard(a, target)
    if getattr(a, "sharding", None) == target:
        return a
    return jax.device_put(a, target)


def shard_lanes(kernel, mesh, axes, inp, *args, out_lane_axis: int = 1):
    """Run ``kernel(inp, *args)`` on every device's block of lanes under :func:`jax.shard_map`.

    ``kernel`` is a :func:`functools.partial` of a function with hashable keywords (the compiled program is cached
    on them, the mesh and the layout); ``inp`` is a :class:`polyjax.PreparedInputs` whose lane arrays are sharded
    over ``axes``; ``args`` are replicated. Every output array has its lane axis at ``out_lane_axis`` and comes
    back sharded over ``axes``.
    """
    layout = (inp.lane_directions, inp.weights.shape[0] == 1, inp.mask.shape[0] == 1, inp.batch, inp.shared)
    fn, in_inp = _compiled(kernel.func, tuple(sorted(kernel.keywords.items())), mesh, axes, layout, len(args),
                           out_lane_axis, type(inp))
    inp = jax.tree.map(lambda a, spec: _place(a, mesh, spec), inp, in_inp)
    return fn(inp, *args)


@functools.lru_cache(maxsize=64)
def _compiled(func, keywords, mesh, axes, layout, n_args, out_lane_axis, inp_type):
    lane_dirs, w_shared, m_shared, batch, shared = layout
    lane = P(axes)
    in_inp = inp_type(
        u=lane if lane_dirs else P(), v=lane if lane_dirs else P(), values=lane, weights=P() if w_shared else lane,
        mask=P() if m_shared else lane, lane_bad=lane, batch=batch, shared=shared, lane_directions=lane_dirs,
    )
    out = P(*((None,) * out_lane_axis + (axes,)))
    fn = jax.shard_map(functools.partial(func, **dict(keywords)), mesh=mesh, in_specs=(in_inp,) + (P(),) * n_args,
                       out_specs=out, check_vma=False)
    return jax.jit(fn), in_inp
