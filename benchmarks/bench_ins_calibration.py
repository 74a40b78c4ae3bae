"""Consistency of ``jaxnav ins`` from a grade preset alone: before and after the default noise calibration.

A script, not a test (statistics over several simulated recordings take minutes):

    PYTHONPATH=. .venv/bin/python benchmarks/bench_ins_calibration.py            # refreshes its RESULTS.md section
    PYTHONPATH=. .venv/bin/python benchmarks/bench_ins_calibration.py --no-write # print only

Recordings (``tests/experiments/_recording.py``, written as KF-GINS files with their true trajectory):
a car (110 s, up to 12 m/s, 50 Hz IMU, 2 Hz RTK-level GNSS) and a handheld walk (120 s at 1.4 m/s,
same sensors), each with GNSS withheld on two 15 s outages, and an IMU whose white noise (ARW, VRW)
is ``FACTOR`` times the consumer preset's (1: the preset is right; 4: a real installation's
vibration and temperature). Each case runs ``SEEDS`` seeds from the same config (``grade =
"consumer"``, 15 states, gate 0.9999): *before* = the preset as given (``calibrate = false``),
*after* = the default ``calibrate = "auto"``.

Scored against the truth, forward filter (IMU position, every filter epoch; "outages" the epochs
inside the withheld windows): the 3-D position NEES e' P^-1 e (3 expected) and the share of position
components within 3 sigma (99.73 % expected). 95 % bands: the NEES averaged over the K seeds at an
epoch is chi^2(3K)/K for a consistent filter, so its 95 % band is [chi^2_0.025(3K), chi^2_0.975(3K)]/K
(Bar-Shalom's ANEES test); the share of epochs whose seed-averaged NEES falls inside is reported (95 %
expected). For the 3-sigma coverage of n epoch components the binomial 95 % band of a share p = 0.9973
is p +- 1.96 sqrt(p (1 - p) / n_eff); errors along a run are correlated over an outage, so n_eff is
taken as the number of outage windows times components times seeds (a conservative band).
"""

from __future__ import annotations

import argparse
import math
import pathlib
import sys
import tempfile
import time

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests" / "experiments"))

from _harness import cpu_model, git_revision, loadavg, write_section
from _recording import car_config, short_car_spec, walk_spec, write_car, write_truth_nav

BEGIN = "<!-- BEGIN bench_ins_calibration results -->"
END = "<!-- END bench_ins_calibration results -->"
CONSUMER_ARW = math.radians(0.5) / 60  # rad/sqrt(s)
CONSUMER_VRW = 0.1 / 60  # m/s/sqrt(s)
EVALUATE = "first_s = 40.0\noutage_s = 15.0\ngap_s = 20.0\nend_margin_s = 5.0"


def case(folder, platform, factor, seed):
    """(prep, truth) of one recording: the consumer-preset config on a car or a walk."""
    from jaxnav.experiments.ins_run import prepare
    from jaxnav.io import load_ins_config, read_ins_truth

    spec = short_car_spec() if platform == "car" else walk_spec()
    rec = write_car(
        folder,
        seed=seed,
        spec=spec,
        imu_rate=50.0,
        vibration=0.0,
        gyro_white=factor * CONSUMER_ARW,
        accel_white=factor * CONSUMER_VRW,
        gyro_bias=math.radians(100.0) / 3600,
        accel_bias=10e-3 * 9.81,
    )
    write_truth_nav(rec, folder / "truth.nav", step=5)
    cfg = car_config(
        rec,
        folder,
        time_offset=0.15,
        noise='grade = "consumer"',
        tune='calibrate = "auto"',
        evaluate=EVALUATE,
        evaluate_extra='truth = "truth.nav"',
        min_speed=3.0 if platform == "car" else 1.0,
    )
    c = load_ins_config(cfg)
    return prepare(c, progress=None), read_ins_truth(c)


def score(prep, truth, d=None):
    """Forward NEES per filter epoch, in-outage flags, 3-sigma flags (E, N, U) and the gated share of a run."""
    from jaxnav.experiments.ins_run import run_ins, truth_errors

    run = run_ins(prep, d)
    e = truth_errors(run, truth, "forward")
    inside = np.zeros(np.asarray(e.t).size, bool)
    for a, b in np.asarray(prep.outages):
        inside |= (np.asarray(e.t) >= a) & (np.asarray(e.t) < b)
    within = np.abs(np.asarray(e.pos_enu)) <= 3.0 * np.asarray(e.sig_pos_enu)
    n_used = int(np.count_nonzero(np.asarray(prep.meas.mask)[:, :3].any(-1)))
    return np.asarray(e.nees_pos), inside, within, int(run.result.n_gated) / n_used, np.asarray(e.t)


def chi2_band(k_dof: int):
    from scipy.stats import chi2

    return chi2.ppf(0.025, k_dof), chi2.ppf(0.975, k_dof)


