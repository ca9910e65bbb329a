r"""The front door of compact fits: :func:`fit_compact`, the most accurate model of at most ``N`` numbers."""

from __future__ import annotations

from collections.abc import Hashable, Mapping
from typing import Any, NamedTuple

import jax.numpy as jnp
import numpy as np

from .._errors import InputError, UnknownNameError
from .._measurements import Measurements
from .._solve.threads import one_lapack_thread
from .families import FAMILIES
from .model import CompactBRDF, family_named
from .select import candidate_chains, choose, refit

METRICS = ("log", "l2")
#: the default budget of numbers per material (the size of the published SGD fits)
DEFAULT_BUDGET = 33


class BudgetError(InputError):
    """The budget of numbers per material admits no configuration of any family asked for."""


def _check(data, budget, metric, families, folds) -> tuple[str, ...]:
    """The argument checks of :func:`fit_compact`, before any work; the families' names."""
    if not isinstance(data, Measurements):
        raise InputError(f"data: expected a polyjax.Measurements of RGB values (*batch, 3, n), found "
                         f"{type(data).__name__}")
    if data.values.ndim < 2 or data.values.shape[-2] != 3:
        raise InputError(f"data.values: expected RGB values of shape (*batch, 3, n), found {data.values.shape}")
    if data.u.ndim != 2 or data.v.ndim != 2:
        raise InputError(f"data.u, data.v: expected directions (n, 3) shared by every material, found "
                         f"{data.u.shape} and {data.v.shape}")
    if isinstance(budget, bool) or not isinstance(budget, (int, np.integer)) or budget < 1:
        raise InputError(f"budget: expected a positive number of numbers per material, found {budget!r}")
    if metric not in METRICS:
        raise InputError(f"metric: expected one of {METRICS}, found {metric!r}")
    names = tuple(FAMILIES) if families is None else ((families,) if isinstance(families, str) else tuple(families))
    for name in names:
        if name not in FAMILIES:
            raise UnknownNameError(f"families: {name!r} is not a family (known: {sorted(FAMILIES)})")
    if not names:
        raise InputError("families: expected at least one family name")
    if isinstance(folds, bool) or not isinstance(folds, (int, np.integer)) or not 2 <= folds <= data.n_samples:
        raise InputError(f"folds: expected an integer from 2 to the number of samples ({data.n_samples}), "
                         f"found {folds!r}")
    return names


def _arrays(data: Measurements) -> tuple:
    """``(u, v, values, weights, mask)`` of ``data`` as JAX arrays, one mask per material given to its three
    channels."""
    mask = jnp.asarray(data.mask)
    if mask.ndim == data.values.ndim - 1:
        mask = mask[..., None, :]
    return jnp.asarray(data.u), jnp.asarray(data.v), jnp.asarray(data.values), jnp.asarray(data.weights), mask


