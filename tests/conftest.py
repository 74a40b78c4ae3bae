"""Test configuration: float64 everywhere, persistent compilation cache for local reruns."""

import os
import pathlib
import sys


def _pin_xdist_worker():
    """Give each pytest-xdist worker its own share of the CPUs, before jax starts its thread pools.

    Unpinned, XLA processes side by side on a 2-core machine slow each other down far more than
    twofold (measured: a compile-heavy test took 37 s with two copies pinned to one core each, and
    104 s with the same two copies unpinned). Notebook kernels inherit their worker's share.
    """
    worker = os.environ.get("PYTEST_XDIST_WORKER", "")
    n = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "0") or 0)
    if not worker.startswith("gw") or n < 2 or not hasattr(os, "sched_setaffinity"):
        return
    cpus = sorted(os.sched_getaffinity(0))
    if len(cpus) < n:
        return
    os.sched_setaffinity(0, set(cpus[int(worker[2:]) % n :: n]))


_pin_xdist_worker()


#: XLA flags for quick compiles: (flag, value). The second selects XLA's older CPU emitters for
#: fusions, which compile the suite's programs 2-4x faster (measured on the S0 filter program: 11.5
#: -> 3.3 s) and run them ~1.5x slower; XLA refuses unknown flags, so it is probed first.
FAST_FLAGS = (("--xla_backend_optimization_level", "0"), ("--xla_cpu_use_fusion_emitters", "false"))


def _xla_accepts(flags: str) -> bool:
    """Whether this jaxlib starts with these XLA_FLAGS (it aborts on a flag it does not know)."""
    import subprocess

    env = dict(os.environ, XLA_FLAGS=flags, JAX_PLATFORMS="cpu")
    code = "import jax; jax.devices()"
    try:
        return subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, timeout=120).returncode == 0
    except (OSError, subprocess.SubprocessError):
        return False


def _fast_compiles():
    """Compile the tests' programs quickly (:data:`FAST_FLAGS`), before jax starts.

    The suite checks numbers, not speed, and is compile-bound: -O0 cut cold module times by
    10-15 % (measured: test_filters_fast 67 -> 57 s, test_demo + test_sim 98 -> 88 s) with the
    same results (no fast-math at either level). Benchmarks run with XLA's defaults. A flag set
    by the caller wins; xdist workers, notebook kernels and subprocesses inherit the environment
    (so the probe runs once, in the first process).
    """
    flags = os.environ.get("XLA_FLAGS", "")
    for name, value in FAST_FLAGS:
        if name.lstrip("-") in flags:
            continue
        trial = f"{flags} {name}={value}".strip()
        if name == FAST_FLAGS[0][0] or _xla_accepts(trial):
            flags = trial
    os.environ["XLA_FLAGS"] = flags


_fast_compiles()

import jax

import jaxnav

jaxnav.enable_x64()
# The persistent compilation cache is opt-in (JAXNAV_JAX_CACHE=FOLDER, for repeated local runs): under
# `make test` on the 2-core machine, a worker aborted inside jax's cache write (SIGABRT in
# compilation_cache.put_executable_and_time) in two runs, in different tests, taking its module down.
# One folder per xdist worker, since jax writes entries without a lock; subprocesses (notebook kernels,
# doc pages) share their worker's folder.
if os.environ.get("JAXNAV_JAX_CACHE"):
    _cache = pathlib.Path(os.environ["JAXNAV_JAX_CACHE"])
    jax.config.update("jax_compilation_cache_dir", str(_cache / os.environ.get("PYTEST_XDIST_WORKER", "main")))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)

SHARED = pathlib.Path(__file__).resolve().parents[2] / "shared"


import pytest

# `make test` runs `pytest -n 2 --dist loadscope --no-loadscope-reorder`: each module (and each
# notebook's class in test_notebooks.py) goes to one worker whole, so module-scoped fixtures and
# their compilations are built once. Scopes are handed out in collection order, so the long ones
# (measured cold, serial) are put first and the run does not end on one of them.
HEAVY = (
    "test_docs_snippets.py",
    "test_notebooks.py::TestNotebook05",
    "test_tune_s0.py",
    "test_ins_time_offset.py",
    "test_demo.py",
    "test_distributed.py",
    "test_ins_simulated.py",
    "test_integration.py",
    "test_notebooks.py::TestNotebook01",
    "test_notebooks.py::TestNotebook04",
    "test_cadastral.py",
    "test_notebooks.py::TestNotebook02",
    "test_sim.py",
    "test_notebooks.py::TestNotebook03",
    "test_tune.py",
    "test_notebooks.py::TestNotebook00",
    "test_monitoring.py",
    "test_parallel.py",
    "test_filters_transforms.py",
)


def _rank(item):
    return next((i for i, h in enumerate(HEAVY) if h in item.nodeid), len(HEAVY))


def pytest_collection_modifyitems(config, items):
    """Heaviest scopes first (a stable sort: the order inside a module is kept)."""
    items.sort(key=_rank)


#: top-level modules whose native code stays out of the test process: numba's llvmlite carries a
#: second LLVM (numba/numba#7857); Hector (netCDF4) and pyproj bundle HDF5, SQLite, curl and TIFF.
#: They were suspected when workers segfaulted inside XLA compiles, but the crashes came with and
#: without them: the cause was the mapping limit (see _bounded_memory_mappings). They run in a
#: subprocess all the same (tests/reference/pyins_run.py, hector_run.py, proj_run.py), so that a
#: test process holds only jaxnav's own native code.
FOREIGN_NATIVE = ("llvmlite", "numba", "netCDF4", "hector", "pyproj")


@pytest.fixture(autouse=True)
def _no_foreign_native_code_in_process():
    """Fail any test that imports one of FOREIGN_NATIVE into the test process."""
    yield
    loaded = [m for m in FOREIGN_NATIVE if m in sys.modules]
    if loaded:
        pytest.fail(f"{', '.join(loaded)} imported in the test process: run that reference in a subprocess instead")


def _max_map_count() -> int:
    try:
        return int(pathlib.Path("/proc/sys/vm/max_map_count").read_text())
    except (OSError, ValueError):
        return 0


def _map_count() -> int:
    try:
        with open("/proc/self/maps", "rb") as f:
            return sum(1 for _ in f)
    except OSError:
        return 0


MAX_MAP_COUNT = _max_map_count()


@pytest.fixture(autouse=True)
def _bounded_memory_mappings():
    """Drop jax's compiled executables when this process holds 30 % of the kernel's mapping limit.

    Every XLA CPU executable keeps about three memory mappings for its code until its cache entry
    goes. A test worker compiles tens of thousands of programs (eager ops included) and, near
    vm.max_map_count (65530 by default), the next compile's mmap fails and XLA segfaults: the
    crashes in varying tests of long-lived workers that never reproduced alone. Clearing the caches
    costs recompiles only in the tests that follow; nothing is cleared below the threshold
    (tests/filters/test_nonlinear.py alone leaves 22 000 mappings).
    """
    yield
    if MAX_MAP_COUNT and _map_count() > 0.3 * MAX_MAP_COUNT:
        import gc

        jax.clear_caches()
        gc.collect()
