"""Shared pieces of the benchmark scripts: machine banner helpers, load average, results writer.

Each ``bench_*.py`` keeps its own measurements and report; this module holds what they all
need so that the banner and the RESULTS.md sections are produced one way.
"""

from __future__ import annotations

import importlib.metadata as _md
import os
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def package_version(dist: str) -> str:
    """Installed version of a distribution, or 'not installed'."""
    try:
        return _md.version(dist)
    except _md.PackageNotFoundError:
        return "not installed"


def cpu_model() -> str:
    """The CPU model name from /proc/cpuinfo ('unknown' elsewhere)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return "unknown"


def git_revision() -> str:
    """Short HEAD of the repository, flagged when jaxnav/ has uncommitted changes."""
    try:
        rev = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True, timeout=10
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--", "jaxnav"], cwd=ROOT, capture_output=True, text=True, timeout=10
        ).stdout.strip()
        return (rev or "unknown") + (" + uncommitted changes in jaxnav/" if dirty else "")
    except Exception:
        return "unknown"


def loadavg():
    """1/5/15-minute load average (NaN where unavailable)."""
    try:
        return os.getloadavg()
    except OSError:
        return (float("nan"),) * 3


def write_section(path, report: str, begin: str, end: str) -> None:
    """Replace (or append) the text between the markers ``begin`` and ``end`` in a results file."""
    path = Path(path)
    block = f"{begin}\n\n{report}\n\n{end}"
    if path.exists():
        text = path.read_text()
        if begin in text and end in text:
            pre, rest = text.split(begin, 1)
            path.write_text(pre + block + rest.split(end, 1)[1])
            return
        path.write_text(text.rstrip() + "\n\n" + block + "\n")
        return
    path.write_text("# Benchmark results\n\n" + block + "\n")


# --------------------------------------------------------------------------------------
# timing: compile separate from run, block_until_ready, min and median of repeats
# --------------------------------------------------------------------------------------


class Timing:
    """Compile time and run times of one jitted call (seconds)."""

    def __init__(self, compile_s, runs):
        self.compile_s, self.runs = compile_s, list(runs)

    @property
    def min(self):
        return min(self.runs)

    @property
    def median(self):
        import statistics

        return statistics.median(self.runs)


def time_jit(fn, args, repeats=5, *, warmup=1):
    """Time a jitted function: AOT ``lower().compile()`` measured on its own, then ``repeats``
    calls of the compiled executable, each ended by ``jax.block_until_ready``.

    Returns (:class:`Timing`, output of the first run).
    """
    import time

    import jax

    t0 = time.perf_counter()
    compiled = fn.lower(*args).compile()
    comp = time.perf_counter() - t0
    out = jax.block_until_ready(compiled(*args))
    for _ in range(max(0, warmup - 1)):
        jax.block_until_ready(compiled(*args))
    runs = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(compiled(*args))
        runs.append(time.perf_counter() - t0)
    return Timing(comp, runs), out


def matmul_rate(n=1024, repeats=10):
    """The machine's dense float64 n x n matmul rate through XLA (GFLOP/s, best of repeats).

    The "limit" the throughput ratios refer to; measure it in the same run as the benchmark.
    """
    import time

    import jax
    import jax.numpy as jnp
    import numpy as np

    rng = np.random.default_rng(0)
    a = jnp.asarray(rng.standard_normal((n, n)), jnp.float64)
    b = jnp.asarray(rng.standard_normal((n, n)), jnp.float64)
    mm = jax.jit(jnp.matmul)
    jax.block_until_ready(mm(a, b))
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(mm(a, b))
        best = min(best, time.perf_counter() - t0)
    return 2.0 * n**3 / best / 1e9


def device_banner():
    """Markdown table rows: machine, load, devices, versions, date (for a RESULTS.md section)."""
    import datetime as _dt
    import platform

    import jax

    la = loadavg()
    rows = [
        ("date", _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M UTC")),
        ("machine", f"{cpu_model()}, {os.cpu_count()} logical cores, {platform.system()} {platform.release()}"),
        ("load average (1/5/15 min) at start", f"{la[0]:.2f} / {la[1]:.2f} / {la[2]:.2f}"),
        ("JAX devices", ", ".join(str(d) for d in jax.devices()) + f" (x64 {jax.config.jax_enable_x64})"),
        ("python", platform.python_version()),
        ("jaxnav source", f"git {git_revision()}"),
        ("versions", ", ".join(f"{d} {package_version(d)}" for d in ("jax", "jaxlib", "numpy", "dynamax"))),
    ]
    return "| | |\n|---|---|\n" + "\n".join(f"| {k} | {v} |" for k, v in rows)
