"""Benchmark a full INS/GNSS post-processing run (forward filter + RTS smoother) of 10 min of 100 Hz data.

A script, not a test. It runs in the *main* test environment ``.venv`` (pyins is a test extra there):

    .venv/bin/python benchmarks/bench_ins_run.py            # full run, refreshes its RESULTS.md section
    .venv/bin/python benchmarks/bench_ins_run.py --no-write # print only

Workload: the first 600 s of the S0 trajectory (IMU 100 Hz: 60 000 increments; GPS 1 Hz position +
velocity), well specified (every velocity step sensed), one seed, float64 — the size of a typical
drive handed to ``jaxnav ins``. What is timed, after compilation (first call reported separately):

  jaxnav fwd+RTS     ``loosely_coupled`` (18 states, saving what the smoother needs) + ``smooth``
                     (the RTS pass fed back to the navigation states), as ``jaxnav ins`` calls them;
  jaxnav fwd+RTS two-speed   the same with ``nav_every=10`` (two-speed mechanization between fixes);
  jaxnav forward     the filter alone (per-epoch navigation state saved);
  pyins forward      ``pyins.filters.run_feedback_filter`` (python-ins; numba strapdown loop, Python/
                     NumPy filter), the reference a Python user has at hand; pyins has no fixed-interval
                     smoother on this path, so its row is forward only.

Agreement: RMS of the position error against the truth at the fixes for each.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import statistics
import time
from pathlib import Path
from types import SimpleNamespace

import jax
import numpy as np
from _harness import cpu_model, git_revision, loadavg, write_section
from _harness import package_version as _version
from bench_insgnss import PyinsCase, enu_err, make_setup, pyins_pos_after_fix, rms, simulate_seeds, take

from jaxnav.experiments.s0 import S0Setup, s0_measurements
from jaxnav.ins import LCPropagation, LCSave, loosely_coupled, smooth

HERE = Path(__file__).resolve().parent
BEGIN = "<!-- BEGIN bench_ins_run results -->"
END = "<!-- END bench_ins_run results -->"
SAVE = ("nav", "biases", "covs", "pred_covs", "Phi", "corrections")


def timed(fn, repeats):
    t0 = time.perf_counter()
    out = jax.block_until_ready(fn())
    first = time.perf_counter() - t0
    runs = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        runs.append(time.perf_counter() - t0)
    return out, first, min(runs), statistics.median(runs)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--duration", type=float, default=600.0, help="seconds of the S0 trajectory (default 600)")
    p.add_argument("--repeats", type=int, default=5, help="timed calls after the first (default 5)")
    p.add_argument("--pyins-repeats", type=int, default=1, help="timed pyins calls after the first (default 1)")
    p.add_argument("--no-write", action="store_true", help="print the report only")
    args = p.parse_args(argv)
    load0 = loadavg()
    S0 = make_setup()
    S = S0Setup(S0.exp, duration=args.duration)
    d = take(simulate_seeds(S, jax.random.split(jax.random.PRNGKey(0), 1)), 0)
    dth, dv, gpos, gvel, valid, nav0 = d
    meas = s0_measurements(S.cfg, SimpleNamespace(pos=gpos, vel=gvel, valid=valid), S.t_gnss)
    N, M = S.t_imu.size, S.t_gnss.size

    def fwd(nav_every=1, save=SAVE):
        return loosely_coupled(
            nav0,
            S.t_imu,
            dth,
            dv,
            meas,
            S.params,
            dt_imu=S.cfg.dt,
            save=LCSave(tuple(save)),
            propagation=LCPropagation(nav_every=nav_every),
        )

    def fwd_rts(nav_every=1):
        res = fwd(nav_every)
        nav, _, _ = smooth(res)
        return res.epochs.nav, nav

    rows = []
    for name, fn, reps in (
        ("jaxnav fwd+RTS", lambda: fwd_rts(1), args.repeats),
        ("jaxnav fwd+RTS two-speed (nav_every=10)", lambda: fwd_rts(10), args.repeats),
        ("jaxnav forward", lambda: fwd(1, ("nav",)).epochs.nav, args.repeats),
    ):
        out, first, tmin, tmed = timed(fn, reps)
        rows.append((name, first, tmin, tmed, out))
        print(f"{name}: first {first:.2f} s, min {tmin:.3f} s, median {tmed:.3f} s", flush=True)
    pc = PyinsCase(S, d)
    out_p, first_p, tmin_p, tmed_p = timed(pc.run, args.pyins_repeats)
    print(f"pyins forward: first {first_p:.2f} s (numba compile included), min {tmin_p:.3f} s", flush=True)
    truth = np.asarray(S.truth.pos)[S.gidx]
    err = {}
    f_nav, s_nav = rows[0][4]
    err["jaxnav forward"] = rms(enu_err(S, np.asarray(f_nav.pos), truth)[:-1])
    err["jaxnav RTS"] = rms(enu_err(S, np.asarray(s_nav.pos), truth)[:-1])
    f2, s2 = rows[1][4]
    err["jaxnav RTS two-speed"] = rms(enu_err(S, np.asarray(s2.pos), truth)[:-1])
    ppos, idx = pyins_pos_after_fix(S, out_p)
    err["pyins forward"] = rms(enu_err(S, ppos, np.asarray(S.truth.pos)[idx])[:-1])
    load1 = loadavg()
    lines = [
        f"## A full INS/GNSS run: forward + RTS over {args.duration:.0f} s of 100 Hz data "
        "(`benchmarks/bench_ins_run.py`)",
        "",
        f"{_dt.datetime.now(_dt.UTC):%Y-%m-%d %H:%M} UTC, commit {git_revision()}, {cpu_model()}, "
        f"load average {load0[0]:.1f} -> {load1[0]:.1f} (1 min); jax {_version('jax')}, python-ins {_version('python-ins')}. "
        f"N = {N} IMU increments, M = {M} GPS fixes (1 Hz position + velocity), 18 states, float64, one seed. "
        "Times: min / median of the timed calls after the first; 'first' includes tracing and compilation "
        "(numba compile for pyins).",
        "",
        "| run | first call, s | min, s | median, s | min vs pyins forward |",
        "|---|---:|---:|---:|---:|",
    ]
    for name, first, tmin, tmed, _ in rows:
        lines.append(f"| {name} | {first:.2f} | {tmin:.3f} | {tmed:.3f} | {tmin / tmin_p:.3f}x |")
    lines.append(f"| pyins forward (`run_feedback_filter`) | {first_p:.2f} | {tmin_p:.3f} | {tmed_p:.3f} | 1x |")
    lines += ["", "Position error RMS against the truth at the fixes (E, N, U, m):", ""]
    for k, v in err.items():
        lines.append(f"- {k}: {', '.join(f'{x:.3f}' for x in v)}")
    report = "\n".join(lines) + "\n"
    print("\n" + report)
    if not args.no_write:
        write_section(HERE / "RESULTS.md", report, BEGIN, END)
        print(f"wrote {HERE / 'RESULTS.md'}")


if __name__ == "__main__":
    main()
