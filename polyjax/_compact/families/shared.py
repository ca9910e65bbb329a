r"""The ``shared`` family: one lobe shape for the three channels, each channel its own offset and scale.

The colour of most materials is in a few numbers, not in the shape: a white paper's channels differ in their
diffuse level, a satin's and a metal's in their scale. So the numbers go to one shape ``S`` shared by the channels,
and each channel ``c`` adds a diffuse offset ``d_c`` and a scale ``s_c``:

.. math::
    f_c(u, v) = \max\big(0,\ d_c + s_c\, S(u, v)\big), \qquad S = \exp(\min(g, g_{top})) - 1,

    g(u, v) = \sum_{j < k} a_j B_j(u, v) + t(u, v) \sum_{j < m} e_j B_j(u, v) + \sum_l p_l P_l(u, v),

``B_j`` the rows of the learned basis (``basis.py``: its mean and principal components of ``log(1 + f)``,
tabulated on the folded grid), ``t = cos(theta_u) - cos(theta_v)`` the non-reciprocal factor (``skew.py``), and
``P_l`` the monomials ``s^i q^j z^r`` of total degree 1 to ``p`` in the symmetric variables ``s = cos theta_u +
cos theta_v``, ``q = cos theta_u cos theta_v``, ``z = u_x v_x + u_y v_y``, with the Lommel-Seeliger term
``1 / (s + 0.05)`` (single scattering in a diffusing medium, as paper's) when ``p >= 0``: smooth shapes the basis
learned from MERL does not span. ``g_top`` is the largest ``g`` at the folded grid's nodes inside the 80-degree
cutoff (both orientations of each node): where the data weigh little, the model does not exceed its value where
they weigh. Every column is bounded, so ``f`` is bounded at every direction above the horizon, and never negative.
``k + m + n_P + 6`` numbers per material (:meth:`SharedShapeFamily.n_numbers`).

The fit, a few closed-form solves:

1. the shape of the channels' mean: ``g`` fitted to it by the basis family's fit (``basis.py``: one linearised
   weighted solve, then its Gauss-Newton steps on the log metric mixed with equation (11)'s L2);
2. each channel's ``(d_c, s_c)``: one weighted least-squares solve of two unknowns (the log metric linearised in
   ``f``, mixed with equation (11)'s L2 as the basis fit mixes them).

Gauss-Newton steps on every parameter at once after step 2 (``3 n`` rows) lowered the held-out L2 by 0-8 % on the
RGL satin and gold-metallic-paint and tripled the fit's time; the cross-validation fits each fold as step 1 does
(:func:`fit_folds`), so the family stays cheap enough to be tried beside the others.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np

from . import _grid
from ._on_basis import OnLearnedBasis
from .basis import G_MAX, _inside_nodes, _lstsq, _weights, mix_for
from .basis import _fit as basis_fit
from .basis import fit_folds as basis_fit_folds
from .skew import skew_factor

#: the degrees of the symmetric polynomial terms a configuration may add (-1: none)
POLY_DEGREES = (-1, 3)
#: the numbers of skew rows a configuration may use
SKEW_ROWS = (0, 5)
#: the offset of the Lommel-Seeliger term ``1 / (s + LS_OFFSET)``
LS_OFFSET = 0.05
#: per material: three offsets and three scales
COLOUR_NUMBERS = 6


def n_poly(p: int) -> int:
    """Columns of the symmetric terms of degree ``p``: the monomials of degree 1 to ``p`` in three variables and
    the Lommel-Seeliger term (0 for ``p < 0``)."""
    return 0 if p < 0 else (p + 1) * (p + 2) * (p + 3) // 6


def _poly_terms(u, v, p, xp=jnp):
    """``(n, n_poly(p))``: the symmetric terms at directions ``(n, 3)`` (module docstring); ``xp`` numpy for
    constants."""
    x, y = xp.clip(u[:, 2], 0.0, 1.0), xp.clip(v[:, 2], 0.0, 1.0)
    s, q, z = x + y, x * y, u[:, 0] * v[:, 0] + u[:, 1] * v[:, 1]
    cols = [s ** i * q ** j * z ** r for i in range(p + 1) for j in range(p + 1 - i) for r in range(p + 1 - i - j)
            if i + j + r > 0]
    return xp.stack(cols + [1.0 / (s + LS_OFFSET)], -1)


class SharedShapeFamily(OnLearnedBasis):
    """One shape for the three channels (module docstring); configurations ``(k, m, p)``: ``k`` basis rows, ``m``
    of them also times the non-reciprocal factor, symmetric terms of degree ``p`` (-1: none). ``basis`` and
    ``trained_on`` as :class:`BasisFamily` (default: the shipped basis); parameters ``(*batch, k + m + n_P + 6)``:
    the shape's coefficients, then the offsets ``d`` and the scales ``s`` of R, G, B."""

    name = "shared"

    def n_numbers(self, config) -> int:
        k, m, p = config
        return int(k) + int(m) + n_poly(int(p)) + COLOUR_NUMBERS

    def configs(self, budget: int) -> list[tuple[int, int, int]]:
        """For each ``m`` of :data:`SKEW_ROWS` and ``p`` of :data:`POLY_DEGREES`, the largest ``k`` (at least
        ``max(m, 1)``, at most the basis rows) within ``budget``: three at 33 numbers, ``(27, 0, -1)``,
        ``(22, 5, -1)`` and ``(7, 0, 3)``."""
        out = []
        for p in POLY_DEGREES:
            for m in SKEW_ROWS:
                k = min(budget - COLOUR_NUMBERS - m - n_poly(p), self._rows)
                if k >= max(m, 1):
                    out.append((k, m, p))
        return out

    def candidates(self, budget: int) -> list[tuple[int, int, int]]:
        """The configurations :func:`polyjax.fit_compact` may try within ``budget``: :meth:`candidate_chains`,
        flattened."""
        return [c for chain in self.candidate_chains(budget) for c in chain]

    def candidate_chains(self, budget: int) -> list[list[tuple[int, int, int]]]:
        """For each degree ``p`` the reciprocal configuration, then the one with skew rows: the choice walks a chain
        while the held-out error falls, so the skew rows are tried only where the shape of that degree is the best
        of the heads (a measurement far from reciprocal: the RGL satin; cross-validating them on every material
        would cost a third of :func:`polyjax.fit_compact`'s time)."""
        configs = self.configs(budget)
        chains = [[c for c in configs if c[2] == p] for p in POLY_DEGREES]
        return [chain for chain in chains if chain]

    def columns(self, config, u, v):
        """``(n, k + m + n_P)``: the basis rows, the skew rows, the symmetric terms at directions ``(n, 3)``."""
        return self._design(config, self.program(config)[1], u, v)

    # the choice's program interface (polyjax/_compact/select.py; program, fit and evaluate: OnLearnedBasis); the
    # folds are fitted by its own ``fit_folds`` (its columns not named ``design``: the basis family's fold fits are
    # per channel)

    def _design(self, config, arrays, u, v):
        """``(n, k + m + n_P)``: the columns at directions ``(n, 3)``, the basis rows read from ``arrays[0]``."""
        k, m, p = config
        phi = _grid.sample(arrays[0][: max(k, m)], u, v)
        cols = [phi[:, :k], skew_factor(u, v)[:, None] * phi[:, :m]]
        if p >= 0:
            cols.append(_poly_terms(u, v, p))
        return jnp.concatenate(cols, -1)

    def _top_columns(self, config, arrays, dtype):
        """The columns at the folded grid's nodes inside the 80-degree cutoff, in both orientations ``(2 M, w)``:
        the basis rows are the table's values there (the same in both), the skew rows change sign."""
        k, m, p = config
        idx, _ = _inside_nodes()
        rows = arrays[0][: max(k, m)][:, idx].T
        t, poly = _node_terms(p)
        t, poly = jnp.asarray(t, dtype)[:, None], jnp.asarray(poly, dtype)
        return jnp.concatenate([jnp.concatenate([rows[:, :k], sign * t * rows[:, :m], poly], -1)
                                for sign in (1.0, -1.0)])

    def fit_program(self, config, arrays, u, v, values, weights, mask, metric: str = "log"):
        values = jnp.asarray(values)
        mask = jnp.ones(values.shape, bool) if mask is None else mask
        return _fit(self._design(config, arrays, u, v), u, v, values, weights, mask, mix_for(metric))

    def evaluate_program(self, config, arrays, params, u, v):
        phi = self._design(config, arrays, u, v)
        return shared_value(phi, self._top_columns(config, arrays, phi.dtype), params)

    def fit_folds(self, config, arrays, u, v, values, weights, mask, held, parts, metric: str = "log"):
        """The cross-validation's fold fits ``(*batch, K, w + 6)`` (:func:`fit_folds`)."""
        return fit_folds(self._design(config, arrays, u, v), u, v, jnp.asarray(values), weights, mask, held,
                         parts, mix_for(metric))


