"""Test configuration: float64 once per process, XLA's compile effort, the compilation cache (off unless asked for),
and the data root.

The tests compile with little optimisation (JAX's ``jax_disable_most_optimizations``, through
``JAX_DISABLE_MOST_OPTIMIZATIONS=1``, and XLA's ``--xla_cpu_use_fusion_emitters=false`` in ``XLA_FLAGS``, when the
installed XLA knows it; subprocesses inherit both): compiling, not running, is most of the suite's time.
``POLYJAX_TEST_XLA_OPT=full`` runs the tests on fully optimised programs, as users get them.

JAX's persistent compilation cache is off in the tests by default: each process compiles its own programs. With it on
(one folder per run shared by the pytest-xdist workers and their subprocesses) a CI run crashed in JAX's cache write
(a segmentation fault in ``put_executable_and_time``, serialising an executable) and then stalled until its time
limit, while measured gains were small (one file: 61 s against 85 s once, 48 s against 43 s the next time).
``POLYJAX_TEST_CACHE=run`` turns the shared per-run folder back on (``jax-cache`` under pytest's base temporary
folder; subprocesses inherit it through ``$POLYJAX_CACHE`` and JAX's ``JAX_*`` variables), ``POLYJAX_TEST_CACHE=DIR``
keeps the programs in ``DIR`` from one run to the next. The user's own cache folder is never written; tests of the
cache itself pass their own folders, and the run's setting is put back after them. With the cache off, JAX's own
switch (``jax_enable_compilation_cache``) is off too, in this process and its subprocesses: otherwise JAX computes a
cache key for every compile with no cache to look in.

After each test its cyclic garbage is collected and the surviving objects are frozen (:func:`gc.freeze`), so that
Python's garbage collector stops scanning the long-lived objects JAX keeps (see ``pytest_runtest_teardown``); a worker
whose compiled programs hold a third of the kernel's limit on memory maps empties JAX's caches first (a worker at the
limit crashed in XLA's compiler: ``_clear_when_maps_run_high``).

In CI (``CI`` set) a missing data root is a failure, not a skip.
"""

import gc
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

# the tests' own numpy and scipy calls (reference fits) with one BLAS thread, as polyjax's calls have by themselves
# (polyjax/_solve/threads): the two pytest-xdist workers share two cores, where OpenBLAS's busy-waiting threads starve
# each other; set before numpy loads its OpenBLAS, inherited by the workers and subprocesses (tests/test_threads.py
# starts its processes without it)
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
#: "full" compiles the tests' programs with XLA's full optimisation, as users get them
_OPT_ENV = "POLYJAX_TEST_XLA_OPT"
#: XLA's CPU code generation by its elemental emitters instead of its fusion emitters: a third of the compile time
_FAST_XLA_FLAG = "--xla_cpu_use_fusion_emitters=false"
_FAST_COMPILE = os.environ.get(_OPT_ENV, "").strip().lower() != "full"
if _FAST_COMPILE:
    # compilation dominates the suite's time and the tests' programs run for milliseconds: JAX's
    # ``jax_disable_most_optimizations`` (LLVM optimisation level 0, no expensive LLVM passes) and XLA's older
    # elemental code generation together cut the CPU time of compiling a nonlinear fit from about 7 s to 2.5 s; the
    # same HLO and the same IEEE arithmetic (no fast-math), so the same numbers to rounding. Set before JAX starts
    # its CPU backend, and inherited by xdist workers and subprocesses.
    os.environ["JAX_DISABLE_MOST_OPTIMIZATIONS"] = "1"
    flags = os.environ.get("XLA_FLAGS", "")
    if "PYTEST_XDIST_WORKER" not in os.environ and "xla_cpu_use_fusion_emitters" not in flags:
        # an XLA that no longer knows the flag aborts at start: try it in a fresh process first (about a second)
        import subprocess

        trial = subprocess.run([sys.executable, "-c", "import jax; jax.devices()"], capture_output=True, timeout=300,
                               env=dict(os.environ, XLA_FLAGS=f"{flags} {_FAST_XLA_FLAG}".strip()))
        if trial.returncode == 0:
            os.environ["XLA_FLAGS"] = f"{flags} {_FAST_XLA_FLAG}".strip()

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
if _FAST_COMPILE:  # in case a plugin imported JAX before this file (the variable is read when JAX is imported)
    jax.config.update("jax_disable_most_optimizations", True)
