r"""The choice of a compact model by k-fold cross-validation over the samples.

The samples are split into ``folds`` parts by a fixed random permutation (seed 0: the same split for every
material and every run). For each candidate ``(family, config)`` every fold is fitted on the other folds' samples
(the held-out ones masked out) and scored on its own; a candidate's held-out error of one material is

.. math::
    E = \Big[\frac{1}{K}\sum_{k} \frac{1}{3}\sum_{c \in RGB} \varphi_{k,c}^2\Big]^{1/2}

with ``phi`` the L2 of equation (11) (80-degree cutoff) or the log metric of :func:`polyjax.log_error` (every bin
above the horizon). The same rule chooses for every material: the candidate of least held-out error in the
metric asked for, but candidates within :data:`TIE` of the least are tied, and of those the one of least held-out
error in the other metric is taken: up to 5 % of held-out error in the metric asked for traded for the other
(on the RGL-EPFL white paper 3 % of its log error for 18 % of its L2; on the 100 MERL materials at 33 numbers 22
choices change, 1.8 % worse in log error and 13 % better in L2: ``benchmarks/RESULTS.md``); a batch of materials
shares one choice, by the geometric means of ``E`` over the batch.

Not every candidate is fitted (:func:`choose`): the families give them in chains (the basis family's halvings of
``k``; each configuration of the skew family alone); the first of every chain is cross-validated, then the chain
of the best of them is walked while ``E`` falls. On 20 MERL materials at 33 numbers (leave-one-out bases,
``benchmarks/bench_compact_choice.py``) it chose what the exhaustive search does on all 20, cross-validating 7-8
of the 14 candidates.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from .._metrics import _l2_core, _log_core
from .families._grid import node_directions
from .families.basis import fit_folds, mix_for
from .model import family_named

#: the split's seed: the same folds for every material and every run
FOLD_SEED = 0
#: candidates whose held-out error in the metric asked for is within this fraction of the least are tied: the
#: choice takes the tied one of least held-out error in the other metric (:func:`choice_order`)
TIE = 0.05
#: a candidate whose refit exceeds this many times the largest measured value at a node of the grid is refused
PEAK_LIMIT = 10.0


@functools.cache
def _node_directions():
    """Light and view directions of the folded grid's nodes (``families/_grid.py``) both above the horizon."""
    u, v = node_directions()
    keep = (u[:, 2] > 1e-6) & (v[:, 2] > 1e-6)
    return u[keep], v[keep]


@functools.cache
def fold_ids(n: int, folds: int) -> np.ndarray:
    """``(n,)`` the fold of each sample: a fixed random permutation's position modulo ``folds`` (computed once per
    ``(n, folds)``; read-only)."""
    perm = np.random.default_rng(FOLD_SEED).permutation(n)
    ids = np.empty(n, np.int32)
    ids[perm] = np.arange(n) % folds
    ids.flags.writeable = False
    return ids


def rgb_errors(values, predicted, u, v, weights, mask):
    """``(l2, log)`` per material ``(*batch,)``: each the root mean square over the three channels."""
    l2 = _l2_core(values, predicted, u, v, weights, mask, cutoff_deg=80.0)
    lg = _log_core(values, predicted, u, v, weights, mask, cutoff_deg=None)
    return jnp.sqrt(jnp.mean(l2 ** 2, -1)), jnp.sqrt(jnp.mean(lg ** 2, -1))


def fold_masks(n: int, folds: int) -> jax.Array:
    """``(folds, n)``: True for the samples each fold holds out."""
    ids = fold_ids(n, folds)
    return jnp.asarray(ids[None, :] == np.arange(folds)[:, None])


def fold_parts(n: int, folds: int) -> tuple:
    """The folds as index arrays (:func:`polyjax._compact.families.basis.fit_folds`): ``(parts, part_ok, train,
    train_ok)``, each fold's samples ``(K, m)`` and the samples it is fitted on ``(K, (K - 1) m)``, padded (with
    sample 0, ``ok`` False) to equal lengths."""
    ids = fold_ids(n, folds)

    def padded(sets):
        m = max(len(x) for x in sets)
        idx = np.zeros((len(sets), m), np.int32)
        ok = np.zeros((len(sets), m), bool)
        for j, x in enumerate(sets):
            idx[j, : len(x)], ok[j, : len(x)] = x, True
        return jnp.asarray(idx), jnp.asarray(ok)

    parts = padded([np.nonzero(ids == j)[0] for j in range(folds)])
    train = padded([np.nonzero(ids != j)[0] for j in range(folds)])
    return parts + train


