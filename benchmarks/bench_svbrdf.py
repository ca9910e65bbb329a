"""Per-texel SVBRDF fits: texels per second and peak memory per texel on 1, 2, 4, 8 (simulated) devices, against
a numpy per-texel ``lstsq`` loop on the same data, in the same run.

Data: a simulated capture (``polyjax.svbrdf.simulate_capture``) of a ``S x S`` texture blending two analytic
Phong-like materials, ``K`` point lights (32 by default), a fixed camera: per texel ``K`` observations at its own
directions, 3 channels. Fit: ``polyjax.svbrdf.fit_capture`` (Lafortune variables, degree 3, every texel its own
PCA and design, channels sharing it), the observations sharded over the texel rows on a mesh of ``D`` devices
(``XLA_FLAGS=--xla_force_host_platform_device_count=D``, one subprocess per ``D``), timed after compilation
(best of ``--repeats``). Comparison: the same fit with numpy, texel by texel (PCA by ``eigh``, monomial design of
equation (13), ``numpy.linalg.lstsq`` of the three channels), timed on the first ``--numpy-texels`` texels.
Inputs: each device's rows simulated for it (``jax.make_array_from_callback``), so the texture's observations
(2.5 KB per texel at 32 lights, float64) are held once. Peak memory: growth of the process's peak resident set
while the size is simulated and fitted (the inputs included), per texel; and the fit's own part (growth over the
resident set with the inputs in place). The numpy loop's rate is measured on its subsample and scaled per
texel to the whole texture. Simulated devices share the machine's cores: on a 2-core CPU the devices add no
compute, so the rows show what sharding costs, not a speed-up (``docs/scale.md`` has the arithmetic for real
devices).

    python benchmarks/bench_svbrdf.py [--sizes 64,128,256] [--devices 1,2,4,8] [--lights 32] [--repeats 2]
    python benchmarks/bench_svbrdf.py --sizes 1024 --devices 1,8 --repeats 1   # the largest run here
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path


def _phong(kd, ks, n):
    import jax.numpy as jnp

    def f(u, v):
        r = jnp.stack([-u[..., 0], -u[..., 1], u[..., 2]], -1)
        c = jnp.clip(jnp.sum(r * v, -1), 0.0, 1.0) ** n
        return jnp.asarray(kd) / jnp.pi + jnp.asarray(ks) * c[..., None]

    return f


def _numpy_fit_texels(u, v, b, w, degree, cutoff_deg=80.0):
    """numpy, texel by texel: Lafortune variables, PCA, monomials (equation (13)), lstsq of the 3 channels.
    Returns per texel (coefficients, predictions at the kept observations)."""
    import numpy as np

    c = np.cos(np.deg2rad(cutoff_deg)) - 1e-9
    out = []
    for t in range(u.shape[0]):
        ut, vt, bt, wt = u[t], v[t], b[t], w[t]
        keep = (ut[:, 2] >= c) & (vt[:, 2] >= c) & (wt > 0)
        x = np.stack([ut[keep, 0] * vt[keep, 0] + ut[keep, 1] * vt[keep, 1], ut[keep, 2] * vt[keep, 2]], -1)
        xm = x.mean(0)
        _, vec = np.linalg.eigh(np.cov((x - xm).T))
        z = (x - xm) @ vec
        z = z / np.maximum(np.abs(z).max(0), 1e-300)
        sw = np.sqrt(wt[keep]) * ut[keep, 2]
        a = np.concatenate([np.ones((len(z), 1))] + [z**k for k in range(1, degree + 1)], axis=1) * sw[:, None]
        coef = np.linalg.lstsq(a, bt[:, keep].T * sw[:, None], rcond=None)[0]
        out.append((coef, (a / sw[:, None]) @ coef))  # coefficients, predictions (n_kept, 3)
    return out


def _rss_mb() -> float:
    """Peak resident set of the process so far (MB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _current_rss_mb() -> float:
    """Resident set now (MB)."""
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def _observations(mats, size, lights, chunk_rows, start=0, stop=None):
    """The fit's inputs for texture rows ``start .. stop``: ``u, v (h, S, K, 3)``, ``b (h, S, 3, K)``,
    ``w (h, S, K)`` as numpy float64, simulated ``chunk_rows`` rows at a time."""
    import numpy as np

    from polyjax import svbrdf

    stop = size if stop is None else stop
    out = None
    for r0 in range(start, stop, chunk_rows):
        cap = svbrdf.simulate_capture(mats, size, size, n_lights=lights, rows=slice(r0, min(stop, r0 + chunk_rows)))
        part = [np.asarray(a) for a in cap.observations()]
        if out is None:
            out = [np.empty((stop - start,) + a.shape[1:], a.dtype) for a in part]
        for o, a in zip(out, part):
            o[r0 - start: r0 - start + a.shape[0]] = a
    return out


def _sharded_observations(mats, size, lights, chunk_rows, sharding):
    """The fit's inputs as global arrays sharded over the rows, each device's rows simulated for it (the texture's
    inputs are never held twice: only one device's rows are in numpy at a time, per array)."""
    import jax

    shapes = [(size, size, lights, 3), (size, size, lights, 3), (size, size, 3, lights), (size, size, lights)]
    cache = {}

    def part(index, k):
        rows = (index[0].start or 0, index[0].stop or size)
        if rows not in cache:
            cache[rows] = _observations(mats, size, lights, chunk_rows, *rows)
        a, cache[rows][k] = cache[rows][k], None
        if all(x is None for x in cache[rows]):
            del cache[rows]
        return a

    out = []
    for k, shape in enumerate(shapes):
        out.append(jax.make_array_from_callback(shape, sharding, lambda index, k=k: part(index, k)))
    return jax.block_until_ready(out)


def _same_fit(ref, model, inputs, n=200):
    """Largest difference between the numpy loop's predictions and the fitted model's at the first ``n`` texels'
    own observations, relative to the largest value (the two fits span the same space: ~1e-12 when equal)."""
    import jax
    import numpy as np

    n = min(n, len(inputs[0]))
    u, v, b = (a[:n] for a in inputs[:3])
    flat = jax.tree.map(lambda a: np.asarray(a).reshape((-1,) + a.shape[2:])[:n], model)  # unsharded copies
    ours = np.asarray(jax.vmap(lambda m, uu, vv: m(uu, vv))(flat, u, v))  # (n, 3, K)
    c = np.cos(np.deg2rad(80.0)) - 1e-9
    err = 0.0
    for t in range(n):
        keep = (u[t, :, 2] >= c) & (v[t, :, 2] >= c) & (inputs[3][t] > 0)
        err = max(err, float(np.abs(ref[t][1] - ours[t][:, keep].T).max()))
    return err / float(np.abs(b).max())


def worker(args) -> None:
    import jax

    jax.config.update("jax_enable_x64", True)
    import numpy as np
    from jax.sharding import NamedSharding
    from jax.sharding import PartitionSpec as P


    n_dev = jax.device_count()
    mesh = jax.make_mesh((n_dev,), ("rows",))
    mats = [_phong((0.6, 0.3, 0.2), (0.2, 0.2, 0.2), 8.0), _phong((0.1, 0.4, 0.6), (0.5, 0.5, 0.5), 20.0)]
    rows = []
    for size in args.sizes:
        base = _current_rss_mb()
        t0 = time.perf_counter()
        u, v, b, w = _sharded_observations(mats, size, args.lights, args.chunk_rows, NamedSharding(mesh, P("rows")))
        sim_s = time.perf_counter() - t0
        input_mb = sum(a.nbytes for a in (u, v, b, w)) / 2**20
        before_fit = _current_rss_mb()

        def fit(u, v, b, w):
            from polyjax import fit_polynomial

            m = fit_polynomial(u, v, b, "lafortune", args.degree, weights=w, lane_block=args.lane_block)
            return jax.block_until_ready(m)

        t0 = time.perf_counter()
        m = fit(u, v, b, w)
        compile_s = time.perf_counter() - t0
        times = []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            m = fit(u, v, b, w)
            times.append(time.perf_counter() - t0)
        best = min(times)
        peak = _rss_mb() - base
        row = dict(devices=n_dev, size=size, texels=size * size, seconds=best, first_call_s=compile_s,
                   simulate_s=sim_s, texels_per_s=size * size / best, peak_mb=peak,
                   bytes_per_texel=peak * 2**20 / (size * size), input_bytes_per_texel=input_mb * 2**20 / size**2,
                   fit_peak_bytes_per_texel=max(_rss_mb() - before_fit, 0.0) * 2**20 / size**2,
                   out_devices=len(m.coefficients.sharding.device_set), ok=bool(np.all(np.asarray(m.status) == 0)))
        if n_dev == 1 and args.numpy_texels:
            nt = min(args.numpy_texels, size * size)
            head = _observations(mats, size, args.lights, args.chunk_rows, 0, -(-nt // size))  # the first texels
            numpy_part = [a.reshape((-1,) + a.shape[2:])[:nt] for a in head]
            t0 = time.perf_counter()
            ref = _numpy_fit_texels(*numpy_part, args.degree)
            dt = time.perf_counter() - t0
            row.update(numpy_texels=nt, numpy_texels_per_s=nt / dt, speedup_vs_numpy=(size * size / best) / (nt / dt),
                       numpy_full_s_estimate=size * size / (nt / dt), numpy_same_fit=_same_fit(ref, m, numpy_part))
        rows.append(row)
        del u, v, b, w, m
    print("RESULT " + json.dumps(rows))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", default="64,128,256")
    p.add_argument("--devices", default="1,2,4,8")
    p.add_argument("--lights", type=int, default=32)
    p.add_argument("--degree", type=int, default=3)
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--lane-block", type=int, default=1024)
    p.add_argument("--numpy-texels", type=int, default=2000)
    p.add_argument("--chunk-rows", type=int, default=64, help="texture rows simulated at a time")
    p.add_argument("--timeout", type=int, default=3600, help="seconds per device count")
    p.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = p.parse_args()
    args.sizes = [int(s) for s in str(args.sizes).split(",")]
    if args.worker:
        worker(args)
        return
    root = Path(__file__).resolve().parents[1]
    results = []
    for d in [int(x) for x in args.devices.split(",")]:
        env = dict(os.environ, XLA_FLAGS=f"--xla_force_host_platform_device_count={d}",
                   PYTHONPATH=str(root) + os.pathsep + os.environ.get("PYTHONPATH", ""))
        cmd = [sys.executable, __file__, "--worker", "--sizes", ",".join(map(str, args.sizes)), "--lights",
               str(args.lights), "--degree", str(args.degree), "--repeats", str(args.repeats), "--lane-block",
               str(args.lane_block), "--chunk-rows", str(args.chunk_rows), "--numpy-texels",
               str(args.numpy_texels if d == 1 else 0)]
        proc = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=args.timeout)
        if proc.returncode:
            print(proc.stderr[-3000:], file=sys.stderr)
            raise SystemExit(f"worker with {d} devices failed")
        results += json.loads([ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")][-1][7:])
    one = {r["size"]: r for r in results if r["devices"] == 1}
    print(f"SVBRDF per-texel fits: Lafortune, degree {args.degree}, {args.lights} lights, 3 channels per texel")
    print(f"{'devices':>7} {'texels':>9} {'fit s':>8} {'texels/s':>10} {'vs 1 dev':>8} {'peak MB':>8} "
          f"{'B/texel':>8} {'input B/t':>9} {'fit B/t':>8} {'numpy texels/s':>14} {'vs numpy':>8}")
    for r in results:
        base = one.get(r["size"])
        rel = r["texels_per_s"] / base["texels_per_s"] if base else float("nan")
        nps = base.get("numpy_texels_per_s", float("nan")) if base else float("nan")
        print(f"{r['devices']:>7} {r['texels']:>9} {r['seconds']:>8.3f} {r['texels_per_s']:>10.0f} {rel:>8.2f} "
              f"{r['peak_mb']:>8.0f} {r['bytes_per_texel']:>8.0f} {r['input_bytes_per_texel']:>9.0f} "
              f"{r['fit_peak_bytes_per_texel']:>8.0f} {nps:>14.0f} {r['texels_per_s'] / nps:>8.1f}")
    for r in results:
        if "numpy_same_fit" in r:
            print(f"{r['texels']} texels: numpy loop on the first {r['numpy_texels']} texels, all {r['texels']} "
                  f"would take {r['numpy_full_s_estimate']:.0f} s; its predictions differ from the fit's by "
                  f"{r['numpy_same_fit']:.1e} (relative to the largest value)")
    print("load average: " + " ".join(f"{x:.2f}" for x in os.getloadavg()))
    print(json.dumps(results))


if __name__ == "__main__":
    main()
