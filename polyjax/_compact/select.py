r"""The choice of a compact model by k-fold cross-validation over the samples.

The samples are split into ``folds`` parts by a fixed random permutation (seed 0: the same split for every
material and every run). For each candidate ``(family, config)`` every fold is fitted on the other folds' samples
(the held-out ones masked out) and scored on its own; a candidate's held-out error of one material is

.. math::
    E = \Big[\frac{1}{K}\sum_{k} \frac{1}{3}\sum_{c \in RGB} \varphi_{k,c}^2\Big]^{1/2}

with ``phi`` the L2 of equation (11) (80-degree cutoff) or the log metric of :func:`polyjax.log_error` (every bin
above the horizon). The same rule chooses for every material: the candidate of least held-out error in the
metric asked for; a batch of materials shares one choice, the least geometric mean of ``E`` over the batch.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from .._metrics import _l2_core, _log_core
from .families._grid import node_directions
from .model import family_named

#: the split's seed: the same folds for every material and every run
FOLD_SEED = 0
#: a candidate whose refit exceeds this many times the largest measured value at a node of the grid is refused
PEAK_LIMIT = 10.0


@functools.cache
def _node_directions():
    """Light and view directions of the folded grid's nodes (``families/_grid.py``) both above the horizon."""
    u, v = node_directions()
    keep = (u[:, 2] > 1e-6) & (v[:, 2] > 1e-6)
    return u[keep], v[keep]


def fold_ids(n: int, folds: int) -> np.ndarray:
    """``(n,)`` the fold of each sample: a fixed random permutation's position modulo ``folds``."""
    perm = np.random.default_rng(FOLD_SEED).permutation(n)
    ids = np.empty(n, np.int32)
    ids[perm] = np.arange(n) % folds
    return ids


def rgb_errors(values, predicted, u, v, weights, mask):
    """``(l2, log)`` per material ``(*batch,)``: each the root mean square over the three channels."""
    l2 = _l2_core(values, predicted, u, v, weights, mask, cutoff_deg=80.0)
    lg = _log_core(values, predicted, u, v, weights, mask, cutoff_deg=None)
    return jnp.sqrt(jnp.mean(l2 ** 2, -1)), jnp.sqrt(jnp.mean(lg ** 2, -1))


def fold_masks(n: int, folds: int) -> jax.Array:
    """``(folds + 1, n)``: True for the samples each fold holds out; the last row holds none out (the refit)."""
    ids = fold_ids(n, folds)
    return jnp.asarray(np.concatenate([ids[None, :] == np.arange(folds)[:, None], np.zeros((1, n), bool)]))


@functools.partial(jax.jit, static_argnames=("family", "key", "metric"))
def cross_validate(family: str, key, arrays, metric: str, u, v, values, weights, mask, held):
    """One candidate's padded program (``program(config)`` of the family named ``family``: its static ``key``, its
    ``arrays``, data), every fold
    fitted at once (``vmap``; ``held (K + 1, n)``, the last row the refit on every sample).

    Returns:
        ``(params, l2, log, peak)``: the refit's (padded) parameters, the held-out ``(l2, log)`` per material
        ``(*batch,)``, each the root mean square over the ``K`` folds, and the refit's largest value at the grid's
        nodes over the largest measured value, per material.
    """
    mask = jnp.broadcast_to(mask, values.shape)
    family = family_named(family)

    def one(h):
        if hasattr(family, "fit_program"):
            params = family.fit_program(key, arrays, u, v, values, weights, mask & ~h, metric)
            pred = family.evaluate_program(key, arrays, params, u, v)
        else:  # a family without padded programs: its own fit per configuration (``key`` is the configuration)
            params = family.fit(key, u, v, values, weights, mask & ~h, metric)
            pred = family.evaluate(key, params, u, v)
        return params, rgb_errors(values, pred, u, v, weights, mask & h)

    params, (l2, lg) = jax.vmap(one)(held)
    full = jax.tree.map(lambda a: a[-1], params)
    nu, nv = (jnp.asarray(a, values.dtype) for a in _node_directions())
    if hasattr(family, "evaluate_program"):
        at_nodes = family.evaluate_program(key, arrays, full, nu, nv)
    else:
        at_nodes = family.evaluate(key, full, nu, nv)
    top = jnp.max(jnp.where(mask, values, 0.0), axis=(-2, -1))
    peak = jnp.max(jnp.where(jnp.isfinite(at_nodes), at_nodes, jnp.inf), axis=(-2, -1)) / jnp.maximum(top, 1e-30)
    return full, jnp.sqrt(jnp.mean(l2[:-1] ** 2, 0)), jnp.sqrt(jnp.mean(lg[:-1] ** 2, 0)), peak


@functools.partial(jax.jit, static_argnames=("family", "config", "metric"))
def refit(family: str, config, metric: str, u, v, values, weights, mask):
    """The candidate fitted on every sample: its parameters."""
    mask = jnp.broadcast_to(mask, values.shape)
    return family_named(family).fit(config, u, v, values, weights, mask, metric)


def candidates(families, budget: int) -> list[tuple[str, object]]:
    """The ``(family, config)`` the choice tries within ``budget`` numbers per material (each family's
    ``candidates``: its configurations of at most ``budget`` numbers, thinned to bound the fits)."""
    out = []
    for name in families:
        fam = family_named(name)
        thinned = fam.candidates(budget) if hasattr(fam, "candidates") else fam.configs(budget)
        out += [(name, c) for c in thinned if fam.n_numbers(c) <= budget]
    return out


def score(err) -> float:
    """A batch's score of held-out errors ``(*batch,)``: their geometric mean (inf when any is not finite)."""
    err = np.asarray(err)
    return float(np.exp(np.mean(np.log(np.maximum(err, 1e-300))))) if np.all(np.isfinite(err)) else np.inf


def choose(cands, metric: str, u, v, values, weights, mask, n_folds: int, family_objects=None):
    """Cross-validate every candidate (one compiled program per family's program key: the basis family's
    configurations of a width share one); the chosen ``(family, config)``, its refitted parameters and its
    held-out ``(l2, log)``. A candidate whose refit exceeds :data:`PEAK_LIMIT` times the largest measured value
    at a node of the grid (every direction pair the folded grid tabulates) is refused. ``family_objects`` maps
    names to family objects (default: the registered ones)."""
    held = fold_masks(u.shape[-2], n_folds)
    best, best_score = None, np.inf
    for name, config in cands:
        fam = (family_objects or {}).get(name) or family_named(name)
        key, arrays = fam.program(config) if hasattr(fam, "program") else (config, ())
        params, l2, lg, peak = cross_validate(name, key, arrays, metric, u, v, values, weights, mask, held)
        # a blow-up where the samples are few (a poor small model near grazing) is refused, whatever its score
        s = score(lg if metric == "log" else l2) if np.all(np.asarray(peak) <= PEAK_LIMIT) else np.inf
        if best is None or s < best_score:
            params = fam.unpad(config, params) if hasattr(fam, "unpad") else params
            best, best_score = ((name, config), params, (l2, lg)), s
    return best
