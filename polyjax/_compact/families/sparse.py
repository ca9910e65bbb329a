r"""The ``sparse`` family: one shape for the three channels (``shared.py``), its terms chosen per material from a
fixed dictionary.

The learned basis is ordered by the variance of the materials it was learned from; another material's shape
(a measured satin's non-reciprocal sheen, a paper's grazing fall-off) needs some of its later rows and a few
terms it does not span, not its first ``k`` rows. So the shape is

.. math::
    f_c(u, v) = \max\big(0,\ d_c + s_c\, S(u, v)\big), \qquad S = \exp(\min(g, g_{top})) - 1,
    \qquad g = \sum_{j \in J} a_j D_j(u, v),

``J`` a set of ``k`` columns of the dictionary ``D`` (:func:`dictionary`; 106 columns on the shipped basis): the
learned basis's first :data:`D_BASIS` rows, its first :data:`D_SKEW` rows times the non-reciprocal factor
``cos(theta_u) - cos(theta_v)`` (``skew.py``), the symmetric terms of degree 3 with the Lommel-Seeliger term
(``shared.py``, 20 columns), and piecewise-linear hats in the folded grid's coordinates ``a = sqrt(theta_h /
(pi/2))`` (:data:`N_HATS_A`) and ``b = theta_d / (pi/2)`` (:data:`N_HATS_B`) (``_grid.py``; hat ``j`` of ``N`` is
``max(0, 1 - |N a - j|)``, ``j = 1 .. N``): a fall-off or a rise at a half or difference angle that the basis did
not learn (the RGL-EPFL paper's values fall twentyfold past ``theta_h`` of about 67 degrees). ``g_top`` bounds
``g`` as in the shared family (the largest ``g`` at the grid's nodes inside 80 degrees, both orientations), so
``f`` is bounded everywhere above the horizon and never negative. The dictionary's make-up was chosen among twelve
variants (32-86 rows, 8-20 skew rows, degree 3-5, 10-30 hats in ``a`` and 0-20 in ``b``) by the held-out error on
the two RGL-EPFL files at 33 numbers (``benchmarks/bench_compact_dictionary.py``), and checked on the 100 MERL
materials (``benchmarks/bench_compact.py``).

**The set ``J``** is chosen by greedy forward selection (order-recursive matching pursuit in the Gram matrix of
the columns, :func:`select`): ``k`` times, the column that most lowers the residual of the linearised problem of
the basis fit's step 1 (``basis.py``: ``log(1 + f)`` of the channels' mean, the log metric's rows), stacked with
equation (11)'s L2 rows linearised in ``g`` and weighted by ``mix`` (:func:`polyjax._compact.families.basis.mix_for`;
each part normalised by its size ``sum (s y)^2``; the L2 rows alone for ``metric="l2"``). Then the shape's
coefficients and each channel's offset and scale are fitted on the chosen columns as the shared family fits its
own (``shared._fit``: its Gauss-Newton steps on the metric itself). The cross-validation chooses ``J`` again on
each fold's training samples, exactly as the fit would with the fold masked out (each held-out part's Gram
matrices from one pass over the samples, a fold's the total less its own), so the held-out error includes the
selection's.

**Stored numbers.** ``J`` is stored as a bit mask in ``W = ceil(D / 24)`` numbers (24 bits each: integers that
float32 and float64 hold exactly), then the ``k`` coefficients in the order of the dictionary, then ``(d_c)`` and
``(s_c)``: ``k + W + 6`` numbers per material (:meth:`SparseShapeFamily.n_numbers`); 22 columns at 33.
"""

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from . import _grid
from ._on_basis import OnLearnedBasis
from .basis import _inside_nodes, _weights, mix_for
from .shared import COLOUR_NUMBERS, _mean_channel, _node_terms, _poly_terms, n_poly, shared_value
from .shared import _fit as shared_fit
from .skew import skew_factor

#: the learned basis's rows in the dictionary
D_BASIS = 40
#: of those, the rows also times the non-reciprocal factor
D_SKEW = 16
#: the degree of the dictionary's symmetric terms (``shared.py``; 20 columns with the Lommel-Seeliger term)
POLY_DEGREE = 3
#: hats on the grid coordinates ``a`` (warped ``theta_h``) and ``b`` (``theta_d``)
N_HATS_A = 20
N_HATS_B = 10
#: bits of the column mask stored in one number (float32 holds integers below 2^24 exactly)
MASK_BITS = 24
#: the least squared norm, relative to the largest, of a column the selection may take
_RANK_TOL = 1e-10


def dictionary_size(rows: int) -> int:
    """Columns of the dictionary on a basis of ``rows`` rows."""
    return min(D_BASIS, rows) + min(D_SKEW, rows) + n_poly(POLY_DEGREE) + N_HATS_A + N_HATS_B


