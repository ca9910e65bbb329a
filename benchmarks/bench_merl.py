"""Load + fit time per MERL material (3 channels, lafortune variables, p = 5) on all valid bins.

Two sources per material: a MERL ``.binary`` file of the real layout (written once from the neural fit
into a temporary folder) and the neural-BRDF networks evaluated on the MERL grid. The physical floor
is the time to stream the same 34,992,012 bytes from memory (a ``numpy`` copy of an in-memory buffer),
measured in the same run. Target: load + fit (``.binary``) at most 15x that floor. The fit of concrete data is
streamed (``polyjax/_fit/stream.py``: the design is built in row blocks and never held; what depends on the MERL grid
alone, the PCA and CholeskyQR2 of the weighted design, is computed once per process, so a later material costs one
pass over its values, two when the refining pass is needed).

The first material in a process also pays for everything a process does once per grid: the grid's directions and
weights (``merl_grid``), their device copies, and the fit's geometry. It is timed by forgetting all of that before
each timed call (every per-process memo: the grid caches of ``polyjax/data/_merl.py`` and its reused read buffer,
the remembered unit directions and geometry of ``polyjax/_cache/memo.py``); compiled
programs stay compiled (compilation is ``bench_latency.py``'s subject). The loader makes the grid in a thread while
the file is read and gathered, its directions in two threads (the machine's two cores). Two first materials: cold,
with no geometry kept on disk (it is computed, then written), and warm, with the geometry an earlier process kept
beside the compilation cache (``polyjax/_cache/geometry.py``: read and checked; its per-sample rows are made inside
the fit's program, which then checks the samples used and their total weight against the kept ones before its fit
is used). This run's compilation cache, and so that geometry, is in a temporary folder. The dense fit (the path a
traced, differentiable call takes; here the same call under ``jax.jit``) is timed beside them too, and the two L2
must agree to 1e-10 (relative).

Usage: ``POLYJAX_DATA=<data root> python benchmarks/bench_merl.py [n_materials]``
"""

import jax

jax.config.update("jax_enable_x64", True)

import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

import polyjax as pj  # noqa: E402
from polyjax._cache.compilation import memo  # noqa: E402
from polyjax.data import _merl  # noqa: E402


def best_of(fn, repeat=5):  # the same count for the floor and every timed step (minima on a shared machine)
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def forget_grid_work():
    """Drop every per-process memo of the MERL grid's work, as in a fresh process (compiled programs stay), and the
    loader's reused read buffer (a fresh process allocates it)."""
    for cached in (_merl.merl_grid, _merl._device_grid, _merl._above_index):
        cached.cache_clear()
    _merl._SCRATCH.clear()
    memo.forget_all()


def grid_work():  # the part of a first material's time that is the grid's directions and weights on the device
    forget_grid_work()
    return _merl._device_grid(pj.data.MERL_RESOLUTION, "float64")


def first_material(path, kept: Path):
    """Load + fit as the first material of a process; ``kept``: the folder of the geometry kept on disk, emptied
    first for a cold start (the geometry is computed, then written), left as it is for a warm one (read)."""
    forget_grid_work()
    return fit(pj.data.load_merl_binary(path))


def cold_first_material(path, kept: Path):
    for f in kept.glob("geometry-*.npz"):
        f.unlink()
    return first_material(path, kept)


def fit(d):
    m = pj.fit_polynomial(d, variables="lafortune", degree=5)
    m.coefficients.block_until_ready()
    return m


@jax.jit
def _dense(d):  # traced inputs: the dense (differentiable) path
    return pj.fit_polynomial(d, variables="lafortune", degree=5)


def fit_dense(d):
    m = _dense(d)
    m.coefficients.block_until_ready()
    return m


