r"""The ``basis`` family: a principal-component basis of ``g = log(1 + K f)`` learned from measured materials.

The model of one channel with ``k`` coefficients ``c`` is

.. math::
    f(u, v) = \max\big(0, (\exp(\min(\textstyle\sum_j c_j B_j(u, v), G_{max})) - 1) / K\big),

``B_0`` the mean of the learned materials' transformed tables, ``B_1 .. B_{k-1}`` their principal components, each
tabulated on the folded Rusinkiewicz grid (``_grid.py``) and read by trilinear interpolation: bounded at every
direction above the horizon (the table's extremes), never negative. ``k`` coefficients per channel, ``3 k``
numbers per material.

The fit (closed form, then a few Gauss-Newton steps, each an ``(n, k)`` least-squares solve: QR, then the SVD
of its triangle):

1. ``c`` minimising ``sum w J^2 (B c - log(1 + K b))^2``, ``J = cos(theta_u) (1 + K b) / (K (1 + b cos(theta_u)))``:
   the log metric linearised in ``g``, one weighted solve;
2. ``STEPS`` Gauss-Newton steps (halving the step while it does not lower the objective) on
   ``E_log^2 / E_log,0^2 + MIX E_2^2 / E_2,0^2`` (``E_log`` the log metric, ``E_2`` equation (11)'s L2 with its
   80-degree cutoff, ``E_0`` the first solve's values): ``MIX`` weighs the paper's L2 (``metric="log"``:
   ``MIX_LOG``; ``metric="l2"``: the L2 alone).
"""

import functools
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from ..._directions import cutoff_mask
from . import _grid

#: the transform's scale ``K`` in ``g = log(1 + K f)``
K_TRANSFORM = 1.0
#: rows of the shipped basis (the mean and the first principal components)
N_COMPONENTS = 86
#: largest ``g`` the model evaluates (``f`` at most ``(exp(G_MAX) - 1) / K``, 1e5 1/sr)
G_MAX = float(np.log1p(K_TRANSFORM * 1e5))
STEPS = 2
#: the step lengths each Gauss-Newton step tries (besides staying where it is)
STEP_LENGTHS = (1.0, 0.5, 0.25)
#: the degrees of the polynomial terms a configuration may add (-1: none)
DEGREES = (-1, 1, 2, 3)
MIX_LOG = 3.0


def mix_for(metric: str):
    """The weight of equation (11)'s L2 in the Gauss-Newton objective for ``metric`` (module docstring):
    :data:`MIX_LOG` for ``"log"``, None (the L2 alone) for ``"l2"``."""
    return MIX_LOG if metric == "log" else None
_DATA = Path(__file__).parents[1] / "data" / "basis.npz"


@functools.cache
def shipped_basis():
    """The shipped basis ``(N_COMPONENTS, nodes)`` float64 and the names of the materials it was learned from."""
    with np.load(_DATA) as z:
        return np.asarray(z["basis"], np.float64), tuple(str(n) for n in z["materials"])


@functools.cache
def _device_basis(x64: bool):
    """The shipped basis as a JAX array (once per precision mode: float64 with x64 enabled, else float32), made
    eagerly even when the first call is inside a trace (``load_model``'s or a jitted fit's): a cached tracer would
    leak out of it."""
    with jax.ensure_compile_time_eval():
        return jnp.asarray(shipped_basis()[0])