def mask_numbers(size: int) -> int:
    """Numbers that store a mask of ``size`` columns."""
    return math.ceil(size / MASK_BITS)


def _hats(t, n, xp=jnp):
    """``(len(t), n)``: the hats ``max(0, 1 - |n t - j|)``, ``j = 1 .. n``, of a coordinate ``t`` in [0, 1]."""
    return xp.maximum(0.0, 1.0 - xp.abs(n * t[:, None] - xp.arange(1, n + 1)))


def dictionary(table, u, v):
    """``(n, D)``: the dictionary's columns at directions ``(n, 3)`` on the basis ``table (rows, nodes)``
    (module docstring; ``D = dictionary_size(rows)``)."""
    kb, ks = min(D_BASIS, table.shape[0]), min(D_SKEW, table.shape[0])
    phi = _grid.sample(table[:kb], u, v)
    a, b, _ = _grid.coordinates(u, v)
    return jnp.concatenate([phi, skew_factor(u, v)[:, None] * phi[:, :ks], _poly_terms(u, v, POLY_DEGREE),
                            _hats(a, N_HATS_A), _hats(b, N_HATS_B)], -1)


@functools.cache
def _node_hats():
    """The hats at the grid's nodes inside the 80-degree cutoff ``(M, N_HATS_A + N_HATS_B)`` (numpy, computed
    once)."""
    _, (a, b, _) = _inside_nodes()
    out = np.concatenate([_hats(a, N_HATS_A, np), _hats(b, N_HATS_B, np)], -1)
    out.flags.writeable = False
    return out


def _node_columns(table, dtype):
    """The dictionary at the nodes inside the cutoff in both orientations ``(2 M, D)`` (``shared.py``'s bound):
    the skew rows change sign, every other column is symmetric."""
    kb, ks = min(D_BASIS, table.shape[0]), min(D_SKEW, table.shape[0])
    idx, _ = _inside_nodes()
    rows = table[:kb][:, idx].T
    t, poly = _node_terms(POLY_DEGREE)
    t, rest = jnp.asarray(t, dtype)[:, None], jnp.asarray(np.concatenate([poly, _node_hats()], -1), dtype)
    return jnp.concatenate([jnp.concatenate([rows, sign * t * rows[:, :ks], rest], -1) for sign in (1.0, -1.0)])


def pack(chosen):
    """The mask ``chosen (*batch, D)`` (bool) as ``(*batch, W)`` numbers, 24 bits each (bit ``i`` of number ``w``
    is column ``24 w + i``)."""
    size = chosen.shape[-1]
    words = mask_numbers(size)
    bits = jnp.pad(chosen, [(0, 0)] * (chosen.ndim - 1) + [(0, words * MASK_BITS - size)])
    bits = bits.reshape(*chosen.shape[:-1], words, MASK_BITS).astype(jnp.float32)
    return jnp.sum(bits * (2.0 ** np.arange(MASK_BITS, dtype=np.float32)), -1)


def unpack(numbers, size: int):
    """The inverse of :func:`pack`: ``(*batch, W)`` numbers to ``(*batch, size)`` bits, 0.0 or 1.0 (numbers are
    rounded and clipped to ``[0, 2^24 - 1]`` first: a mask, whatever the file holds)."""
    w = jnp.clip(jnp.round(jax.lax.stop_gradient(numbers)), 0.0, 2.0 ** MASK_BITS - 1)
    bits = jnp.floor(w[..., None] / (2.0 ** np.arange(MASK_BITS))) % 2.0
    return bits.reshape(*numbers.shape[:-1], -1)[..., :size]


def dense(params, k: int, size: int):
    """The shape's coefficients on the whole dictionary ``(*batch, D)`` (0 off the mask) and the colour
    ``(*batch, 6)`` from the stored parameters ``(*batch, W + k + 6)``."""
    words = mask_numbers(size)
    bits = unpack(params[..., :words], size)
    coef = params[..., words: words + k]
    pos = jnp.clip(jnp.cumsum(bits, -1).astype(jnp.int32) - 1, 0, k - 1)
    return bits * jnp.take_along_axis(coef, pos, -1), params[..., words + k:]


def _rows(u, v, mean, weights, every):
    """The selection's rows for one material (module docstring): ``(s_log, s_2, y)`` ``(n,)`` each, the row weights
    of the basis fit's linearised step 1 (``basis._initial``: the log metric linearised in ``g``) and of equation
    (11)'s L2 linearised in ``g``, and the target ``log(1 + f)`` of the channels' mean ``f``. A sample's rows do
    not depend on the other samples: a fold's problem is its training samples' rows."""
    b = jnp.maximum(mean, 0.0)
    w, wc = _weights(u, v, mean, weights, every)
    cu = jnp.maximum(u[:, 2], 0.0)
    return jnp.sqrt(w) * cu * (1 + b) / (1 + b * cu), jnp.sqrt(wc) * cu * (1 + b), jnp.log1p(b)