#: the variable naming this run's cache folder, set by the controlling process and inherited by xdist workers
_RUN_CACHE_ENV = "POLYJAX_TEST_RUN_CACHE"
#: "run" (one folder per test run) or a folder a developer names to keep compiled programs between runs (README)
_KEEP_CACHE_ENV = "POLYJAX_TEST_CACHE"
# until pytest_configure names this run's folder: never the user's (the command line turns the cache on by default)
os.environ["POLYJAX_CACHE"] = os.environ.get(_RUN_CACHE_ENV, "off")

# the repository root, for the reference fits and the paper's numbers shared with the benchmarks
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import pytest  # noqa: E402
from _tiers import SLOW_TESTS  # noqa: E402

from polyjax import DATA_ENV, has_data_root  # noqa: E402


@pytest.hookimpl(trylast=True)  # after pytest's tmp_path plugin is configured
def pytest_configure(config):
    """Point JAX's persistent compilation cache at this run's folder, in this process and its subprocesses."""
    from polyjax import enable_compilation_cache

    folder = os.environ.get(_RUN_CACHE_ENV)  # a worker: the folder its controller chose
    if "PYTEST_XDIST_WORKER" not in os.environ:  # the controller or a single process
        keep = os.environ.get(_KEEP_CACHE_ENV, "").strip()
        if keep.lower() in ("", "off", "0", "no", "false", "none"):  # the default: each process compiles its own
            os.environ["POLYJAX_CACHE"] = "off"
            os.environ["JAX_ENABLE_COMPILATION_CACHE"] = "false"  # subprocesses (the command line turns it on)
            os.environ.pop(_RUN_CACHE_ENV, None)
            _cache_off()
            return
        folder = str(config._tmp_path_factory.getbasetemp() / "jax-cache") if keep.lower() == "run" else keep
    elif folder is None:  # a worker of a controller that turned the cache off
        _cache_off()
        return
    os.environ.update({
        _RUN_CACHE_ENV: folder,
        "POLYJAX_CACHE": folder,  # the command line, in-process or in a subprocess
        "JAX_COMPILATION_CACHE_DIR": folder,  # plain ``python -c`` subprocesses (8 devices, 2 processes)
        "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS": "0",
        "JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES": "-1",
    })
    enable_compilation_cache(folder)


def _cache_off() -> None:
    """No persistent cache in this process: JAX's own switch off too, or every compile still computes a cache key
    (serialising and hashing the program, up to a quarter of a large program's compile call) for no cache."""
    jax.config.update("jax_compilation_cache_dir", None)
    jax.config.update("jax_enable_compilation_cache", False)
    try:  # forget a cache checked or opened before (tests of the cache); private API, the settings above suffice
        from jax._src import compilation_cache

        compilation_cache.reset_cache()
    except (ImportError, AttributeError):  # pragma: no cover
        pass


@pytest.fixture(autouse=True)
def _run_compilation_cache():
    """Put this run's cache setting back after a test that changed it (tests of the cache): the run's folder, or no
    cache at all."""
    yield
    folder = os.environ.get(_RUN_CACHE_ENV)
    if folder is None:
        if jax.config.jax_enable_compilation_cache or jax.config.jax_compilation_cache_dir is not None:
            _cache_off()
    elif jax.config.jax_compilation_cache_dir != folder:
        from polyjax import enable_compilation_cache

        enable_compilation_cache(folder)


@pytest.hookimpl(trylast=True)  # after the test's fixtures are torn down
def pytest_runtest_teardown(item, nextitem):
    """Collect the test's cyclic garbage, then freeze every surviving object (:func:`gc.freeze`).

    The suite keeps millions of long-lived Python objects (JAX's traces, jaxprs and compiled programs, cached for
    later tests), and Python's full collections scan them all again and again: measured 6-10% of a worker's time,
    plus ~9 s at the end of each worker (pytest collects five times at exit); with the freeze, about 1%. Frozen
    objects are never scanned; each test's own garbage is still collected here. What was frozen and later becomes
    unreachable in a reference cycle is not freed: a worker's peak memory was 6.1-7.0 GB in six full runs, 6.1 GB
    in two without the freeze.

    Every :data:`_MAPS_EVERY` tests the process's memory maps are counted (:func:`_clear_when_maps_run_high`)."""
    gc.collect()
    _clear_when_maps_run_high()
    gc.freeze()