class BasisFamily:
    """The learned-basis family (module docstring); ``basis`` ``(k_max, nodes)`` (default: the shipped one) and the
    names of the materials it was learned from (``trained_on``: a material's benchmark uses a basis without it)."""

    name = "basis"

    def __init__(self, basis=None, trained_on=None):
        self._basis, self._trained_on = basis, trained_on

    @property
    def basis(self):
        if self._basis is None:
            return _device_basis(jax.config.jax_enable_x64)
        return jnp.asarray(self._basis)

    @property
    def trained_on(self) -> tuple[str, ...]:
        return shipped_basis()[1] if self._trained_on is None else tuple(self._trained_on)

    def configs(self, budget: int) -> list[tuple[int, int]]:
        """``(k, d)``: ``k`` basis rows and the terms of total degree at most ``d`` (none for ``d = -1``) of the
        grid's coordinates, ``3 (k + terms)`` numbers at most ``budget``."""
        k_max = N_COMPONENTS if self._basis is None else int(np.shape(self._basis)[0])
        return [(k, d) for d in DEGREES for k in range(1, k_max + 1) if self.n_numbers((k, d)) <= budget]

    def n_numbers(self, config) -> int:
        k, d = config
        return 3 * (int(k) + n_terms(d))

    def candidates(self, budget: int) -> list[tuple[int, int]]:
        """The configurations :func:`polyjax.fit_compact` may try within ``budget``: :meth:`candidate_chains`,
        flattened."""
        return [c for chain in self.candidate_chains(budget) for c in chain]

    def candidate_chains(self, budget: int) -> list[list[tuple[int, int]]]:
        """For each degree ``d`` the largest ``k`` and its halvings (``k, ceil(k/2), ceil(k/4), .., 1``), largest
        first: the rows are nested, so a smaller ``k`` only wins on little data; the choice walks a chain while
        the held-out error falls (``polyjax/_compact/select.py``). ``k = 1`` (the mean row and the terms alone) is
        not tried: on the 100 MERL materials it was chosen at no budget from 9 to 256 once the shared families came,
        it cost a tenth of the choice's time, and alone (budgets 3 to 5) it is not a model of a material unlike
        MERL's mean: on the RGL-EPFL white paper ``(1, -1)`` has a held-out L2 26 times that of ``f = 0``, its values
        at 80 degrees 36 times the data's largest. So the smallest budget is 6 (``(2, -1)``)."""
        out, seen = [], set()
        for d in DEGREES:
            ks = [k for k, dd in self.configs(budget) if dd == d]
            k, chain = max(ks, default=0), []
            while k >= 2 and (k, d) not in seen:
                chain.append((k, d))
                seen.add((k, d))
                k = (k + 1) // 2
            if chain:
                out.append(chain)
        return out

    def fit(self, config, u, v, values, weights, mask, metric: str = "log"):
        """Coefficients ``(*batch, 3, k + terms)`` of ``values (*batch, 3, n)`` (module docstring)."""
        phi = self.columns(config, u, v)
        return _fit(phi, u, v, jnp.asarray(values), weights, mask, mix_for(metric))

    def evaluate(self, config, params, u, v):
        """Model values ``(*batch, 3, n)`` at directions ``(n, 3)``, bounded by the model's largest value at the
        grid's nodes inside the 80-degree cutoff (:func:`bounded_value`)."""
        return bounded_value(self.columns(config, u, v), self.node_columns(config), params)

    def columns(self, config, u, v):
        """``(n, k + terms)``: the basis rows read at the directions, then the Legendre terms of the coordinates."""
        k, d = config
        phi = _grid.sample(self.basis[:k], u, v)
        if d < 0:
            return phi
        return jnp.concatenate([phi, _legendre_terms(_grid.coordinates(u, v), d)], -1)

    def node_columns(self, config):
        """``(nodes, k + terms)``: the columns at the grid's nodes inside the 80-degree cutoff (the bound's nodes)."""
        k, d = config
        idx, coords = _inside_nodes()
        rows = self.basis[:k][:, idx].T
        if d < 0:
            return rows
        return jnp.concatenate([rows, _legendre_terms(tuple(jnp.asarray(c) for c in coords), d)], -1)

    # the padded programs of the choice (polyjax/_compact/select.py): every configuration of ``width`` columns or
    # fewer shares one compiled fit, its columns picked by index arrays (data, not static), padded with zeros

    def program(self, config):
        """``(key, arrays)``: the static key of the padded program (its width) and the configuration's index arrays
        ``(table, rows, columns, valid)``: the basis table (data, so that another basis, e.g. a leave-one-out one,
        shares the program) and, each ``(width,)``, the basis rows to read, the column of ``[rows | terms of degree
        3]`` each padded column takes, and which are real (the rest are zero columns: their coefficients are 0)."""
        k, d = config
        active = k + n_terms(d)
        width = next(w for w in WIDTHS if w >= active)
        rows = np.zeros(width, np.int32)
        rows[:k] = np.arange(k)
        cols = np.zeros(width, np.int32)
        cols[:k] = np.arange(k)
        cols[k:active] = width + np.asarray(_term_positions(d), np.int32)
        valid = np.arange(width) < active
        return width, (self.basis, jnp.asarray(rows), jnp.asarray(cols), jnp.asarray(valid))

    def design(self, width, arrays, u, v):
        """The padded program's columns ``(n, width)`` at directions ``(n, 3)`` (zero at the padding)."""
        return self._padded(arrays, _grid.sample(arrays[0][arrays[1]], u, v), _legendre_terms(
            _grid.coordinates(u, v), TERMS_MAX))

    def from_design(self, width, arrays, phi, params):
        """The padded model's values ``(*batch, 3, n)`` from its columns ``phi (n, width)`` (bounded as
        :func:`bounded_value`)."""
        idx, coords = _inside_nodes()
        nodes = self._padded(arrays, arrays[0][arrays[1]][:, idx].T,
                             _legendre_terms(tuple(jnp.asarray(c) for c in coords), TERMS_MAX))
        return bounded_value(phi, nodes, params)

    def fit_program(self, width, arrays, u, v, values, weights, mask, metric: str = "log"):
        """The padded fit: coefficients ``(*batch, 3, width)`` (zero at the padding)."""
        return _fit(self.design(width, arrays, u, v), u, v, jnp.asarray(values), weights, mask, mix_for(metric))

    def evaluate_program(self, width, arrays, params, u, v):
        """The padded model's values ``(*batch, 3, n)``."""
        return self.from_design(width, arrays, self.design(width, arrays, u, v), params)

    def unpad(self, config, params):
        """The configuration's own coefficients from the padded ones."""
        k, d = config
        return params[..., : k + n_terms(d)]

    @staticmethod
    def _padded(arrays, rows, terms):
        _, _, cols, valid = arrays
        return jnp.where(valid, jnp.concatenate([rows, terms], -1)[..., cols], 0.0)


