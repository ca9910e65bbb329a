"""Fitting every texel of a capture in closed form: one polynomial BRDF per texel and colour channel."""

from __future__ import annotations

import jax

from .._fit.closed_form import LANE_BLOCK
from .._fit.polynomial import fit_polynomial
from .._model import PolynomialBRDF
from .._solve.threads import one_lapack_thread
from ._capture import Capture


@one_lapack_thread
def fit_capture(capture: Capture, variables: str = "lafortune", degree: int = 3, *, cutoff_deg: float | None = 80.0,
                lane_block: int = LANE_BLOCK, sharding=None, **options) -> PolynomialBRDF:
    r"""Fit a polynomial BRDF (equation (3)) to every texel of ``capture`` from its photographs.

    Each texel is fitted alone, from its own ``K`` observations (``C K`` with ``C`` cameras) at its own light and
    view directions (its own PCA and design; its three channels share them): :func:`polyjax.fit_polynomial` with
    per-lane directions, weighted so that the residuals are the photographs' radiance errors
    (:meth:`Capture.observations`). Closed form, no initial guess; differentiable like every fit.

    Args:
        capture: a :class:`Capture`.
        variables, degree, cutoff_deg: as in :func:`polyjax.fit_polynomial`.
        lane_block: lanes (texel channels) fitted at once inside the loop over blocks.
        sharding: a :class:`jax.sharding.NamedSharding` over the texel rows: the observations are placed with it
            and every device fits its own rows (the result is sharded the same way). None: where they are.
        options: other keywords of :func:`polyjax.fit_polynomial`.

    Returns:
        :class:`polyjax.PolynomialBRDF` of batch shape ``(h, W, 3)``: the coefficient textures.
    """
    u, v, b, w = capture.observations()
    if sharding is not None:
        u, v, b, w = (jax.device_put(a, sharding) for a in (u, v, b, w))
    return fit_polynomial(u, v, b, variables, degree, weights=w, cutoff_deg=cutoff_deg, lane_block=lane_block,
                          **options)
