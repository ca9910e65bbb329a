r"""The light-summed image fit (:mod:`baselines._light_sums`) of a standard material model, its R, G, B channels
jointly: one roughness (metallic, IOR, ...) for the three channels, a colour per channel
(:mod:`baselines._models.joint`).

The image's three channels are one lane: with the joint parameters ``tau = [shared, colour(R), colour(G),
colour(B)]`` and ``tau_k`` channel ``k``'s parameters taken from them, the residuals

.. math:: r_{ik}(\tau) = \sqrt{w_i / \textstyle\sum_l w_l}\;\Big(I_{ik} - \sum_j c_{ijk}\, f(u_{ij}, v_i; \tau_k)\Big),
          \qquad k \in \{R, G, B\},

are minimised together, divided by the data's own L2 over all three channels (so that the tolerances are relative to
the whole image, not to each channel). The starts are the joint record's (every parameter of a standard model is
nonlinear: its guesses, then random draws), every start runs ``stage_steps`` steps of
:func:`baselines._lm.lm_solve`, the best continues to ``max_steps``, and the kept optimum is differentiated by the
implicit function theorem over the joint parameters. The result is reported per channel as
:func:`baselines.fit_to_images` reports every model: ``params (3, P)`` (shared values repeated), ``l2`` per channel,
the lane's result code, steps and starts in each channel.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

from polyjax import RESULTS

from ._implicit import implicit_least_squares, safe_sqrt
from ._light_sums import _safe_directions, light_sum_residual
from ._lm import lm_solve
from ._models.joint import SUFFIX, channel_index
from ._models.registry import get_model
from ._multistart import _LIMIT_TOL, _pick
from ._starts import _nonlinear_starts


def joint_residual(model, u, v):
    """``fn(raw_j, (c, y, sw)) -> (3 N,)``: the three channels' light-summed residuals at the joint raw parameters
    ``raw_j``; ``c (3, N, J)``, ``y`` and ``sw`` ``(3, N)``, safe directions ``u``, ``v`` ``(N, J, 3)``."""
    fn = light_sum_residual(model, u, v)
    idx = jnp.asarray(channel_index(model))

    def fj(raw_j, args):
        return jax.vmap(fn)(raw_j[idx], args).reshape(-1)

    return fj


@functools.partial(jax.jit, static_argnames=("name", "n_starts", "max_steps", "stage_steps", "rtol", "atol"))
def joint_light_sum_kernel(name, u, v, c, y, wpx, key, *, n_starts, max_steps, stage_steps, rtol, atol):
    """Every start of the joint lane: ``u (N, J, 3)``, ``v (N, 3)``, ``c (3, N, J)``, ``y (3, N)``, ``wpx (N,)``.
    Returns the fields of :class:`baselines.BaselineFit` but ``params``, ``l2``, ``success``, per channel
    ``(3, ...)``, except ``raw``: the joint ``(1, Pj)`` that :func:`joint_package` takes. Not differentiable."""
    model, joint = get_model(name), get_model(name + SUFFIX)
    su, sv = _safe_directions(u, v, c)
    sw = jnp.broadcast_to(jnp.sqrt(wpx / jnp.maximum(jnp.sum(wpx), jnp.finfo(wpx.dtype).tiny)), y.shape)
    scale = jnp.sqrt(jnp.sum(sw * sw * y * y))  # the data's own L2 over the three channels
    scale = jnp.where(scale > 0, scale, 1.0)
    fn, lane = joint_residual(model, su, sv), (c, y, sw / scale)

    def solve(r0, budget):
        raw, code, steps = lm_solve(fn, r0, lane, budget, rtol, atol)
        loss = jnp.sum(fn(raw, lane) ** 2)
        finite = jnp.isfinite(loss) & jnp.all(jnp.isfinite(raw))
        return raw, jnp.where(finite, code, RESULTS.NONFINITE), steps, jnp.where(finite, jnp.sqrt(loss), jnp.inf)

    raw0 = joint.to_raw(_nonlinear_starts(joint, n_starts, key).astype(y.dtype))  # (S, Pj)
    raw_s, code_s, steps_s, l2_s = jax.lax.map(lambda r0: solve(r0, jnp.minimum(stage_steps, max_steps)), raw0)
    best = _pick(l2_s, code_s).astype(jnp.int32)
    done = code_s[best] == RESULTS.OK  # converged in stage 1: its stage-1 state (a budget of 0 reports MAX_STEPS)
    raw2, code2, steps2, l22 = solve(raw_s[best], jnp.where(done, 0, max(max_steps - stage_steps, 0)))
    raw2, code2, l22 = (jnp.where(done, a, b) for a, b in ((raw_s[best], raw2), (code_s[best], code2),
                                                            (l2_s[best], l22)))
    ok = jnp.all(jnp.isfinite(raw2))
    code2 = jnp.where(jnp.any(wpx > 0), jnp.where(ok, code2, RESULTS.NONFINITE), RESULTS.NO_SAMPLES)
    raw2 = jnp.where(ok, raw2, raw0[0])
    rep = lambda a: jnp.broadcast_to(a, (3,) + jnp.shape(a))  # noqa: E731
    return dict(
        raw=raw2[None], status=rep(code2.astype(jnp.int32)), steps=rep((steps_s[best] + steps2).astype(jnp.int32)),
        start_l2=rep(l2_s.at[best].set(l22) * scale), start_status=rep(code_s.at[best].set(code2).astype(jnp.int32)),
        best_start=rep(best), at_limit=joint.snap_to_limits(raw2, _LIMIT_TOL)[1][channel_index(model)],
    )


@functools.partial(jax.jit, static_argnames=("name",))
def joint_package(name, raw, u, v, c, y, wpx):
    """The kept joint optimum ``raw (1, Pj)`` with its implicit derivative, as per-channel raw and physical
    parameters ``(3, P)`` and each channel's L2 (that of :func:`baselines._light_sums.package`: the RMS radiance
    residual over the kept pixels divided by the RMS light factor)."""
    model = get_model(name)
    su, sv = _safe_directions(u, v, c)
    sw = jnp.broadcast_to(safe_sqrt(jnp.maximum(wpx, 0.0)), y.shape)
    fj = joint_residual(model, su, sv)
    raw_j = implicit_least_squares(lambda t, cb, yb: fj(t, (cb, yb, sw)), raw, c[None], y[None])[0]
    raw = raw_j[jnp.asarray(channel_index(model))]
    res = fj(raw_j, (c, y, sw)).reshape(y.shape)
    factor = jnp.sum(jnp.where(c != 0, c / jnp.maximum(su[..., 2], 1e-12), 0.0), axis=-1)  # (3, N)
    den = jnp.sum(wpx * factor * factor, axis=-1)
    ok = den > 0
    l2 = jnp.where(ok, jnp.sqrt(jnp.sum(res * res, axis=-1) / jnp.where(ok, den, 1.0)), jnp.inf)
    return raw, model.to_params(raw), l2
