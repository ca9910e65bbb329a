"""Benchmark: BRDF importance sampling with MIS against environment-only and cosine sampling.

A glossy MERL material (the neural-BRDF fit of gold-metallic-paint, Sztrajman et al. 2021; needs POLYJAX_DATA)
on a sphere under the built-in sky (a bright sun and a sky gradient). The environment term is rendered with
each ``sampling=`` mode of ``polyjax.render.render``: ``environment`` (the map's importance sampling alone),
``cosine`` (cosine-weighted), ``brdf`` (the tabulated importance sampler of the BRDF) and ``mis`` (half
environment, half BRDF samples, balance heuristic). Each is compared with a high-spp MIS reference by RMSE
over the sphere's pixels, at equal samples per pixel and at equal time (cosine and environment are given the
spp that takes as long as MIS, sampler construction included). Times are after compilation, best of
``--repeat``. Target: MIS RMSE at least 3x lower than cosine sampling at equal time.

    python benchmarks/bench_sampling.py [--size 64] [--spp 32] [--ref-spp 4096] [--material gold-metallic-paint]
"""

import jax

jax.config.update("jax_enable_x64", True)

import argparse  # noqa: E402
import time  # noqa: E402

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import polyjax as pj  # noqa: E402
import polyjax.render as pr  # noqa: E402

MODES = ("environment", "cosine", "brdf", "mis")


def render(scene, spp, mode, seed=1):
    return pr.render(scene, spp=spp, sampling=mode, seed=seed, dtype=jnp.float32)


def timed(scene, spp, mode, repeat):
    out = render(scene, spp, mode)
    jax.block_until_ready(out.image)  # compile + first run
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = render(scene, spp, mode, seed=1)
        jax.block_until_ready(out.image)
        best = min(best, time.perf_counter() - t0)
    return np.asarray(out.image, np.float64), best


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=64)
    ap.add_argument("--spp", type=int, default=32)
    ap.add_argument("--ref-spp", type=int, default=4096)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--material", default="gold-metallic-paint")
    args = ap.parse_args()
    brdf = pj.data.load_nbrdf(args.material)
    cam = pr.Camera(eye=(0.0, 0.0, 5.0), width=args.size, height=args.size, ortho_height=2.1)
    scene = pr.Scene(cam, [pr.Sphere(brdf)], [pr.procedural_sky()])
    t0 = time.perf_counter()
    ref_result = pr.render(scene, spp=args.ref_spp, sampling="mis", seed=12345, dtype=jnp.float64)
    ref = np.asarray(ref_result.image)
    hit = np.asarray(ref_result.hit)
    print(f"material: MERL {args.material} (neural fit), {args.size}x{args.size} sphere, built-in sky; "
          f"reference: MIS {args.ref_spp} spp, float64 ({time.perf_counter() - t0:.1f} s)")

    def rmse(img):
        return float(np.sqrt(np.mean((img[hit] - ref[hit]) ** 2)))

    rows = {}
    print(f"\nequal samples per pixel ({args.spp} spp):")
    print(f"  {'mode':<12s} {'RMSE':>10s} {'time (s)':>10s}")
    for mode in MODES:
        img, t = timed(scene, args.spp, mode, args.repeat)
        rows[mode] = (rmse(img), t)
        print(f"  {mode:<12s} {rows[mode][0]:10.5f} {t:10.3f}")
    e_mis, t_mis = rows["mis"]
    print(f"  cosine / MIS RMSE: {rows['cosine'][0] / e_mis:.2f}x, environment / MIS: "
          f"{rows['environment'][0] / e_mis:.2f}x")
    print(f"\nequal time (as long as MIS at {args.spp} spp, {t_mis:.3f} s):")
    for mode in ("cosine", "environment"):
        spp = max(1, round(args.spp * t_mis / rows[mode][1]))
        img, t = timed(scene, spp, mode, args.repeat)
        e = rmse(img)
        print(f"  {mode:<12s} {spp:5d} spp  RMSE {e:.5f}  time {t:.3f} s  -> {mode} / MIS RMSE: {e / e_mis:.2f}x "
              f"(time ratio {t / t_mis:.2f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