@functools.cache
def _node_terms(p: int):
    """The skew factor ``(M,)`` and the symmetric terms ``(M, n_poly(p))`` at the nodes inside the 80-degree
    cutoff (numpy, computed once per degree)."""
    idx, _ = _inside_nodes()
    nu, nv = (a[idx] for a in _grid.node_directions())
    t = np.clip(nu[:, 2], 0.0, 1.0) - np.clip(nv[:, 2], 0.0, 1.0)
    poly = _poly_terms(nu, nv, p, np) if p >= 0 else np.zeros((len(idx), 0))
    t.flags.writeable = poly.flags.writeable = False
    return t, poly


def shared_value(phi, nodes, params):
    """``f (*batch, 3, n)`` from the columns ``phi (n, w)``, the bound's node columns ``nodes (M, w)`` and the
    parameters ``(*batch, w + 6)`` (module docstring)."""
    w = phi.shape[-1]
    c, d, s = params[..., :w], params[..., w: w + 3], params[..., w + 3:]
    top = jnp.max(jnp.einsum("mk,...k->...m", nodes, c), -1, keepdims=True)
    shape = jnp.expm1(jnp.minimum(jnp.minimum(jnp.einsum("nk,...k->...n", phi, c), top), G_MAX))
    return jnp.maximum(d[..., None] + s[..., None] * shape[..., None, :], 0.0)


