"""Run PROJ pipelines (pyproj) for the geodesy tests in a process of their own.

pyproj carries its own native libraries (PROJ, SQLite, curl, TIFF); with them loaded beside XLA,
test workers segfaulted inside later XLA compiles. So the reference coordinates are computed here,
in a subprocess, and come back as arrays; the test process holds only jaxnav's native code.

Usage from a test: ``proj_transform([(pipeline, (x, y[, z]), "FORWARD" | "INVERSE"), ...])`` returns
one (k, n) array per job, k the number of coordinates given.
"""

from __future__ import annotations

import importlib.util
import pickle
import subprocess
import sys

import numpy as np


def proj_available() -> bool:
    """Whether pyproj is installed in this interpreter's environment (without importing it here)."""
    return importlib.util.find_spec("pyproj") is not None


def proj_transform(jobs, timeout=300):
    """Each job (pipeline, arrays, direction) through ``pyproj.Transformer.from_pipeline`` in a subprocess."""
    jobs = [(str(p), tuple(np.asarray(a, dtype=np.float64) for a in arrays), str(d)) for p, arrays, d in jobs]
    run = subprocess.run([sys.executable, __file__], input=pickle.dumps(jobs), capture_output=True, timeout=timeout)
    if run.returncode != 0:
        raise RuntimeError(f"proj_run.py failed: {run.stderr.decode(errors='replace')[-2000:]}")
    return pickle.loads(run.stdout)


def _main():
    import pyproj

    jobs = pickle.load(sys.stdin.buffer)
    out = [np.stack(pyproj.Transformer.from_pipeline(p).transform(*arrays, direction=d), 0) for p, arrays, d in jobs]
    sys.stdout.buffer.write(pickle.dumps(out))


if __name__ == "__main__":
    _main()