def study(platforms, factors, seeds):
    from jaxnav.experiments.ins_run import calibrate_noise

    rows = []
    for platform in platforms:
        for factor in factors:
            acc = {"before": [], "after": []}
            cal = []
            for seed in range(seeds):
                with tempfile.TemporaryDirectory() as tmp:
                    prep, truth = case(pathlib.Path(tmp), platform, factor, seed)
                    acc["before"].append(score(prep, truth))
                    t0 = time.perf_counter()
                    d, c = calibrate_noise(prep, "auto")
                    c["wall_time_s"] = time.perf_counter() - t0
                    cal.append(c)
                    acc["after"].append(acc["before"][-1] if not c["ran"] else score(prep, truth, d))
                print(
                    platform,
                    factor,
                    seed,
                    {k: c.get(k) for k in ("ran", "reason", "nis_after_per_dof", "nis_vel_after_per_dof")},
                )
            for when in ("before", "after"):
                runs = acc[when]
                n = min(r[0].size for r in runs)
                nees = np.stack([r[0][:n] for r in runs])
                inside = runs[0][1][:n]
                within = np.concatenate([r[2][:n] for r in runs])
                lo, hi = chi2_band(3 * seeds)
                avg = np.nanmean(nees, 0)
                ok = np.isfinite(avg)
                share_band = float(np.mean((avg[ok] >= lo / seeds) & (avg[ok] <= hi / seeds)))
                sel_in = np.tile(inside, seeds)
                n_eff = 2 * 3 * seeds
                half = 1.96 * math.sqrt(0.9973 * 0.0027 / n_eff)
                rows.append(
                    {
                        "platform": platform,
                        "factor": factor,
                        "when": when,
                        "calibrated": sum(c["ran"] for c in cal) if when == "after" else 0,
                        "nis": np.mean([c["nis_before_per_dof"] for c in cal])
                        if when == "before"
                        else np.mean([c.get("nis_after_per_dof", c["nis_before_per_dof"]) for c in cal]),
                        "nis_vel": np.mean([c["nis_vel_before_per_dof"] for c in cal])
                        if when == "before"
                        else np.mean([c.get("nis_vel_after_per_dof", c["nis_vel_before_per_dof"]) for c in cal]),
                        "nees_all": float(np.nanmean(nees)),
                        "nees_out": float(np.nanmean(nees[:, inside])),
                        "anees_band": (lo / seeds, hi / seeds),
                        "share_epochs_in_band": share_band,
                        "cov_all": float(np.mean(within)),
                        "cov_out": float(np.mean(within[sel_in])),
                        "cov_band": (0.9973 - half, min(1.0, 0.9973 + half)),
                        "gated": float(np.mean([r[3] for r in runs])),
                        "cal_s": float(np.mean([c["wall_time_s"] for c in cal])),
                    }
                )
    return rows


def table(rows, seeds):
    out = [
        f"| recording | true noise / preset | run | calibrated (of {seeds}) | GNSS NIS per dof pos / vel | NEES all (outages) "
        "| epochs with seed-mean NEES in its 95 % band | 3-sigma coverage all (outages) | gated share | check + calibration, s |",
        "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        out.append(
            f"| {r['platform']} | {r['factor']:g}x | {r['when']} | {r['calibrated']} | {r['nis']:.2f} / {r['nis_vel']:.2f} | "
            f"{r['nees_all']:.2f} ({r['nees_out']:.2f}) | {100 * r['share_epochs_in_band']:.0f} % | "
            f"{100 * r['cov_all']:.1f} % ({100 * r['cov_out']:.1f} %) | {100 * r['gated']:.1f} % | "
            + (f"{r['cal_s']:.0f} |" if r["when"] == "after" else "- |")
        )
    r0 = rows[0]
    out.append("")
    out.append(
        f"Bands for {seeds} seeds: seed-mean NEES [{r0['anees_band'][0]:.2f}, {r0['anees_band'][1]:.2f}] "
        f"(3 expected; 95 % of the epochs expected inside); 3-sigma coverage "
        f"[{100 * r0['cov_band'][0]:.1f} %, {100 * r0['cov_band'][1]:.1f} %] (99.73 % expected)."
    )
    return "\n".join(out)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--no-write", action="store_true")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--factors", type=float, nargs="+", default=[1.0, 4.0])
    ap.add_argument("--platforms", nargs="+", default=["car", "handheld"])
    a = ap.parse_args()
    import jax

    jax.config.update("jax_enable_x64", True)
    t0 = time.perf_counter()
    rows = study(a.platforms, a.factors, a.seeds)
    text = table(rows, a.seeds)
    load = "/".join(f"{x:.1f}" for x in loadavg())
    head = (
        "## `jaxnav ins` noise self-calibration: consistency from a grade preset (`benchmarks/bench_ins_calibration.py`)\n\n"
        f"`PYTHONPATH=. .venv/bin/python benchmarks/bench_ins_calibration.py --seeds {a.seeds}` ({git_revision()}, {cpu_model()}, "
        f"load {load}, {time.perf_counter() - t0:.0f} s): consumer preset, 15 states, gate 0.9999; "
        'before = the preset as given, after = `calibrate = "auto"`; forward filter against the truth.\n\n'
    )
    print(head + text)
    if not a.no_write:
        write_section(HERE / "RESULTS.md", head + text, BEGIN, END)


if __name__ == "__main__":
    main()
