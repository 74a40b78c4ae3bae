"""Benchmark the INS/GNSS filter with the issue-18 options: 21 states, NHC pseudo-measurements, the chi-square gate.

A script, not a test:

    .venv/bin/python benchmarks/bench_aiding.py            # ~10 min on a loaded 2-core machine; prints a table
    .venv/bin/python benchmarks/bench_aiding.py --quick    # 120 s of data, one repeat

Workload: a simulated car (``tests/ins/test_aiding.py``'s segments, repeated to fill the run),
10 min of 100 Hz IMU (60 000 increments, MEMS grade: 30 deg/h, 3 mg), GNSS 1 Hz position + velocity
with two 60 s outages. Each row is one forward filter (:func:`jaxnav.ins.loosely_coupled`, saving
what :func:`jaxnav.ins.smooth` needs) plus the RTS smoother, in one user call each, timed from the
host arrays to the smoothed positions on the host. "compile" = first call - min of the later calls;
"run" = min (median) of ``--repeats`` later calls. The issue's target: forward + RTS of 10 min of
100 Hz data in under 2 s after compilation.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

from jaxnav import ins, sim
from jaxnav.ins import LCParams, PVMeasurements

CAR_HEAD = """
name = "car"
[time]
duration_s = %s
imu_rate_hz = 100.0
[start]
lat_deg = 48.0
lon_deg = 11.0
height_m = 500.0
heading_deg = 20.0
speed_mps = 15.0
[gyro]
bias_deg_per_h = 30.0
arw_deg_per_sqrt_h = 0.3
[accel]
bias_mg = 3.0
vrw_ug_per_sqrt_hz = 150.0
[gnss]
rate_hz = 1.0
first_epoch_s = 1.0
pos_sigma_m = 1.0
vel_sigma_mps = 0.05
outages_s = %s
[initial_errors]
attitude_arcsec = 300.0
velocity_mps = 0.1
position_m = 1.0
"""
CYCLE = """
[[segments]]
kind = "turn"
duration_s = 10.0
dheading_deg = 90.0
hold_s = 20.0
[[segments]]
kind = "accelerate"
duration_s = 5.0
dspeed_mps = 5.0
hold_s = 20.0
[[segments]]
kind = "turn"
duration_s = 15.0
dheading_deg = -120.0
hold_s = 20.0
[[segments]]
kind = "accelerate"
duration_s = 5.0
dspeed_mps = -5.0
hold_s = 25.0
"""  # 120 s


def _setup(duration):
    outages = [[duration * 0.3, duration * 0.3 + 60.0], [duration * 0.7, duration * 0.7 + 60.0]]
    text = CAR_HEAD % (duration, outages) + CYCLE * int(duration // 120)
    cfg = sim.loads_scenario(text)
    truth = sim.make_trajectory(cfg)
    r = sim.simulate(cfg, jax.random.PRNGKey(3), trajectory=truth)
    gn = r.gnss
    M = gn.t.shape[0]
    R = np.diag([1.0] * 3 + [0.05**2] * 3)
    meas = PVMeasurements(
        t=np.asarray(gn.t),
        pos=np.asarray(gn.pos),
        vel=np.asarray(gn.vel),
        R=np.broadcast_to(R, (M, 6, 6)),
        mask=np.broadcast_to(np.asarray(gn.valid)[:, None], (M, 6)),
        lever=np.zeros((M, 3)),
    )
    v3 = lambda x: np.broadcast_to(np.asarray(x, float), (3,))
    nz = cfg.noise
    kw = dict(
        att=v3(cfg.initial_errors.attitude),
        vel=0.1,
        pos_enu=1.0,
        gyro_bias=v3(nz.gyro_bias_initial),
        accel_bias=v3(nz.accel_bias_initial),
    )
    p15 = LCParams(
        P0=ins.ERROR_MODEL_15.P0(truth.pos[0], **kw),
        Qc=ins.ERROR_MODEL_15.Qc(ins.ImuNoise(gyro_arw=v3(nz.gyro_arw), accel_vrw=v3(nz.accel_vrw))),
        tau_markov=300.0,
    )
    noise21 = ins.ImuNoise(
        gyro_arw=v3(nz.gyro_arw),
        accel_vrw=v3(nz.accel_vrw),
        gyro_bias_instability=v3(nz.gyro_bias_initial) * 0.1,
        gyro_bias_tau=3600.0,
        accel_bias_instability=v3(nz.accel_bias_initial) * 0.1,
        accel_bias_tau=3600.0,
    )
    p21 = LCParams(
        P0=ins.ERROR_MODEL_21.P0(truth.pos[0], gyro_scale=1e-2, accel_scale=1e-3, **kw),
        Qc=ins.ERROR_MODEL_21.Qc(noise21),
        tau_markov=np.full(6, 3600.0),
    )
    return cfg, truth, r, meas, p15, p21


SAVE = ins.LCSave(("nav", "biases", "covs", "pred_covs", "Phi", "corrections"))


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
    duration = 120.0 if args.quick else 600.0
    repeats = 1 if args.quick else args.repeats
    t0 = time.perf_counter()
    cfg, truth, r, meas, p15, p21 = _setup(duration)
    t_imu = np.asarray(truth.t[1:])
    dth, dv = np.asarray(r.imu.dtheta), np.asarray(r.imu.dv)
    nav0 = jax.tree_util.tree_map(np.asarray, r.nav0)
    print(
        f"data: {duration:.0f} s, {t_imu.size} IMU samples, {meas.t.size} GNSS epochs; simulated in "
        f"{time.perf_counter() - t0:.1f} s",
        flush=True,
    )
    rows = [
        ("15 states, GNSS only", 15, p15, (), None, 1),
        ("21 states, GNSS only", 21, p21, (), None, 1),
        ("21 states + NHC 2 Hz + gate", 21, p21, (ins.nhc(rate_hz=2.0),), 0.999, 1),
        ("21 states + NHC 10 Hz + gate", 21, p21, (ins.nhc(rate_hz=10.0),), 0.999, 1),
        ("21 states + NHC 2 Hz + gate, nav_every=10", 21, p21, (ins.nhc(rate_hz=2.0),), 0.999, 10),
        ("15 states, GNSS only, nav_every=10", 15, p15, (), None, 10),
    ]
    out = []
    for name, n, params, aids, gate, ne in rows:

        def call():
            model = ins.error_model_for(n)
            res = ins.loosely_coupled(
                nav0,
                t_imu,
                dth,
                dv,
                meas,
                params,
                dt_imu=cfg.dt,
                error_model=model,
                aids=aids,
                gate=None if gate is None else ins.LCGate(gate),
                propagation=ins.LCPropagation(nav_every=ne),
                save=SAVE,
            )
            nav_s, _, _ = ins.smooth(res, error_model=model)
            return np.asarray(nav_s.pos), res

        t1 = time.perf_counter()
        pos, res = call()
        first = time.perf_counter() - t1
        times = []
        for _ in range(repeats):
            t1 = time.perf_counter()
            call()
            times.append(time.perf_counter() - t1)
        tmin, tmed = min(times), float(np.median(times))
        out.append((name, first - tmin, tmin, tmed, pos.shape[0], int(res.n_gated)))
        print(
            f"| {name} | {first - tmin:.1f} s | {tmin:.2f} s ({tmed:.2f}) | {pos.shape[0]} | {int(res.n_gated)} |",
            flush=True,
        )
    print()
    print(
        f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, {platform.processor() or platform.machine()}, "
        f"Python {platform.python_version()}, jax {jax.__version__}, load {os.getloadavg()}"
    )
    print("| run (forward + RTS) | compile | run min (median) | filter epochs | gated |")
    print("|---|---|---|---|---|")
    for name, c, tmin, tmed, ne_, ng in out:
        print(f"| {name} | {c:.1f} s | {tmin:.2f} s ({tmed:.2f} s) | {ne_} | {ng} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