#: the widths of the padded programs (one compiled fit per width and data shape)
WIDTHS = (4, 8, 12, 24, 48, 86, 128)
#: the largest degree of the polynomial terms
TERMS_MAX = 3


def n_terms(d: int) -> int:
    """Terms of total degree at most ``d`` in three variables (0 for ``d < 0``)."""
    return 0 if d < 0 else (d + 1) * (d + 2) * (d + 3) // 6


def _legendre(t, d):
    x = 2 * t - 1
    p = [jnp.ones_like(x), x]
    for n in range(1, d):
        p.append(((2 * n + 1) * x * p[n] - n * p[n - 1]) / (n + 1))
    return p[: d + 1]


def _legendre_terms(coords, d):
    pa, pb, pc = (_legendre(t, d) for t in coords)
    return jnp.stack([pa[i] * pb[j] * pc[m] for i in range(d + 1) for j in range(d + 1 - i)
                      for m in range(d + 1 - i - j)], -1)


def _value(g):
    return jnp.maximum(jnp.expm1(jnp.minimum(g, G_MAX)) / K_TRANSFORM, 0.0)


def bounded_value(phi, nodes, params):
    r"""``f = max(0, expm1(min(g, g_max)) / K)``, ``g = phi c`` at the directions, ``g_max`` the largest ``g`` of
    the model at the grid's nodes inside the 80-degree cutoff (``nodes (m, k)``): where the data weigh little
    (grazing directions, where the log metric's ``cos theta_u`` vanishes) the model never exceeds its own value
    where they weigh; computed from the coefficients (nothing stored). ``phi (n, k)``, ``params (*batch, k)``."""
    g = jnp.einsum("nk,...k->...n", phi, params)
    top = jnp.max(jnp.einsum("mk,...k->...m", nodes, params), -1, keepdims=True)
    return _value(jnp.minimum(g, top))


@functools.cache
def _inside_nodes():
    """The flat indices of the grid's nodes whose light and view directions are within 80 degrees of the normal,
    and their unit coordinates ``(a, b, c)`` (numpy)."""
    u, v = _grid.node_directions()
    c = np.cos(np.radians(80.0))
    idx = np.nonzero((u[:, 2] >= c) & (v[:, 2] >= c))[0]
    axes = np.meshgrid(*(np.linspace(0.0, 1.0, n) for n in _grid.SHAPE), indexing="ij")
    return idx, tuple(a.reshape(-1)[idx] for a in axes)


