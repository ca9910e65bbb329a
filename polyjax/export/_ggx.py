r"""glTF's specular lobe (glTF 2.0 specification, appendix B: Trowbridge-Reitz/GGX distribution, Smith
height-correlated visibility) and its fit to a tabulated lobe (:func:`fit_ggx_lobes`).

With ``alpha = roughness^2``, ``h`` the half vector of the local light ``u`` and view ``v``:

.. math::
    D = \frac{\alpha^2}{\pi\,((h_z)^2(\alpha^2 - 1) + 1)^2}, \qquad
    V = \frac{1}{2\,(u_z\sqrt{v_z^2(1-\alpha^2)+\alpha^2} + v_z\sqrt{u_z^2(1-\alpha^2)+\alpha^2})},

and the specular BRDF is ``F D V`` with Schlick's ``F = F0 + (1 - F0)(1 - v.h)^5``. The fit factors the reflectance
out: a lobe ``f_k(u, v)`` (RGB) is matched by ``a_k D V + b_k / pi`` (``a_k >= 0`` and ``b_k`` RGB: a lobe fitted to
photographs may also lift or lower the diffuse level, ``b_k`` of either sign, which the texel's diffuse albedo takes
over), in the L2 of paper equation (11) (residuals weighted by ``cos theta_u``, both directions within 80 degrees of
the normal). The direction pairs are either random (a quarter of the views near the mirror direction) or, for a
capture fit, those a capture sees (:func:`capture_directions`: the lobes were fitted there, and a fitted
polynomial lobe means nothing far outside). For each roughness of a grid the amplitudes are the closed-form
least-squares solution (two columns per channel, QR); the roughness is the grid's best, refined on a finer grid around
it (steps of about ``2e-4``). ``a_k`` then plays glTF's ``F0`` at normal incidence (Schlick's rise towards grazing
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
        offset: ``(K, 3)`` RGB diffuse offset ``b_k`` (the lobe's share of the diffuse albedo).
        relative_l2: ``(K,)`` the fit's L2 (equation (11), channels pooled) over the lobe's own L2.
    """

    roughness: Float[Array, " k"]
    amplitude: Float[Array, "k 3"]
    offset: Float[Array, "k 3"]
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


