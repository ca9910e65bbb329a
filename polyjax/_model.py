"""The fitted polynomial BRDF: an ``equinox.Module`` that evaluates equation (3) at any directions."""

from __future__ import annotations

import dataclasses
import functools
from typing import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, Int
from numpy.polynomial import legendre, polynomial

from ._arrays import is_traced
from ._basis import BASES, design_matrix, exponents, n_terms
from ._directions import call_directions, safe_normalize
from ._errors import InputError
from ._results import RESULTS
from ._variables import get_variables

#: the links of a polynomial model: equation (3) itself, or ``f = exp(P) - eps`` (:mod:`polyjax._fit.log`)
LINKS = ("identity", "log")
#: the fields of :class:`PolynomialSpec`, in order: the model's definition wherever it is given by keyword
SPEC_FIELDS = ("variables", "degree", "basis", "interactions", "link", "eps", "clamp")


class PolynomialSpec(eqx.Module):
    r"""The definition of a polynomial BRDF model, apart from the numbers a fit finds: a frozen, hashable value.

    The model is ``f = P`` (equation (3); equation (2) with ``interactions``) or, with ``link="log"``,
    ``f = exp(P) - eps``, where ``P`` is a polynomial of degree ``degree`` in the principal components of the
    explanatory variables ``variables`` (section 3), written in ``basis``. One definition serves every place that
    names a model: the fitters (``spec=`` of :func:`polyjax.fit_polynomial`, :func:`polyjax.fit_log_polynomial`,
    :func:`polyjax.fit_polynomial_to_images`, equal to their keyword arguments of the same names), a fitted model
    (:attr:`PolynomialBRDF.spec`), a saved model (the same fields, by name, in the file's header: ``docs/formats.md``)
    and the command line (``--variables --degree --basis --interactions --link --eps --clamp``).

    Attributes:
        variables: a registered variable set (stored by its canonical name: ``"as"`` becomes
            ``"ashikhmin-shirley"``).
        degree: ``p``, or a tuple of degrees (fitted at once, a leading degree axis; the log link takes one).
        basis: ``"legendre"`` (scaled Legendre polynomials, well conditioned) or ``"monomial"`` (the paper's powers).
        interactions: the full response surface of equation (2) instead of equation (3).
        link: ``"identity"`` or ``"log"``.
        eps: the log link's offset in 1/sr (``f >= -eps``); unused by the identity link.
        clamp: evaluate the polynomial at its scaled components clamped to the fitted box (a constant extension
            outside the fitted samples' range: :attr:`PolynomialBRDF.clamp`); Legendre basis only.

    Raises:
        InputError, UnknownNameError: a field that is not one of the values above, naming the field.
    """

    variables: str = eqx.field(static=True)
    degree: int | tuple[int, ...] = eqx.field(static=True)
    basis: str = eqx.field(static=True)
    interactions: bool = eqx.field(static=True)
    link: str = eqx.field(static=True)
    eps: float = eqx.field(static=True)
    clamp: bool = eqx.field(static=True)

    def __init__(self, variables: str = "lafortune", degree: int | Sequence[int] = 5, basis: str = "legendre",
                 interactions: bool = False, link: str = "identity", eps: float = 1e-3, clamp: bool = False):
        self.variables = get_variables(variables).name
        self.degree = _spec_degree(degree)
        if basis not in BASES:
            raise InputError(f"basis: expected one of {BASES}, found {basis!r}")
        self.basis = basis
        if not isinstance(interactions, (bool, np.bool_)):
            raise InputError(f"interactions: expected True or False, found {interactions!r}")
        self.interactions = bool(interactions)
        if link not in LINKS:
            raise InputError(f"link: expected one of {LINKS}, found {link!r}")
        self.link = link
        if isinstance(eps, bool) or not isinstance(eps, (int, float, np.floating, np.integer)) or not (
                np.isfinite(eps) and eps > 0):
            raise InputError(f"eps: expected a positive offset in 1/sr, found {eps!r}")
        self.eps = float(eps)
        self.clamp = check_clamp(clamp, basis)

    @property
    def n_parameters(self) -> int | tuple[int, ...]:
        """``k p + 1`` (equation (3)) or ``C(k + p, p)`` (equation (2)): one number, or one per degree."""
        k = get_variables(self.variables).k
        if isinstance(self.degree, tuple):
            return tuple(n_terms(k, p, self.interactions) for p in self.degree)
        return n_terms(k, self.degree, self.interactions)

    def to_dict(self) -> dict:
        """The fields as JSON values (``degree`` a list when several)."""
        return {f: (list(v) if isinstance(v, tuple) else v) for f in SPEC_FIELDS for v in [getattr(self, f)]}

    @classmethod
    def from_dict(cls, fields: dict) -> "PolynomialSpec":
        """The definition :meth:`to_dict` wrote (missing fields take their defaults; unknown keys are refused)."""
        unknown = sorted(set(fields) - set(SPEC_FIELDS))
        if unknown:
            raise InputError(f"PolynomialSpec: unknown fields {unknown}; expected some of {list(SPEC_FIELDS)}")
        return cls(**fields)


