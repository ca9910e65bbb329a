"""Fitting a texture across processes (and hosts) with JAX's own distributed runtime.

Every process calls :func:`jax.distributed.initialize` (coordinator address, process count and id), loads only
its rows of the texture, and the rows of all processes form one global array
(:func:`jax.make_array_from_process_local_data`) sharded over a mesh of every device of every process. The fit
is then the sharded fit of :func:`polyjax.fit_polynomial` (one ``shard_map``, no communication: texels are
independent); each process writes the shards it holds (:func:`write_texture_shards`), so no texture is ever
gathered to one host. On CPUs the processes talk through JAX's CPU collectives (gloo), used here only for
start-up and the scalar summaries.
"""

from __future__ import annotations

import socket
from typing import Callable

import jax
import numpy as np
from jax.sharding import NamedSharding
from jax.sharding import PartitionSpec as P

from .._errors import InputError
from .._fit.polynomial import fit_polynomial
from .._model import PolynomialBRDF

#: the mesh axis of the texel rows
ROWS = "rows"


def initialize(coordinator: str, num_processes: int, process_id: int, *, cpu_collectives: str | None = "gloo",
               timeout_s: int = 120) -> None:
    """:func:`jax.distributed.initialize` for a multi-process fit (on CPUs with ``cpu_collectives``); a no-op for
    one process. Call it first, before any other JAX call of the process."""
    if num_processes < 1 or not (0 <= process_id < num_processes):
        raise InputError(f"process_id, num_processes: expected 0 <= process_id < num_processes, found {process_id} "
                         f"and {num_processes}")
    if num_processes == 1:
        return
    if cpu_collectives:
        jax.config.update("jax_cpu_collectives_implementation", cpu_collectives)
    jax.distributed.initialize(coordinator_address=coordinator, num_processes=int(num_processes),
                               process_id=int(process_id), initialization_timeout=int(timeout_s))


def row_mesh() -> jax.sharding.Mesh:
    """A one-axis mesh (:data:`ROWS`) over every device of every process, in process order."""
    return jax.make_mesh((jax.device_count(),), (ROWS,), devices=sorted(jax.devices(), key=lambda d: (
        d.process_index, d.id)))


def local_rows(height: int, mesh: jax.sharding.Mesh | None = None) -> tuple[int, int]:
    """The rows ``[start, stop)`` of a texture of ``height`` rows that this process holds on ``mesh``."""
    mesh = row_mesh() if mesh is None else mesh
    n = mesh.devices.size
    if height % n:
        raise InputError(f"height: expected a number of texel rows divisible by the {n} devices, found {height}")
    sh = NamedSharding(mesh, P(ROWS))
    idx = sh.addressable_devices_indices_map((height,)).values()
    return min(i[0].start or 0 for i in idx), max(i[0].stop or height for i in idx)


def fit_rows_distributed(load_rows: Callable[[int, int], dict], height: int, variables: str = "lafortune",
                         degree: int = 3, *, mesh=None, **options) -> PolynomialBRDF:
    """Fit a texture of ``height`` rows, every process loading and fitting its own rows.

    Args:
        load_rows: ``load_rows(start, stop) -> dict(u=, v=, values=, weights=)``, the inputs of
            :func:`polyjax.fit_polynomial` for rows ``start .. stop`` (leading axis: rows; per-lane directions).
        height: the texture's rows (divisible by the number of devices).
        variables, degree, options: as in :func:`polyjax.fit_polynomial`.
        mesh: a one-axis mesh over all devices (:func:`row_mesh` by default).

    Returns:
        The fitted :class:`polyjax.PolynomialBRDF` of batch ``(height, ...)``, a global array sharded over the
        rows: each process holds (and should write, :func:`write_texture_shards`) only its own rows.
    """
    mesh = row_mesh() if mesh is None else mesh
    start, stop = local_rows(height, mesh)
    local = load_rows(start, stop)
    sharding = NamedSharding(mesh, P(ROWS))
    glob = {}
    for name, a in local.items():
        a = np.asarray(a)
        if a.shape[0] != stop - start:
            raise InputError(f"load_rows: expected {name} with {stop - start} rows ({start}..{stop}), found "
                             f"{a.shape}")
        glob[name] = jax.make_array_from_process_local_data(sharding, a, (height,) + a.shape[1:])
    return fit_polynomial(glob.pop("u"), glob.pop("v"), glob.pop("values"), variables, degree, **glob, **options)


def free_port() -> int:
    """A free TCP port on localhost (for a coordinator address in tests and examples)."""
    with socket.socket() as s:
        s.bind(("localhost", 0))
        return s.getsockname()[1]


__all__ = ["ROWS", "fit_rows_distributed", "free_port", "initialize", "local_rows", "row_mesh"]