@functools.partial(jax.jit, static_argnames=("family", "key", "metric"))
def cross_validate(family: str, key, arrays, metric: str, u, v, values, weights, mask, held, parts):
    """One candidate's held-out errors: its program (``program(config)`` of the family named ``family``: its static
    ``key``, its ``arrays``) fitted on every fold's training samples at once (``held (K, n)`` the samples each
    fold holds out; ``parts``, :func:`fold_parts`) and scored on the held-out ones.

    A family with columns (``design``, ``from_design``: ``basis``, ``skew``) is fitted by
    :func:`polyjax._compact.families.basis.fit_folds` on its columns computed once; one with its own fold fits
    (``fit_folds``: ``shared``) by them; another by its own padded fit per fold, the held-out samples masked out.

    Returns:
        ``(l2, log)`` per material ``(*batch,)``, each the root mean square over the ``K`` folds.
    """
    mask = jnp.broadcast_to(mask, values.shape)
    fam = family_named(family)
    if hasattr(fam, "design"):
        phi = fam.design(key, arrays, u, v)
        coef = fit_folds(phi, u, v, values, weights, mask, *parts, mix_for(metric))
        pred = jax.vmap(lambda c: fam.from_design(key, arrays, phi, c), in_axes=-2)(coef)
    elif hasattr(fam, "fit_folds"):
        coef = fam.fit_folds(key, arrays, u, v, values, weights, mask, held, parts, metric)
        pred = jax.vmap(lambda c: fam.evaluate_program(key, arrays, c, u, v), in_axes=-2)(coef)
    else:
        pred = jax.vmap(lambda h: fam.evaluate_program(key, arrays, fam.fit_program(
            key, arrays, u, v, values, weights, mask & ~h, metric), u, v))(held)
    l2, lg = jax.vmap(lambda p, h: rgb_errors(values, p, u, v, weights, mask & h))(pred, held)
    return jnp.sqrt(jnp.mean(l2 ** 2, 0)), jnp.sqrt(jnp.mean(lg ** 2, 0))


@functools.partial(jax.jit, static_argnames=("family", "key", "metric"))
def refit_peak(family: str, key, arrays, metric: str, u, v, values, weights, mask):
    """The candidate's program fitted on every sample: its (padded) parameters and its largest value at the grid's
    nodes over the largest measured value, per material ``(*batch,)``."""
    mask = jnp.broadcast_to(mask, values.shape)
    fam = family_named(family)
    params = fam.fit_program(key, arrays, u, v, values, weights, mask, metric)
    nu, nv = (jnp.asarray(a, values.dtype) for a in _node_directions())
    at_nodes = fam.evaluate_program(key, arrays, params, nu, nv)
    top = jnp.max(jnp.where(mask, values, 0.0), axis=(-2, -1))
    peak = jnp.max(jnp.where(jnp.isfinite(at_nodes), at_nodes, jnp.inf), axis=(-2, -1)) / jnp.maximum(top, 1e-30)
    return params, peak


@functools.partial(jax.jit, static_argnames=("family", "config", "metric"))
def refit(family: str, config, metric: str, u, v, values, weights, mask):
    """The candidate fitted on every sample: its parameters."""
    mask = jnp.broadcast_to(mask, values.shape)
    return family_named(family).fit(config, u, v, values, weights, mask, metric)