#: how often (in tests) a worker counts its memory maps
_MAPS_EVERY = 8
#: the share of the kernel's limit on a process's memory maps (``vm.max_map_count``) at which JAX's caches are cleared
_MAPS_SHARE = 1 / 3
_tests_since_count = 0


def _map_count() -> int | None:
    """The memory maps this process holds (lines of ``/proc/self/maps``; None where there is no such file)."""
    try:
        with open("/proc/self/maps", "rb") as f:
            return f.read().count(b"\n")
    except OSError:
        return None


def _max_map_count() -> int:
    try:
        return int(Path("/proc/sys/vm/max_map_count").read_text())
    except (OSError, ValueError):
        return 65530  # Linux's default


def _clear_when_maps_run_high() -> None:
    """Each compiled CPU program holds a few memory maps of its own (its code and constants: about 3 for a small
    program) until it is dropped, and a worker keeps every program it compiled in JAX's caches. A slow-tier worker
    reached Linux's limit (``vm.max_map_count``, 65,530 maps) after about 8 minutes and 20,000 compilations, and
    the next compile died in XLA's ``backend_compile_and_load`` with a segmentation fault (counted while the tier
    ran: 63,950 maps 20 s before the crash). So when this worker holds more than :data:`_MAPS_SHARE` of the limit,
    JAX's caches are emptied (:func:`jax.clear_caches`) and the frozen objects unfrozen and collected, so that the
    programs are freed; later tests compile what they need again."""
    global _tests_since_count
    _tests_since_count += 1
    if _tests_since_count < _MAPS_EVERY:
        return
    _tests_since_count = 0
    count = _map_count()
    if count is not None and count > _MAPS_SHARE * _max_map_count():
        jax.clear_caches()
        gc.unfreeze()
        gc.collect()


#: CPU seconds (user + system, subprocesses included) of each test file alone in one process on 2 cores, measured in
#: one sequence on a shared machine (load average 3-6): xdist hands whole files to its workers in this order, longest
#: first (``--no-loadscope-reorder``), so that no long file starts near the end while the other worker runs out of
#: files. A worker shares compiled programs between its files, so a run needs less than the sum.
FILE_SECONDS = {"test_sampling.py": 64, "test_grad_fit.py": 60, "test_export.py": 53, "test_baselines.py": 48,
    "test_fit_images_baselines.py": 46, "test_svbrdf.py": 42, "test_render_mis.py": 39, "test_fit_images.py": 38,
    "test_reproduce.py": 37, "test_grad_baselines.py": 33, "test_robust_optimizer.py": 32, "test_scale.py": 31,
    "test_latency.py": 29, "test_fit.py": 29, "test_grad_render.py": 28, "test_published.py": 24, "test_logfit.py": 22,
    "test_user_defects.py": 22, "test_render.py": 21, "test_stream_geometry.py": 21, "test_tabulate.py": 19,
    "test_robust_data.py": 18, "test_robust_geometry.py": 18, "test_lstsq.py": 18, "test_robust_degree.py": 16,
    "test_saved_models.py": 16, "test_robust_edge_inputs.py": 15, "test_data_nbrdf.py": 13, "test_nbrdf_sets.py": 11,
    "test_robust_properties.py": 11, "test_mitsuba.py": 10, "test_robust_rank.py": 9, "test_render_cli.py": 9,
    "test_cli_usability.py": 9, "test_data_merl.py": 8, "test_robust_symmetry.py": 7, "test_cli.py": 7,
    "test_fit_images_cli.py": 6, "test_inputs.py": 6, "test_render_image.py": 6, "test_data_cornell.py": 5,
    "test_architecture.py": 3}
