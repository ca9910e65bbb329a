r"""glTF's specular lobe (glTF 2.0 specification, appendix B: Trowbridge-Reitz/GGX distribution, Smith
height-correlated visibility) and its fit to a tabulated lobe (:func:`fit_ggx_lobes`).

With ``alpha = roughness^2``, ``h`` the half vector of the local light ``u`` and view ``v``:

.. math::
    D = \frac{\alpha^2}{\pi\,((h_z)^2(\alpha^2 - 1) + 1)^2}, \qquad
    V = \frac{1}{2\,(u_z\sqrt{v_z^2(1-\alpha^2)+\alpha^2} + v_z\sqrt{u_z^2(1-\alpha^2)+\alpha^2})},

and the specular BRDF is ``F D V`` with Schlick's ``F = F0 + (1 - F0)(1 - v.h)^5``. The fit factors the reflectance
out: a lobe ``f_k(u, v)`` (RGB) is matched by ``a_k D V`` (``a_k`` RGB, ``>= 0``), in the L2 of paper equation (11)
(residuals weighted by ``cos theta_u``, both directions within 80 degrees of the normal), at random direction pairs
of which a quarter lie near the mirror direction. For each roughness of a grid the amplitudes are the closed-form
least-squares solution (one column per channel); the roughness is the grid's best, refined on a finer grid around
it (steps of about ``1e-4``). ``a_k`` then plays glTF's ``F0`` at normal incidence (Schlick's rise towards grazing
angles, which the fitted lobe may or may not show, is the glTF model's own).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._errors import InputError

_COARSE = np.linspace(0.02, 1.0, 99)  # roughness grid: steps of 0.01
_FINE = np.linspace(-0.01, 0.01, 101)  # around the coarse optimum: steps of 2e-4


def ggx_specular(u, v, roughness) -> Float[Array, "... n"]:
    """``D V`` of the module notes (no Fresnel) at local unit directions ``u``, ``v`` ``(n, 3)`` for ``roughness``
    (glTF's, ``alpha = roughness^2``; any shape broadcastable against ``(..., 1)``); 0 below the horizon."""
    u, v = jnp.asarray(u), jnp.asarray(v)
    a2 = jnp.maximum(jnp.asarray(roughness, u.dtype)[..., None], 1e-4) ** 4
    h = u + v
    hz = h[:, 2] / jnp.maximum(jnp.linalg.norm(h, axis=-1), 1e-12)
    uz, vz = jnp.maximum(u[:, 2], 0.0), jnp.maximum(v[:, 2], 0.0)
    d = a2 / (jnp.pi * (hz * hz * (a2 - 1.0) + 1.0) ** 2)
    den = uz * jnp.sqrt(vz * vz * (1.0 - a2) + a2) + vz * jnp.sqrt(uz * uz * (1.0 - a2) + a2)
    vis = 0.5 / jnp.maximum(den, 1e-12)
    return jnp.where((uz > 0) & (vz > 0), d * vis, 0.0)


class GGXLobes(eqx.Module):
    """The glTF lobes fitted to ``K`` tabulated lobes (:func:`fit_ggx_lobes`).

    Attributes:
        roughness: ``(K,)`` glTF roughness (``alpha = roughness^2``).
        amplitude: ``(K, 3)`` RGB factor ``a_k`` of ``D V`` (glTF's ``F0`` of the lobe).
        relative_l2: ``(K,)`` the fit's L2 (equation (11), channels pooled) over the lobe's own L2.
    """

    roughness: Float[Array, " k"]
    amplitude: Float[Array, "k 3"]
    relative_l2: Float[Array, " k"]


def _directions(n: int, seed: int):
    """``n`` light/view pairs uniform on the upper hemisphere, a quarter of the views near the mirror direction."""
    rng = np.random.default_rng(seed)

    def hemisphere(k):
        w = rng.normal(size=(k, 3))
        w[:, 2] = np.abs(w[:, 2]) + 1e-3
        return w / np.linalg.norm(w, axis=1, keepdims=True)

    u, v = hemisphere(n), hemisphere(n)
    k = n // 4
    mirror = u[:k] * np.array([-1.0, -1.0, 1.0]) + 0.05 * rng.normal(size=(k, 3))
    mirror[:, 2] = np.abs(mirror[:, 2]) + 0.02
    v[:k] = mirror / np.linalg.norm(mirror, axis=1, keepdims=True)
    return u, v


@jax.jit
def _grid_fit(u, v, f, roughness):
    """Per lobe: the amplitudes ``(K, G, 3)`` and pooled weighted squared residuals ``(K, G)`` at each roughness of
    the grid ``(G,)`` (``f (K, n, 3)``; the weights of equation (11): ``cos^2 theta_u`` within 80 degrees)."""
    c = jnp.cos(jnp.radians(80.0))
    w = jnp.where((u[:, 2] >= c) & (v[:, 2] >= c), u[:, 2] ** 2, 0.0)
    g = ggx_specular(u, v, roughness)  # (G, n)
    gg = jnp.einsum("n,gn,gn->g", w, g, g)
    gf = jnp.einsum("n,gn,knc->kgc", w, g, f)
    amp = jnp.maximum(gf / jnp.maximum(gg, 1e-300)[None, :, None], 0.0)
    ff = jnp.einsum("n,knc->kc", w, f * f)
    res = ff[:, None, :] - 2.0 * amp * gf + amp * amp * gg[None, :, None]
    return amp, jnp.sum(res, -1), jnp.sum(ff, -1)


def fit_ggx_lobes(lobes, *, samples: int = 8192, seed: int = 0) -> GGXLobes:
    """Fit glTF's GGX lobe (module notes) to each of ``K`` lobes.

    Args:
        lobes: a callable ``lobes(u, v) -> (K, n, 3)`` (a capture fit's ``lobes``) or ``(n, 3)`` (one lobe) of the
            BRDF values at local unit directions ``u``, ``v`` ``(n, 3)``.
        samples: direction pairs the lobes are tabulated at (at least 256).
        seed: the directions' random seed.

    Returns:
        A :class:`GGXLobes` of the ``K`` fits.

    Raises:
        InputError: ``lobes`` is not callable, or returns values of another shape, or non-finite values.
    """
    if not callable(lobes):
        raise InputError(f"lobes: expected a callable lobes(u, v) -> (K, n, 3), found {type(lobes).__name__}")
    if not isinstance(samples, int) or samples < 256:
        raise InputError(f"samples: expected an integer >= 256, found {samples!r}")
    u, v = _directions(samples, seed)
    f = np.asarray(lobes(jnp.asarray(u), jnp.asarray(v)), np.float64)
    f = f[None] if f.ndim == 2 else f
    if f.ndim != 3 or f.shape[1:] != (samples, 3) or not np.isfinite(f).all():
        raise InputError(f"lobes: expected finite values of shape (K, {samples}, 3), found {np.shape(f)}")
    amp, res, own = _grid_fit(u, v, f, jnp.asarray(_COARSE))
    best = _COARSE[np.argmin(np.asarray(res), axis=1)]  # (K,)
    fine = np.clip(best[:, None] + _FINE[None, :], 0.01, 1.0)  # (K, F): each lobe its own grid
    fits = [_grid_fit(u, v, f[k:k + 1], jnp.asarray(fine[k])) for k in range(f.shape[0])]
    i = [int(np.argmin(np.asarray(r)[0])) for _, r, _ in fits]
    roughness = np.array([fine[k, j] for k, j in enumerate(i)])
    amplitude = np.stack([np.asarray(a)[0, j] for (a, _, _), j in zip(fits, i)])
    res_best = np.array([max(float(np.asarray(r)[0, j]), 0.0) for (_, r, _), j in zip(fits, i)])
    rel = np.sqrt(res_best / np.maximum(np.asarray(own), 1e-300))
    return GGXLobes(jnp.asarray(roughness), jnp.asarray(amplitude), jnp.asarray(rel))
