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
#: the degrees of the polynomial terms a configuration may add (-1: none)
DEGREES = (-1, 1, 2, 3)
MIX_LOG = 3.0
_DATA = Path(__file__).parents[1] / "data" / "basis.npz"


@functools.cache
def shipped_basis():
    """The shipped basis ``(N_COMPONENTS, nodes)`` float64 and the names of the materials it was learned from."""
    with np.load(_DATA) as z:
        return np.asarray(z["basis"], np.float64), tuple(str(n) for n in z["materials"])


class BasisFamily:
    """The learned-basis family (module docstring); ``basis`` ``(k_max, nodes)`` (default: the shipped one) and the
    names of the materials it was learned from (``trained_on``: a material's benchmark uses a basis without it)."""

    name = "basis"

    def __init__(self, basis=None, trained_on=None):
        self._basis, self._trained_on = basis, trained_on

    @property
    def basis(self):
        return jnp.asarray(shipped_basis()[0] if self._basis is None else self._basis)

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

    def fit(self, config, u, v, values, weights, mask, metric: str = "log"):
        """Coefficients ``(*batch, 3, k + terms)`` of ``values (*batch, 3, n)`` (module docstring)."""
        phi = self.columns(config, u, v)
        mix = MIX_LOG if metric == "log" else None
        return _fit(phi, u, v, jnp.asarray(values), weights, mask, mix)

    def evaluate(self, config, params, u, v):
        """Model values ``(*batch, 3, n)`` at directions ``(n, 3)``."""
        return _value(jnp.einsum("nk,...k->...n", self.columns(config, u, v), params))

    def columns(self, config, u, v):
        """``(n, k + terms)``: the basis rows read at the directions, then the Legendre terms of the coordinates."""
        k, d = config
        phi = _grid.sample(self.basis[:k], u, v)
        if d < 0:
            return phi
        return jnp.concatenate([phi, _legendre_terms(_grid.coordinates(u, v), d)], -1)


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


def _fit_lane(phi, cu, b, w, wc, *, mix):
    jac = cu * (1 + K_TRANSFORM * b) / (K_TRANSFORM * (1 + b * cu))
    s = jnp.sqrt(w) * jac
    c = _lstsq(phi * s[:, None], s * jnp.log1p(K_TRANSFORM * b))
    target = jnp.log1p(b * cu)

    def errors(c):
        f = _value(phi @ c)
        r_log = jnp.sqrt(w) * (jnp.log1p(f * cu) - target)
        r_2 = jnp.sqrt(wc) * cu * (f - b)
        return f, r_log, r_2

    _, r_log0, r_20 = errors(c)
    s_log = jnp.sqrt(jnp.sum(r_log0**2)) + 1e-30
    s_2 = jnp.sqrt(jnp.sum(r_20**2)) + 1e-30
    a_log, a_2 = (1.0, 0.0) if mix is None else (1.0, jnp.sqrt(mix))
    a_log, a_2 = (0.0, 1.0) if mix is None else (a_log, a_2)

    def objective(c):
        _, r_log, r_2 = errors(c)
        return (a_log / s_log) ** 2 * jnp.sum(r_log**2) + (a_2 / s_2) ** 2 * jnp.sum(r_2**2)

    def step(c, _):
        f, r_log, r_2 = errors(c)
        df = jnp.where(f > 0, jnp.exp(jnp.minimum(phi @ c, G_MAX)) / K_TRANSFORM, 0.0)
        d_log = (a_log / s_log) * jnp.sqrt(w) * cu * df / (1 + f * cu)
        d_2 = (a_2 / s_2) * jnp.sqrt(wc) * cu * df
        q = jnp.sqrt(d_log**2 + d_2**2)  # one row per sample: the stacked rows' Gauss-Newton step, n rows not 2n
        t = -((a_log / s_log) * d_log * r_log + (a_2 / s_2) * d_2 * r_2) / jnp.where(q > 0, q, 1.0)
        delta = _lstsq(phi * q[:, None], t)
        trials = c + jnp.array([1.0, 0.5, 0.25, 0.125, 0.0])[:, None] * delta
        best = jnp.argmin(jax.vmap(objective)(trials))
        return trials[best], None

    return jax.lax.scan(step, c, None, length=STEPS)[0]
