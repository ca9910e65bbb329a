"""Latency a user feels: the first nonlinear fit in a fresh process, timed from outside.

For each of the 7 nonlinear models of the paper, on one CUReT material (sample 25) from 16 starts, fresh Python
processes, one after the other, in one run:

- ``plain``: the alternative without JAX: the model in plain numpy (``benchmarks/plain_models.py``) fitted by
  ``scipy.optimize.least_squares(method="lm")`` (finite-difference Jacobian) from the same 16 starts (computed by
  this parent process and passed in a file with the data); the reference of the ratios;
- ``polyjax cold``: ``baselines.fit`` after ``pj.enable_compilation_cache`` on an empty folder, split into import,
  the first call (trace + compile + write the saved program, ``baselines/_aot.py``, + fit) and a second call (the
  fit alone); ``compile`` is first minus second;
- ``polyjax warm``: the same with the folder the cold process filled (the saved program loaded: no tracing);
- ``jax-cache warm``: the same with ``POLYJAX_SAVED_PROGRAMS=off`` (JAX's compilation cache alone, which still
  traces and lowers every program: the warm run before saved programs; ``--no-jax-cache-row`` skips it);
- ``staged cold``: the previous kernel (one traced Levenberg-Marquardt loop per stage: screening, refinement and
  two range-limit rounds), kept for the jaxopt backend and run here with optimistix, cold cache, no saved program:
  the "before" of the one-loop kernel (``--no-staged`` skips it);
- ``scipy``: ``scipy.optimize.least_squares(method="lm")`` from the same starts on the same residuals evaluated by
  jitted JAX functions (the baselines' model, as in ``bench_baselines.py``; process, JAX import and the residuals'
  compilation included): the second comparison.

The whole-process row (``--whole-process``, ``--whole-process-only``): the difference of the medians of two kinds of
fresh process, alternated, after one process has warmed the cache: ``import polyjax, baselines`` alone (x64 on, the
cache enabled) and the same plus the data and a warm first fit, each timed from outside (start, imports, work,
interpreter exit): what a warm first fit costs a script as a whole. Target: within 0.5 s. The row also times the
command a user runs, ``polyjax --cache-dir <the folder> fit --model <name> --json`` (warmed by one run of its own: its
fit keeps the command's default starts), against the same imports: the command reads the data, fits, scores the
zero model, prints and ends its process without the interpreter's teardown (``polyjax/_run/ending.py``).

``after import`` is the time in the process after ``import polyjax`` (the import of baselines, the data and the
first fit). Targets: a warm first fit within 0.5 s of ``import polyjax``, cold at most 8x the plain process;
and, against the JAX-based scipy process, warm <= 2x and cold <= 4x. Ratios are whole-process times.

    POLYJAX_DATA=... python benchmarks/bench_latency.py [--models cook-torrance,ward] [--no-staged]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TARGET_WARM, TARGET_COLD = 2.0, 4.0  # against the JAX-based scipy process
TARGET_AFTER_IMPORT, TARGET_COLD_PLAIN = 0.5, 8.0  # warm: seconds after import polyjax; cold: x the plain process

_CHILD = r"""
import json, sys, time
t0 = time.perf_counter()
import jax
jax.config.update("jax_enable_x64", True)
import numpy as np
import polyjax as pj
t_polyjax = time.perf_counter() - t0
cache = sys.argv[3]
if cache != "-":
    pj.enable_compilation_cache(cache)
import baselines as bl
name, mode = sys.argv[1], sys.argv[2]
data = pj.data.load_curet(samples=[25])
t_import = time.perf_counter() - t0
if mode == "scipy":
    from scipy.optimize import least_squares
    u, v = jax.numpy.asarray(data.u), jax.numpy.asarray(data.v)
    starts = np.load(sys.argv[4])["starts"]  # the 16 starts baselines.fit uses, computed by the parent process
    w, wc2 = pj.internal.fit_weights(u, v, data.weights, None, 80.0)
    sw2 = wc2 / jax.numpy.sum(w)
    y = jax.numpy.asarray(data.values)
    fn = jax.jit(lambda r, yb: bl.residuals(name, r, u, v, yb, sw2))
    jac = jax.jit(jax.jacfwd(lambda r, yb: bl.residuals(name, r, u, v, yb, sw2)))
    t1 = time.perf_counter()
    best = []
    for b in range(y.shape[0]):
        l2 = np.inf
        for s in starts[b]:
            try:
                sol = least_squares(lambda r: np.asarray(fn(r, y[b])), s, jac=lambda r: np.asarray(jac(r, y[b])),
                                    method="lm")
                l2 = min(l2, float(np.sqrt(2 * sol.cost)))
            except Exception:
                pass
        best.append(l2)
    t2 = time.perf_counter()
    again = None
