"""What the families built on a learned basis beside the basis family itself share (``skew``, ``shared``): the
basis they read (the shipped one, or another, e.g. learned without the material fitted) and their fit and
evaluation through the choice's program interface (``polyjax/_compact/select.py``): one program per
configuration, the basis table passed as data, so that another basis is the one fitted."""

import numpy as np

from .basis import N_COMPONENTS, BasisFamily


class OnLearnedBasis:
    """A family on a learned basis: ``basis`` and ``trained_on`` as :class:`BasisFamily` (default: the shipped
    basis). A subclass gives ``fit_program`` and ``evaluate_program``; ``fit`` and ``evaluate`` are theirs on the
    configuration's program."""

    def __init__(self, basis=None, trained_on=None):
        self._inner = BasisFamily(basis, trained_on)
        self._rows = N_COMPONENTS if basis is None else int(np.shape(basis)[0])

    @property
    def trained_on(self) -> tuple[str, ...]:
        return self._inner.trained_on

    def program(self, config):
        return config, (self._inner.basis,)

    def fit(self, config, u, v, values, weights, mask, metric: str = "log"):
        """The parameters of ``values (*batch, 3, n)`` (the family's module docstring)."""
        return self.fit_program(config, self.program(config)[1], u, v, values, weights, mask, metric)

    def evaluate(self, config, params, u, v):
        """Model values ``(*batch, 3, n)`` at directions ``(n, 3)``."""
        return self.evaluate_program(config, self.program(config)[1], params, u, v)

    def unpad(self, config, params):
        return params
