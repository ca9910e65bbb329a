r"""The ``polynomial`` family: the closed-form polynomial of the paper's variables with the log link and the clamp.

A configuration ``(variables, degree, interactions)`` is fitted by :func:`polyjax.fit_polynomial` with
``link="log"`` (``f = exp(P) - eps``, a few weighted closed-form solves) and ``clamp=True`` (the polynomial is
evaluated at its components clamped to the fitted box, so it is bounded at every direction); the value is then
clamped at 0 (``exp(P) - eps`` can be slightly negative). ``metric="l2"`` fits with equation (11)'s 80-degree
cutoff, ``metric="log"`` on every sample above the horizon. The fitted :class:`polyjax.PolynomialBRDF` is the
parameter pytree. Numbers per material: every value the evaluation reads, per channel the ``m`` coefficients and
the principal components' mean, rotation, box centre and half-widths (``k + k^2 + 2 k`` for ``k`` variables):
``3 (m + k^2 + 3 k)``.
"""

import jax.numpy as jnp

from ..._fit.polynomial import fit_polynomial, n_parameters
from ..._variables import get_variables

#: the variable sets and interaction choices the family tries
VARIABLES = (("rusinkiewicz", True), ("rusinkiewicz", False), ("lafortune", False))
MAX_DEGREE = 12


class PolynomialFamily:
    """The log-link, clamped polynomial (module docstring); configurations ``(variables, degree, interactions)``."""

    name = "polynomial"

    def configs(self, budget: int) -> list[tuple[str, int, bool]]:
        return [(var, p, inter) for var, inter in VARIABLES for p in range(1, MAX_DEGREE + 1)
                if self.n_numbers((var, p, inter)) <= budget]

    def n_numbers(self, config) -> int:
        """``3 (m + k^2 + 3 k)``: the coefficients and the stored principal components and box, three channels."""
        var, p, inter = config
        k = int(get_variables(var).k)
        return 3 * (int(n_parameters(var, p, inter)) + k * k + 3 * k)

    def candidates(self, budget: int) -> list[tuple[str, int, bool]]:
        """The configurations :func:`polyjax.fit_compact` tries: the largest degree of each variable set within
        ``budget`` (each degree is its own compiled fit; a lower one is nested in it)."""
        best = {}
        for var, p, inter in self.configs(budget):
            best[(var, inter)] = max(best.get((var, inter), 0), p)
        return [(var, p, inter) for (var, inter), p in best.items()]

    # the choice's program interface (polyjax/_compact/select.py): one program per configuration, nothing padded

    def program(self, config):
        return config, ()

    def fit_program(self, config, arrays, u, v, values, weights, mask, metric: str = "log"):
        return self.fit(config, u, v, values, weights, mask, metric)

    def evaluate_program(self, config, arrays, params, u, v):
        return self.evaluate(config, params, u, v)

    def unpad(self, config, params):
        return params

    def fit(self, config, u, v, values, weights, mask, metric: str = "log"):
        """The fitted :class:`polyjax.PolynomialBRDF` of ``values (*batch, 3, n)``."""
        var, p, inter = config
        return fit_polynomial(u, v, values, variables=var, degree=p, interactions=inter, weights=weights,
                              mask=mask, cutoff_deg=80.0 if metric == "l2" else None, link="log", clamp=True)

    def evaluate(self, config, params, u, v):
        """Model values ``(*batch, 3, n)``, clamped at 0."""
        return jnp.maximum(params(u, v), 0.0)