def main(n_materials: int = 6):
    names = pj.data.TABLE3_MATERIALS[:n_materials]
    with tempfile.TemporaryDirectory() as tmp:
        # the compilation cache (and so the geometry kept beside it) in a folder of this run
        kept = pj.enable_compilation_cache(Path(tmp) / "cache") / "polyjax-geometry"
        files = {}
        _, _, _, above = pj.data.merl_grid()
        for name in names:
            d = pj.data.load_merl_nbrdf(name)
            full = np.full((3, pj.data.MERL_N_BINS), -1.0)
            full[:, above] = np.asarray(d.values)
            files[name] = pj.data.write_merl_binary(Path(tmp) / f"{name}.binary", full)
        # warm-up: compile the fit kernel and the network once for this shape
        fit(pj.data.load_merl_binary(files[names[0]]))
        fit(pj.data.load_merl_nbrdf(names[0]))
        fit_dense(pj.data.load_merl_binary(files[names[0]]))

        blob = files[names[0]].read_bytes()
        floor = best_of(lambda: np.frombuffer(blob, np.uint8).copy())
        t_grid = best_of(grid_work)
        rows = []
        for name in names:
            t_bin_load = best_of(lambda name=name: pj.data.load_merl_binary(files[name]).values.block_until_ready())
            t_nb_load = best_of(lambda name=name: pj.data.load_merl_nbrdf(name).values.block_until_ready(), 2)
            d = pj.data.load_merl_binary(files[name])
            t_fit = best_of(lambda d=d: fit(d))
            # load + fit of the first material of a process, grid work included: no kept geometry, then kept
            t_first = best_of(lambda name=name: cold_first_material(files[name], kept))
            t_warm = best_of(lambda name=name: first_material(files[name], kept))
            t_dense = best_of(lambda d=d: fit_dense(d), 2)
            l2 = np.asarray(fit(d).l2)
            l2_dense = np.asarray(fit_dense(d).l2)
            rel = float(np.max(np.abs(l2 - l2_dense) / l2_dense))
            rows.append((name, d.n_samples, t_bin_load, t_nb_load, t_fit, l2, t_dense, rel, t_first, t_warm))
    print(f"stream {len(blob):,} bytes from memory (floor): {floor * 1e3:.1f} ms")
    print(f"{'material':22s} {'n':>9s} {'binary load':>12s} {'nbrdf load':>11s} {'fit p=5':>9s} "
          f"{'bin load+fit':>13s} {'/floor':>7s} {'first cold':>11s} {'first warm':>11s} {'dense fit':>10s} "
          f"{'L2 rel diff':>12s}  L2 (R, G, B)")
    for name, n, tb, tn, tf, l2, td, rel, t1, tw in rows:
        tot = tb + tf
        print(f"{name:22s} {n:9d} {tb * 1e3:10.0f}ms {tn * 1e3:9.0f}ms {tf * 1e3:7.0f}ms {tot * 1e3:11.0f}ms "
              f"{tot / floor:7.1f} {t1 / floor:10.1f}x {tw / floor:10.1f}x {td * 1e3:8.0f}ms {rel:12.1e}  "
              f"{np.array2string(l2, precision=4)}")
    ratio = np.mean([(r[2] + r[4]) / floor for r in rows])
    worst = max(r[7] for r in rows)
    print(f"mean load+fit / floor: {ratio:.1f}x (target <= 15x): {'met' if ratio <= 15 else 'NOT met'}; "
          f"streamed fit {np.mean([r[6] / r[4] for r in rows]):.1f}x faster than the dense fit; "
          f"L2 equal to the dense fit to {worst:.1e} (target 1e-10): {'met' if worst <= 1e-10 else 'NOT met'}")
    cold = np.mean([r[8] / floor for r in rows])
    warm = np.mean([r[9] / floor for r in rows])
    print(f"the first material in a process (load + fit with the grid's directions, weights and geometry made again, "
          f"as in a fresh process; compiled programs kept): cold (no geometry kept on disk) {cold:.1f}x the floor "
          f"({np.mean([r[8] for r in rows]) * 1e3:.0f} ms), warm (the geometry kept beside the compilation cache by "
          f"an earlier process) {warm:.1f}x ({np.mean([r[9] for r in rows]) * 1e3:.0f} ms); the grid's directions "
          f"and weights on the device take {t_grid * 1e3:.0f} ms = {t_grid / floor:.1f}x the floor of either")

if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 6)
