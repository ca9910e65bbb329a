"""What every baseline model shares: parameter transforms, safe geometry, the model record.

Parameters are optimised unconstrained (``raw``) and mapped to their physical range by smooth
transforms:

- ``POSITIVE``: ``r^2`` in ``[0, inf)`` (albedos, lobe scales);
- ``UNIT``: ``sin^2(r)`` in ``[0, 1]`` (Fresnel reflectance at normal incidence);
- ``LogBounded(lo, hi)``: ``exp(log lo + (log hi - log lo) sin^2(r))`` in ``[lo, hi]``
  (exponents, roughnesses: scale-free steps, and bounded so no exponent overflows);
- ``Bounded(hi)``: ``hi |sin(r)|`` in ``[0, hi]``, for a parameter the model uses only squared
  (Oren-Nayar's ``sigma``): ``sigma^2 = hi^2 sin^2(r)`` is smooth in ``r`` and its bound 0 is a
  stationary point with non-zero curvature;
- ``REAL``: the identity (Lafortune's lobe coefficients).

Why not softplus / sigmoid: measured data often puts the optimum *on* a bound (no diffuse
term, ``F0 = 1``, a Lambertian Oren-Nayar ``sigma -> 0``). With an asymptotic transform the
optimiser then walks towards infinity in ``raw`` and never meets its step tolerance; with these
transforms a bound is reached at a finite ``raw`` where the derivative vanishes, i.e. at an
ordinary stationary point, and Levenberg-Marquardt converges there.
"""

from __future__ import annotations

import dataclasses
from typing import Callable, Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from polyjax import half_vector

#: Smallest cosine used in denominators: keeps grazing samples finite (1 / EPS_COS at most).
EPS_COS = 1e-6


@dataclasses.dataclass(frozen=True)
class Transform:
    """A smooth bijection from the real line to a parameter's physical range."""

    kind: str  # "positive", "unit", "logbounded", "bounded", "real"
    lo: float = 0.0
    hi: float = 0.0

    def forward(self, r):
        if self.kind == "positive":
            return r * r
        if self.kind == "unit":
            return jnp.sin(r) ** 2
        if self.kind == "logbounded":
            a, b = np.log(self.lo), np.log(self.hi)
            return jnp.exp(a + (b - a) * jnp.sin(r) ** 2)
        if self.kind == "bounded":
            return self.hi * jnp.abs(jnp.sin(r))
        return r

    def snap(self, r, tol: float = 1e-2):
        """Pull ``r`` onto the range limit it is within ``tol`` of, in the unit coordinate ``sin^2(r)``.

        The ``sin^2`` transforms reach their limits at the stationary points ``r = k pi / 2``, where
        the Jacobian column of the parameter vanishes. Gauss-Newton ignores the transform's curvature
        there, so a fit whose optimum lies beyond a limit creeps towards it without meeting the step
        tolerance; put on the limit exactly, the parameter stays there and the others converge.

        Returns:
            ``(r_snapped, at_limit)``; ``positive`` and ``real`` parameters are returned unchanged
            with ``at_limit = False``.
        """
        if self.kind not in ("unit", "logbounded", "bounded"):
            return r, jnp.zeros(jnp.shape(r), bool)
        t = jnp.sin(r) ** 2
        near = (t < tol) | (t > 1.0 - tol)
        half = 0.5 * np.pi
        return jnp.where(near, half * jnp.round(r / half), r), near

    def inverse(self, p):
        """The preimage in ``[0, pi/2]`` (or ``[0, inf)``); values on or beyond a bound are pulled just inside."""
        if self.kind == "positive":
            return jnp.sqrt(jnp.maximum(p, 1e-12))
        if self.kind == "unit":
            return jnp.arcsin(jnp.sqrt(jnp.clip(p, 1e-6, 1 - 1e-6)))
        if self.kind == "logbounded":
            a, b = np.log(self.lo), np.log(self.hi)
            t = jnp.clip((jnp.log(jnp.maximum(p, 1e-300)) - a) / (b - a), 1e-6, 1 - 1e-6)
            return jnp.arcsin(jnp.sqrt(t))
        if self.kind == "bounded":
            return jnp.arcsin(jnp.clip(p / self.hi, 1e-6, 1 - 1e-6))
        return p


