r"""The page's environment map: a small latitude-longitude map lighting the sphere by quadrature over its texels.

The map follows :class:`polyjax.render.EnvironmentLight`: row ``i`` at ``theta_i = (i + 1/2) pi / H`` from ``+y``,
column ``j`` at ``phi_j = (j + 1/2) 2 pi / W - pi`` from ``-z`` towards ``+x``, direction
``d = (sin theta sin phi, cos theta, -sin theta cos phi)``. The page adds to each pixel

    ``L_env = sum_ij L_ij max(f(u_ij, v), 0) cos+ theta_ij  dW_ij``,  ``dW_ij = sin theta_i (pi / H) (2 pi / W)``

(the midpoint rule over the map's texels, no visibility: a lone sphere cannot occlude itself), and rays that miss
see ``L`` of the texel they point at (``EnvironmentLight.radiance``). This is a deterministic quadrature, not the
renderer's importance-sampled estimate; a bigger map is first averaged down to :data:`SHAPE` texels (each block
weighted by solid angle, so its power is kept).
"""

from __future__ import annotations

import base64

import numpy as np

from .._errors import InputError
from ..render import load_envmap, procedural_sky

#: the texels (rows, columns) of the page's map: 512 BRDF evaluations per pixel
SHAPE = (16, 32)


def environment_map(env) -> np.ndarray:
    """``(16, 32, 3)`` float32 radiance from an ``EnvironmentLight``, an ``(H, W, 3)`` map whose size is a multiple of
    16 x 32 (averaged down by solid angle), ``"sky"`` (:func:`polyjax.render.procedural_sky` at 64 x 128) or an
    OpenEXR path (:func:`polyjax.render.load_envmap`)."""
    if isinstance(env, str):
        env = procedural_sky() if env == "sky" else load_envmap(env)
    img = np.asarray(getattr(env, "image", env), np.float64)
    h, w = SHAPE
    if img.ndim != 3 or img.shape[2] != 3 or img.shape[0] % h or img.shape[1] % w:
        raise InputError(f"environment: expected an (H, W, 3) latitude-longitude map with H a multiple of {h} and W "
                         f"of {w}, found shape {img.shape}")
    if not np.all(np.isfinite(img)) or img.min() < 0:
        raise InputError("environment: expected finite, non-negative radiance")
    bh, bw = img.shape[0] // h, img.shape[1] // w
    sin = np.sin((np.arange(img.shape[0]) + 0.5) * np.pi / img.shape[0])
    weighted = (img * sin[:, None, None]).reshape(h, bh, w, bw, 3).sum(axis=(1, 3))
    coarse_sin = np.sin((np.arange(h) + 0.5) * np.pi / h)
    # the block's power sum L sin dtheta dphi over the coarse texel's solid angle sin theta_c (bh dtheta) (bw dphi)
    return (weighted / (bh * bw * coarse_sin[:, None, None])).astype(np.float32)


def environment_json(env) -> dict | None:
    """The page's JSON of the map (base64 float32 RGB texels, row-major from the zenith), or None."""
    if env is None:
        return None
    img = environment_map(env)
    return {"height": img.shape[0], "width": img.shape[1],
            "texels": base64.b64encode(np.ascontiguousarray(img).tobytes()).decode("ascii")}
