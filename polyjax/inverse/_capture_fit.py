r"""Shape and material from photographs: :func:`fit_capture` fits a capture's normals and spatially varying BRDF
from its images alone, and :class:`CaptureFit` holds them.

The model of pixel ``p`` under light ``l`` (direction ``d_l``, irradiance ``E_l``, view ``(0, 0, 1)``):

.. math:: I_{l,c}(p) = E_{l,c} \max(0, n_p \cdot d_l) \Big(\frac{\rho_{p,c}}{\pi} + \sum_k m_{p,k}\, g_{k,c}(u, v)\Big),

``rho_p`` the pixel's diffuse albedo, ``g_k`` ``K`` polynomial lobes shared by every pixel (Rusinkiewicz variables,
clamped: :mod:`polyjax.inverse._mix`), ``m_p >= 0`` the pixel's weights of them. The fit:

1. **Start**: robust Lambertian normals (:func:`polyjax.inverse._normals.lambertian_normals`: reweighted least
   squares that reject highlights and shadows), the diffuse albedo from them, the pixels split into ``K`` groups
   by the strength of their specular residual (quantiles) and one lobe fitted per group; the samples then weighted
   as in step 2 and the lobes refitted (``ROBUST_START``: the first alternation does not fit cast shadows).
2. **Alternation**, ``iterations`` times: the lobes refitted in closed form on a fixed sample of pixels; every
   pixel's ``rho, m`` by non-negative least squares; its normal, ``rho`` and ``m`` together by Levenberg-Marquardt
   steps (:func:`polyjax.inverse._normals.joint_normals`; the weights projected onto ``>= 0``, then bounded as
   :func:`polyjax.inverse._mix.solve_mix` bounds them): updating the normal alone with the BRDF fixed (``UPDATE =
   "normal"``) zigzags between the two and needs many more alternations (cat, every fourth pixel: 6.35 degrees
   after 12 alternations, still moving; jointly 6.0 after 6, converged); its samples'
   weights by a Cauchy function of the residual over the pixel's noise (its median absolute deviation, at least the
   images' quantisation step: cast shadows, inter-reflection and highlights the lobes miss count less).
   Pixels are processed in blocks of ``block`` (memory), each block one compiled, vmapped program.
3. **Convergence**: stops when the mean change of the normals is under ``tol_deg``; ``status`` is
   ``RESULTS.OK``, or ``RESULTS.MAX_STEPS`` when ``iterations`` ran out first.

Samples at or above the capture's saturation are never used; samples below twice the quantisation step start
with weight 0 (shadow or black). The fit is differentiable with respect to the images (every step is JAX).
"""

from __future__ import annotations

from functools import partial

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from .._arrays import is_traced
from .._errors import InputError
from .._io import POLYNOMIAL_KIND, ModelKind, register_model_kind
from .._model import PolynomialBRDF
from .._results import RESULTS, raise_on_status
from ._capture import Capture
from ._capture import relight as relight_model
from ._mix import fit_lobes, lobe_table, lobe_values, shade, shade_table, solve_mix
from ._normals import gauss_newton_normals, joint_normals, lambertian_normals

#: the robust weights' Cauchy scale in noise units, and the noise floor in quantisation steps (measured:
#: ``benchmarks/bench_capture.py``)
CAUCHY_SCALE, FLOOR_STEPS = 3.0, 2.0


