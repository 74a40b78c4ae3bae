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
        rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                             timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--", "jaxnav"], cwd=ROOT, capture_output=True,
                               text=True, timeout=10).stdout.strip()
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