FILE_SECONDS["test_data_rgl.py"] = 38
#: files added since, from their slowest tests in one full run (2-core machine, 2026-12-01): estimates of the same kind
FILE_SECONDS.update({"test_export_materialx_usd.py": 50, "test_standard_models.py": 45, "test_user_defects_2.py": 45,
                     "test_standard_openpbr_usd.py": 40, "test_view.py": 31, "test_photometric.py": 30,
                     "test_export_standard_cli.py": 25, "test_blender.py": 25, "test_export_standard.py": 20,
                     "test_threads.py": 15, "test_baseline_saved_programs.py": 29})
#: where a file not in the table (not measured yet) starts: as a file of this many seconds
UNMEASURED_SECONDS = 20


def _file_rank(its) -> tuple:
    name = its[0].nodeid.split("::")[0].rsplit("/", 1)[-1]
    return -FILE_SECONDS.get(name, UNMEASURED_SECONDS), -len(its)


@pytest.hookimpl(tryfirst=True)  # before pytest's own ``-m`` selection reads the markers
def pytest_collection_modifyitems(config, items):
    """The slow tier marked (:data:`_tiers.SLOW_TESTS`); the longest files first (:data:`FILE_SECONDS`; xdist hands
    whole files to its workers in this order, ``--no-loadscope-reorder``, so the longest do not start last); without
    a data root, skip the data tests (a failure in CI)."""
    for item in items:
        if f"{item.nodeid.split('::')[0].rsplit('/', 1)[-1]}::{item.name}" in SLOW_TESTS:
            item.add_marker(pytest.mark.slow)
    files: dict[str, list] = {}
    for item in items:
        files.setdefault(item.nodeid.split("::")[0], []).append(item)
    order = sorted(files.values(), key=_file_rank)
    items[:] = [it for its in order for it in its]  # sorted() is stable: the order within a file is kept
    if has_data_root():
        return
    if os.environ.get("CI"):
        raise pytest.UsageError(
            f"CI: the measured data root is missing; set {DATA_ENV} to the folder holding curet/, cornell/, "
            "nbrdf_sztrajman2021/ (the data tests must run in CI, not be skipped)"
        )
    skip = pytest.mark.skip(reason=f"no data root (set {DATA_ENV})")
    for item in items:
        if "data" in item.keywords:
            item.add_marker(skip)


@pytest.fixture(scope="session")
def data_root():
    from polyjax import data_root as _root

    return _root()


@pytest.fixture()
def no_data(monkeypatch):
    """The data root unset: the command line falls back on its synthetic default."""
    monkeypatch.delenv(DATA_ENV, raising=False)


_VALIDATE_JS = """
const path = require("path"), fs = require("fs");
const validator = require(path.join(process.argv[2], "gltf-validator"));
const file = process.argv[3];
validator.validateBytes(new Uint8Array(fs.readFileSync(file)),
                        {uri: path.basename(file), format: file.endsWith(".glb") ? "glb" : "gltf"})
  .then((r) => console.log(JSON.stringify(r.issues)))
  .catch((e) => { console.error(String(e)); process.exit(1); });
"""


@pytest.fixture(scope="session")
def validator(tmp_path_factory):
    """Khronos' glTF validator (npm ``gltf-validator`` in ``$POLYJAX_NODE_MODULES``, else ``.ci/node``): a function
    of a ``.gltf``/``.glb`` path giving the issues report (a dict); missing, a skip (a failure in CI)."""
    modules = Path(os.environ.get("POLYJAX_NODE_MODULES", Path(__file__).resolve().parents[1] / ".ci" / "node"
                                  / "node_modules"))
    if shutil.which("node") is None or not (modules / "gltf-validator").is_dir():
        message = f"node or the npm package gltf-validator in {modules} (POLYJAX_NODE_MODULES) is missing"
        (pytest.fail if os.environ.get("CI") else pytest.skip)(message)
    script = tmp_path_factory.mktemp("node") / "validate.js"
    script.write_text(_VALIDATE_JS)

    def run(path):
        out = subprocess.run(["node", str(script), str(modules), str(path)], capture_output=True, text=True,
                             timeout=120)
        assert out.returncode == 0, out.stderr
        return json.loads(out.stdout)

    return run