class CaptureFit(eqx.Module):
    """Normals and spatially varying BRDF of a capture (:func:`fit_capture`). The BRDF of pixel ``p``:
    ``diffuse[p] / pi + sum_k mix[p, k] * lobes(u, v)[k]``.

    Attributes:
        normals: ``(H, W, 3)`` unit normals, camera frame (``(0, 0, 1)`` off the mask), as ``Capture.normals``.
        mask: ``(H, W)`` the pixels fitted.
        diffuse: ``(H, W, 3)`` diffuse albedo ``rho_d`` (the BRDF's diffuse term is ``rho_d / pi``).
        mix: ``(H, W, K)`` non-negative weights of the ``K`` shared lobes.
        lobe_model: the lobes, a :class:`polyjax.PolynomialBRDF` of batch ``(K, 3)`` (lobe, channel).
        status: a ``RESULTS`` code (``OK``: converged; ``MAX_STEPS``: iterations ran out first).
        iterations: the alternations run.
        residuals: ``(Lf, H, W, 3)`` what the model leaves of each fitted photograph, over irradiance
            (``I / E - max(0, n . d) f``; 0 for saturated samples and off the mask), or None.
        fit_directions: ``(Lf, 3)`` the fitted lights' directions (with ``residuals``), or None.
    """

    normals: Float[Array, "h w 3"]
    mask: Bool[Array, "h w"]
    diffuse: Float[Array, "h w 3"]
    mix: Float[Array, "h w k"]
    lobe_model: PolynomialBRDF
    status: Int[Array, ""]
    iterations: int = eqx.field(static=True, default=0)
    residuals: Float[Array, "lf h w 3"] | None = None
    fit_directions: Float[Array, "lf 3"] | None = None

    @property
    def n_lobes(self) -> int:
        return int(self.mix.shape[-1])

    def lobes(self, u, v) -> Float[Array, "k n 3"]:
        """``(K, n, 3)`` values of the shared lobes at local directions ``u, v (n, 3)`` (``z``: the normal)."""
        return lobe_values(self.lobe_model, jnp.asarray(u), jnp.asarray(v))

    def brdf(self, u, v) -> Float[Array, "h w n 3"]:
        """Every pixel's BRDF ``(H, W, n, 3)`` at local directions ``u, v (n, 3)``."""
        g = self.lobes(u, v)
        return self.diffuse[:, :, None, :] / jnp.pi + jnp.einsum("hwk,knc->hwnc", self.mix, g)


def _check(capture, lobes, iterations, block):
    if not isinstance(capture, Capture):
        raise InputError(f"capture: expected a polyjax.Capture, found {type(capture).__name__}")
    for name, val, lo in (("lobes", lobes, 1), ("iterations", iterations, 0), ("block", block, 1)):
        if int(val) != val or int(val) < lo:
            raise InputError(f"{name}: expected an integer >= {lo}, found {val!r}")
    if not np.asarray(capture.mask).any():
        raise InputError("capture.mask: expected at least one object pixel to fit")


def _pixels(capture):
    """``obs (P, L, 3)`` (images over irradiance), usable ``ok (P, L, 3)``, the noise floor ``(L, 3)``."""
    mask = np.asarray(capture.mask)
    images = jnp.asarray(capture.images)[:, mask]  # (L, P, 3)
    e = jnp.asarray(capture.light_intensities)
    obs = jnp.moveaxis(images / e[:, None, :], 0, 1)
    floor = max(float(capture.quantisation), 1e-6) / e
    sat = jnp.all(images < capture.saturation, axis=-1, keepdims=True)
    ok = jnp.moveaxis(sat & (images >= FLOOR_STEPS * max(float(capture.quantisation), 1e-6)), 0, 1)
    return obs, ok, floor


#: a block's size is a multiple of this (fewer compiled shapes across captures)
BLOCK_QUANTUM = 256


