"""The fit of a standard material model: the three colour channels of each material jointly
(:mod:`baselines._models.joint`), then the result in the per-channel layout of every other baseline fit
(``params (..., 3, P)``, ``l2`` per channel)."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

import polyjax as pj
from polyjax import RESULTS, InputError

from . import _jaxopt
from ._implicit import implicit_optimum
from ._models.joint import SUFFIX, channel_index, joint_lanes, per_channel
from ._models.registry import get_model
from ._multistart import fit_kernel


def check_channels(model, batch: tuple) -> None:
    """A standard model needs the R, G, B channels of each material as the last batch axis."""
    if not batch or batch[-1] != 3:
        raise InputError(
            f"values: the standard material model {model.name!r} fits the R, G, B channels of each material jointly "
            f"and expects values of shape (..., 3, n) (channels last before the samples), found batch shape {batch}"
        )


def fit_joint(model, inp, wl, wc2, key, raw0, backend: str, opts: dict) -> dict:
    """The multi-start kernel of ``backend`` on the joint record and material lanes ``(M, 3 n)``, then the kept
    optimum (implicit derivative) as per-channel fields ``(3 M, ...)`` (see :func:`_package`)."""
    sg = jax.lax.stop_gradient
    y, wlj, wc2j = joint_lanes(inp.values, wl, wc2)
    args = (model.name + SUFFIX, sg(inp.u), sg(inp.v), sg(y), sg(wlj), sg(wc2j),
            jax.random.PRNGKey(0) if key is None else key, None if raw0 is None else sg(raw0))
    if backend == "optimistix":
        out = fit_kernel(*args, **opts)
    else:  # loaded on first use (baselines/_jaxopt/__init__.py)
        out = _jaxopt.staged_kernel(*args, backend=backend, **opts)
    return _package(model.name, out, inp.u, inp.v, inp.values, jnp.broadcast_to(wl, inp.values.shape),
                    jnp.broadcast_to(wc2, inp.values.shape))


@functools.partial(jax.jit, static_argnames=("name",))
def _package(name, out, u, v, y, wl, wc2):
    """The material lanes' kernel output ``out`` as per-channel lanes: the kept joint optimum with its implicit
    derivative, each channel's parameters, its L2 of equation (11) against its own values ``y (3 M, n)``; the
    result codes, steps and starts of a material repeated for its three channels."""
    model = get_model(name)
    joint = get_model(name + SUFFIX)
    m, n = y.shape[0] // 3, y.shape[1]
    raw_j = implicit_optimum(joint, out["raw"], u, v, y.reshape(m, 3 * n), wl.reshape(m, 3 * n),
                             wc2.reshape(m, 3 * n))
    raw = per_channel(model, raw_j).reshape(3 * m, -1)
    params = model.to_params(raw)
    pred = jax.vmap(lambda p: model.evaluate(p, u, v))(params)
    l2 = pj.l2_error(y, pred, u, v, weights=wl, cutoff_deg=None, mask=wc2 > 0)
    rep = lambda a: jnp.repeat(a, 3, axis=0)  # noqa: E731
    fields = {k: rep(out[k]) for k in ("status", "steps", "start_l2", "start_status", "best_start")}
    rows = jnp.arange(3 * m)
    at_limit = rep(out["at_limit"])[rows[:, None], jnp.asarray(channel_index(model))[rows % 3]]
    success = (fields["status"] == RESULTS.OK) & jnp.isfinite(l2)
    return dict(fields, raw=raw, params=params, l2=l2, at_limit=at_limit, success=success)