@functools.cache
def _term_positions(d: int) -> tuple[int, ...]:
    """Positions of the terms of degree at most ``d`` (in :func:`_legendre_terms`' order) among those of degree
    at most :data:`TERMS_MAX`."""
    every = _exponents(TERMS_MAX)
    return tuple(every.index(e) for e in _exponents(d)) if d >= 0 else ()


def _exponents(d: int) -> list[tuple[int, int, int]]:
    return [(i, j, m) for i in range(d + 1) for j in range(d + 1 - i) for m in range(d + 1 - i - j)]


def _weights(u, v, values, weights, mask):
    n = values.shape[-1]
    w = jnp.ones(n) if weights is None else jnp.asarray(weights, values.dtype)
    m = jnp.ones(n, bool) if mask is None else jnp.asarray(mask, bool)
    w = jnp.broadcast_to(jnp.where(m, w, 0.0), values.shape)
    wc = jnp.where(cutoff_mask(u, v, 80.0), w, 0.0)
    return w, wc


@functools.partial(jax.jit, static_argnames=("mix",))
def _fit(phi, u, v, values, weights, mask, mix):
    b = jnp.maximum(values, 0.0)
    w, wc = _weights(u, v, values, weights, mask)
    cu = jnp.maximum(u[:, 2], 0.0)
    lane = jnp.vectorize(functools.partial(_fit_lane, phi, cu, mix=mix), signature="(n),(n),(n)->(k)")
    return lane(b, w, wc)


def _lstsq(a, y):
    """Least squares ``min |a c - y|`` by the QR of ``[a, y]`` (Householder), then the SVD of its small triangle."""
    k = a.shape[-1]
    r = jnp.linalg.qr(jnp.concatenate([a, y[:, None]], -1), mode="r")
    return jnp.linalg.lstsq(r[:k, :k], r[:k, k], rcond=1e-12)[0]


def _initial(phi, cu, b, w):
    """Step 1's weighted least-squares problem ``(A, y)``: the log metric linearised in ``g`` (module docstring)."""
    jac = cu * (1 + K_TRANSFORM * b) / (K_TRANSFORM * (1 + b * cu))
    s = jnp.sqrt(w) * jac
    return phi * s[:, None], s * jnp.log1p(K_TRANSFORM * b)


def _fit_lane(phi, cu, b, w, wc, *, mix):
    return _refine(phi, cu, b, w, wc, _lstsq(*_initial(phi, cu, b, w)), mix=mix)


def _refine(phi, cu, b, w, wc, c, *, mix):
    """Step 2: :data:`STEPS` Gauss-Newton steps from ``c`` (module docstring), each trying the step lengths
    :data:`STEP_LENGTHS` and keeping the best of them and of staying. ``g = phi c`` and its residuals are carried with
    ``c``: a step costs one QR, one product ``phi delta`` and the trials' residuals (their transcendental
    functions are most of a step's time)."""
    target = jnp.log1p(b * cu)
    sw, swc = jnp.sqrt(w), jnp.sqrt(wc)

    def errors(g):
        f = _value(g)
        return f, sw * (jnp.log1p(f * cu) - target), swc * cu * (f - b)

    g0 = phi @ c
    f0, r_log0, r_20 = errors(g0)
    s_log = jnp.sqrt(jnp.sum(r_log0**2)) + 1e-30
    s_2 = jnp.sqrt(jnp.sum(r_20**2)) + 1e-30
    a_log, a_2 = (1.0, 0.0) if mix is None else (1.0, jnp.sqrt(mix))
    a_log, a_2 = (0.0, 1.0) if mix is None else (a_log, a_2)

    def objective(r_log, r_2):
        return (a_log / s_log) ** 2 * jnp.sum(r_log**2, -1) + (a_2 / s_2) ** 2 * jnp.sum(r_2**2, -1)

    def step(carry, _):
        c, g, f, r_log, r_2, obj = carry
        df = jnp.where(f > 0, f + 1.0 / K_TRANSFORM, 0.0)  # d f / d g = exp(min(g, G_MAX)) / K where f > 0
        d_log = (a_log / s_log) * sw * cu * df / (1 + f * cu)
        d_2 = (a_2 / s_2) * swc * cu * df
        q = jnp.sqrt(d_log**2 + d_2**2)  # one row per sample: the stacked rows' Gauss-Newton step, n rows not 2n
        t = -((a_log / s_log) * d_log * r_log + (a_2 / s_2) * d_2 * r_2) / jnp.where(q > 0, q, 1.0)
        delta = _lstsq(phi * q[:, None], t)
        alphas = jnp.asarray(STEP_LENGTHS, g.dtype)
        g_t = g + alphas[:, None] * (phi @ delta)
        f_t, r_log_t, r_2_t = errors(g_t)
        objs = jnp.append(objective(r_log_t, r_2_t), obj)
        i = jnp.argmin(objs)
        pick = lambda trial, now: jnp.concatenate([trial, now[None]])[i]  # noqa: E731
        alpha = jnp.append(alphas, 0.0)[i]
        return (c + alpha * delta, pick(g_t, g), pick(f_t, f), pick(r_log_t, r_log), pick(r_2_t, r_2), objs[i]), None

    start = (c, g0, f0, r_log0, r_20, objective(r_log0, r_20))
    return jax.lax.scan(step, start, None, length=STEPS)[0][0]