POSITIVE = Transform("positive")
UNIT = Transform("unit")
REAL = Transform("real")


def LogBounded(lo: float, hi: float) -> Transform:  # noqa: N802
    return Transform("logbounded", lo, hi)


def Bounded(hi: float) -> Transform:  # noqa: N802
    return Transform("bounded", 0.0, hi)


@dataclasses.dataclass(frozen=True)
class BaselineModel:
    """The record of one baseline model in :data:`baselines.MODELS`.

    Attributes:
        name: the registry name, e.g. ``"cook-torrance"``.
        param_names: names of the constrained parameters, in order.
        transforms: one :class:`Transform` per parameter (raw -> constrained).
        evaluate: ``evaluate(params, u, v) -> f`` (pure JAX; ``params`` constrained, ``(P,)``).
        n_linear: the first ``n_linear`` parameters enter linearly through :attr:`columns`
            (used to seed every start by a small linear solve).
        columns: ``columns(nonlinear, u, v) -> (n, n_linear)`` basis with ``f = columns @ linear``.
        assemble: ``assemble(linear, nonlinear) -> params``; default: concatenation.
        guesses: ``(S0, P - n_linear)`` deterministic starting values of the nonlinear parameters.
        sample: ``sample(key, k) -> (k, P - n_linear)`` random starting values of the nonlinear parameters.
        reference: the literature reference.
        anisotropic: True for the anisotropic variants.
    """

    name: str
    param_names: tuple[str, ...]
    transforms: tuple[Transform, ...]
    evaluate: Callable
    n_linear: int
    columns: Callable
    guesses: np.ndarray
    sample: Callable
    reference: str = ""
    assemble: Callable | None = None
    anisotropic: bool = False
    linear: bool = False  # True for a linear model fitted in closed form (Zernike)
    #: names of parameters shared by the R, G, B channels of one material, fitted jointly; () fits each channel alone
    shared_across_channels: tuple[str, ...] = ()
    #: ``to_material(params (3, P)) -> dict``: a material's constrained R, G, B parameters named as its specification
    to_material: Callable | None = None
    #: ``evaluate_rgb(params (3, P), u, v) -> (3, n)``: the three channels at once (the joint record uses it; e.g. to
    #: compute what depends on the shared parameters once); None evaluates each channel with ``evaluate``
    evaluate_rgb: Callable | None = None

    @property
    def n_params(self) -> int:
        return len(self.param_names)

    def to_params(self, raw: Float[Array, "... P"]) -> Float[Array, "... P"]:
        """Map unconstrained parameters to physical ones."""
        return jnp.stack([t.forward(raw[..., i]) for i, t in enumerate(self.transforms)], axis=-1)

    def snap_to_limits(self, raw: Float[Array, "... P"], tol: float = 1e-2):
        """:meth:`Transform.snap` of every parameter: ``(raw_snapped, at_limit)``, both ``(..., P)``."""
        out = [t.snap(raw[..., i], tol) for i, t in enumerate(self.transforms)]
        return jnp.stack([o[0] for o in out], axis=-1), jnp.stack([o[1] for o in out], axis=-1)

    def to_raw(self, params: Float[Array, "... P"]) -> Float[Array, "... P"]:
        """Inverse of :meth:`to_params` (values at or beyond the range limits are pulled inside)."""
        params = jnp.asarray(params)
        return jnp.stack([t.inverse(params[..., i]) for i, t in enumerate(self.transforms)], axis=-1)

    def __call__(self, params, u, v):
        return self.evaluate(params, u, v)

    def combine(self, linear, nonlinear):
        if self.assemble is not None:
            return self.assemble(linear, nonlinear)
        return jnp.concatenate([linear, nonlinear], axis=-1)


