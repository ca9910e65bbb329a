"""Arrays: whether values are traced, and host data onto the device without a compiled program.

:func:`is_traced` is the one test of "is this inside ``jit``/``grad``/``vmap``?" (a tracer among the leaves); every
eager-only check (a Python error before any work, a table look-up, a memo) asks it.

In this JAX, ``jnp.asarray`` of a numpy array (or a list) runs a small compiled program (``jit(stage)``, or
``jit(convert_element_type)`` with a ``dtype``) and compiles it anew for every new shape: ~20 ms each, most of the
cost of loading a model or a data set of a new size. :func:`device_array` converts on the host with numpy and hands
the result to :func:`jax.device_put`, which compiles nothing; JAX arrays and tracers go through ``jnp.asarray``
unchanged (inside a trace nothing is compiled).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np


def is_traced(*xs) -> bool:
    """True when a leaf of any argument is a JAX tracer (``jit``/``grad``/``vmap`` hand tracers in)."""
    return any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree.leaves(xs))


def is_concrete(*xs) -> bool:
    """True when no leaf of any argument is a JAX tracer: ``not is_traced(*xs)``."""
    return not is_traced(*xs)


def device_array(a, dtype=None) -> jax.Array:
    """``jnp.asarray(a, dtype)`` with the same dtype rules (JAX's canonical dtypes: float64 only with x64 on), but
    host data (numpy arrays, sequences, numpy scalars) converted by numpy and put on the default device: no compiled
    program. Python scalars and JAX arrays (concrete or traced) go to ``jnp.asarray`` (weak types kept)."""
    if isinstance(a, (jax.Array, int, float, complex, bool)) or a is None:
        return jnp.asarray(a, dtype)
    host = np.asarray(a)
    if host.dtype == np.dtype(object):
        return jnp.asarray(a, dtype)
    want = jax.dtypes.canonicalize_dtype(host.dtype if dtype is None else dtype)
    return jax.device_put(host.astype(want, copy=False))


def cast_concrete(x, dtype) -> jax.Array:
    """``x.astype(dtype)`` for a JAX array; a concrete, unsharded one of another dtype is converted on the host (no
    compiled program); tracers and sharded arrays are cast on the device."""
    if x.dtype == dtype:
        return x
    if is_traced(x) or len(getattr(x, "devices", lambda: ())()) != 1:
        return x.astype(dtype)
    return jax.device_put(np.asarray(x).astype(dtype), next(iter(x.devices())))