@functools.partial(jax.jit, static_argnames=("mix",))
def fit_folds(phi, u, v, values, weights, mask, parts, part_ok, train, train_ok, mix):
    r"""Every fold's fit of the cross-validation at once, each on the other folds' samples: coefficients
    ``(*batch, 3, K, k)`` of ``values (*batch, 3, n)`` on the design ``phi (n, k)``, equal to :func:`_fit` with the
    fold's samples masked out (to rounding) at a fraction of its cost.

    Step 1's weights do not depend on the fit, so its least-squares problems share one factorisation: the triangle
    ``R_j`` of each fold's weighted rows ``[A_j, y_j]`` (``K`` QRs of ``n / K`` rows), and fold ``j``'s problem is
    the QR of the stacked triangles of the other folds (``[A, y]`` over their rows has the same ``R``, up to signs:
    the TSQR of Demmel et al. 2012). Step 2's Gauss-Newton steps weigh the rows by the fold's own fit, so each is
    solved on the fold's training rows alone (gathered, ``(K - 1) n / K`` of them), not on all ``n`` with zero
    weights.

    Args:
        parts: ``(K, m)`` the samples of each fold (indices, padded where ``part_ok`` is False);
        train: ``(K, (K - 1) m)`` the samples each fold is fitted on, padded where ``train_ok`` is False.
    """
    b = jnp.maximum(values, 0.0)
    w, wc = _weights(u, v, values, weights, mask)
    cu = jnp.maximum(u[:, 2], 0.0)
    lane = jnp.vectorize(functools.partial(_fold_lanes, phi, cu, parts, part_ok, train, train_ok, mix=mix),
                         signature="(n),(n),(n)->(f,k)")
    return lane(b, w, wc)


def _fold_lanes(phi, cu, parts, part_ok, train, train_ok, b, w, wc, *, mix):
    k, n_folds = phi.shape[-1], parts.shape[0]
    a, y = _initial(phi, cu, b, w)
    ay = jnp.concatenate([a, y[:, None]], -1)
    tri = jax.vmap(lambda idx, ok: jnp.linalg.qr(jnp.where(ok[:, None], ay[idx], 0.0), mode="r"))(parts, part_ok)
    others = np.array([[i for i in range(n_folds) if i != j] for j in range(n_folds)])
    stacked = tri[others].reshape(n_folds, -1, k + 1)  # (K, (K - 1)(k + 1), k + 1)
    r = jnp.linalg.qr(stacked, mode="r")
    c0 = jax.vmap(lambda t: jnp.linalg.lstsq(t[:k, :k], t[:k, k], rcond=1e-12)[0])(r)

    def one(c, idx, ok):
        return _refine(phi[idx], cu[idx], b[idx], jnp.where(ok, w[idx], 0.0), jnp.where(ok, wc[idx], 0.0), c,
                       mix=mix)

    return jax.vmap(one)(c0, train, train_ok)
