"""Benchmark: render only the effects a scene needs vs. the same scene forced to compute every effect.

A 512 x 512 sphere with a p = 5 polynomial model (fitted to the built-in synthetic data, or to
CUReT when POLYJAX_DATA is set) under (a) one point light and (b) an environment map at 64
samples per pixel. Times are after compilation (best of several runs); the pixels of both paths
are compared. Targets: (a) under 0.1 s on a 2-core CPU; "only needed" several times faster than
"all effects", with identical pixels.

    python benchmarks/bench_render.py [--size 512] [--spp 64] [--repeat 5]
"""

import jax

jax.config.update("jax_enable_x64", True)

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

import polyjax as pj  # noqa: E402
import polyjax.render as pr  # noqa: E402


def fitted_model():
    if pj.has_data_root():
        m = pj.data.load("curet:25")
        name = f"CUReT {m.names[0]}"
    else:
        m = pj.data.synthetic_default()
        name = "synthetic (built-in, not measured)"
    model = pj.fit_polynomial(m, variables="lafortune", degree=5)
    return model[0], name


def timed(fn, repeat):
    out = fn()
    jax.block_until_ready(out.image)  # compile + first run
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        jax.block_until_ready(out.image)
        best = min(best, time.perf_counter() - t0)
    return out, best


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    model, name = fitted_model()
    brdf = pr.rgb_brdf(model)
    cam = pr.Camera(eye=(0.0, 0.0, 5.0), width=args.size, height=args.size, ortho_height=2.1)
    scenes = {
        "point light": pr.Scene(cam, [pr.Sphere(brdf)], [pr.PointLight(position=(2.0, 2.0, 4.0), intensity=24.0)]),
        f"environment map, {args.spp} spp": pr.Scene(cam, [pr.Sphere(brdf)], [pr.procedural_sky()]),
    }
    print(f"model: p = 5 polynomial ({model.variables}) fitted to {name}; {args.size} x {args.size} pixels; "
          f"{jax.device_count()} device(s), backend {jax.default_backend()}")
    for label, scene in scenes.items():
        needed, t_needed = timed(lambda scene=scene: pr.render(scene, spp=args.spp), args.repeat)
        forced, t_all = timed(lambda scene=scene: pr.render(scene, spp=args.spp, force_all_effects=True), args.repeat)
        same = bool(np.array_equal(np.asarray(needed.image), np.asarray(forced.image)))
        print(f"{label}:")
        print(f"  only needed  {t_needed * 1e3:9.1f} ms  effects {needed.effects.names()}")
        print(f"  all effects  {t_all * 1e3:9.1f} ms  effects {forced.effects.names()}")
        print(f"  speed-up {t_all / t_needed:.1f}x; identical pixels: {same}")


if __name__ == "__main__":
    main()
