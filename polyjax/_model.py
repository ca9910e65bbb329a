"""The fitted polynomial BRDF: an ``equinox.Module`` that evaluates equation (3) at any directions."""

from __future__ import annotations

import dataclasses
import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, Int
from numpy.polynomial import legendre, polynomial

from ._arrays import is_traced
from ._basis import design_matrix, exponents, n_terms
from ._directions import safe_normalize
from ._errors import InputError
from ._results import RESULTS
from ._variables import get_variables


class PolynomialBRDF(eqx.Module):
    r"""A fitted polynomial BRDF (paper, equation (3)), possibly a batch of them.

    ``f(u, v) = sum_i beta_i B_i(t(X(u, v)))`` where ``X`` are the explanatory variables,
    ``Z = (X - mean) @ rotation`` their principal components, ``t = (Z - centre) / halfwidth``
    and ``B_i`` the basis functions of :func:`polyjax.design_matrix` (Legendre by default, or the
    paper's monomials ``Z_j^d``). Every array field has the same leading batch shape
    (materials, channels, degrees ...); call the model to evaluate all of them at once.

    Attributes:
        coefficients: ``(*batch, m)`` basis coefficients, ``m = k * max_degree + 1`` (0 beyond a lane's degree).
        degree: ``(*batch,)`` the degree ``p`` of each lane.
        mean, rotation: PCA transform, ``(*batch, k)`` and ``(*batch, k, k)``.
        centre, halfwidth: affine map of each component onto ``[-1, 1]`` (0 and 1 for monomials); a
            half-width of ``inf`` marks a component that was constant over the fitted samples (``t = 0``).
        l2: ``(*batch,)`` L2 error (equation (11)) on the fitted data.
        rank, condition: numerical rank and condition number of the weighted design.
        n_used: samples that entered the fit.
        status: :class:`polyjax.RESULTS` codes (``RESULTS.<CODE>.message`` says what each means).
        variables, basis, interactions, max_degree: static description of the model family.
        link, eps: ``"identity"`` (equation (3) itself, the default) or ``"log"``: the model is then
            ``f = exp(poly) - eps``, the polynomial fitted in log space (:func:`polyjax.fit_log_polynomial`).
        clamp: evaluate at the scaled components clamped to the fitted box, ``t_j -> min(max(t_j, -1), 1)``
            (``[-1, 1]`` holds every fitted sample's components): the fitted model inside the box, and outside it
            the value at the nearest point of the box (a constant extension along each component), so the
            model stays bounded where no sample constrained it (a degree-8 polynomial grows like ``t^8`` there).
            False (the default): the polynomial everywhere. Legendre basis only (a monomial model keeps no
            range). Every evaluator honours it: calls, renders, the GLSL, numpy and Dr.Jit exports (the Mitsuba
            plugin, the viewer) and MERL tables; it does not change the fit.
    """

    coefficients: Float[Array, "*batch m"]
    degree: Int[Array, "*batch"]
    mean: Float[Array, "*batch k"]
    rotation: Float[Array, "*batch k k"]
    centre: Float[Array, "*batch k"]
    halfwidth: Float[Array, "*batch k"]
    l2: Float[Array, "*batch"]
    rank: Int[Array, "*batch"]
    condition: Float[Array, "*batch"]
    n_used: Int[Array, "*batch"]
    status: Int[Array, "*batch"]
    variables: str = eqx.field(static=True)
    basis: str = eqx.field(static=True)
    interactions: bool = eqx.field(static=True)
    max_degree: int = eqx.field(static=True)
    link: str = eqx.field(static=True, default="identity")  # log link: f = exp(poly) - eps (polyjax._fit.log)
    eps: float = eqx.field(static=True, default=0.0)
    clamp: bool = eqx.field(static=True, default=False)  # constant extension outside the fitted box (docs above)

    def __check_init__(self):
        if not isinstance(self.clamp, bool):  # a static field: hashed, and saved as JSON
            raise InputError(f"clamp: expected True or False, found {self.clamp!r}")
        check_clamp(self.clamp, self.basis)

    @property
    def batch_shape(self) -> tuple[int, ...]:
        return tuple(self.degree.shape)

    @property
    def k(self) -> int:
        return int(self.mean.shape[-1])

    @property
    def n_params(self) -> Int[Array, "*batch"]:
        """Number of parameters of each lane: ``k p + 1`` (or ``C(k+p, p)`` with interactions)."""
        table = np.array([n_terms(self.k, p, self.interactions) for p in range(self.max_degree + 1)])
        if not is_traced(self.degree):  # no compiled program for a table look-up
            return table[np.asarray(self.degree)]
        return jnp.asarray(table)[self.degree]

    @property
    def ok(self) -> Array:
        """True for lanes whose fit has full rank and samples."""
        return self.status == RESULTS.OK

    def __getitem__(self, index) -> "PolynomialBRDF":
        """Select lanes of the batch (``model[3]``, ``model[:, 0]``)."""
        if not self.batch_shape:
            raise IndexError("this PolynomialBRDF has no batch axes")
        key = _index_key(index)
        if key is None:  # an array index
            return jax.tree.map(lambda a: a[index], self)
        return _select(self, key)  # one compiled program per index (op by op, two per field)

    def _lane(self, params, x: Float[Array, "... k"]) -> Float[Array, "..."]:
        coef, mean, rot, centre, hw = params
        t = ((x - mean) @ rot - centre) / hw
        if self.clamp:  # the nearest point of the fitted box; on its faces the inside's derivative (not clip's 1/2)
            t = jnp.where(t > 1.0, 1.0, jnp.where(t < -1.0, -1.0, t))
        return design_matrix(t, self.max_degree, self.basis, self.interactions) @ coef

    def __call__(self, u: ArrayLike, v: ArrayLike) -> Float[Array, "*batch ..."]:
        """Evaluate at light directions ``u`` and view directions ``v``.

        Args:
            u, v: ``(..., 3)`` directions (broadcast together; renormalised).

        Returns:
            ``(*batch, ...)`` BRDF values; 0 where ``u`` or ``v`` is below the horizon or has no
            direction. The polynomial's values are not clamped and can be negative (:attr:`clamp` clamps its
            arguments to the fitted box).
        """
        dtype = self.coefficients.dtype
        u, v = (a if isinstance(a, jax.Array) else np.asarray(a, dtype) for a in (u, v))
        if u.ndim < 1 or v.ndim < 1 or u.shape[-1] != 3 or v.shape[-1] != 3:
            raise InputError(f"u, v: expected directions of shape (..., 3), found {u.shape} and {v.shape}")
        try:
            np.broadcast_shapes(u.shape, v.shape)
        except ValueError:
            raise InputError(
                f"u and v: expected shapes that broadcast together, found {u.shape} and {v.shape}") from None
        return _evaluate(self, u, v)

    def paper_coefficients(self) -> np.ndarray:
        r"""The coefficients ``beta`` of equation (3) in the paper's monomials of the raw components.

        Converts this model's basis (e.g. scaled Legendre) to ``f = beta_0 + sum_{d,j} beta_{(d-1)k+j} Z_j^d``.
        Only for models without interaction terms.

        Returns:
            ``(*batch, k * max_degree + 1)`` numpy array in the order of equation (13).
        """
        if self.interactions:
            raise ValueError("paper_coefficients: only defined for the model of equation (3) (interactions=False)")
        k, p = self.k, self.max_degree
        coef = np.asarray(self.coefficients, dtype=np.float64).reshape(-1, k * p + 1)
        centre = np.asarray(self.centre, dtype=np.float64).reshape(-1, k)
        hw = np.asarray(self.halfwidth, dtype=np.float64).reshape(-1, k)
        out = np.zeros_like(coef)
        for b in range(coef.shape[0]):
            beta0 = coef[b, 0]
            for j in range(k):
                series = np.zeros(p + 1)
                series[1:] = coef[b, 1 + j :: k][:p]
                power_t = legendre.leg2poly(series) if self.basis == "legendre" else series
                power_t = np.pad(power_t, (0, p + 1 - len(power_t)))
                # substitute t = (Z - c) / h  -> power series in Z
                affine = np.array([-centre[b, j] / hw[b, j], 1.0 / hw[b, j]])
                in_z = np.zeros(p + 1)
                acc = np.array([1.0])
                for d in range(p + 1):
                    in_z[: len(acc)] += power_t[d] * acc
                    acc = polynomial.polymul(acc, affine)
                beta0 += in_z[0]
                out[b, 1 + j :: k] = in_z[1:]
            out[b, 0] = beta0
        return out.reshape(self.coefficients.shape)


