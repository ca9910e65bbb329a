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
from .model import evaluate_family, family_named

#: the split's seed: the same folds for every material and every run
FOLD_SEED = 0


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


@functools.partial(jax.jit, static_argnames=("family", "config", "metric"))
def cross_validate(family: str, config, metric: str, u, v, values, weights, mask, folds):
    """Held-out ``(l2, log)`` per material ``(*batch,)`` of one candidate, all folds in one program.

    ``folds (K, n)`` holds True for the samples each fold holds out; ``mask`` broadcasts to ``values``.
    """
    fam = family_named(family)
    mask = jnp.broadcast_to(mask, values.shape)

    def one(held):
        params = fam.fit(config, u, v, values, weights, mask & ~held, metric)
        pred = evaluate_family(family, config, params, u, v)
        return rgb_errors(values, pred, u, v, weights, mask & held)

    l2, lg = jax.lax.map(one, folds)
    return jnp.sqrt(jnp.mean(l2 ** 2, 0)), jnp.sqrt(jnp.mean(lg ** 2, 0))


@functools.partial(jax.jit, static_argnames=("family", "config", "metric"))
def refit(family: str, config, metric: str, u, v, values, weights, mask):
    """The candidate fitted on every sample: its parameters."""
    mask = jnp.broadcast_to(mask, values.shape)
    return family_named(family).fit(config, u, v, values, weights, mask, metric)


def candidates(families, budget: int) -> list[tuple[str, object]]:
    """Every ``(family, config)`` of ``families`` within ``budget`` numbers per material."""
    return [(name, c) for name in families for c in family_named(name).configs(budget)
            if family_named(name).n_numbers(c) <= budget]


def choose(cands, metric: str, u, v, values, weights, mask, n_folds: int):
    """Cross-validate every candidate; the chosen ``(family, config)`` and its held-out ``(l2, log)``."""
    held = jnp.asarray(fold_ids(u.shape[-2], n_folds)[None, :] == np.arange(n_folds)[:, None])
    best, best_score, best_err = None, np.inf, None
    for family, config in cands:
        l2, lg = cross_validate(family, config, metric, u, v, values, weights, mask, held)
        err = np.asarray(lg if metric == "log" else l2)
        score = float(np.exp(np.mean(np.log(np.maximum(err, 1e-300))))) if np.all(np.isfinite(err)) else np.inf
        if best is None or score < best_score:
            best, best_score, best_err = (family, config), score, (l2, lg)
    return best, best_err