def _factors(size_log, size_2, mix):
    """The weights of the log rows and of the L2 rows: each part normalised by its size ``sum (s y)^2``, the L2
    part weighted by ``mix`` (None: the L2 alone)."""
    if mix is None:
        return 0.0, 1.0 / (size_2 + 1e-300)
    return 1.0 / (size_log + 1e-300), mix / (size_2 + 1e-300)


def _normal(cols, s, y):
    """The Gram matrix ``(..., D, D)`` and right-hand side ``(..., D)`` of the rows ``s cols`` and ``s y``, and the
    size ``sum (s y)^2 (...)`` (leading axes: parts of the samples)."""
    a = cols * s[..., None]
    sy = s * y
    return jnp.einsum("...nd,...ne->...de", a, a), jnp.einsum("...nd,...n->...d", a, sy), jnp.sum(sy ** 2, -1)


def select(gram, corr, k: int):
    """The mask ``(D,)`` of ``k`` columns chosen greedily (order-recursive matching pursuit) for ``min |A x - y|``
    given ``gram = A^T A`` and ``corr = A^T y``: each step takes the column whose part orthogonal to those taken
    best explains the residual, ``(a_j^T r)^2 / |a_j^perp|^2``; its projections on the new direction update every
    column's in ``O(k D)``. Columns of (relatively) zero norm are never taken while others remain."""
    size = gram.shape[0]
    d = jnp.diagonal(gram)
    ok = d > _RANK_TOL * jnp.max(d)
    scale = jnp.where(ok, 1.0 / jnp.sqrt(jnp.where(ok, d, 1.0)), 0.0)
    g = gram * scale[:, None] * scale[None, :]
    p = corr * scale
    norm2 = jnp.where(ok, 1.0, 0.0)

    def step(carry, i):
        p, norm2, proj, chosen = carry
        free = ~chosen & (norm2 > _RANK_TOL)
        j = jnp.argmax(jnp.where(free, p ** 2 / jnp.where(free, norm2, 1.0), -1.0) + jnp.where(chosen, -2.0, 0.0))
        nj = jnp.sqrt(jnp.maximum(norm2[j], _RANK_TOL))
        t = (g[j] - proj[:, j] @ proj) / nj
        t = jnp.where(norm2[j] > _RANK_TOL, t, 0.0)
        rj = p[j] / nj
        return (p - t * rj, jnp.maximum(norm2 - t ** 2, 0.0), proj.at[i].set(t), chosen.at[j].set(True)), None

    start = (p, norm2, jnp.zeros((k, size), gram.dtype), jnp.zeros(size, bool))
    return jax.lax.scan(step, start, jnp.arange(k))[0][3]


def _fit_chosen(cols, chosen, k, u, v, values, weights, mask, mix):
    """The shared family's fit on the chosen columns (in the dictionary's order): ``(k + 6,)``."""
    idx = jnp.nonzero(chosen, size=k, fill_value=0)[0]
    return shared_fit(cols[:, idx], u, v, values, weights, mask, mix)


def choose_columns(cols, k, mix, u, v, values, weights, mask):
    """One material's mask of ``k`` columns ``(D,)`` from ``values (3, n)``, ``mask (3, n)``: the selection's
    problem (module docstring) with the L2 rows weighted by ``mix``."""
    mean, every = _mean_channel(values, mask)
    s_log, s_2, y = _rows(u, v, mean[0], weights, every[0])
    f_log, f_2 = _factors(jnp.sum((s_log * y) ** 2), jnp.sum((s_2 * y) ** 2), mix)
    return select(*_normal(cols, jnp.sqrt(f_log * s_log ** 2 + f_2 * s_2 ** 2), y)[:2], k)


def fit_with(cols, chosen, k, mix, u, v, values, weights, mask):
    """One material's parameters ``(W + k + 6,)``: the mask ``chosen (D,)`` packed, then its columns fitted with
    the L2 weighted by ``mix``."""
    return jnp.concatenate([pack(chosen).astype(cols.dtype),
                            _fit_chosen(cols, chosen, k, u, v, values, weights, mask, mix)])


def _fit_one(cols, k, mix, u, v, values, weights, mask):
    """One material's parameters ``(W + k + 6,)`` from ``values (3, n)``, ``mask (3, n)``."""
    chosen = choose_columns(cols, k, mix, u, v, values, weights, mask)
    return fit_with(cols, chosen, k, mix, u, v, values, weights, mask)


