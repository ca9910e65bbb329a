r"""The saved-model kind of :class:`CompactBRDF` (``polyjax.CompactBRDF``; file format in ``docs/formats.md``).

The header's ``static`` holds ``family`` (its name), ``config`` (the configuration's ``repr``), ``n_numbers`` (per
material) and ``leaves`` (the parameters' pytree paths, in order); the arrays are the parameters' leaves ``p0``,
``p1``, ... and the held-out errors ``l2`` and ``log``. Loading finds the configuration among the family's
configurations of at most ``n_numbers`` numbers by its ``repr``, and the parameters' tree structure by tracing the
family's fit on a small problem (no computation).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from .._arrays import device_array
from .._io import ModelKind, register_model_kind
from .model import CompactBRDF, family_named

KIND_NAME = "polyjax.CompactBRDF"
_PROBE_SAMPLES = 64


def _to_arrays(model: CompactBRDF) -> tuple[dict, dict]:
    leaves = jax.tree_util.tree_flatten_with_path(model.params)[0]
    static = {"family": model.family, "config": repr(model.config), "n_numbers": model.n_numbers,
              "leaves": [jax.tree_util.keystr(path) for path, _ in leaves]}
    arrays = {f"p{i}": np.asarray(leaf) for i, (_, leaf) in enumerate(leaves)}
    arrays.update(l2=np.asarray(model.l2), log=np.asarray(model.log))
    return static, arrays


def config_from_repr(family: str, text: str, n_numbers: int):
    """The configuration of ``family`` whose ``repr`` is ``text``, among those of at most ``n_numbers`` numbers."""
    for c in family_named(family).configs(int(n_numbers)):
        if repr(c) == text:
            return c
    raise KeyError(f"family {family!r} has no configuration {text} of at most {n_numbers} numbers")


@functools.lru_cache(maxsize=64)
def params_structure(family: str, config):
    """The tree structure of ``family``'s parameters for ``config`` (its fit traced on a small problem)."""
    rng = np.random.default_rng(0)
    d = rng.normal(size=(2, _PROBE_SAMPLES, 3))
    d[..., 2] = np.abs(d[..., 2]) + 0.1
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    u, v = jnp.asarray(d[0]), jnp.asarray(d[1])
    values = jnp.ones((3, _PROBE_SAMPLES))
    shapes = jax.eval_shape(lambda a, b, y: family_named(family).fit(
        config, a, b, y, jnp.ones(_PROBE_SAMPLES), jnp.ones((3, _PROBE_SAMPLES), bool), "log"), u, v, values)
    return jax.tree.structure(shapes)


def _from_arrays(static: dict, arrays: dict) -> CompactBRDF:
    family = static["family"]
    config = config_from_repr(family, static["config"], static["n_numbers"])
    tree = params_structure(family, config)
    leaves = [device_array(arrays[f"p{i}"]) for i in range(tree.num_leaves)]
    return CompactBRDF(params=jax.tree.unflatten(tree, leaves), l2=device_array(arrays["l2"]),
                       log=device_array(arrays["log"]), family=family, config=config)


KIND = register_model_kind(ModelKind(kind=KIND_NAME, type=CompactBRDF, to_arrays=_to_arrays,
                                     from_arrays=_from_arrays))
