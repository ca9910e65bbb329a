r"""Multi-start Levenberg-Marquardt on image residuals whose radiance is a sum over light samples.

Under several point or directional lights, or an environment map, the radiance of a kept pixel ``i`` in colour
channel ``k`` is ``L_ik = sum_j c_ijk f(u_ij, v_i; params)`` (:func:`polyjax.image_rows`), so its residual

.. math:: r_{ik}(\tau) = \sqrt{w_i / \textstyle\sum_l w_l}\;\Big(I_{ik} - \sum_j c_{ijk}\, f(u_{ij}, v_i; \tau)\Big)

is not that of one BRDF sample and :func:`baselines.fit` does not apply; this kernel minimises it per channel with the
same pieces: the model's starts (its guesses of the nonlinear parameters, then random ones, the linear parameters
seeded by a non-negative least-squares solve on the light-summed columns), every start for ``stage_steps`` steps of
:func:`baselines._lm.lm_solve`, the best start of each channel continued to ``max_steps``, and the kept optimum
differentiated by the implicit function theorem (:func:`baselines._implicit.implicit_least_squares`). There is no
range-limit round (:func:`baselines.fit`'s snapping of a start stuck next to a limit); ``at_limit`` still reports
parameters on a limit.

Cost and memory: each residual evaluates the model at ``N J`` directions (``N`` kept pixels, ``J`` light samples);
the starts run one after another (``lax.map``), the three channels together (``vmap``).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

from polyjax import RESULTS

from ._implicit import implicit_least_squares, safe_sqrt
from ._lm import lm_solve
from ._models.registry import get_model
from ._multistart import _LIMIT_TOL, _at, _pick
from ._starts import _linear_seed, _nonlinear_starts

_UP = (0.0, 0.0, 1.0)


def _safe_directions(u, v, c):
    """``u`` and ``v`` (broadcast to ``u``'s shape) with ``+z`` at samples of zero weight in every channel (padding,
    pixels not kept): the model and its derivatives stay finite there, where they are multiplied by 0."""
    lit = jnp.any(c != 0, axis=0)  # (N, J)
    up = jnp.asarray(_UP, u.dtype)
    su = jnp.where(lit[..., None], u, up)
    sv = jnp.where(jnp.any(lit, axis=1)[:, None], v, up)
    return su, jnp.broadcast_to(sv[:, None, :], u.shape)


def light_sum_residual(model, u, v):
    """``fn(raw, (c, y, sw)) -> sw (y - sum_j c_j f(u_j, v))`` of one channel: ``u (N, J, 3)`` and ``v (N, J, 3)``
    safe directions (:func:`_safe_directions`), ``c (N, J)``, ``y`` and ``sw`` ``(N,)``."""

    def fn(raw, args):
        c, y, sw = args
        f = model.evaluate(model.to_params(raw), u, v)
        pred = jnp.sum(jnp.where(c != 0, c * f, 0.0), axis=1)
        return jnp.where(sw > 0, sw * (y - pred), 0.0)

    return fn


def _starts(model, u, v, c, y, sw, key, n_starts):
    """Raw starts ``(B, S, P)``: the model's nonlinear starts, linear parameters seeded on the light-summed
    columns ``sum_j c_j columns(u_j, v)`` (one start at a time: the columns are ``(N, J, L)``)."""
    nl = _nonlinear_starts(model, n_starts, key).astype(y.dtype)  # (S, Pnl)

    def seed(q):
        cols = jnp.einsum("njl,bnj->bnl", model.columns(q, u, v), c)  # (B, N, L)
        return jax.vmap(_linear_seed)(cols, y, sw * sw)

    lin = jnp.swapaxes(jax.lax.map(seed, nl), 0, 1)  # (B, S, L)
    params = jax.vmap(jax.vmap(model.combine), in_axes=(0, None))(lin, nl)
    return model.to_raw(params)


@functools.partial(jax.jit, static_argnames=("name", "n_starts", "max_steps", "stage_steps", "rtol", "atol"))
def light_sum_kernel(name, u, v, c, y, wpx, key, *, n_starts, max_steps, stage_steps, rtol, atol):
    """Every start of every channel: ``u (N, J, 3)``, ``v (N, 3)``, ``c (B, N, J)``, ``y (B, N)``, ``wpx (N,)``
    (0 off the fit). Returns a dict of ``(B, ...)`` arrays, the fields of :class:`baselines.BaselineFit` but
    ``params``, ``l2`` and ``success`` (:func:`package` computes them, differentiably). Not differentiable itself."""
    model = get_model(name)
    su, sv = _safe_directions(u, v, c)
    sw = jnp.sqrt(wpx / jnp.maximum(jnp.sum(wpx), jnp.finfo(wpx.dtype).tiny))
    sw = jnp.broadcast_to(sw, y.shape)
    # residuals in units of the data's own L2 (the L2 of f = 0), so the tolerances are relative
    scale = jnp.sqrt(jnp.sum(sw * sw * y * y, axis=-1, keepdims=True))
    scale = jnp.where(scale > 0, scale, 1.0)
    sw = sw / scale
    fn = light_sum_residual(model, su, sv)
    lanes = (c, y, sw)

    def solve(r0, budget, lane):
        raw, code, steps = lm_solve(fn, r0, lane, budget, rtol, atol)
        res = fn(raw, lane)
        loss = jnp.sum(res * res)
        finite = jnp.isfinite(loss) & jnp.all(jnp.isfinite(raw))
        return raw, jnp.where(finite, code, RESULTS.NONFINITE), steps, jnp.where(finite, jnp.sqrt(loss), jnp.inf)

    raw0 = _starts(model, su, sv, c, y, sw, key, n_starts)  # (B, S, P)
    first = jnp.minimum(stage_steps, max_steps)
    stage1 = jax.lax.map(lambda r0: jax.vmap(solve, in_axes=(0, None, 0))(r0, first, lanes), jnp.swapaxes(raw0, 0, 1))
    raw_s, code_s, steps_s, l2_s = (jnp.swapaxes(a, 0, 1) for a in stage1)  # (B, S, ...)
    best = _pick(l2_s, code_s).astype(jnp.int32)
    raw_b, code_b, steps_b = _at(raw_s, best), _at(code_s, best), _at(steps_s, best)
    budget = jnp.where(code_b == RESULTS.OK, 0, max(max_steps - stage_steps, 0))
    raw2, code2, steps2, l22 = jax.vmap(solve)(raw_b, budget, lanes)
    done = code_b == RESULTS.OK  # converged in stage 1: keep its stage-1 state (a budget of 0 reports MAX_STEPS)
    raw2, code2, l22 = jnp.where(done[:, None], raw_b, raw2), jnp.where(done, code_b, code2), jnp.where(
        done, _at(l2_s, best), l22)
    rows = jnp.arange(best.shape[0])
    ok = jnp.all(jnp.isfinite(raw2), axis=-1)
    code2 = jnp.where(jnp.any(wpx > 0), code2, RESULTS.NO_SAMPLES)
    return dict(
        raw=jnp.where(ok[:, None], raw2, raw0[:, 0]), status=jnp.where(ok, code2, RESULTS.NONFINITE).astype(jnp.int32),
        steps=(steps_b + steps2).astype(jnp.int32), start_l2=l2_s.at[rows, best].set(l22) * scale,
        start_status=code_s.at[rows, best].set(code2).astype(jnp.int32), best_start=best,
        at_limit=model.snap_to_limits(raw2, _LIMIT_TOL)[1],
    )


@functools.partial(jax.jit, static_argnames=("name",))
def package(name, raw, u, v, c, y, wpx):
    """The kept optimum with its implicit derivative, its physical parameters and L2: the root-mean-square radiance
    residual over the kept pixels divided by the root-mean-square light factor ``sum_j c_j / cos(theta_u,j)``
    (``E V`` under one light: equation (11) of the light-factor-weighted BRDF residuals, as
    :func:`baselines.fit_to_images` reports under one light)."""
    model = get_model(name)
    su, sv = _safe_directions(u, v, c)
    fn = light_sum_residual(model, su, sv)
    sw = safe_sqrt(jnp.maximum(wpx, 0.0))
    raw = implicit_least_squares(lambda t, cb, yb: fn(t, (cb, yb, sw)), raw, c, y)
    res = jax.vmap(lambda t, cb, yb: fn(t, (cb, yb, sw)))(raw, c, y)
    factor = jnp.sum(jnp.where(c != 0, c / jnp.maximum(su[..., 2], 1e-12), 0.0), axis=-1)  # (B, N)
    den = jnp.sum(wpx * factor * factor, axis=-1)
    ok = den > 0
    l2 = jnp.where(ok, jnp.sqrt(jnp.sum(res * res, axis=-1) / jnp.where(ok, den, 1.0)), jnp.inf)
    return raw, model.to_params(raw), l2
