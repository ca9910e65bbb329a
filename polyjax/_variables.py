"""Explanatory variables X(u, v) of the polynomial model (paper, section 3).

Each set maps a light direction ``u`` and a view direction ``v`` (unit vectors in the local frame,
normal ``n = +z``) to ``k`` scalar variables:

==========================  =========================================  ====  ==========
name                        variables                                  k     reciprocal
==========================  =========================================  ====  ==========
``ward``                    n.h, (n.u)(n.v)                  (sec 3.1)  2     yes
``ashikhmin-shirley``       n.h, v.h, max(n.u, n.v)         (eq. 9)    3     yes
``lafortune``               ux vx + uy vy, uz vz             (sec 3.3)  2     yes
``lafortune-anisotropic``   ux vx, uy vy, uz vz              (eq. 10)   3     yes
``rusinkiewicz``            theta_h, theta_d                           2     yes
``rusinkiewicz-phid``       theta_h, theta_d, sin^2(theta_d) cos(2 phi_d)  3  yes
==========================  =========================================  ====  ==========

The Rusinkiewicz half/difference angles (Rusinkiewicz 1998) are the coordinates measured BRDFs
(MERL) are tabulated in: ``theta_h`` the polar angle of ``h``, ``theta_d`` the angle between ``u``
and ``h``, ``phi_d`` the azimuth of ``u`` about ``h`` in the frame where ``phi_h = 0``. Swapping
``u`` and ``v`` sends ``phi_d`` to ``phi_d + pi``, so ``phi_d`` enters as
``sin^2(theta_d) cos(2 phi_d) = d_x^2 - d_y^2``: reciprocal, even in ``phi_d`` (isotropic), smooth
where ``phi_d`` is undefined (``theta_d = 0``). The three variables describe every isotropic BRDF;
an anisotropic one would also need ``phi_h``. Angles are computed as ``atan2`` of a guarded norm
and a cosine (never ``arccos``), so values and gradients stay finite at ``theta = 0``; at
``theta_h = 0`` (``h = n``, ``phi_h`` undefined) ``phi_h = 0`` is used.

``h = (u + v)/|u + v|`` is the half vector; ``v.h = u.h``, so every built-in set is symmetric
in ``u`` and ``v`` and the fitted model is reciprocal. Users can add their own set with
:func:`register_variables`.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._directions import half_vector
from ._errors import InputError, UnknownNameError

#: ``jax.jit`` of each variable function, made once: a set evaluated outside a trace runs as one compiled program
_compiled = functools.lru_cache(maxsize=None)(jax.jit)

VariableFn = Callable[[Float[Array, "... 3"], Float[Array, "... 3"]], Float[Array, "... k"]]


@dataclasses.dataclass(frozen=True)
class VariableSet:
    """A named set of explanatory variables.

    Attributes:
        name: registry key.
        fn: ``fn(u, v) -> (..., k)``, a pure JAX function.
        k: number of variables.
        symmetric: True when ``fn(u, v) == fn(v, u)`` (the fitted model is then reciprocal).
        description: one line naming the variables.
    """

    name: str
    fn: VariableFn
    k: int
    symmetric: bool
    description: str = ""

    def __call__(self, u, v):
        return _compiled(self.fn)(u, v)


def _ward(u, v):
    h = half_vector(u, v)
    return jnp.stack([h[..., 2], u[..., 2] * v[..., 2]], axis=-1)


def _ashikhmin_shirley(u, v):
    h = half_vector(u, v)
    vh = jnp.sum(v * h, axis=-1)
    return jnp.stack([h[..., 2], vh, jnp.maximum(u[..., 2], v[..., 2])], axis=-1)


def _lafortune(u, v):
    return jnp.stack([u[..., 0] * v[..., 0] + u[..., 1] * v[..., 1], u[..., 2] * v[..., 2]], axis=-1)


def _lafortune_anisotropic(u, v):
    return u * v


def _safe_norm(a):
    """``|a|`` over the last axis with a finite (zero) gradient at ``a = 0``."""
    r2 = jnp.sum(a * a, axis=-1)
    pos = r2 > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, r2, 1.0)), 0.0)


def _half_difference(u, v):
    """``theta_h``, ``theta_d`` and the difference vector ``d`` (``u`` in the frame of ``h`` with ``phi_h = 0``)."""
    h = half_vector(u, v)
    rh = _safe_norm(h[..., :2])
    theta_h = jnp.arctan2(rh, h[..., 2])
    theta_d = jnp.arctan2(_safe_norm(jnp.cross(u, h)), jnp.sum(u * h, axis=-1))
    pole = rh <= 0
    rs = jnp.where(pole, 1.0, rh)
    cos_p, sin_p = jnp.where(pole, 1.0, h[..., 0] / rs), jnp.where(pole, 0.0, h[..., 1] / rs)
    x = cos_p * u[..., 0] + sin_p * u[..., 1]  # d = R_y(-theta_h) R_z(-phi_h) u
    y = -sin_p * u[..., 0] + cos_p * u[..., 1]
    dx = x * h[..., 2] - u[..., 2] * rh
    return theta_h, theta_d, dx, y


def _rusinkiewicz(u, v):
    theta_h, theta_d, _, _ = _half_difference(u, v)
    return jnp.stack([theta_h, theta_d], axis=-1)


def _rusinkiewicz_phid(u, v):
    theta_h, theta_d, dx, dy = _half_difference(u, v)
    return jnp.stack([theta_h, theta_d, dx * dx - dy * dy], axis=-1)


_REGISTRY: dict[str, VariableSet] = {}
_ALIASES = {"as": "ashikhmin-shirley", "ashikhmin": "ashikhmin-shirley", "laf": "lafortune"}


def _register_builtin(name: str, fn: VariableFn, k: int, description: str) -> None:
    """A built-in set, symmetric by construction (tested): registered without running JAX on import."""
    _REGISTRY[name] = VariableSet(name, fn, k, True, description)


def register_variables(
    name: str, fn: VariableFn, k: int, *, symmetric: bool = False, description: str = "", overwrite: bool = False
) -> VariableSet:
    """Register a set of explanatory variables under ``name``.

    Args:
        name: the key used in ``fit_polynomial(..., variables=name)`` and stored with saved models.
        fn: ``fn(u, v) -> (..., k)``, traceable by JAX, finite for every unit ``u``, ``v`` above the horizon.
        k: number of variables it returns.
        symmetric: declare ``fn(u, v) == fn(v, u)``; checked on random directions.
        description: one line for reports.
        overwrite: allow replacing an existing set.

    Returns:
        The registered :class:`VariableSet`.
    """
    key = name.strip().lower()
    if key in _REGISTRY and not overwrite:
        raise InputError(f"variables {name!r}: a set of that name exists (pass overwrite=True to replace it)")
    if int(k) < 1:
        raise InputError(f"k: expected a positive number of variables, found {k}")
    rng = np.random.default_rng(0)
    w = rng.normal(size=(2, 8, 3))
    w[..., 2] = np.abs(w[..., 2]) + 0.1
    w /= np.linalg.norm(w, axis=-1, keepdims=True)
    out = jnp.asarray(fn(jnp.asarray(w[0]), jnp.asarray(w[1])))
    if out.shape != (8, int(k)):
        raise InputError(
            f"variables {name!r}: fn(u, v) for u, v of shape (8, 3) should return (8, {k}), returned {out.shape}"
        )
    if symmetric:
        swapped = jnp.asarray(fn(jnp.asarray(w[1]), jnp.asarray(w[0])))
        if not bool(jnp.allclose(out, swapped, rtol=1e-5, atol=1e-6)):
            raise InputError(f"variables {name!r}: declared symmetric but fn(u, v) != fn(v, u)")
    vs = VariableSet(key, fn, int(k), bool(symmetric), description)
    _REGISTRY[key] = vs
    return vs


def get_variables(name: str | VariableSet) -> VariableSet:
    """Look up a variable set by name (aliases: ``"as"``, ``"laf"``)."""
    if isinstance(name, VariableSet):
        return name
    key = str(name).strip().lower()
    key = _ALIASES.get(key, key)
    try:
        return _REGISTRY[key]
    except KeyError:
        raise UnknownNameError(f"variables {name!r}: expected one of {sorted(_REGISTRY)}") from None


def variable_sets() -> tuple[str, ...]:
    """Names of every registered variable set."""
    return tuple(sorted(_REGISTRY))


def explanatory_variables(name: str, u, v) -> Float[Array, "... k"]:
    """Evaluate the variable set ``name`` at directions ``u``, ``v``."""
    return get_variables(name).fn(jnp.asarray(u), jnp.asarray(v))


_register_builtin("ward", _ward, 2, "n.h, (n.u)(n.v)  [paper sec. 3.1]")
_register_builtin("ashikhmin-shirley", _ashikhmin_shirley, 3, "n.h, v.h, max(n.u, n.v)  [paper eq. (9)]")
_register_builtin("lafortune", _lafortune, 2, "ux vx + uy vy, uz vz  [paper sec. 3.3]")
_register_builtin("lafortune-anisotropic", _lafortune_anisotropic, 3, "ux vx, uy vy, uz vz  [paper eq. (10)]")
_register_builtin("rusinkiewicz", _rusinkiewicz, 2, "theta_h, theta_d  [Rusinkiewicz 1998]")
_register_builtin("rusinkiewicz-phid", _rusinkiewicz_phid, 3,
                  "theta_h, theta_d, sin^2(theta_d) cos(2 phi_d)  [Rusinkiewicz 1998]")
