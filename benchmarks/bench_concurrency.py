"""Benchmark: polyjax calls while other polyjax processes (or threads) run at the same time.

Workloads, each repeated for ``--seconds`` after compilation:

- ``curet``: the CUReT batched fit (61 materials x 205 samples, Lafortune p = 8), called eagerly;
- ``baseline``: ``baselines.fit("cook-torrance", curet:25, n_starts=16)``;
- ``merl``: the streamed fit of one MERL material (neural green-latex on the 1.46 M-bin grid, p = 5, 3 channels);
- ``render``: a 256 x 256 sphere of a p = 5 polynomial under a point light (XLA's own threads, no LAPACK);
- ``matmul``: a jitted (768, 768) @ (768, 768) product, 8 times (XLA's own threads, plain JAX).

Groups of 1, 2 and 4 processes run each workload at once (started together, after each has compiled everything),
and one process runs it in 2 Python threads; each group under four settings: ``off`` (polyjax leaves LAPACK's
threads as the environment set them: the code before the limit), ``on`` (the default: jaxlib's LAPACK library set
to one thread at polyjax's first call and kept there), ``restore`` (the first design, kept for comparison: one
thread inside each call, ``with pj.lapack_threads(1)`` around it, the previous count put back after) and ``env``
(``OPENBLAS_NUM_THREADS=1`` set before the process started, the known-good reference).
Reported: the median time per call of each process, its ratio to one process alone under
the same setting, and the group's throughput against one process alone. Target (with N processes on C cores):
each call at most ``1.25 max(1, N / C)`` times the time alone (``on``) for a call that keeps one core busy alone (the
LAPACK work), and ``1.25 max(1, N u / C)`` for one that keeps ``u`` cores busy alone (XLA's own threads: two processes
on two cores then each run at about half speed, not slower; ``u`` is measured, CPU time over wall time alone);
alone, ``on`` at least as fast as ``env``.

Without a data root the CUReT and MERL workloads are replaced by the built-in synthetic data (said in the output).

    python benchmarks/bench_concurrency.py [--seconds 3] [--procs 1,2,4] [--workloads curet,baseline,merl,render,matmul]
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
WORKLOADS = ("curet", "baseline", "merl", "render", "matmul")
SETTINGS = ("off", "on", "restore", "env")


def _workloads(names):
    """name -> a function running one call to completion (compiled on first use)."""
    import jax
    import jax.numpy as jnp

    import baselines
    import polyjax as pj
    import polyjax.render as pr

    data = pj.has_data_root()
    curet = pj.data.load_curet() if data else pj.data.synthetic_default()
    one = pj.data.load("curet:25") if data else curet[0]
    out = {}
    if "curet" in names:
        out["curet"] = lambda: pj.fit_polynomial(curet, variables="lafortune", degree=8).l2
    if "baseline" in names:
        key = jax.random.PRNGKey(0)
        out["baseline"] = lambda: baselines.fit("cook-torrance", one, n_starts=16, key=key).l2
    if "merl" in names:
        merl = pj.data.load("merl-nbrdf:green-latex") if data else pj.data.tabulate(
            pj.fit_polynomial(one, variables="lafortune", degree=5)[0], grid="merl")
        out["merl"] = lambda: pj.fit_polynomial(merl, variables="lafortune", degree=5).l2
    if "render" in names:
        model = pj.fit_polynomial(one, variables="lafortune", degree=5)[0]
        cam = pr.Camera(eye=(0.0, 0.0, 5.0), width=256, height=256, ortho_height=2.1)
        scene = pr.Scene(cam, [pr.Sphere(pr.rgb_brdf(model))], [pr.PointLight(position=(2.0, 2.0, 4.0),
                                                                                intensity=24.0)])
        out["render"] = lambda: pr.render(scene).image
    if "matmul" in names:
        a = jnp.asarray(jax.random.normal(jax.random.PRNGKey(1), (768, 768)))
        prod = jax.jit(lambda a: jax.lax.fori_loop(0, 8, lambda i, x: jnp.tanh(x @ a), a))
        out["matmul"] = lambda: prod(a)
    return out, ("measured (CUReT, neural MERL)" if data else "synthetic (built-in, not measured)")


def _time_calls(fn, seconds, times):
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        t0 = time.perf_counter()
        fn().block_until_ready()
        times.append(time.perf_counter() - t0)


def _restoring(fn):
    """``fn`` inside ``pj.lapack_threads(1)``: one thread for the call, the previous count put back after it."""
    import polyjax as pj

    def call():
        with pj.lapack_threads(1):
            return fn().block_until_ready()
    return call


def worker(names, threads, restore):
    """A worker process: compile every workload, say 'ready', then run each workload when told to."""
    import jax

    jax.config.update("jax_enable_x64", True)
    fns, what = _workloads(names)
    if restore:
        fns = {k: _restoring(f) for k, f in fns.items()}
    for fn in fns.values():
        fn().block_until_ready()
        fn().block_until_ready()
    print(json.dumps({"ready": True, "data": what}), flush=True)
    for line in sys.stdin:
        name, seconds = line.split()
        per_thread = [[] for _ in range(threads)]
        cpu0, wall0 = time.process_time(), time.perf_counter()
        pool = [threading.Thread(target=_time_calls, args=(fns[name], float(seconds), t)) for t in per_thread]
        for t in pool:
            t.start()
        for t in pool:
            t.join()
        cores_used = (time.process_time() - cpu0) / (time.perf_counter() - wall0)
        print(json.dumps({"median": [statistics.median(t) for t in per_thread], "cores": cores_used,
                          "calls": [len(t) for t in per_thread], "seconds": float(seconds)}), flush=True)


def _group(n_procs, threads, setting, names, seconds):
    """Start ``n_procs`` workers, run every workload on all of them at once; {name: [per-worker result]}."""
    env = dict(os.environ, PYTHONPATH=str(ROOT), POLYJAX_LAPACK_THREADS="1" if setting == "on" else "off")
    env.pop("OPENBLAS_NUM_THREADS", None)
    if setting == "env":
        env["OPENBLAS_NUM_THREADS"] = "1"
    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", ",".join(names), "--threads", str(threads)] + (
        ["--restore"] if setting == "restore" else [])
    procs = [subprocess.Popen(cmd, env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
             for _ in range(n_procs)]
    info = [json.loads(p.stdout.readline()) for p in procs]
    out = {}
    for name in names:
        for p in procs:
            p.stdin.write(f"{name} {seconds}\n")
            p.stdin.flush()
        out[name] = [json.loads(p.stdout.readline()) for p in procs]
    for p in procs:
        p.stdin.close()
        p.wait()
    return out, info[0]["data"]


def _row(name, setting, label, results, alone, cores, n):
    medians = [m for r in results for m in r["median"]]
    rate = sum(c / r["seconds"] for r in results for c in r["calls"])
    base = alone[(name, setting)]
    worst = max(medians) / base["median"]
    target = 1.25 * max(1.0, n * max(1.0, base["cores"]) / cores)  # a call that keeps u cores busy alone
    return (f"| {name} | {setting} | {label} | {', '.join(f'{m * 1e3:.2f}' for m in medians)} | {worst:.2f}x "
            f"(target <= {target:.2f}x: {'met' if worst <= target else 'missed'}) | {rate / base['rate']:.2f}x |")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--procs", default="1,2,4")
    ap.add_argument("--workloads", default=",".join(WORKLOADS))
    ap.add_argument("--settings", default=",".join(SETTINGS))
    ap.add_argument("--worker", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--threads", type=int, default=1, help=argparse.SUPPRESS)
    ap.add_argument("--restore", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    names = [w for w in args.workloads.split(",") if w]
    if args.worker is not None:
        return worker(args.worker.split(","), args.threads, args.restore)
    cores = os.cpu_count()
    groups = [(int(n), 1, f"{n} process{'es' if int(n) > 1 else ''}") for n in args.procs.split(",")] + [
        (1, 2, "2 threads, 1 process")]
    settings = args.settings.split(",")
    print(f"{cores} cores; load average before: {os.getloadavg()[0]:.2f}; {args.seconds} s per workload and group")
    rows, alone, data = [], {}, None
    for n, threads, label in groups:
        for setting in settings:
            if setting in ("env", "restore") and n * threads > 2:  # references: alone and in pairs
                continue
            res, data = _group(n, threads, setting, names, args.seconds)
            print(f"{label}, {setting}: " + "; ".join(f"{k} {[round(m * 1e3, 2) for r in v for m in r['median']]} ms"
                                                      for k, v in res.items()), flush=True)
            for name in names:
                if n == 1 and threads == 1:
                    r = res[name][0]
                    alone[(name, setting)] = {"median": r["median"][0], "rate": r["calls"][0] / r["seconds"],
                                              "cores": r["cores"]}
                rows.append((name, setting, label, res[name], n * threads))
    print(f"data: {data}; load average after: {os.getloadavg()[0]:.2f}")
    print("cores busy alone (CPU time / wall time): " + ", ".join(
        f"{k[0]} {k[1]} {v['cores']:.2f}" for k, v in sorted(alone.items())))
    print("| workload | setting | group | ms per call (median, each process or thread) | slowest / alone | "
          "throughput / alone |")
    print("|---|---|---|---|---|---|")
    for name, setting, label, res, n in sorted(rows, key=lambda r: (WORKLOADS.index(r[0]), r[4], r[1])):
        print(_row(name, setting, label, res, alone, cores, n))
    for name in names:
        if ("on" in settings) and ("env" in settings):
            on, env = alone[(name, "on")]["median"], alone[(name, "env")]["median"]
            off = alone.get((name, "off"), {}).get("median", float("nan"))
            print(f"alone, {name}: on {on * 1e3:.2f} ms, env {env * 1e3:.2f} ms (on / env {on / env:.2f}x), "
                  f"off {off * 1e3:.2f} ms (off / on {off / on:.2f}x)")


if __name__ == "__main__":
    main()