def candidate_chains(families, budget: int, family_objects=None) -> list[list[tuple[str, object]]]:
    """The chains of ``(family, config)`` the choice walks within ``budget`` numbers per material (each family's
    ``candidate_chains``, else each of its ``candidates`` (or ``configs``) a chain of its own; ``family_objects``
    as :func:`choose`): a chain is walked in order while the held-out error falls."""
    out = []
    for name in families:
        fam = (family_objects or {}).get(name) or family_named(name)
        if hasattr(fam, "candidate_chains"):
            chains = fam.candidate_chains(budget)
        else:
            chains = [[c] for c in (fam.candidates(budget) if hasattr(fam, "candidates") else fam.configs(budget))]
        chains = [[(name, c) for c in chain if fam.n_numbers(c) <= budget] for chain in chains]
        out += [chain for chain in chains if chain]
    return out


def candidates(families, budget: int) -> list[tuple[str, object]]:
    """Every ``(family, config)`` the choice may try within ``budget`` (:func:`candidate_chains`, flattened)."""
    return [c for chain in candidate_chains(families, budget) for c in chain]


def score(err) -> float:
    """A batch's score of held-out errors ``(*batch,)``: their geometric mean (inf when any is not finite)."""
    err = np.asarray(err)
    return float(np.exp(np.mean(np.log(np.maximum(err, 1e-300))))) if np.all(np.isfinite(err)) else np.inf


def choice_order(primary, secondary) -> list[int]:
    """The order in which candidates are refitted, from their scores in the metric asked for and in the other one
    (:func:`score` of each, lists of equal length): those within :data:`TIE` of the least primary score (the ties)
    by their secondary score, then the rest by their primary score (ties of a score kept in the order given)."""
    primary, secondary = np.asarray(primary, float), np.asarray(secondary, float)
    tied = primary <= (1.0 + TIE) * np.min(primary)  # every one when none is finite (scores are never NaN)
    first = sorted(np.nonzero(tied)[0], key=lambda i: (secondary[i], primary[i], i))
    rest = sorted(np.nonzero(~tied)[0], key=lambda i: (primary[i], i))
    return [int(i) for i in first + rest]


def choose(chains, metric: str, u, v, values, weights, mask, n_folds: int, family_objects=None):
    """The choice, a greedy search: cross-validate the first candidate of every chain (:func:`candidate_chains`),
    then walk the chain of the best of them while its held-out error falls (the next candidate while it beats the
    best so far); refit the candidates on every sample in the order of :func:`choice_order` (the ties of least
    held-out error by their error in the other metric, then the rest by held-out error) and return the first whose
    refit stays within :data:`PEAK_LIMIT` times the largest measured value at every node of the grid (every
    direction pair the folded grid tabulates): a blow-up where the samples are few is refused whatever its score
    (when none stays within it, the first in that order). ``family_objects`` maps names to family objects
    (default: the registered ones; e.g. a basis learned without the material).

    Returns:
        ``((family, config), params, (l2, log), tried)``: the choice, its refitted parameters, its held-out errors
        ``(*batch,)`` and the number of candidates cross-validated.
    """
    held = fold_masks(u.shape[-2], n_folds)
    parts = fold_parts(u.shape[-2], n_folds)
    scored = []

    def trial(name, config):
        fam = (family_objects or {}).get(name) or family_named(name)
        key, arrays = fam.program(config)
        l2, lg = cross_validate(name, key, arrays, metric, u, v, values, weights, mask, held, parts)
        primary, secondary = (lg, l2) if metric == "log" else (l2, lg)
        scored.append((score(primary), score(secondary), name, config, fam, key, arrays, (l2, lg)))
        return scored[-1][0]

    heads = [trial(*chain[0]) for chain in chains]
    lead = int(np.argmin(heads))
    best = heads[lead]
    for name, config in chains[lead][1:] if np.isfinite(best) else ():
        s = trial(name, config)
        if not s < best:
            break
        best = s
    first = None
    for i in choice_order([t[0] for t in scored], [t[1] for t in scored]):
        _, _, name, config, fam, key, arrays, errs = scored[i]
        params, peak = refit_peak(name, key, arrays, metric, u, v, values, weights, mask)
        unpad = fam.unpad(config, params)
        first = first or ((name, config), unpad, errs, len(scored))
        if np.all(np.asarray(peak) <= PEAK_LIMIT):
            return (name, config), unpad, errs, len(scored)
    return first