def check_clamp(clamp, basis: str) -> bool:
    """The ``clamp=`` option of a fit checked before any work (:attr:`PolynomialBRDF.clamp`)."""
    if not isinstance(clamp, (bool, np.bool_)):
        raise InputError(f"clamp: expected True or False, found {clamp!r}")
    if clamp and basis != "legendre":
        raise InputError(f"clamp: only for the Legendre basis (its components are scaled onto [-1, 1] over the "
                         f"fitted samples), found basis {basis!r}")
    return bool(clamp)


def with_clamp(model: PolynomialBRDF, clamp: bool) -> PolynomialBRDF:
    """``model`` evaluated with :attr:`PolynomialBRDF.clamp` set to ``clamp`` (the same arrays)."""
    return model if model.clamp == clamp else dataclasses.replace(model, clamp=bool(clamp))


def evaluate_paper_form(beta: ArrayLike, z: ArrayLike, degree: int) -> Array:
    """Equation (3) evaluated literally: ``beta_0 + sum_{d, j} beta_{(d-1)k+j} Z_j^d`` for components ``z (..., k)``."""
    z = jnp.asarray(z)
    return design_matrix(z, degree, "monomial", False) @ jnp.asarray(beta)


__all__ = ["PolynomialBRDF", "evaluate_paper_form", "exponents"]


