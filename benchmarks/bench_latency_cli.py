"""Whole-process latency of ``polyjax fit``: cold and warm persistent compilation cache, fresh processes.

Every row is a fresh Python process timed from outside (wall clock, ``subprocess``), as a user meets it:

* ``import polyjax`` alone (the floor under every command);
* ``polyjax fit`` (CUReT sample 25 when ``POLYJAX_DATA`` is set, else the synthetic default; Lafortune, p = 7)
  with an empty cache folder (cold: compiles, writes the compilation cache and the fit's executable,
  ``polyjax/_fit/saved.py``), then again with the same folder (warm: loads the executable: no tracing, lowering or
  compiling), with the same folder but ``POLYJAX_SAVED_PROGRAMS=off`` (warm from JAX's compilation cache alone:
  every program traced and lowered, then loaded), and with ``--no-cache``;
* the number of files in the cache folder (recursively) after each run: a warm run that compiled anything would
  add files.

Target: ``polyjax fit`` with a warm cache <= 1.5 s. Usage: ``python benchmarks/bench_latency_cli.py [repeats]``.
"""

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TARGET_WARM = 1.5


def run(args, env):
    t = time.perf_counter()
    proc = subprocess.run([sys.executable, *args], cwd=ROOT, env=env, capture_output=True, text=True)
    elapsed = time.perf_counter() - t
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(args)} failed ({proc.returncode}): {proc.stderr[-2000:]}")
    return elapsed, proc


def bench_cli(repeats: int = 3) -> dict:
    """Times (s) of the ``polyjax fit`` rows; the best of ``repeats`` for the warm and import rows."""
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    env.pop("POLYJAX_CACHE", None)
    env.pop("POLYJAX_SAVED_PROGRAMS", None)
    fit = ["-m", "polyjax", "fit", "--sample", "25", "--variables", "lafortune", "--degree", "7"]
    with tempfile.TemporaryDirectory() as tmp:
        cache = Path(tmp) / "cache"
        imp = min(run(["-c", "import polyjax"], env)[0] for _ in range(repeats))
        cold, proc = run(fit + ["--cache-dir", str(cache)], env)
        files_cold = count_files(cache)
        warm_runs = [run(fit + ["--cache-dir", str(cache)], env)[0] for _ in range(repeats)]
        files_warm = count_files(cache)
        jax_only = dict(env, POLYJAX_SAVED_PROGRAMS="off")
        run(fit + ["--cache-dir", str(cache)], jax_only)  # compiles the separate programs of this path once
        jax_cache_runs = [run(fit + ["--cache-dir", str(cache)], jax_only)[0] for _ in range(repeats)]
        no_cache = run(fit + ["--no-cache"], env)[0]
    return {"import": imp, "cold": cold, "warm": min(warm_runs), "warm_runs": warm_runs, "no_cache": no_cache,
            "jax_cache": min(jax_cache_runs), "jax_cache_runs": jax_cache_runs,
            "files_cold": files_cold, "files_warm": files_warm, "notice": "compiling" in proc.stderr}


def count_files(folder: Path) -> int:
    return sum(1 for p in folder.rglob("*") if p.is_file())


def main(repeats: int = 3) -> None:
    r = bench_cli(repeats)
    data = "CUReT sample 25" if os.environ.get("POLYJAX_DATA") else "synthetic default (POLYJAX_DATA not set)"
    print(f"polyjax fit, Lafortune p = 7, {data}; fresh processes, wall clock from outside")
    print(f"  import polyjax                  {r['import']:6.2f} s  (best of {repeats})")
    print(f"  polyjax fit, --no-cache         {r['no_cache']:6.2f} s")
    print(f"  polyjax fit, cold cache         {r['cold']:6.2f} s  ({r['files_cold']} programs written; compile "
          f"notice on stderr: {'yes' if r['notice'] else 'no'})")
    print(f"  polyjax fit, warm cache         {r['warm']:6.2f} s  (best of {repeats}: "
          + ", ".join(f"{t:.2f}" for t in r["warm_runs"]) + f"; cache files {r['files_cold']} -> {r['files_warm']})")
    print(f"  ... JAX cache alone       {r['jax_cache']:6.2f} s  (POLYJAX_SAVED_PROGRAMS=off, best of {repeats}: "
          + ", ".join(f"{t:.2f}" for t in r["jax_cache_runs"]) + ")")
    print(f"  warm / cold {r['warm'] / r['cold']:.2f}, warm / no-cache {r['warm'] / r['no_cache']:.2f}, "
          f"warm / warm with the JAX cache only {r['warm'] / r['jax_cache']:.2f}, "
          f"warm - import {r['warm'] - r['import']:.2f} s")
    met = r["warm"] <= TARGET_WARM
    print(f"target: polyjax fit warm <= {TARGET_WARM} s: {'met' if met else 'NOT met'}; every warm program from the "
          f"cache: {'yes' if r['files_warm'] == r['files_cold'] else 'NO'}")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 3)