def _blocks(n: int, block: int):
    """``(start, stop)`` of the blocks of pixels, and the padded size of one: the fewest blocks of at most ``block``
    pixels (rounded up to :data:`BLOCK_QUANTUM`), of equal size, so the last is padded by less than a quantum per
    block (45,200 pixels in blocks of 4,096: 12 of 3,840, not 11 full ones and one of 144 padded to 4,096)."""
    count = -(-n // block)
    size = -(-n // count)
    if block >= BLOCK_QUANTUM:
        size = min(-(-size // BLOCK_QUANTUM) * BLOCK_QUANTUM, block)
    return [(i, min(i + size, n)) for i in range(0, n, size)], size


def _blockwise(fn, arrays, n: int, block: int):
    """``fn`` applied to blocks of the leading axis of ``arrays`` (the last block padded by repetition, one compiled
    shape), outputs concatenated."""
    spans, size = _blocks(n, block)
    outs = []
    for a, b in spans:
        idx = jnp.minimum(jnp.arange(a, a + size), n - 1)
        res = fn(*[x[idx] for x in arrays])
        outs.append(jax.tree_util.tree_map(lambda y, m=b - a: y[:m], res))
    return jax.tree_util.tree_map(lambda *ys: jnp.concatenate(ys), *outs)


@jax.jit
def _start_block(obs, ok, directions):
    n, rho_grey = lambertian_normals(obs, jnp.all(ok, -1), directions)
    cos = jnp.maximum(jnp.einsum("pi,li->pl", n, directions), 0.0)
    inlier = ok & (cos[..., None] > 0.2)
    num = jnp.sum(jnp.where(inlier, obs * cos[..., None], 0.0), 1)
    den = jnp.sum(jnp.where(inlier, cos[..., None] ** 2, 0.0), 1)
    rho = jnp.pi * num / jnp.where(den > 0, den, 1.0)
    spec = jnp.where(inlier, obs - cos[..., None] * rho[:, None] / jnp.pi, 0.0)
    strength = jnp.max(jnp.mean(spec, -1), 1) / jnp.maximum(jnp.mean(rho, -1) / jnp.pi, 1e-6)
    return n, rho, strength


def _robust_weights(n, obs, ok, rho, mix, directions, table, floor):
    """Cauchy weights of a block's samples (module notes)."""
    pred = jax.vmap(lambda ni, r, m: shade_table(ni, r, m, directions, table))(n, rho, mix)
    r = obs - pred
    s = 1.4826 * jnp.median(jnp.abs(r), axis=(1, 2))
    z = r / jnp.maximum(s[:, None, None], floor[None])
    return ok * (1.0 / (1.0 + (z / CAUCHY_SCALE) ** 2))


@jax.jit
def _iterate_block(n, obs, ok, w, directions, table, floor):
    """One alternation of a block: mix, normals, mix again, weights."""
    rho, mix = solve_mix(n, obs, w, directions, table)
    shade_fn = lambda ni, p: shade_table(ni, p[0], p[1], directions, table)  # noqa: E731
    n2, _ = gauss_newton_normals(n, obs, w, shade_fn, (rho, mix))
    rho, mix = solve_mix(n2, obs, w, directions, table)
    w2 = _robust_weights(n2, obs, ok, rho, mix, directions, table, floor)
    change = jnp.degrees(jnp.arccos(jnp.clip(jnp.sum(n * n2, -1), -1.0, 1.0)))
    return n2, rho, mix, w2, change


def _initial_mix(strength, k: int):
    """``(P, K)`` one-hot groups of the pixels by quantiles of their specular strength."""
    edges = jnp.quantile(strength, jnp.linspace(0.0, 1.0, k + 1)[1:-1])
    group = jnp.searchsorted(edges, strength)
    return jax.nn.one_hot(group, k, dtype=strength.dtype)


def _start(obs, ok, directions, k, block, sample, floor):
    """The start of module notes step 1: ``(normals, weights, lobes)``."""
    n_px = obs.shape[0]
    n, rho, strength = _blockwise(lambda o, q: _start_block(o, q, directions), (obs, ok), n_px, block)
    w = ok.astype(obs.dtype)
    mix = _initial_mix(strength, k)
    lobes = fit_lobes(n[sample], obs[sample], w[sample], rho[sample], mix[sample], directions)
    if ROBUST_START:
        w = _blockwise(partial(_weights_block, directions=directions, table=lobe_table(lobes), floor=floor),
                       (n, obs, ok, w), n_px, block)
        rho, mix = _blockwise(partial(_mix_block, directions=directions, table=lobe_table(lobes)), (n, obs, w),
                              n_px, block)
        lobes = fit_lobes(n[sample], obs[sample], w[sample], rho[sample], mix[sample], directions)
    return n, w, lobes


#: the start's samples are weighted robustly (module notes) before the first alternation
ROBUST_START = True


@jax.jit
def _weights_block(n, obs, ok, w, directions, table, floor):
    rho, mix = solve_mix(n, obs, w, directions, table)
    return _robust_weights(n, obs, ok, rho, mix, directions, table, floor)


@jax.jit
def _mix_block(n, obs, w, directions, table):
    return solve_mix(n, obs, w, directions, table)


def fit_capture(capture: Capture, *, lobes: int = 2, iterations: int = 12, tol_deg: float = 0.1,
                block: int = 8192, n_sample: int = 3000, use_normals: bool = False, throw: bool = False,
                seed: int = 0) -> CaptureFit:
    """Fit normals and a spatially varying BRDF to a capture's photographs (module notes).

    Args:
        capture: a :class:`polyjax.Capture` (normals optional: used only with ``use_normals``).
        lobes: ``K``, the number of shared specular lobes.
        iterations: the most alternations (lobes, mix, normals, weights); measured on the DiLiGenT objects
            (``benchmarks/bench_capture.py``): most converge in 5-9.
        tol_deg: convergence: the mean change of the normals in one alternation, degrees.
        block: pixels per compiled block at most (bounds memory; the blocks are made equal). 8192 measured 5 %
            faster than 4096 on cat at full resolution (45,200 pixels, 48 lights), with equal blocks 9 % faster than
            4096 with a padded last block.
        n_sample: pixels (a fixed random sample) the shared lobes are fitted on.
        use_normals: keep the capture's own normals (the BRDF alone is fitted).
        throw: raise :class:`polyjax.FitError` unless the status is ``OK``.
        seed: the sample's seed.

    Returns:
        :class:`CaptureFit`.
    """
    _check(capture, lobes, iterations, block)
    if use_normals and capture.normals is None:
        raise InputError("use_normals: the capture has no normals (capture.normals is None)")
    mask = np.asarray(capture.mask)
    obs, ok, floor = _pixels(capture)
    directions = jnp.asarray(capture.light_directions)
    n_px = obs.shape[0]
    rng = np.random.default_rng(seed)
    sample = jnp.asarray(np.sort(rng.choice(n_px, size=min(n_sample, n_px), replace=False)))
    n, w, lobe_model = _start(obs, ok, directions, lobes, block, sample, floor)
    if use_normals:
        n = jnp.asarray(capture.normals)[mask]
    status, done = RESULTS.MAX_STEPS, 0
    block_fn = _fixed_block if use_normals else (_joint_block if UPDATE == "joint" else _iterate_block)
    while done < iterations:
        done += 1
        table = lobe_table(lobe_model)
        n, rho, mix, w, change = _blockwise(partial(block_fn, directions=directions, table=table, floor=floor),
                                            (n, obs, ok, w), n_px, block)
        lobe_model = fit_lobes(n[sample], obs[sample], w[sample], rho[sample], mix[sample], directions)
        if not use_normals and not is_traced(change) and float(jnp.mean(change)) < tol_deg:
            status = RESULTS.OK
            break
    if use_normals:
        status = RESULTS.OK
    table = lobe_table(lobe_model)
    rho, mix = _blockwise(lambda nb, o, wb: solve_mix(nb, o, wb, directions, table), (n, obs, w), n_px, block)
    fit = _assemble(mask, n, rho, mix, lobe_model, status, done)
    pred = _blockwise(lambda a, b, c: _relight_block(a, b, c, directions, lobe_model), (n, rho, mix), n_px, block)
    unsat = jnp.moveaxis(jnp.all(jnp.asarray(capture.images)[:, mask] < capture.saturation, -1), 0, 1)
    res = jnp.where(unsat[..., None], obs - pred, 0.0)
    h, w_ = mask.shape
    res_img = jnp.zeros((h * w_,) + res.shape[1:], res.dtype).at[jnp.asarray(np.flatnonzero(mask))].set(res)
    fit = eqx.tree_at(lambda f: (f.residuals, f.fit_directions), fit,
                      (jnp.moveaxis(res_img.reshape(h, w_, -1, 3), 2, 0), directions),
                      is_leaf=lambda x: x is None)
    return raise_on_status("fit_capture", fit.status, fit) if throw else fit


#: the normal update: "joint" (normal and BRDF coefficients together) or "normal" (the normal alone)
UPDATE, JOINT_STEPS = "joint", 3


@jax.jit
def _joint_block(n, obs, ok, w, directions, table, floor):
    """One alternation of a block: mix, then normals and mix together, then the exact mix and weights."""
    rho, mix = solve_mix(n, obs, w, directions, table)
    shade_fn = lambda ni, x: shade_table(ni, x[:3], x[3:], directions, table)  # noqa: E731
    n2, x, _ = joint_normals(n, jnp.concatenate([rho, mix], -1), obs, w, shade_fn, steps=JOINT_STEPS)
    rho, mix = x[:, :3], x[:, 3:]
    w2 = _robust_weights(n2, obs, ok, rho, mix, directions, table, floor)
    change = jnp.degrees(jnp.arccos(jnp.clip(jnp.sum(n * n2, -1), -1.0, 1.0)))
    return n2, rho, mix, w2, change


@jax.jit
def _fixed_block(n, obs, ok, w, directions, table, floor):
    """One alternation with the normals kept."""
    rho, mix = solve_mix(n, obs, w, directions, table)
    w2 = _robust_weights(n, obs, ok, rho, mix, directions, table, floor)
    return n, rho, mix, w2, jnp.zeros(n.shape[0], n.dtype)


def _assemble(mask, n, rho, mix, lobe_model, status, done) -> CaptureFit:
    """The pixels' fields scattered back to ``(H, W, ...)`` images."""
    h, w = mask.shape
    idx = jnp.asarray(np.flatnonzero(mask))

    def image(values, fill):
        out = jnp.broadcast_to(jnp.asarray(fill, values.dtype), (h * w,) + values.shape[1:])
        return out.at[idx].set(values).reshape((h, w) + values.shape[1:])

    return CaptureFit(normals=image(n, [0.0, 0.0, 1.0]), mask=jnp.asarray(mask), diffuse=image(rho, 0.0),
                      mix=image(mix, 0.0), lobe_model=lobe_model, status=jnp.asarray(int(status), jnp.int32),
                      iterations=done)


@jax.jit
def _relight_block(n, rho, mix, directions, lobes):
    return jax.vmap(lambda ni, r, m: shade(ni, r, m, directions, lobes))(n, rho, mix)


#: the fitted lights whose residuals a relit image interpolates (inverse-angle weights); measured on the DiLiGenT
#: objects (``benchmarks/bench_capture.py``)
RESIDUAL_NEIGHBOURS = 3


def residual_interpolation(fit: CaptureFit, directions, k: int = RESIDUAL_NEIGHBOURS) -> Float[Array, "l h w 3"]:
    """``(L, H, W, 3)`` the fit's residuals (over irradiance) interpolated to the lights ``directions``: the ``k``
    fitted lights nearest in angle, weights ``1 / angle`` normalised (a fitted light returns its own residual)."""
    ang = jnp.arccos(jnp.clip(directions @ fit.fit_directions.T, -1.0, 1.0))
    ang_k, near = jax.lax.top_k(-ang, min(k, ang.shape[1]))
    wts = 1.0 / jnp.maximum(-ang_k, 1e-9)
    wts = wts / jnp.sum(wts, axis=1, keepdims=True)
    return jnp.einsum("tj,tjhwc->thwc", wts, fit.residuals[near])


def relight_fit(fit: CaptureFit, capture: Capture, *, block: int = 4096,
                residuals: bool = True) -> Float[Array, "l h w 3"]:
    """The images ``(L, H, W, 3)`` a :class:`CaptureFit` predicts under ``capture``'s lights (same camera, same
    image size): ``E_l (max(0, n . d_l) f_p(u, v) + r_l)`` on the fit's mask, 0 elsewhere, ``r_l`` the fit's
    residuals interpolated from the nearest fitted lights (:func:`residual_interpolation`: cast shadows and
    inter-reflection the BRDF does not model; ``residuals=False`` or a fit without them: the model alone);
    differentiable."""
    if tuple(np.shape(capture.mask)) != tuple(np.shape(fit.mask)):
        raise InputError(f"capture: expected images of the fit's size {tuple(np.shape(fit.mask))}, found "
                         f"{tuple(np.shape(capture.mask))}")
    mask = np.asarray(fit.mask)
    directions = jnp.asarray(capture.light_directions)
    n, rho, mix = fit.normals[mask], fit.diffuse[mask], fit.mix[mask]
    pred = _blockwise(lambda a, b, c: _relight_block(a, b, c, directions, fit.lobe_model), (n, rho, mix),
                      n.shape[0], block)  # (P, L, 3)
    e = jnp.asarray(capture.light_intensities)
    h, w = mask.shape
    out = jnp.zeros((h * w, directions.shape[0], 3), pred.dtype).at[jnp.asarray(np.flatnonzero(mask))].set(pred)
    out = jnp.moveaxis(out.reshape(h, w, -1, 3), 2, 0)
    if residuals and fit.residuals is not None:
        out = out + residual_interpolation(fit, directions) * jnp.asarray(mask)[None, ..., None]
    return out * e[:, None, None, :]


def relight(model, capture: Capture, **kwargs) -> Float[Array, "l h w 3"]:
    """The images ``(L, H, W, 3)`` that ``model`` predicts under the lights of ``capture``, in its units: a
    :class:`CaptureFit` through :func:`relight_fit` (its own normals), any other model (a fitted BRDF, one for every
    pixel) on the capture's normals (:func:`polyjax.inverse._capture.relight`). Keyword arguments go to them."""
    if isinstance(model, CaptureFit):
        return relight_fit(model, capture, **kwargs)
    return relight_model(model, capture, **kwargs)


_MAPS = ("normals", "mask", "diffuse", "mix", "status")


def _to_arrays(fit: CaptureFit):
    """``(static, arrays)`` of a :class:`CaptureFit` for :func:`polyjax.save_model`: its maps, and its lobes'
    fields under ``lobe.``."""
    static, arrays = POLYNOMIAL_KIND.to_arrays(fit.lobe_model)
    out = {f"lobe.{k}": v for k, v in arrays.items()}
    out.update({k: np.asarray(getattr(fit, k)) for k in _MAPS})
    if fit.residuals is not None:
        out.update(residuals=np.asarray(fit.residuals), fit_directions=np.asarray(fit.fit_directions))
    return {"iterations": fit.iterations, "lobe": static}, out


def _from_arrays(static, arrays) -> CaptureFit:
    lobe = POLYNOMIAL_KIND.from_arrays(static["lobe"], {k[5:]: v for k, v in arrays.items() if k.startswith("lobe.")})
    extra = {k: jnp.asarray(arrays[k]) for k in ("residuals", "fit_directions") if k in arrays}
    return CaptureFit(**{k: jnp.asarray(arrays[k]) for k in _MAPS}, lobe_model=lobe,
                      iterations=int(static["iterations"]), **extra)


#: saved by :func:`polyjax.save_model` (``.npz``: the maps and the lobes' polynomial), read by
#: :func:`polyjax.load_model` (kind ``polyjax.CaptureFit``, found through the entry point group ``polyjax.models``)
CAPTURE_FIT_KIND = register_model_kind(ModelKind(kind="polyjax.CaptureFit", type=CaptureFit, to_arrays=_to_arrays,
                                                 from_arrays=_from_arrays, status_names=tuple(r.name for r in RESULTS)))

__all__ = ["CAPTURE_FIT_KIND", "CaptureFit", "fit_capture", "relight", "relight_fit"]
