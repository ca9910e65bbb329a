r"""The derivative of a nonlinear fit: the kept start's optimum by the implicit function theorem.

At a minimum ``tau*`` of ``L(tau; d) = 1/2 sum_i r_i(tau; d)^2`` (``d`` = values, weights, ``u``, ``v``) the
gradient ``g(tau*; d) = J^T r`` vanishes, so along a change of the data

.. math:: H\, \dot\tau = -\,\partial_d g\; \dot d, \qquad H = \partial_\tau g
          \quad\text{(the full Hessian of } L\text{, second-order terms included).}

``jax.lax.custom_root`` applies this rule (forward and reverse mode, ``vmap``): the primal is the optimum the solver
found (never differentiated through its loop); the ``P x P`` system is solved with a damping ``1e-12 tr(H)`` so that
a parameter on a limit of its range (its transform's Jacobian column vanishes, a zero row and column of ``H`` and of
the right-hand side) gets derivative 0 and stays on its limit. The choice of start is piecewise constant. A lane that
did not converge (``status`` not ``OK``) gets the derivative of the point it stopped at, as if it were optimal.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def safe_sqrt(x):
    """``sqrt(x)`` for ``x >= 0`` with derivative 0 (not inf, not NaN) where ``x = 0`` (cut samples)."""
    pos = x > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, x, 1.0)), 0.0)


def residuals_of(model, u, v, y, wl, wc2):
    """``raw -> sqrt(w cos^2 / sum w) (y - f)`` of one lane (``y``, ``wl``, ``wc2`` are ``(n,)``)."""
    den = jnp.sum(wl)
    sw = safe_sqrt(wc2 / jnp.where(den > 0, den, 1.0))

    def fn(raw):
        f = model.evaluate(model.to_params(raw), u, v)
        keep = sw > 0
        return jnp.where(keep, sw * (y - jnp.where(keep, f, 0.0)), 0.0)

    return fn


def _damped_solve(h, b):
    p = h.shape[-1]
    lam = 1e-12 * jnp.maximum(jnp.trace(jnp.abs(h)), jnp.finfo(h.dtype).tiny)
    return jnp.linalg.solve(h + lam * jnp.eye(p, dtype=h.dtype), b)


def implicit_optimum(model, raw, u, v, y, wl, wc2):
    """``raw (B, P)`` unchanged, differentiable w.r.t. ``u``, ``v``, ``y``, ``wl``, ``wc2`` as the optimum of each
    lane's least-squares objective (see the module docs). ``raw`` itself carries no derivative."""
    wl = jnp.broadcast_to(wl, y.shape)
    wc2 = jnp.broadcast_to(wc2, y.shape)
    return implicit_least_squares(lambda t, yb, wlb, wc2b: residuals_of(model, u, v, yb, wlb, wc2b)(t), raw,
                                  y, wl, wc2)


def implicit_least_squares(residual, raw, *lanes):
    """``raw (B, P)`` unchanged, differentiable as the minimiser of ``1/2 |residual(raw_b, *lanes_b)|^2`` per lane
    ``b`` (the rule of the module docs); ``lanes`` are arrays ``(B, ...)``, and ``residual`` may close over data
    shared by every lane (differentiated too). ``raw`` itself carries no derivative."""
    raw = jax.lax.stop_gradient(raw)

    def one(raw_b, *lane):
        grad = lambda t: jax.grad(lambda s: 0.5 * jnp.sum(residual(s, *lane) ** 2))(t)  # noqa: E731
        return jax.lax.custom_root(
            grad, raw_b, solve=lambda g, x0: raw_b,
            tangent_solve=lambda g, b: _damped_solve(jax.jacfwd(g)(jnp.zeros_like(b)), b),
        )

    return jax.vmap(one)(raw, *lanes)