@jax.jit
def _evaluate(model: PolynomialBRDF, u, v):
    """:meth:`PolynomialBRDF.__call__` after its checks: one compiled program per model family and shapes (op by
    op, each of its few dozen operations would be compiled on its own for every new shape)."""
    dtype = model.coefficients.dtype
    u, ok_u = safe_normalize(jnp.asarray(u, dtype))
    v, ok_v = safe_normalize(jnp.asarray(v, dtype))
    u, v = jnp.broadcast_arrays(u, v)
    above = ok_u & ok_v & (u[..., 2] > 0) & (v[..., 2] > 0)
    x = get_variables(model.variables).fn(u, v)
    nb = len(model.batch_shape)
    params = (model.coefficients, model.mean, model.rotation, model.centre, model.halfwidth)
    if nb == 0:
        out = model._lane(params, x)
    else:
        flat = jax.tree.map(lambda a: a.reshape((-1,) + a.shape[nb:]), params)
        out = jax.vmap(lambda p: model._lane(p, x))(flat)
        out = out.reshape(model.batch_shape + out.shape[1:])
    if model.link == "log":  # f = exp(poly) - eps (polyjax._fit.log)
        out = jnp.exp(out) - model.eps
    return jnp.where(above, out, 0.0)


def _index_key(index):
    """A hashable form of a basic index (integers, slices, None, Ellipsis and tuples of them; slices are not
    hashable before Python 3.12), or None for any other index."""
    if isinstance(index, tuple):
        keys = tuple(_index_key(i) for i in index)
        return None if None in keys else ("tuple", keys)
    if isinstance(index, slice):
        parts = (index.start, index.stop, index.step)
        ok = all(p is None or (isinstance(p, (int, np.integer)) and not isinstance(p, bool)) for p in parts)
        return ("slice", tuple(None if p is None else int(p) for p in parts)) if ok else None
    if isinstance(index, (int, np.integer)) and not isinstance(index, bool):
        return ("int", int(index))
    if index is None or index is Ellipsis:
        return ("atom", index)
    return None


def _from_key(key):
    """The index :func:`_index_key` made ``key`` from."""
    kind, value = key
    if kind == "tuple":
        return tuple(_from_key(k) for k in value)
    return slice(*value) if kind == "slice" else value


@functools.partial(jax.jit, static_argnames=("key",))
def _select(model: PolynomialBRDF, key) -> PolynomialBRDF:
    index = _from_key(key)
    return jax.tree.map(lambda a: a[index], model)
