"""Starting points of the multi-start fit: the model's deterministic guesses of its nonlinear parameters first,
then random ones drawn from ``key``; for each, the parameters that enter linearly (albedos, lobe scale) are seeded
by a small non-negative linear least-squares solve on the fit's objective (paper equation (11))."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from polyjax import InputError
from polyjax.internal import prepare_inputs

from ._models.common import BaselineModel
from ._models.registry import get_model


def _linear_seed(cols, y, wc2):
    """Non-negative weighted LSQ of ``y ~ cols @ c`` for 1 or 2 columns; tiny positive floor."""
    sw = jnp.sqrt(wc2)
    a = cols * sw[:, None]
    b = y * sw
    norm_b = jnp.sqrt(jnp.sum(b * b))
    aa = jnp.sum(a * a, axis=0)
    aa_safe = jnp.where(aa > 0, aa, 1.0)
    floor = 1e-3 * jnp.maximum(norm_b, 1e-12) / jnp.sqrt(aa_safe)
    single = jnp.maximum(a.T @ b / aa_safe, 0.0)  # each column alone
    L = cols.shape[1]
    if L == 1:
        return jnp.maximum(single, floor)
    g = a.T @ a + 1e-12 * jnp.trace(a.T @ a) * jnp.eye(L, dtype=a.dtype)
    full = jnp.linalg.solve(g, a.T @ b)
    cands = [full] + [jnp.zeros(L, a.dtype).at[j].set(single[j]) for j in range(L)]
    ok = [jnp.all(full >= 0) & jnp.all(jnp.isfinite(full))] + [jnp.bool_(True)] * L
    res = jnp.stack([jnp.where(o, jnp.sum((b - a @ c) ** 2), jnp.inf) for c, o in zip(cands, ok)])
    best = jnp.stack(cands)[jnp.argmin(res)]
    return jnp.maximum(jnp.where(jnp.isfinite(best), best, 0.0), floor)


def _nonlinear_starts(model: BaselineModel, n_starts: int, key):
    det = jnp.asarray(model.guesses[: min(n_starts, len(model.guesses))])
    n_rand = n_starts - det.shape[0]
    if n_rand > 0:
        det = jnp.concatenate([det, model.sample(key, n_rand).astype(det.dtype)], axis=0)
    return det


def starts(model: BaselineModel, u, v, y, wc2, key, n_starts):
    """Raw starting parameters ``(B, S, P)``."""
    nl = _nonlinear_starts(model, n_starts, key).astype(y.dtype)  # (S, Pnl)
    if model.n_linear == 0:  # every parameter nonlinear (the standard materials): the starts as they are
        return jnp.broadcast_to(model.to_raw(nl), (y.shape[0],) + nl.shape)
    cols = jax.vmap(lambda q: model.columns(q, u, v))(nl)  # (S, n, L)
    lin = jax.vmap(lambda yb, wb: jax.vmap(lambda c: _linear_seed(c, yb, wb))(cols))(y, wc2)  # (B, S, L)
    params = jax.vmap(jax.vmap(model.combine), in_axes=(0, None))(lin, nl)
    return model.to_raw(params)


@functools.partial(jax.jit, static_argnames=("name", "n_starts"))
def _starts_kernel(name, u, v, y, wc2, key, n_starts):
    return starts(get_model(name), u, v, y, wc2, key, n_starts)


def initial_guesses(
    name: str, u, v=None, values=None, *, weights=None, mask=None, cutoff_deg: float | None = 80.0,
    n_starts: int = 16, key=None,
) -> Float[Array, "*batch S P"]:
    """The unconstrained starting parameters :func:`fit` uses, ``(*batch, n_starts, P)``.

    Map them with ``get_model(name).to_params``; useful to start another solver from the same points.
    """
    model = get_model(name)
    check_n_starts(n_starts)
    if model.linear:
        raise InputError(f"{model.name} is linear and fitted in closed form: it has no starting points")
    inp, cutoff = prepare_inputs("initial_guesses", u, v, values, weights, mask, cutoff_deg=cutoff_deg)
    _, wc2 = inp.objective_weights(cutoff)
    key = jax.random.PRNGKey(0) if key is None else key
    raw = _starts_kernel(model.name, inp.u, inp.v, inp.values, wc2, key, int(n_starts))
    return raw.reshape(inp.batch + raw.shape[1:])


def check_n_starts(n_starts) -> None:
    if not isinstance(n_starts, (int, np.integer)) or n_starts < 1:
        raise InputError(f"n_starts: expected a positive integer, found {n_starts!r}")