def _folds_one(cols, k, mix, u, v, held, parts, values, weights, mask):
    """One material's fold fits ``(K, W + k + 6)``: each fold's columns chosen on its training samples, as
    :func:`_fit_one` chooses them with the fold masked out (the rows of a sample do not depend on the others:
    each part's sums once, a fold's training sums their total less its own), then fitted without the fold."""
    mean, every = _mean_channel(values, mask)
    s_log, s_2, y = _rows(u, v, mean[0], weights, every[0])
    part, ok = parts[0], parts[1]
    train = []
    for s in (s_log, s_2):  # the held-out parts' sums (K, ...), then each fold's training sums
        train.append([jnp.sum(x, 0) - x for x in _normal(cols[part], s[part] * ok, y[part])])
    (g_log, c_log, n_log), (g_2, c_2, n_2) = train

    def one(g_log, c_log, n_log, g_2, c_2, n_2):
        f_log, f_2 = _factors(n_log, n_2, mix)
        return select(f_log * g_log + f_2 * g_2, f_log * c_log + f_2 * c_2, k)

    chosen = jax.vmap(one)(g_log, c_log, n_log, g_2, c_2, n_2)
    fits = jax.vmap(lambda ch, h: _fit_chosen(cols, ch, k, u, v, values, weights, mask & ~h, mix))(chosen, held)
    return jnp.concatenate([pack(chosen).astype(cols.dtype), fits], -1)


class SparseShapeFamily(OnLearnedBasis):
    """One shape for the three channels, its ``k`` terms chosen per material from a dictionary (module
    docstring); configurations ``(k, D)``, ``D`` the dictionary's size; ``basis`` and ``trained_on`` as
    :class:`BasisFamily` (default: the shipped basis); parameters ``(*batch, W + k + 6)``: the mask, the
    coefficients, then the offsets ``d`` and the scales ``s`` of R, G, B."""

    name = "sparse"

    @property
    def size(self) -> int:
        return dictionary_size(self._rows)

    def n_numbers(self, config) -> int:
        k, size = config
        return int(k) + mask_numbers(int(size)) + COLOUR_NUMBERS

    def configs(self, budget: int) -> list[tuple[int, int]]:
        """``(k, D)`` for every ``k`` from 1 to the dictionary's size within ``budget``."""
        size = self.size
        return [(k, size) for k in range(1, size + 1) if self.n_numbers((k, size)) <= budget]

    def candidates(self, budget: int) -> list[tuple[int, int]]:
        """The configuration :func:`polyjax.fit_compact` tries within ``budget``: the most columns (the
        selection stops at ``k`` itself; fewer columns only win on little data)."""
        configs = self.configs(budget)
        return configs[-1:]

    def candidate_chains(self, budget: int) -> list[list[tuple[int, int]]]:
        """:meth:`candidates`, a chain of one."""
        return [[c] for c in self.candidates(budget)]

    def columns(self, config, u, v):
        """``(n, D)``: the dictionary at directions ``(n, 3)``."""
        return dictionary(self.program(config)[1][0], u, v)

    def fit_program(self, config, arrays, u, v, values, weights, mask, metric: str = "log"):
        values = jnp.asarray(values)
        mask = jnp.broadcast_to(jnp.ones(values.shape, bool) if mask is None else mask, values.shape)
        weights = jnp.ones(values.shape[-1], values.dtype) if weights is None else jnp.asarray(weights)
        one = functools.partial(_fit_one, dictionary(arrays[0], u, v), int(config[0]), mix_for(metric), u, v)
        return jnp.vectorize(one, signature="(c,n),(n),(c,n)->(p)")(values, weights, mask)

    def evaluate_program(self, config, arrays, params, u, v):
        cols = dictionary(arrays[0], u, v)
        coef, colour = dense(params, int(config[0]), cols.shape[-1])
        return shared_value(cols, _node_columns(arrays[0], cols.dtype), jnp.concatenate([coef, colour], -1))

    def fit_folds(self, config, arrays, u, v, values, weights, mask, held, parts, metric: str = "log"):
        """The cross-validation's fold fits ``(*batch, K, W + k + 6)``, each fold's columns chosen without it."""
        values = jnp.asarray(values)
        weights = jnp.ones(values.shape[-1], values.dtype) if weights is None else jnp.asarray(weights)
        one = functools.partial(_folds_one, dictionary(arrays[0], u, v), int(config[0]), mix_for(metric), u, v,
                                held, parts)
        return jnp.vectorize(one, signature="(c,n),(n),(c,n)->(f,p)")(values, weights,
                                                                        jnp.broadcast_to(mask, values.shape))
