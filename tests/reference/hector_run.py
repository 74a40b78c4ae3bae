"""Run Hector's ``estimatetrend`` (hector-ts, Bos et al. 2013) on one daily component: the outside
reference for station velocities under coloured noise. Used by tests/monitoring/test_trajectory.py
and benchmarks/bench_monitoring.py."""

from __future__ import annotations

import json
import pathlib
import shutil
import subprocess
import sys
import tempfile

import numpy as np

MJD_J2000 = 51544.5


def hector_available() -> bool:
    """Whether Hector's ``estimatetrend`` is on the path of this interpreter's environment."""
    return _exe() is not None


def _exe():
    cand = pathlib.Path(sys.executable).parent / "estimatetrend"
    return str(cand) if cand.exists() else shutil.which("estimatetrend")


def hector_covariance_row(n: int, d: float, one_minus_phi: float):
    """Hector's first row of the GGM covariance (``hector.ggm._covariance_row``), computed in a subprocess.

    Hector imports netCDF4 (with its bundled HDF5 and compression libraries); the test process keeps
    only jaxnav's native code (see tests/conftest.py), so the row comes back as an array.
    """
    code = (
        "import sys, numpy as np; from hector.ggm import _covariance_row; "
        "np.save(sys.argv[1], np.asarray(_covariance_row(int(sys.argv[2]), float(sys.argv[3]), float(sys.argv[4]))))"
    )
    with tempfile.TemporaryDirectory() as tmp:
        out = pathlib.Path(tmp) / "row.npy"
        subprocess.run(
            [sys.executable, "-c", code, str(out), str(n), repr(d), repr(one_minus_phi)], check=True, timeout=300
        )
        return np.load(out)


def run_hector(t_s, y_m, *, steps_s=(), noise="FlickerGGM White", reml=True, timeout=600) -> dict:
    """Hector's estimatetrend on a daily series; returns its JSON (mm, mm/yr) plus "wall_s".

    Args:
      t_s: (N,) s since J2000 of the valid days (daily sampling, gaps allowed).
      y_m: (N,) values, m.  steps_s: step epochs, s since J2000 (Hector "offset" lines).
      noise: Hector's NoiseModels ("FlickerGGM White", "FlickerGGM RandomWalkGGM White", ...).
    """
    import time

    exe = _exe()
    if exe is None:
        raise RuntimeError("hector-ts is not installed (pip install hector-ts)")
    with tempfile.TemporaryDirectory() as d:
        d = pathlib.Path(d)
        (d / "pre").mkdir()
        mjd = np.asarray(t_s, float) / 86400.0 + MJD_J2000
        lines = ["# sampling period 1.0"] + [f"# offset {s / 86400.0 + MJD_J2000:.4f}" for s in steps_s]
        lines += [f"{m:.4f} {v * 1e3:.6f}" for m, v in zip(mjd, np.asarray(y_m, float))]
        (d / "pre/S.mom").write_text("\n".join(lines) + "\n")
        (d / "estimatetrend.ctl").write_text(
            "DataFile S.mom\nDataDirectory pre\nOutputFile out.mom\ninterpolate no\nPhysicalUnit mm\n"
            "TimeUnit days\nScaleFactor 1.0\nperiodicsignals 365.25 182.625\n"
            f"estimateoffsets {'yes' if len(steps_s) else 'no'}\nNoiseModels {noise}\nGGM_1mphi 6.9e-06\n"
            f"useRMLE {'yes' if reml else 'no'}\nVerbose no\n"
        )
        t0 = time.perf_counter()
        r = subprocess.run([exe, "-i", "estimatetrend.ctl"], cwd=d, capture_output=True, text=True, timeout=timeout)
        wall = time.perf_counter() - t0
        if r.returncode != 0 or not (d / "estimatetrend.json").exists():
            raise RuntimeError(f"estimatetrend failed ({r.returncode}): {r.stderr[-2000:]}{r.stdout[-2000:]}")
        out = json.loads((d / "estimatetrend.json").read_text())
    out["wall_s"] = wall
    return out