def _mean_channel(values, mask):
    """The channels' mean ``(*batch, 1, n)`` and where every channel is measured ``(*batch, 1, n)``."""
    mask = jnp.broadcast_to(mask, values.shape)
    every = jnp.all(mask, -2, keepdims=True)
    return jnp.where(every, jnp.mean(jnp.maximum(values, 0.0), -2, keepdims=True), 0.0), every


@functools.partial(jax.jit, static_argnames=("mix",))
def _fit(phi, u, v, values, weights, mask, mix):
    """Parameters ``(*batch, w + 6)``: step 1 (the basis family's fit of the channels' mean), then step 2."""
    mean, every = _mean_channel(values, mask)
    c = basis_fit(phi, u, v, mean, weights, every, mix)[..., 0, :]
    return _with_colour(phi, u, v, values, weights, jnp.broadcast_to(mask, values.shape), c, mix)


@functools.partial(jax.jit, static_argnames=("mix",))
def fit_folds(phi, u, v, values, weights, mask, held, parts, mix):
    """Every fold's fit of the cross-validation at once: parameters ``(*batch, K, w + 6)``, equal to :func:`_fit`
    with the fold's samples masked out (``held (K, n)``; ``parts``: :func:`polyjax._compact.select.fold_parts`),
    step 1 by the basis family's shared factorisations (:func:`polyjax._compact.families.basis.fit_folds`)."""
    mean, every = _mean_channel(values, mask)
    c = basis_fit_folds(phi, u, v, mean, weights, every, *parts, mix)[..., 0, :, :]  # (*batch, K, w)
    mask = jnp.broadcast_to(mask, values.shape)
    return jax.vmap(lambda cf, h: _with_colour(phi, u, v, values, weights, mask & ~h, cf, mix),
                    in_axes=(-2, 0), out_axes=-2)(c, held)


def _with_colour(phi, u, v, values, weights, mask, c, mix):
    """Step 2: the shape's coefficients ``c (*batch, w)`` and each channel's offset and scale, ``(*batch, w + 6)``."""
    b = jnp.maximum(values, 0.0)
    w, wc = _weights(u, v, values, weights, mask)
    cu = jnp.maximum(u[:, 2], 0.0)
    shape = jnp.expm1(jnp.minimum(jnp.einsum("nk,...k->...n", phi, c), G_MAX))[..., None, :]
    a_log, a_2 = (0.0, 1.0) if mix is None else (1.0, float(np.sqrt(mix)))
    ds = jnp.vectorize(functools.partial(_colour, cu, a_log, a_2), signature="(n),(n),(n),(n)->(t)")(
        jnp.broadcast_to(shape, b.shape), b, w, wc)  # (*batch, 3, 2)
    return jnp.concatenate([c, ds[..., 0], ds[..., 1]], -1)


def _colour(cu, a_log, a_2, shape, b, w, wc):
    """One channel's ``(d, s)`` minimising the log metric linearised in ``f`` (rows ``sqrt(w) cos / (1 + b cos)``)
    and equation (11)'s L2 (rows ``sqrt(wc) cos``), each normalised by the size of the channel's data."""
    rl, r2 = jnp.sqrt(w) * cu / (1 + b * cu), jnp.sqrt(wc) * cu
    nl = a_log / (jnp.sqrt(jnp.sum((rl * b) ** 2)) + 1e-30)
    n2 = a_2 / (jnp.sqrt(jnp.sum((r2 * b) ** 2)) + 1e-30)
    a = jnp.stack([jnp.ones_like(shape), shape], -1)
    return _lstsq(jnp.concatenate([a * (nl * rl)[:, None], a * (n2 * r2)[:, None]]),
                  jnp.concatenate([nl * rl * b, n2 * r2 * b]))
