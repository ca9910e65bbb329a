r"""The folded Rusinkiewicz grid a learned basis is tabulated on, and its multilinear interpolation.

An isotropic, reciprocal BRDF depends on ``(theta_h, theta_d, phi_d)`` with ``phi_d`` folded into ``[0, pi/2]``
(isotropy maps ``phi_d -> -phi_d``, reciprocity ``phi_d -> phi_d + pi``): the folded angle is
``atan2(|d_y|, |d_x|)`` of the difference vector ``d``, the same for ``(u, v)`` and ``(v, u)``. The grid's unit
coordinates are

.. math::
    a = \sqrt{\theta_h / (\pi/2)}, \quad b = \theta_d / (\pi/2), \quad c = \varphi_d^{fold} / (\pi/2),

each in ``[0, 1]`` (``a`` warped as MERL's own ``theta_h`` axis, to resolve a sharp peak), with ``SHAPE`` nodes
on each axis including both ends. A table ``(*lead, Na, Nb, Nc)`` is read at a point by trilinear interpolation
(coordinates clipped to the box: every direction above the horizon maps inside it, so the value is bounded by the
table's extremes everywhere).
"""

import jax.numpy as jnp
import numpy as np

#: nodes on the (a, b, c) axes
SHAPE = (48, 24, 12)
_HALF_PI = 0.5 * np.pi
_TINY = 1e-30


def _safe_sqrt(x):
    pos = x > _TINY
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, x, 1.0)), 0.0)


def coordinates(u, v):
    """Unit grid coordinates ``(a, b, c)``, each ``(...)``, of light/view directions ``(..., 3)``
    (gradient-safe at the pole and at ``d_x = d_y = 0``)."""
    s = u + v
    n2 = jnp.sum(s * s, axis=-1, keepdims=True)
    ok = n2 > _TINY
    h = jnp.where(ok, s / _safe_sqrt(jnp.where(ok, n2, 1.0)), jnp.array([0.0, 0.0, 1.0], s.dtype))
    r = _safe_sqrt(h[..., 0] ** 2 + h[..., 1] ** 2)
    pole = r <= 1e-15
    safe = jnp.where(pole, 1.0, r)
    cos_p = jnp.where(pole, 1.0, h[..., 0] / safe)
    sin_p = jnp.where(pole, 0.0, h[..., 1] / safe)
    x = cos_p * u[..., 0] + sin_p * u[..., 1]
    y = -sin_p * u[..., 0] + cos_p * u[..., 1]
    cos_t, sin_t = h[..., 2], r
    dx = x * cos_t - u[..., 2] * sin_t
    dz = x * sin_t + u[..., 2] * cos_t
    theta_h = jnp.arctan2(r, h[..., 2])
    rho = _safe_sqrt(dx * dx + y * y)
    theta_d = jnp.arctan2(rho, dz)
    zero = rho <= 1e-15
    phi = jnp.where(zero, 0.0, jnp.arctan2(jnp.abs(y), jnp.abs(jnp.where(zero, 1.0, dx))))
    a = _safe_sqrt(jnp.clip(theta_h / _HALF_PI, 0.0, 1.0))
    return a, jnp.clip(theta_d / _HALF_PI, 0.0, 1.0), jnp.clip(phi / _HALF_PI, 0.0, 1.0)


def _axis(t, n):
    """Cell index ``i`` (0 .. n-2) and fraction of ``t`` in [0, 1] on ``n`` uniform nodes."""
    x = jnp.clip(t, 0.0, 1.0) * (n - 1)
    i = jnp.clip(jnp.floor(x), 0, n - 2).astype(jnp.int32)
    return i, x - i


def interpolation(u, v, shape=SHAPE):
    """The 8 corner node indices ``(..., 8)`` (flat, into ``prod(shape)``) and their trilinear weights ``(..., 8)``."""
    (ia, fa), (ib, fb), (ic, fc) = (_axis(t, n) for t, n in zip(coordinates(u, v), shape))
    idx, wts = [], []
    for da in (0, 1):
        for db in (0, 1):
            for dc in (0, 1):
                idx.append(((ia + da) * shape[1] + ib + db) * shape[2] + ic + dc)
                wts.append((fa if da else 1 - fa) * (fb if db else 1 - fb) * (fc if dc else 1 - fc))
    return jnp.stack(idx, -1), jnp.stack(wts, -1)


def sample(table, u, v):
    """Table ``(k, prod(SHAPE))`` read at directions ``(n, 3)``: ``(n, k)``, trilinear."""
    idx, w = interpolation(u, v)
    rows = jnp.asarray(table).T  # (nodes, k): each corner gathers whole rows, (n, k) at a time
    out = w[:, 0, None] * rows[idx[:, 0]]
    for j in range(1, idx.shape[-1]):
        out = out + w[:, j, None] * rows[idx[:, j]]
    return out


def node_directions(shape=SHAPE):
    """Light and view unit vectors ``(prod(shape), 3)`` at the nodes (``phi_h = 0``), in numpy float64."""
    a, b, c = (np.linspace(0.0, 1.0, n) for n in shape)
    th, td, pd = np.meshgrid(a * a * _HALF_PI, b * _HALF_PI, c * _HALF_PI, indexing="ij")
    dx, dy, dz = np.sin(td) * np.cos(pd), np.sin(td) * np.sin(pd), np.cos(td)
    ct, st = np.cos(th), np.sin(th)
    u = np.stack([dx * ct + dz * st, dy, dz * ct - dx * st], -1).reshape(-1, 3)
    v = np.stack([-dx * ct + dz * st, -dy, dz * ct + dx * st], -1).reshape(-1, 3)
    return u, v