@one_lapack_thread
def fit_compact(data: Measurements, budget: int = DEFAULT_BUDGET, *, metric: str = "log", families=None,
                folds: int = 3) -> CompactBRDF:
    r"""The most accurate compact model of at most ``budget`` numbers per material, chosen by cross-validation.

    The candidates of every family (``polyjax/_compact/families``) that store at most ``budget`` numbers per
    material (all three channels counted) are fitted on ``folds - 1`` folds of the samples and scored on the
    held-out fold, every fold in one program (``polyjax/_compact/select.py``; the basis family's configurations
    of one width share one compiled program). They come in chains (the basis family's largest ``k`` of each
    degree, then its halvings; each of the skew family's candidates alone; the shared family's reciprocal shape,
    then the same with skew rows; the sparse family's most columns; each of the polynomial's largest degrees of a
    variable set alone): the first of every chain is tried, then the chain of the best of
    them is walked while the held-out error falls. The candidate of least held-out error in ``metric`` is
    returned, refitted on every sample, except that candidates within 5 % of the least are tied and the tie of
    least held-out error in the other metric is taken (``select.TIE``, ``select.choice_order``); a candidate
    whose refit exceeds 10 times the largest measured value at a node of the grid is refused (the next one is
    refitted). The choice follows one rule for every material; a batch of materials shares one choice (fit
    materials one at a time for a choice of their own).

    Args:
        data: :class:`polyjax.Measurements` of RGB values ``(*batch, 3, n)``, directions ``(n, 3)``.
        budget: the most numbers stored per material (33, the size of the published SGD fits, by default).
        metric: ``"log"`` (the log metric of :func:`polyjax.log_error`, every bin above the horizon) or ``"l2"``
            (equation (11), 80-degree cutoff): what the fits minimise and the choice compares.
        families: a family name or names to choose among (every registered family when None).
        folds: the number of cross-validation folds (at least 2).

    Returns:
        A :class:`polyjax.CompactBRDF` of batch shape ``*batch``, with its held-out errors ``.l2`` and ``.log``.

    Raises:
        InputError: data that is not RGB ``Measurements``, a budget, metric or folds out of range.
        BudgetError: no configuration of the families asked for fits within ``budget`` (names the smallest).
        UnknownNameError: a family name that is not registered.
    """
    choice = _choose(data, budget, metric, families, folds, None)
    return CompactBRDF(params=choice.params, l2=choice.l2, log=choice.log, family=choice.family,
                       config=choice.config)


class Choice(NamedTuple):
    """:func:`choose_compact`'s result: the chosen family's name and configuration, its parameters refitted on
    every sample, its held-out errors ``(*batch,)`` and the number of candidates cross-validated."""

    family: str
    config: Hashable
    params: Any
    l2: Any
    log: Any
    tried: int


@one_lapack_thread
def choose_compact(data: Measurements, budget: int = DEFAULT_BUDGET, *, families: Mapping, metric: str = "log",
                   folds: int = 3) -> Choice:
    """:func:`fit_compact`'s choice among family objects of one's own: ``families`` maps registered family names
    to family objects (e.g. ``{"basis": CompactBasisFamily(loo_basis), "skew": CompactSkewFamily(loo_basis)}``,
    a basis learned without the material fitted). The result's parameters are the given family object's
    (evaluate them with its ``evaluate``: a :class:`CompactBRDF` evaluates with the registered families)."""
    if not isinstance(families, Mapping):
        raise InputError(f"families: expected a mapping of family names to family objects, found "
                         f"{type(families).__name__}")
    return _choose(data, budget, metric, tuple(families), folds, dict(families))


def _choose(data, budget, metric, families, folds, objects) -> Choice:
    names = _check(data, budget, metric, families, folds)
    chains = candidate_chains(names, int(budget), objects)
    if not chains:
        smallest = next((b for b in range(int(budget) + 1, 10 ** 4) if candidate_chains(names, b, objects)), None)
        raise BudgetError(f"budget: {budget} numbers per material admits no model of the families {list(names)}: "
                          f"expected a budget of at least {smallest}")
    u, v, values, weights, mask = _arrays(data)
    (family, config), params, (l2, lg), tried = choose(chains, metric, u, v, values, weights, mask, int(folds),
                                                      objects)
    return Choice(family, config, params, l2, lg, tried)


def compact_families() -> dict:
    """The registered families of compact models, by name (each has ``configs(budget)``, ``n_numbers(config)``,
    ``fit`` and ``evaluate``: ``polyjax/_compact/families/__init__.py``)."""
    return dict(FAMILIES)


@one_lapack_thread
def fit_compact_family(data: Measurements, family: str, config, *, metric: str = "log") -> CompactBRDF:
    """One family's configuration fitted on every sample of ``data``, no choice (``l2``/``log`` NaN): the
    benchmarks' and tests' way to a given model."""
    _check(data, family_named(family).n_numbers(config), metric, family, 2)
    params = refit(family, config, metric, *_arrays(data))
    nan = jnp.full(data.values.shape[:-2], jnp.nan)
    return CompactBRDF(params=params, l2=nan, log=nan, family=family, config=config)
