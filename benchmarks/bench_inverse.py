"""Benchmark: BRDFs from images. polyjax's closed-form polynomial fit beside Mitsuba 3's inverse rendering.

Scene: a GGX rough-plastic unit sphere (alpha 0.2, diffuse (0.2, 0.4, 0.6)) seen from distance 5
with a 30-degree field of view, rendered by Mitsuba 3 under 4 point lights (one 128 x 128 image
each, pixel centres: ``docs/conventions.md``). From the same 4 images:

- **polyjax closed form**: ``pj.fit_polynomial_to_images`` (Ashikhmin-Shirley variables, p = 6);
  one weighted least-squares solve. Time of a call after the first (the first compiles, reported
  separately), median of ``--repeat`` calls.
- **Mitsuba 3 gradient descent**: its usual inverse-rendering loop (``llvm_ad_rgb``, ``prb``
  integrator, Adam, lr 0.05, 100 iterations, 16 samples per pixel per image) on the true BSDF's
  parameters (alpha, diffuse reflectance) from alpha 0.5, diffuse 0.5. Total loop time, and the
  first iteration (kernel compilation) separately.
- **Cook-Torrance from images** (``baselines.fit_to_images``, 16 starts): multi-start Levenberg-Marquardt on the
  image residuals. Time of the second call (the first, with compilation, separately).

Each result is rendered under a fifth (held-out) light and compared with Mitsuba's render of the
true BSDF there (PSNR). Targets: closed form >= 10x faster than Mitsuba's loop, held-out PSNR >= 35 dB; the
Cook-Torrance fit >= 35 dB.

    DRJIT_LIBLLVM_PATH=/path/to/libLLVM.so.19.1 python benchmarks/bench_inverse.py [--iterations 100] [--repeat 5]
"""

import jax

jax.config.update("jax_enable_x64", True)

import argparse  # noqa: E402
import time  # noqa: E402

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import polyjax as pj  # noqa: E402
import polyjax.render as pr  # noqa: E402
from polyjax.render._mitsuba import mitsuba_roughplastic, mitsuba_scene_dict, render_mitsuba  # noqa: E402

SIZE = 128
ALPHA, ALBEDO = 0.2, (0.2, 0.4, 0.6)
FIT_LIGHTS = [(3.0, 2.0, 4.0), (-3.0, 1.0, 3.0), (0.0, -3.0, 4.0), (4.0, 0.0, -1.0)]
HELD_OUT = (-2.0, -2.0, 4.0)
INTENSITY = 30.0


def scene(position, brdf=None):
    cam = pr.Camera(eye=(0.0, 0.0, 5.0), width=SIZE, height=SIZE, fov_deg=30.0)
    return pr.Scene(cam, [pr.Sphere(brdf if brdf is not None else pr.Lambertian(0.5))],
                    [pr.PointLight(position, INTENSITY)])


def polyjax_fit(scenes, images, repeat):
    def run():
        fit = pj.fit_polynomial_to_images(scenes, images, variables="ashikhmin-shirley", degree=6,
                                          interactions=False, link="identity", weighting="radiance",
                                          cutoff_deg=80.0, clamp=False)  # the linear fit these results measured
        return jax.block_until_ready(fit)

    t0 = time.perf_counter()
    run()
    first = time.perf_counter() - t0
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fit = run()
        times.append(time.perf_counter() - t0)
    return fit, first, float(np.median(times))


def cook_torrance_fit(scenes, images):
    """``baselines.fit_to_images("cook-torrance", ...)`` on the same images: (fit, first call s, second call s)."""
    import baselines

    def run():
        return jax.block_until_ready(
            baselines.fit_to_images("cook-torrance", scenes, images, n_starts=16, key=jax.random.PRNGKey(0)))

    t0 = time.perf_counter()
    run()
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    fit = run()
    return fit, first, time.perf_counter() - t0