def capture_directions(normals, mask, n: int, seed: int = 0):
    """``n`` light/view pairs as a capture sees them, local to its normals: the view ``(0, 0, 1)`` of the camera
    and a light uniform over the camera's front hemisphere (``z > 0``, as the lights of a photometric capture), at
    pixels of ``mask`` drawn at random, in the frame of their normal ``(H, W, 3)``; pairs with either direction
    below the surface are drawn again (at most 64 rounds)."""
    rng = np.random.default_rng(seed)
    n_px = np.asarray(normals, np.float64)[np.asarray(mask, bool)]
    if n_px.size == 0:
        raise InputError("mask: expected at least one pixel to draw the lobes' directions at")
    us, vs, have = [], [], 0
    for _ in range(64):
        nrm = n_px[rng.integers(0, len(n_px), n)]
        nrm = nrm / np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-12)
        light = rng.normal(size=(n, 3))
        light[:, 2] = np.abs(light[:, 2])
        light /= np.linalg.norm(light, axis=1, keepdims=True)
        a = np.where(np.abs(nrm[:, :1]) < 0.9, np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
        tan = np.cross(a, nrm)
        tan /= np.linalg.norm(tan, axis=1, keepdims=True)
        frame = np.stack([tan, np.cross(nrm, tan), nrm], 1)  # (n, 3, 3): rows t, b, n
        u, v = np.einsum("pij,pj->pi", frame, light), frame[:, :, 2]
        keep = (u[:, 2] > 1e-3) & (v[:, 2] > 1e-3)
        us.append(u[keep])
        vs.append(v[keep])
        have += int(keep.sum())
        if have >= n:
            break
    u, v = np.concatenate(us)[:n], np.concatenate(vs)[:n]
    if len(u) < n:
        raise InputError("normals: too few of them face the camera to draw the lobes' directions at")
    return u, v


@jax.jit
def _grid_fit(u, v, f, roughness):
    """Per lobe: the amplitudes ``(K, G, 3)``, diffuse offsets ``(K, G, 3)`` and pooled weighted squared
    residuals ``(K, G)`` at each roughness of the grid ``(G,)`` (``f (K, n, 3)``; the weights of equation (11):
    ``cos theta_u`` on the residual, within 80 degrees), and the lobes' own pooled squares ``(K,)``."""
    c = jnp.cos(jnp.radians(80.0))
    w = jnp.where((u[:, 2] >= c) & (v[:, 2] >= c), u[:, 2], 0.0)
    g = ggx_specular(u, v, roughness)  # (G, n)
    cols = jnp.stack([g * w, jnp.broadcast_to(w / jnp.pi, g.shape)], -1)  # (G, n, 2)
    q, r = jnp.linalg.qr(cols)
    rhs = w[None, :, None] * f  # (K, n, 3)
    qb = jnp.einsum("gni,knc->kgic", q, rhs)
    x = jax.scipy.linalg.solve_triangular(r[None, :, None], jnp.moveaxis(qb, 2, 3)[..., None], lower=False)[..., 0]
    amp, off = x[..., 0], x[..., 1]  # (K, G, 3)
    col = w / jnp.pi
    alone = jnp.einsum("n,knc->kc", col, rhs)[:, None, :] / jnp.maximum(jnp.sum(col * col), 1e-300)
    off = jnp.where(amp < 0, alone, off)  # a negative lobe: the offset alone (then b / pi = its mean)
    amp = jnp.maximum(amp, 0.0)
    pred = amp[:, :, None, :] * (g * w)[None, :, :, None] + off[:, :, None, :] * (w / jnp.pi)[None, None, :, None]
    res = jnp.sum((rhs[:, None] - pred) ** 2, axis=(2, 3))
    return amp, off, res, jnp.sum(rhs * rhs, axis=(1, 2))


def _offset_only(u, v, f):
    """The pooled weighted squared residual ``(K,)`` of each lobe fitted by a diffuse offset alone, and the offset
    ``(K, 3)`` (the weights of :func:`_grid_fit`)."""
    c = np.cos(np.radians(80.0))
    w = np.where((u[:, 2] >= c) & (v[:, 2] >= c), u[:, 2], 0.0)
    col, rhs = w / np.pi, w[None, :, None] * f
    off = np.einsum("n,knc->kc", col, rhs) / max(float(np.sum(col * col)), 1e-300)
    res = np.sum((rhs - off[:, None, :] * col[None, :, None]) ** 2, axis=(1, 2))
    return res, off


def fit_ggx_lobes(lobes, *, directions=None, samples: int = 8192, seed: int = 0,
                  min_gain: float = 0.1) -> GGXLobes:
    """Fit glTF's GGX lobe and a diffuse offset (module notes) to each of ``K`` lobes.

    Args:
        lobes: a callable ``lobes(u, v) -> (K, n, 3)`` (a capture fit's ``lobes``) or ``(n, 3)`` (one lobe) of the
            BRDF values at local unit directions ``u``, ``v`` ``(n, 3)``.
        directions: ``(u, v)``, the local direction pairs to fit at (e.g. :func:`capture_directions`); default
            ``samples`` random pairs over the hemisphere.
        samples: the number of random pairs (at least 256).
        seed: their random seed.
        min_gain: a GGX lobe is kept only where it lowers the L2 of the offset alone by this fraction (default
            10%); otherwise the lobe is the offset alone (amplitude 0, roughness 1): a GGX lobe that explains
            almost nothing of a lobe is a guess, and the narrowest guess (a spike between the samples) would
            make glTF mirrors of diffuse texels.

    Returns:
        A :class:`GGXLobes` of the ``K`` fits.

    Raises:
        InputError: ``lobes`` is not callable, or returns values of another shape, or non-finite values.
    """
    if not callable(lobes):
        raise InputError(f"lobes: expected a callable lobes(u, v) -> (K, n, 3), found {type(lobes).__name__}")
    if not isinstance(samples, int) or samples < 256:
        raise InputError(f"samples: expected an integer >= 256, found {samples!r}")
    u, v = _directions(samples, seed) if directions is None else (np.asarray(d, np.float64) for d in directions)
    if u.ndim != 2 or u.shape[1] != 3 or v.shape != u.shape:
        raise InputError(f"directions: expected two (n, 3) arrays, found {u.shape}, {v.shape}")
    f = np.asarray(lobes(jnp.asarray(u), jnp.asarray(v)), np.float64)
    f = f[None] if f.ndim == 2 else f
    if f.ndim != 3 or f.shape[1:] != (len(u), 3) or not np.isfinite(f).all():
        raise InputError(f"lobes: expected finite values of shape (K, {len(u)}, 3), found {np.shape(f)}")
    res = np.asarray(_grid_fit(u, v, f, jnp.asarray(_COARSE))[2])
    best = _COARSE[np.argmin(res, axis=1)]  # (K,)
    flat = _offset_only(u, v, f)  # (K,): the residual of the offset alone, and the offset
    out = []
    for k in range(f.shape[0]):  # each lobe on its own fine grid
        fine = np.clip(best[k] + _FINE, 0.01, 1.0)
        amp, off, r, own = (np.asarray(x)[0] for x in _grid_fit(u, v, f[k:k + 1], jnp.asarray(fine)))
        j = int(np.argmin(r))
        rough, amp, off, r = fine[j], amp[j], off[j], max(float(r[j]), 0.0)
        if r > (1.0 - min_gain) ** 2 * flat[0][k]:  # GGX explains too little: the offset alone
            rough, amp, off, r = 1.0, np.zeros(3), flat[1][k], flat[0][k]
        out.append((rough, amp, off, np.sqrt(r / max(float(own), 1e-300))))
    rough, amp, off, rel = (np.stack(x) for x in zip(*out))
    return GGXLobes(jnp.asarray(rough), jnp.asarray(amp), jnp.asarray(off), jnp.asarray(rel))