def _spec_degree(degree) -> int | tuple[int, ...]:
    """One non-negative integer, or a non-empty tuple of them (the message of the fitters' own check)."""
    degrees = np.atleast_1d(np.asarray(degree))
    if (isinstance(degree, bool) or degrees.ndim != 1 or degrees.size == 0
            or not np.issubdtype(degrees.dtype, np.integer) or np.any(degrees < 0)):
        raise InputError(f"degree: expected a non-negative integer or a sequence of them, found {degree!r}")
    return int(degrees[0]) if np.ndim(degree) == 0 else tuple(int(p) for p in degrees)


def spec_of(fn: str, spec, defaults: dict, **given) -> PolynomialSpec:
    """The model definition of a call of the fitter ``fn``: ``spec`` if given (a :class:`PolynomialSpec`), else
    made of the keyword arguments ``given`` (``variables=..., degree=...``). Keyword arguments that differ from
    their ``defaults`` and from ``spec`` are refused: the definition is given one way or the other."""
    if spec is None:
        return PolynomialSpec(**given)
    if not isinstance(spec, PolynomialSpec):
        raise InputError(f"{fn}: spec: expected a polyjax.PolynomialSpec, found {type(spec).__name__}")
    given = dict(given, variables=get_variables(given["variables"]).name)
    defaults = dict(defaults, variables=get_variables(defaults["variables"]).name)
    clash = [k for k, x in given.items() if not _same(x, defaults[k]) and not _same(x, getattr(spec, k))]
    if clash:
        both = ", ".join(f"{k}={given[k]!r} and spec.{k}={getattr(spec, k)!r}" for k in clash)
        raise InputError(f"{fn}: the model's definition is given twice, found {both}: pass spec= or keywords")
    return spec


def _same(a, b) -> bool:
    """Equal as definitions: ``7``, ``[7]`` and ``(7,)`` differ (one degree, or a degree axis)."""
    if isinstance(a, str) or isinstance(b, str):
        return a == b
    return np.shape(a) == np.shape(b) and bool(np.all(np.asarray(a) == np.asarray(b)))


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
        log_top: ``(*batch,)`` the log link's bound on the polynomial: ``f = exp(min(P, log_top)) - eps``, with
            ``log_top`` the largest ``P`` at the fitted samples (:func:`polyjax.fit_log_polynomial` sets it), so the
            model never exceeds its largest value at the samples, between them included (with few samples a
            degree-8 ``P`` reaches 50 between them: ``f`` of 1e22). None (the identity link, and models saved
            before the field existed): no bound. Every evaluator honours it, as :attr:`clamp`.
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
    log_top: Float[Array, "*batch"] | None = None  # the log link's bound on P (docs above)

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
    def spec(self) -> PolynomialSpec:
        """The model's definition (:class:`PolynomialSpec`): its variables, basis, interactions, link (with ``eps``)
        and highest degree ``max_degree`` (a fit of several degrees gives the highest; ``degree`` holds each lane's)."""
        return PolynomialSpec(self.variables, self.max_degree, self.basis, self.interactions, self.link,
                              self.eps if self.link == "log" else 1e-3, self.clamp)

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
        u, v = call_directions(u, v, self.coefficients.dtype)
        return _evaluate(self, u, v)

    def polynomial(self, u: ArrayLike, v: ArrayLike) -> Float[Array, "*batch ..."]:
        """The polynomial ``P`` itself at light directions ``u`` and view directions ``v``: the BRDF of the identity
        link, ``log(f + eps)`` of the log link before its bound :attr:`log_top` (:attr:`clamp` applies); 0 where
        ``u`` or ``v`` is below the horizon or has no direction. Arguments as :meth:`__call__`."""
        u, v = call_directions(u, v, self.coefficients.dtype)
        return _evaluate(self, u, v, raw=True)

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


__all__ = ["PolynomialBRDF", "PolynomialSpec", "evaluate_paper_form", "exponents"]


@functools.partial(jax.jit, static_argnames=("raw",))
def _evaluate(model: PolynomialBRDF, u, v, raw: bool = False):
    """:meth:`PolynomialBRDF.__call__` after its checks: one compiled program per model family and shapes (op by
    op, each of its few dozen operations would be compiled on its own for every new shape); ``raw``: the polynomial
    without the link (:meth:`PolynomialBRDF.polynomial`)."""
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
    if model.link == "log" and not raw:  # f = exp(min(poly, log_top)) - eps (polyjax._fit.log)
        if model.log_top is not None:  # the bound; at P = log_top the polynomial's derivative (not min's 1/2)
            top = jnp.reshape(model.log_top, model.batch_shape + (1,) * (out.ndim - nb))
            out = jnp.where(out > top, top, out)
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
