"""Principal components of the explanatory variables (paper, section 3).

Convention: covariance PCA, centred and unweighted, over the samples used in the fit (a 0/1
mask). ``Z = (X - mean) @ rotation``; the columns of ``rotation`` are the eigenvectors of the
covariance sorted by decreasing variance, each signed so that its entry of largest magnitude
is positive (so runs and machines agree). Entries within ``sqrt(eps)`` of the largest magnitude
count as tied and the first of them decides: symmetric data (e.g. samples closed under swapping
``x`` and ``y``) give eigenvectors like ``(a, -a, b)`` whose two largest entries differ only by
rounding, and a plain ``argmax`` then flipped the sign with the order of the samples.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from ._solve.linalg import eigh
from ._solve.threads import one_lapack_thread


class PCA(eqx.Module):
    """A fitted principal-component transform.

    Attributes:
        mean: ``(k,)`` sample mean of X.
        rotation: ``(k, k)`` eigenvectors as columns.
        variance: ``(k,)`` variances of the components (eigenvalues), decreasing.
    """

    mean: Float[Array, "*batch k"]
    rotation: Float[Array, "*batch k k"]
    variance: Float[Array, "*batch k"]

    def __call__(self, x: Float[Array, "... k"]) -> Float[Array, "... k"]:
        """Principal components ``Z = (X - mean) @ rotation``."""
        return (x - self.mean) @ self.rotation


@one_lapack_thread
@jax.jit
def fit_pca(x: Float[Array, "n k"], keep: Float[Array, " n"] | None = None) -> PCA:
    """Fit the PCA of the rows of ``x`` where ``keep > 0``.

    Args:
        x: ``(n, k)`` explanatory variables.
        keep: ``(n,)`` 0/1 (or boolean) mask of the samples used; all when None.

    Returns:
        :class:`PCA`. With no kept sample the mean is 0 and the rotation the identity.

    Differentiable (``jvp``, ``grad``, ``jacfwd``, ``jacrev``, ``vmap`` of them) with respect to ``x``
    through :func:`polyjax._solve.linalg.eigh`'s rule: ``d lambda_i = r_i^T dC r_i`` and
    ``dr_i = sum_{j != i} r_j (r_j^T dC r_i) / (lambda_i - lambda_j)`` for the covariance ``C``; the sort and
    the sign rule are piecewise constant. ``keep`` is a 0/1 selection and has no derivative. Tied
    eigenvalues (within ``sqrt(eps)`` of the largest; e.g. two variables of equal variance and no
    correlation, as when the samples are closed under swapping ``x`` and ``y`` and under mirroring ``u``)
    leave the rotation inside their eigenspace undetermined: the derivative holds that rotation fixed
    (the coupling term is set to 0), so it is finite, and exact for what does not depend on the rotation:
    the eigenspace, the sum of its variances, and the L2 and values (not the coefficients) of a degree-1 fit
    or of one with ``interactions=True``. A fit of degree > 1 without interactions depends on the rotation
    and is not differentiable there (``docs/robustness.md``).
    """
    n, k = x.shape
    m = jnp.ones((n,), x.dtype) if keep is None else (jnp.asarray(keep) > 0).astype(x.dtype)
    cnt = jnp.sum(m)
    mean = jnp.sum(m[:, None] * x, axis=0) / jnp.maximum(cnt, 1.0)
    xc = (x - mean) * m[:, None]
    cov = (xc.T @ xc) / jnp.maximum(cnt - 1.0, 1.0)
    return pca_from_covariance(mean, cov)


@jax.jit
def pca_from_covariance(mean: Float[Array, " k"], cov: Float[Array, "k k"]) -> PCA:
    """The :class:`PCA` of samples with this mean and covariance (the eigen-decomposition and sign rule of
    :func:`fit_pca`, which calls it; the streamed fit gives it moments accumulated over the samples' ``(k, n)``
    layout)."""
    k = mean.shape[0]
    evals, evecs = eigh(cov)
    evals = evals[::-1]
    evecs = evecs[:, ::-1]
    mag = jnp.abs(evecs)
    tied = mag >= jnp.max(mag, axis=0, keepdims=True) - jnp.sqrt(jnp.finfo(cov.dtype).eps)
    idx = jnp.argmax(tied, axis=0)  # the first (near-)largest entry of each column
    sign = jnp.sign(evecs[idx, jnp.arange(k)])
    sign = jnp.where(sign == 0, 1.0, sign)
    evecs = evecs * sign[None, :]
    return PCA(mean=mean, rotation=evecs, variance=jnp.maximum(evals, 0.0))