else:
    if mode == "staged":  # the previous kernel: one traced solver loop per stage
        import baselines._fit as F
        from baselines._jaxopt.staged import staged_kernel
        F.fit_kernel = lambda *a, **k: staged_kernel(*a, backend="optimistix", **k)
    t1 = time.perf_counter()
    f = bl.fit(name, data, n_starts=16)
    jax.block_until_ready(f.l2)
    t2 = time.perf_counter()
    f = bl.fit(name, data, n_starts=16)
    jax.block_until_ready(f.l2)
    again = time.perf_counter() - t2
    best = np.asarray(f.l2).tolist()
print(json.dumps(dict(polyjax_s=t_polyjax, import_s=t_import, first_s=t2 - t1, again_s=again,
                      after_s=t2 - t0 - t_polyjax, l2=best)))
"""

#: the whole-process row's child: the imports alone (``none``), or the imports, the data and one warm fit (``fit``)
_WHOLE = r"""
import sys, time
t0 = time.perf_counter()
import jax
jax.config.update("jax_enable_x64", True)
import polyjax as pj
pj.enable_compilation_cache(sys.argv[3])
import baselines as bl
t1 = time.perf_counter()
if sys.argv[2] == "fit":
    f = bl.fit(sys.argv[1], pj.data.load_curet(samples=[25]), n_starts=16)
    jax.block_until_ready(f.l2)
print(time.perf_counter() - t1)
"""
TARGET_WHOLE = 0.5  # seconds: a warm first fit's whole process against import polyjax, baselines


def whole_process_row(name: str, repeats: int = 5) -> dict:
    """The whole-process row of ``name`` (module docs): medians of ``repeats`` alternated processes of each kind."""
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    env.pop("POLYJAX_CACHE", None)
    times = {"none": [], "fit": [], "cli": []}
    inside = []
    with tempfile.TemporaryDirectory() as cache:
        def one(mode):
            cmd = ([sys.executable, "-m", "polyjax", "--cache-dir", cache, "fit", "--model", name, "--json"]
                   if mode == "cli" else [sys.executable, "-c", _WHOLE, name, mode, cache])
            t0 = time.perf_counter()
            out = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=ROOT, check=True)
            wall = time.perf_counter() - t0
            if mode == "cli":
                json.loads(out.stdout)  # the command's whole output, flushed before its process ended
                return wall, None
            return wall, float(out.stdout.strip().splitlines()[-1])
        one("fit")  # cold: fills the cache
        one("cli")  # the command's own program (its default starts), cold
        for _ in range(repeats):
            for mode in ("none", "fit", "cli"):
                wall, work = one(mode)
                times[mode].append(wall)
                if mode == "fit":
                    inside.append(work)
    med = {k: sorted(v)[len(v) // 2] for k, v in times.items()}
    row = dict(import_s=med["none"], fit_s=med["fit"], difference_s=med["fit"] - med["none"],
               inside_s=sorted(inside)[len(inside) // 2], cli_s=med["cli"], cli_difference_s=med["cli"] - med["none"])
    print(f"{name:18s} whole process (median of {repeats}): import polyjax, baselines {row['import_s']:.2f} s; "
          f"+ data and warm first fit {row['fit_s']:.2f} s; difference {row['difference_s']:.2f} s (inside the "
          f"process {row['inside_s']:.2f} s)   [target <= {TARGET_WHOLE} s: "
          f"{'MET' if row['difference_s'] <= TARGET_WHOLE else 'MISSED'}]; `polyjax fit --model {name}` "
          f"{row['cli_s']:.2f} s, difference {row['cli_difference_s']:.2f} s", flush=True)
    return row


#: the plain process: numpy and scipy only (no JAX), the data and starts from the parent's file
_PLAIN = r"""
import json, sys, time
t0 = time.perf_counter()
import numpy as np
import scipy.optimize
sys.path.insert(0, sys.argv[3])
from benchmarks import plain_models
d = np.load(sys.argv[4])
t_import = time.perf_counter() - t0
l2 = [plain_models.fit_best_l2(sys.argv[1], d["u"], d["v"], y, d["weights"], s)
      for y, s in zip(d["values"], d["starts"])]