def mitsuba_inverse(bsdf, images, iterations, spp=16, lr=0.05):
    """Mitsuba 3's gradient-descent inverse rendering of (alpha, diffuse reflectance) on the 4 images."""
    import drjit as dr
    import mitsuba as mi

    mi.set_variant("llvm_ad_rgb")
    start = {**bsdf, "alpha": 0.5, "diffuse_reflectance": {"type": "rgb", "value": [0.5, 0.5, 0.5]}}
    integrator = {"type": "prb", "max_depth": 2}
    scenes = [mi.load_dict(mitsuba_scene_dict(scene(p), start, pixel_centres=False, spp=spp, integrator=integrator))
              for p in FIT_LIGHTS]
    params = [mi.traverse(s) for s in scenes]
    ka, kd = "sphere0.bsdf.alpha", "sphere0.bsdf.diffuse_reflectance.value"
    refs = [mi.TensorXf(np.asarray(img, np.float32)) for img in images]
    opt = mi.ad.Adam(lr=lr)
    opt[ka] = params[0][ka]
    opt[kd] = params[0][kd]
    times = []
    for it in range(iterations):
        t0 = time.perf_counter()
        for p in params:
            p[ka] = opt[ka]
            p[kd] = opt[kd]
            p.update()
        loss = 0.0
        for s, p, ref in zip(scenes, params, refs):
            img = mi.render(s, p, spp=spp, seed=it)
            loss = loss + dr.mean(dr.square(img - ref), axis=None)
        dr.backward(loss)
        opt.step()
        opt[ka] = dr.clip(opt[ka], 0.01, 1.0)
        opt[kd] = dr.clip(opt[kd], 0.0, 1.0)
        dr.eval(opt[ka], opt[kd])
        times.append(time.perf_counter() - t0)
    alpha = float(np.asarray(opt[ka]).reshape(-1)[0])
    diffuse = np.asarray(opt[kd], float).reshape(-1)[:3]
    return alpha, diffuse, float(np.sum(times)), times[0]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--iterations", type=int, default=100)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()

    truth, bsdf = mitsuba_roughplastic(ALPHA, ALBEDO)
    scenes = [scene(p) for p in FIT_LIGHTS]
    images = [render_mitsuba(s, bsdf) for s in scenes]
    held_ref = render_mitsuba(scene(HELD_OUT), bsdf)

    def held_psnr(brdf):
        img = np.asarray(pr.render(scene(HELD_OUT, brdf), dtype=jnp.float64).image)
        return float(pj.psnr(img, held_ref))

    print(f"rough plastic (GGX alpha {ALPHA}, diffuse {ALBEDO}), {len(FIT_LIGHTS)} Mitsuba images {SIZE}x{SIZE}; "
          f"held-out light at {HELD_OUT}")
    print(f"check: polyjax render of the true BSDF vs Mitsuba under the held-out light: {held_psnr(truth):.1f} dB")

    fit, first, t_fit = polyjax_fit(scenes, images, args.repeat)
    p_fit = held_psnr(fit)
    print(f"polyjax closed form (ashikhmin-shirley, p=6): {t_fit * 1e3:.1f} ms per fit (first call with "
          f"compilation {first:.2f} s); held-out PSNR {p_fit:.1f} dB")

    alpha, diffuse, t_mi, t_mi_first = mitsuba_inverse(bsdf, images, args.iterations)
    recovered, _ = mitsuba_roughplastic(alpha, diffuse)
    held_mi = render_mitsuba(scene(HELD_OUT), {**bsdf, "alpha": alpha,
                                               "diffuse_reflectance": {"type": "rgb", "value": diffuse.tolist()}})
    p_mi = float(pj.psnr(held_mi, held_ref))
    print(f"Mitsuba 3 Adam ({args.iterations} iterations, 16 spp, llvm_ad_rgb): {t_mi:.2f} s (first iteration with "
          f"kernel compilation {t_mi_first:.2f} s); recovered alpha {alpha:.3f} of {ALPHA}, diffuse "
          f"{np.round(diffuse, 3).tolist()} of {list(ALBEDO)}; held-out PSNR {p_mi:.1f} dB "
          f"(polyjax render of it: {held_psnr(recovered):.1f} dB)")

    ct, ct_first, t_ct = cook_torrance_fit(scenes, images)
    p_ct = held_psnr(ct)
    print(f"cook-torrance from images (baselines.fit_to_images, 16 starts): {t_ct:.2f} s per fit (first call with "
          f"compilation {ct_first:.2f} s); params per channel (rho_d, rho_s, m, F0) "
          f"{np.round(np.asarray(ct.params), 3).tolist()}; held-out PSNR {p_ct:.1f} dB (target >= 35 dB: "
          f"{'MET' if p_ct >= 35.0 else 'MISSED'})")

    speedup = t_mi / t_fit
    print(f"ratio: Mitsuba loop / polyjax closed form = {speedup:.0f}x (target >= 10x); "
          f"polyjax held-out PSNR {p_fit:.1f} dB (target >= 35 dB)")


if __name__ == "__main__":
    main()