def uniform_sampler(bounds: Sequence[tuple[float, float, bool]]) -> Callable:
    """``sample(key, k)``: independent draws per parameter, uniform in ``[lo, hi]`` (log-uniform when flagged)."""

    def sample(key, k):
        cols = []
        for i, (lo, hi, log) in enumerate(bounds):
            t = jax.random.uniform(jax.random.fold_in(key, i), (k,))
            cols.append(jnp.exp(np.log(lo) + (np.log(hi) - np.log(lo)) * t) if log else lo + (hi - lo) * t)
        return jnp.stack(cols, axis=-1)

    return sample


def grid(*axes: Sequence[float]) -> np.ndarray:
    """All combinations of the given values, first axis slowest: ``(prod len, n_axes)``."""
    mesh = np.meshgrid(*[np.asarray(a, float) for a in axes], indexing="ij")
    return np.stack([m.ravel() for m in mesh], axis=-1)


class Geometry:
    """Clamped cosines and the half vector of a batch of ``(u, v)`` pairs.

    ``above`` marks pairs with both directions strictly above the horizon; the specular lobes
    are set to 0 elsewhere. Denominators use cosines clamped to :data:`EPS_COS`, so values and
    gradients stay finite at grazing angles and for ``u = -v`` (where the half vector is ``+z``).
    """

    def __init__(self, u, v):
        u = jnp.asarray(u)
        v = jnp.asarray(v)
        self.u, self.v = u, v
        self.cu_raw = u[..., 2]
        self.cv_raw = v[..., 2]
        self.above = (self.cu_raw > 0) & (self.cv_raw > 0)
        self.cu = jnp.maximum(self.cu_raw, EPS_COS)
        self.cv = jnp.maximum(self.cv_raw, EPS_COS)
        self.h = half_vector(u, v)
        self.nh = jnp.maximum(self.h[..., 2], EPS_COS)  # cos(theta_h)
        self.vh = jnp.maximum(jnp.sum(v * self.h, axis=-1), EPS_COS)  # cos(theta_d)
        self.tan2_h = jnp.maximum(1.0 / (self.nh * self.nh) - 1.0, 0.0)  # tan^2(theta_h)


def lobe(g: Geometry, value):
    """``value`` where both directions are above the horizon, 0 elsewhere."""
    return jnp.where(g.above, value, 0.0)


def safe_pow(base, exponent):
    """``max(base, 0) ** exponent`` with finite values and gradients (0 where ``base <= 0``)."""
    pos = base > 0
    b = jnp.where(pos, base, 1.0)
    return jnp.where(pos, jnp.exp(jnp.minimum(exponent * jnp.log(b), 600.0)), 0.0)


def schlick(f0, cos_d):
    """Schlick's Fresnel approximation ``F0 + (1 - F0)(1 - cos)^5``."""
    return f0 + (1.0 - f0) * (1.0 - cos_d) ** 5


def diffuse_specular_columns(specular: Callable) -> Callable:
    """``columns(nl, u, v)`` of a model ``rho_d / pi + rho_s specular(*nl, g)`` (Ward, Ward-Duer, anisotropic Ward,
    Cook-Torrance, Ashikhmin-Shirley): the diffuse column ``1 / pi`` and the specular lobe at the nonlinear
    parameters ``nl`` (e.g. ``alpha``; ``m, F0``), the columns of the two parameters that enter linearly."""

    def columns(nl, u, v):
        g = Geometry(u, v)
        lobe_ = specular(*(nl[i] for i in range(nl.shape[0])), g)
        return jnp.stack([jnp.full_like(g.cu, 1.0 / jnp.pi), lobe_], -1)

    return columns