assert "jax" not in sys.modules
print(json.dumps(dict(polyjax_s=None, import_s=t_import, first_s=time.perf_counter() - t0 - t_import, again_s=None,
                      after_s=None, l2=l2)))
"""


def run(name, mode, cache, inputs="-", env_extra=None):
    """One fresh process of ``mode``; its record with ``wall_s``, the whole process timed from outside."""
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""), **(env_extra or {}))
    env.pop("POLYJAX_CACHE", None)
    code, third = (_PLAIN, str(ROOT)) if mode == "plain" else (_CHILD, cache)
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", code, name, mode, third, inputs], capture_output=True, text=True,
                         env=env, cwd=ROOT, check=False)
    wall = time.perf_counter() - t0
    if out.returncode != 0:
        raise RuntimeError(f"{name} {mode}: {out.stderr[-2000:]}")
    rec = json.loads(out.stdout.strip().splitlines()[-1])
    rec["wall_s"] = wall
    return rec


def _inputs(path, bl, pj, jax, np, name):
    """The data (CUReT 25) and the 16 starts ``baselines.fit`` uses, saved for the plain and scipy processes."""
    data = pj.data.load_curet(samples=[25])
    starts = np.asarray(bl.initial_guesses(name, data, n_starts=16, key=jax.random.PRNGKey(0)))
    weights = np.where(np.asarray(data.mask), np.asarray(data.weights), 0.0)
    values = np.asarray(data.values).reshape(-1, data.n_samples)
    np.savez(path, u=np.asarray(data.u), v=np.asarray(data.v), values=values, weights=weights, starts=starts)


def _processes(name, args, bl, pj, jax, np):
    """Every process of one model, one after the other: ``{row: record}``."""
    off = {"POLYJAX_SAVED_PROGRAMS": "off"}
    with tempfile.TemporaryDirectory() as tmp:
        inputs = os.path.join(tmp, "inputs.npz")
        _inputs(inputs, bl, pj, jax, np, name)
        cache, cache_jax, cache_old = (os.path.join(tmp, d) for d in ("cache", "cache-jax", "cache-staged"))
        recs = {"plain": run(name, "plain", "-", inputs), "scipy": run(name, "scipy", "-", inputs),
                "polyjax cold": run(name, "fit", cache), "polyjax warm": run(name, "fit", cache)}
        if not args.no_jax_cache_row:
            run(name, "fit", cache_jax, env_extra=off)  # fills JAX's cache with this path's programs
            recs["jax-cache warm"] = run(name, "fit", cache_jax, env_extra=off)
        if not args.no_staged:
            recs["staged cold"] = run(name, "staged", cache_old, env_extra=off)
    return recs


def main(argv=None):
    sys.path.insert(0, str(ROOT))
    import jax

    jax.config.update("jax_enable_x64", True)
    import numpy as np

    import baselines as bl
    import polyjax as pj
    from baselines import PAPER_MODELS

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", default=",".join(m for m in PAPER_MODELS if m != "zernike"))
    ap.add_argument("--no-staged", action="store_true", help="skip the previous (staged) kernel")
    ap.add_argument("--no-jax-cache-row", action="store_true", help="skip the warm run from JAX's cache alone")
    ap.add_argument("--whole-process", action="store_true", help="also the whole-process row of each model")
    ap.add_argument("--whole-process-only", action="store_true", help="the whole-process row of each model alone")
    ap.add_argument("--repeats", type=int, default=5, help="processes of each kind in the whole-process row")
    args = ap.parse_args(argv)
    if args.whole_process or args.whole_process_only:
        print(f"load average at the start {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
        whole = {name: whole_process_row(name, args.repeats) for name in args.models.split(",")}
        if args.whole_process_only:
            print(f"load average at the end {os.getloadavg()[0]:.2f}")
            return whole
    print("first baselines.fit in a fresh process, CUReT sample 25, 16 starts; seconds (wall = whole process; "
          "after import = in the process after import polyjax); load average at the start "
          f"{os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    print(f"{'model':18s} {'run':14s} {'wall':>6s} {'import':>6s} {'after import':>12s} {'compile':>7s} "
          f"{'fit ms':>7s} {'L2':>10s} {'x plain':>7s} {'x scipy':>7s}")
    rows = {}
    for name in args.models.split(","):
        recs = _processes(name, args, bl, pj, jax, np)
        for label, r in recs.items():
            print(_row(name, label, r, recs["plain"]["wall_s"], recs["scipy"]["wall_s"]), flush=True)
        rows[name] = recs
    _summary(rows, args)
    print(f"load average at the end {os.getloadavg()[0]:.2f}")
    return rows


def _row(name, label, r, plain, scipy):
    again = r["again_s"]
    comp = "" if again is None else f"{r['first_s'] - again:7.2f}"
    fit_ms = f"{(again if again is not None else r['first_s']) * 1e3:7.1f}"
    after = "" if r["after_s"] is None else f"{r['after_s']:12.2f}"
    return (f"{name:18s} {label:14s} {r['wall_s']:6.2f} {r['import_s']:6.2f} {after:>12s} {comp:>7s} {fit_ms} "
            f"{min(r['l2']):10.6f} {r['wall_s'] / plain:7.2f} {r['wall_s'] / scipy:7.2f}")


def _summary(rows, args):
    after = [r["polyjax warm"]["after_s"] for r in rows.values()]
    print(f"polyjax warm: first fit {min(after):.2f}-{max(after):.2f} s after import polyjax   "
          f"[target <= {TARGET_AFTER_IMPORT} s: {'MET' if max(after) <= TARGET_AFTER_IMPORT else 'MISSED'}]")
    cold = [r["polyjax cold"]["wall_s"] / r["plain"]["wall_s"] for r in rows.values()]
    print(f"polyjax cold: {min(cold):.2f}-{max(cold):.2f}x the plain numpy/scipy process   "
          f"[target <= {TARGET_COLD_PLAIN:.0f}x: {'MET' if max(cold) <= TARGET_COLD_PLAIN else 'MISSED'}]")
    warm = [r["polyjax warm"]["wall_s"] / r["plain"]["wall_s"] for r in rows.values()]
    print(f"polyjax warm: {min(warm):.2f}-{max(warm):.2f}x the plain numpy/scipy process")
    for label, target in (("polyjax warm", TARGET_WARM), ("polyjax cold", TARGET_COLD)):
        worst = max(r[label]["wall_s"] / r["scipy"]["wall_s"] for r in rows.values())
        print(f"{label}: at most {worst:.2f}x the JAX-based scipy process   [target <= {target:.0f}x: "
              f"{'MET' if worst <= target else 'MISSED'}]")
    if not args.no_jax_cache_row:
        gain = [r["jax-cache warm"]["wall_s"] / r["polyjax warm"]["wall_s"] for r in rows.values()]
        print(f"saved programs vs JAX's compilation cache alone, warm process: {min(gain):.2f}-{max(gain):.2f}x "
              "faster")
    if not args.no_staged:
        ratio = [r["staged cold"]["first_s"] / r["polyjax cold"]["first_s"] for r in rows.values()]
        print(f"polyjax cold vs the staged kernel, first call: {min(ratio):.2f}-{max(ratio):.2f}x faster")
    same = max(abs(min(r["polyjax warm"]["l2"]) - min(r["plain"]["l2"])) / min(r["plain"]["l2"])
               for r in rows.values())
    print(f"L2 of polyjax against the plain process: at most {same:.1e} apart (relative)")


if __name__ == "__main__":
    main()
