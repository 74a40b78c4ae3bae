"""Benchmark jaxnav's loosely coupled INS/GNSS feedback filter against pyins's feedback filter on S0.

A script, not a test. It runs in the *main* test environment ``.venv`` (pyins is a test extra
there: ``python-ins``):

    .venv/bin/python benchmarks/bench_insgnss.py              # full run (~3.5 min idle), refreshes RESULTS.md
    .venv/bin/python benchmarks/bench_insgnss.py --quick      # smoke run, writes nothing
    .venv/bin/python benchmarks/bench_insgnss.py --batches 4,8 --repeats 1 --pyins-repeats 0   # loaded machine

Workload: the full S0 run of ``make demo`` (``jaxnav/cli/_demo_s0.py``): 2000 s, IMU 100 Hz
(200 000 increments), GPS 1 Hz position + velocity (2000 fixes, 10 m / 0.1 m/s), the scenario's
initial errors and sensor errors drawn per seed by ``jaxnav.sim.simulate``. The *well-specified*
variant is used (``unsensed_velocity_steps = false``: every velocity step is in the IMU output), so
both filters are in their comfort zone; classic filter (no inflation), float64.

Implementations (each gets the same simulated increments and fixes, converted ENU/RFU -> NED/FRD
with P = [[0,1,0],[1,0,0],[0,0,-1]] for pyins, see tests/test_pyins.py):
  jaxnav   ``jaxnav.ins.loosely_coupled`` (18 states: attitude, velocity, position (lat, lon, h),
           gyro random constant, gyro first-order Markov drift (tau 300 s), accelerometer random
           constant; phi-angle error model in ENU; Phi/Qd by Van Loan once per 1 s epoch from the
           epoch-averaged F; 6-D position + velocity update; feedback after every fix), as the
           demo calls it (``jaxnav.experiments.s0.S0Setup`` parameters), saving only the per-epoch navigation
           state. Single seed: the user call (host-side validation + IMU segmentation included).
           Seeds: ``jax.jit(jax.vmap(...))`` over the per-seed IMU record, fixes and initial state.
  pyins    ``pyins.filters.run_feedback_filter`` (python-ins 1.0.1; EKF with feedback), what a
           pyins user calls: ``strapdown.compute_increments_from_imu`` + ``Position`` and
           ``NedVelocity`` measurements + ``run_feedback_filter(time_step=1.0)``. 15 states:
           9 INS errors of the *modified* phi-angle model (Scherzinger & Reid: velocity error
           relative to the true velocity in the platform frame) in NED, gyro bias (random constant
           + random walk), accelerometer bias (random constant). pyins has no Gauss-Markov state,
           so the gyro drift (0.1 deg/h constant + 0.1 deg/h Markov, tau 300 s) is modelled as a
           random constant of sd sqrt(0.1^2 + 0.1^2) deg/h plus a random walk of the Markov
           process's driving intensity sqrt(2 sigma^2 / tau). Its covariance is propagated over
           1 s (``time_step``) with the mid-interval trajectory. Per-seed batches are a Python loop
           (timed on ``--pyins-seeds`` seeds and scaled: a sequential loop has no batch effects).

Timing: the first call (trace + XLA compile for jaxnav; numba compile of pyins's strapdown loop)
is timed on its own with the persistent compilation cache off; "compile" = first call - median
later call. Later calls: ``--repeats`` (x2 for the single-seed rows) round-robin in a shuffled
order, ``jax.block_until_ready`` on the outputs; min and median reported. Data simulation and the
conversion to pyins's DataFrames are outside the timings.

Agreement: per-seed RMS over the fixes of the position error (E, N, U) against the truth for both
(jaxnav: the state after feedback at each fix; pyins: its trajectory one IMU sample after the fix,
since pyins's stored trajectory row at the fix time is the state *before* the feedback; the last
fix, which pyins never processes, is left out of both), and the RMS of the jaxnav - pyins difference.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import os
import platform
import random
import statistics
import sys
import time
import warnings
from pathlib import Path
from types import SimpleNamespace

import jax
import numpy as np
from _harness import cpu_model, git_revision, loadavg, write_section
from _harness import package_version as _version

import jaxnav

jaxnav.enable_x64()
jax.config.update("jax_enable_compilation_cache", False)

import jax.numpy as jnp
import pandas as pd
from pyins import filters as pfilters
from pyins import inertial_sensor, measurements, strapdown, transform

from jaxnav import sim
from jaxnav.experiments.s0 import S0Setup, load_experiment, s0_measurements
from jaxnav.geodesy import curvilinear_to_enu
from jaxnav.ins import LCPropagation, LCSave, error_model_for, loosely_coupled
from jaxnav.ins import attitude as att

warnings.filterwarnings("ignore", message="The copy keyword is deprecated")  # pandas 3 vs pyins 1.0.1
warnings.filterwarnings("ignore", category=FutureWarning)

HERE = Path(__file__).resolve().parent
BEGIN = "<!-- BEGIN bench_insgnss results -->"
END = "<!-- END bench_insgnss results -->"
P = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])  # NED<->ENU, FRD<->RFU
DEG = np.pi / 180.0


# --------------------------------------------------------------------------------------- data
def make_setup():
    exp = load_experiment()
    exp["scenario"]["unsensed_velocity_steps"] = False  # well specified: both filters in their comfort zone
    return S0Setup(exp)


def simulate_seeds(S, keys):
    """Per-seed data needed by the filters (vmapped simulate, only the key-dependent fields returned)."""

    def one(k):
        r = sim.simulate(S.cfg, k, trajectory=S.truth)
        return r.imu.dtheta, r.imu.dv, r.gnss.pos, r.gnss.vel, r.gnss.valid, r.nav0

    return jax.block_until_ready(jax.jit(jax.vmap(one))(keys))


def take(data, i):
    return jax.tree_util.tree_map(lambda a: a[i], data)


def v3(x):
    return np.broadcast_to(np.asarray(x, float), (3,))


class PyinsCase:
    """One seed's data converted to pyins's conventions (built outside the timings)."""

    def __init__(self, S, d):
        dth, dv, gpos, gvel, valid, nav0 = (np.asarray(a) if not hasattr(a, "q_bn") else a for a in d)
        t = np.asarray(S.truth.t)
        gyro = dth @ P.T
        acc = dv @ P.T
        # increment-type IMU: the first row duplicated as the "before" sample (pyins convention)
        self.imu = pd.DataFrame(
            np.hstack([np.vstack([gyro[:1], gyro]), np.vstack([acc[:1], acc])]),
            index=t,
            columns=["gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"],
        )
        tg = t[S.gidx]  # exactly the IMU sample times (pyins matches fixes to its time grid)
        ok = np.asarray(valid, bool)
        self.pos = pd.DataFrame({"lat": gpos[ok, 0] / DEG, "lon": gpos[ok, 1] / DEG, "alt": gpos[ok, 2]}, index=tg[ok])
        vn = gvel[ok] @ P.T
        self.vel = pd.DataFrame({"VN": vn[:, 0], "VE": vn[:, 1], "VD": vn[:, 2]}, index=tg[ok])
        C = P @ np.asarray(att.quat_to_dcm(jnp.asarray(nav0.q_bn))) @ P
        rph = transform.mat_to_rph(C)
        v = P @ np.asarray(nav0.v_n)
        p0 = np.asarray(nav0.pos)
        self.pva0 = pd.Series(
            {
                "lat": p0[0] / DEG,
                "lon": p0[1] / DEG,
                "alt": p0[2],
                "VN": v[0],
                "VE": v[1],
                "VD": v[2],
                "roll": rph[0],
                "pitch": rph[1],
                "heading": rph[2],
            },
            name=t[0],
        )
        cfg = S.cfg
        ie, nz = cfg.initial_errors, cfg.noise
        self.sd = dict(
            position_sd=float(np.mean(v3(ie.position))),
            velocity_sd=float(np.mean(v3(ie.velocity))),
            level_sd=float(np.mean(v3(ie.attitude))) / DEG,
            azimuth_sd=float(v3(ie.attitude)[2]) / DEG,
        )
        gb, gm, gt = v3(nz.gyro_bias_initial), v3(nz.gyro_bias_instability), v3(nz.gyro_bias_tau)
        self.gyro_kw = dict(bias_sd=np.sqrt(gb**2 + gm**2), noise=v3(nz.gyro_arw), bias_walk=np.sqrt(2 * gm**2 / gt))
        self.accel_kw = dict(bias_sd=v3(nz.accel_bias_initial), noise=v3(nz.accel_vrw))
        self.pos_sd, self.vel_sd = float(np.mean(v3(cfg.gnss.pos_sigma))), float(np.mean(v3(cfg.gnss.vel_sigma)))

    def run(self):
        """What a pyins user calls (increments, measurement objects, the feedback filter)."""
        inc = strapdown.compute_increments_from_imu(self.imu, "increment")
        meas = [measurements.Position(self.pos, self.pos_sd), measurements.NedVelocity(self.vel, self.vel_sd)]
        return pfilters.run_feedback_filter(
            self.pva0,
            increments=inc,
            gyro_model=inertial_sensor.EstimationModel(**self.gyro_kw),
            accel_model=inertial_sensor.EstimationModel(**self.accel_kw),
            measurements=meas,
            time_step=1.0,
            with_altitude=True,
            **self.sd,
        )


# --------------------------------------------------------------------------------------- errors
def enu_err(S, pos, ref):
    """(M, 3) E, N, U metres of pos - ref ([lat, lon, h] rows), radii (R + h) at the reference."""
    return np.asarray(curvilinear_to_enu(np.asarray(ref), np.asarray(pos) - np.asarray(ref)))


def pyins_pos_after_fix(S, out):
    """pyins trajectory one IMU sample after each fix (its row at the fix is the pre-feedback state)."""
    tr = out.trajectory
    idx = np.minimum(S.gidx + 1, len(tr) - 1)
    lla = tr[["lat", "lon", "alt"]].to_numpy()[idx]
    return np.stack([lla[:, 0] * DEG, lla[:, 1] * DEG, lla[:, 2]], -1), idx


def rms(x, axis=0):
    return np.sqrt(np.mean(np.asarray(x) ** 2, axis=axis))


# --------------------------------------------------------------------------------------- timing
class Row:
    def __init__(self, name, fn, runs_per_call, *, scale=1.0, note=""):
        self.name, self.fn, self.n, self.scale, self.note = name, fn, runs_per_call, scale, note
        self.first = None
        self.runs = []
        self.out = None
        self.compile_fixed = None  # compile time measured separately (pyins: numba warm-up)

    def call(self):
        t0 = time.perf_counter()
        out = self.fn()
        if self.name.startswith("jaxnav"):
            out = jax.block_until_ready(out)
        return time.perf_counter() - t0, out

    @property
    def times(self):
        return self.runs if self.runs else [self.first]  # no repeats: the (already warm) first call

    @property
    def tmin(self):
        return min(self.times) * self.scale

    @property
    def tmed(self):
        return statistics.median(self.times) * self.scale

    @property
    def compile_s(self):
        if self.compile_fixed is not None:
            return self.compile_fixed
        return max(self.first - statistics.median(self.times), 0.0)


def run_rows(rows, repeats, log):
    for r in rows:
        r.first, r.out = r.call()
        log(f"  first call  {r.name}: {r.first:.3f} s")
    order = [r for r in rows for _ in range(repeats[r.name] if isinstance(repeats, dict) else repeats)]
    random.Random(0).shuffle(order)
    for r in order:
        r.runs.append(r.call()[0])
    for r in rows:
        log(
            f"  {r.name}: min {min(r.times):.4f} s, median {statistics.median(r.times):.4f} s"
            + (f" (x{r.scale:g} extrapolated)" if r.scale != 1.0 else "")
        )


# --------------------------------------------------------------------------------------- machine


def machine_info():
    cpu = cpu_model()
    rev = git_revision()
    return {
        "date": _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "machine": f"{cpu}, {os.cpu_count()} logical cores, {platform.system()} {platform.release()} {platform.machine()}",
        "python": platform.python_version(),
        "jax devices": ", ".join(str(d) for d in jax.devices()) + " (x64, persistent compile cache off)",
        "jaxnav source": f"git {rev}",
        "versions": ", ".join(
            f"{d} {_version(d)}" for d in ("jax", "jaxlib", "numpy", "scipy", "pandas", "numba", "python-ins", "jaxnav")
        ),
    }


def _fmt_t(s):
    if s >= 1.0:
        return f"{s:.2f} s"
    if s >= 1e-3:
        return f"{s * 1e3:.1f} ms"
    return f"{s * 1e6:.0f} µs"


def _fmt_rate(x):
    return f"{x / 1e6:.2f} M" if x >= 1e6 else f"{x / 1e3:.1f} k"


def write_results(path, report):
    write_section(path, report, BEGIN, END)


# --------------------------------------------------------------------------------------- main
def main(argv=None):
    p = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument(
        "--batches",
        default="8,32,64",
        help="vmapped seed counts (default 8,32,64; ~3.3 min in all "
        "on the idle 2-core machine, several times that under load: use 4,8 then)",
    )
    p.add_argument(
        "--nav-every",
        type=int,
        default=10,
        help="samples per navigation-frame update in the two-speed rows (default 10)",
    )
    p.add_argument(
        "--repeats",
        type=int,
        default=2,
        help="timed calls per batched row after the first (default 2; jaxnav single: 3x that)",
    )
    p.add_argument(
        "--pyins-repeats",
        type=int,
        default=1,
        help="timed pyins calls after the first (default 1: one pyins run is ~20 s idle; numba is "
        "compiled beforehand, so the first call is already warm)",
    )
    p.add_argument("--pyins-seeds", type=int, default=1, help="seeds run through pyins for the agreement (default 1)")
    p.add_argument("--quick", action="store_true", help="B = 2, 1 repeat, writes nothing")
    p.add_argument("--results", default=str(HERE / "RESULTS.md"), help="results file (default benchmarks/RESULTS.md)")
    p.add_argument("--no-write", action="store_true", help="print the report only")
    args = p.parse_args(argv)
    if args.quick:
        args.batches, args.repeats, args.pyins_seeds = "2", 1, 1
        if "--results" not in (argv or sys.argv):
            args.no_write = True
    batches = [int(b) for b in args.batches.split(",")]
    log = lambda m: print(m, flush=True)
    wall0 = time.perf_counter()
    load0 = loadavg()
    info = machine_info()
    log(f"bench_insgnss: {info['date']}; {info['machine']}; load {load0[0]:.2f}; {info['versions']}")

    # ---- data
    t0 = time.perf_counter()
    S = make_setup()
    Bmax = max(batches + [args.pyins_seeds])
    keys = jax.random.split(jax.random.PRNGKey(2019), Bmax)
    data = simulate_seeds(S, keys)
    N, M = int(data[0].shape[1]), int(data[2].shape[1])
    t_sim = time.perf_counter() - t0
    log(f"setup + simulated {Bmax} seeds ({N} IMU samples, {M} fixes each) in {t_sim:.1f} s")
    n_states = S.exp["filter"]["n_states"]
    t_imu, t_g = S.t_imu, S.t_gnss

    def lc(dth, dv, gpos, gvel, valid, nav0, nav_every=1):
        meas = s0_measurements(S.cfg, SimpleNamespace(pos=gpos, vel=gvel, valid=valid), t_g)
        return loosely_coupled(
            nav0,
            t_imu,
            dth,
            dv,
            meas,
            S.params,
            dt_imu=S.cfg.dt,
            error_model=error_model_for(n_states),
            inflation=None,
            save=LCSave(("nav",)),
            propagation=LCPropagation(nav_every=nav_every),
        )

    K = args.nav_every

    d0 = take(data, 0)

    # ---- single seed: jaxnav user call vs pyins
    pc = [PyinsCase(S, take(data, i)) for i in range(args.pyins_seeds)]
    log(f"single seed, N = {N}")

    def lc_checked():
        res = lc(*d0)
        checks.append(res)
        return res.epochs.nav

    checks = []
    rows1 = [
        Row(
            "jaxnav",
            lc_checked,
            1,
            note="`loosely_coupled(...)` user call (host validation + segmentation), per-epoch nav saved",
        ),
        Row(
            "pyins",
            lambda: pc[0].run(),
            1,
            note="`compute_increments_from_imu` + `run_feedback_filter(time_step=1.0)`, Position + NedVelocity",
        ),
        Row(
            f"jaxnav nav_every={K}",
            lambda: lc(*d0, nav_every=K).epochs.nav,
            1,
            note=f"the same call with `nav_every={K}`: two-speed mechanization between the fixes",
        ),
    ]
    # numba compile of pyins's strapdown loop, on its own (so pyins's first timed call is warm)
    t0 = time.perf_counter()
    strapdown.Integrator(pc[0].pva0).integrate(strapdown.compute_increments_from_imu(pc[0].imu.iloc[:11], "increment"))
    t_numba = time.perf_counter() - t0
    log(f"  numba warm-up (pyins strapdown loop compile) {t_numba:.2f} s")
    jax.clear_caches()
    run_rows(
        rows1, {"jaxnav": 3 * args.repeats, "pyins": args.pyins_repeats, f"jaxnav nav_every={K}": 3 * args.repeats}, log
    )
    rows1[1].compile_fixed = t_numba
    res0 = checks[0]
    assert int(res0.status) == 0, int(res0.status)
    assert np.allclose(np.asarray(res0.epochs.t_nav), np.asarray(S.truth.t)[S.gidx]), "epoch states not at the fixes"

    # ---- batches
    f_b = jax.jit(jax.vmap(lambda *a: lc(*a).epochs.nav))
    f_bk = jax.jit(jax.vmap(lambda *a: lc(*a, nav_every=K).epochs.nav))
    rowsB = []
    for B in batches:
        dB = jax.tree_util.tree_map(lambda a, B=B: a[:B], data)
        rowsB.append(
            Row(
                f"jaxnav B={B}",
                lambda dB=dB: f_b(*dB),
                B,
                note="`jit(vmap(loosely_coupled))` over IMU record, fixes, initial state",
            )
        )
        rowsB.append(
            Row(f"jaxnav nav_every={K} B={B}", lambda dB=dB: f_bk(*dB), B, note=f"the same with `nav_every={K}`")
        )
    log(f"vmapped seeds, B = {batches}")
    run_rows(rowsB, args.repeats, log)

    # ---- agreement (pyins on pyins-seeds seeds; jaxnav batch for the same seeds)
    log(f"agreement on {args.pyins_seeds} seeds")
    nav_all = (
        rowsB[-2].out
        if rowsB[-2].n >= args.pyins_seeds
        else f_b(*jax.tree_util.tree_map(lambda a: a[: args.pyins_seeds], data))
    )
    truth_g = np.asarray(S.truth.pos)[S.gidx]
    agree = []
    for i in range(args.pyins_seeds):
        out = rows1[1].out if i == 0 else pc[i].run()
        ppos, idx = pyins_pos_after_fix(S, out)
        jpos = np.asarray(nav_all.pos[i])
        ej = enu_err(S, jpos, truth_g)[:-1]
        ep = enu_err(S, ppos, np.asarray(S.truth.pos)[idx])[:-1]
        vj = (np.asarray(nav_all.v_n[i]) - np.asarray(S.truth.v_n)[S.gidx])[:-1]
        vp = (out.trajectory[["VE", "VN", "VD"]].to_numpy()[idx] * [1, 1, -1] - np.asarray(S.truth.v_n)[idx])[:-1]
        agree.append(
            dict(
                j=rms(ej),
                p=rms(ep),
                d=rms(ej - ep),
                vj=rms(vj),
                vp=rms(vp),
                dv=rms(vj - vp),
                maxd=float(np.max(np.linalg.norm(ej - ep, axis=1))),
            )
        )
        log(
            f"  seed {i}: pos RMS E/N/U jaxnav {np.round(agree[-1]['j'], 3)} pyins {np.round(agree[-1]['p'], 3)} "
            f"diff {np.round(agree[-1]['d'], 3)}; vel RMS jaxnav {np.round(agree[-1]['vj'], 4)} "
            f"pyins {np.round(agree[-1]['vp'], 4)}"
        )
    # the same jaxnav single result equals the batch row (vmap does not change the numbers)
    single_vs_batch = float(np.max(np.abs(np.asarray(rows1[0].out.pos) - np.asarray(nav_all.pos[0]))))
    # two-speed against the per-sample loop, same seed (m, ENU)
    two_vs_one = float(np.max(np.abs(enu_err(S, np.asarray(rows1[2].out.pos), np.asarray(rows1[0].out.pos)))))
    two_err = rms(enu_err(S, np.asarray(rows1[2].out.pos), truth_g)[:-1])

    load1 = loadavg()
    wall = time.perf_counter() - wall0
    report = build_report(
        args, info, load0, load1, wall, N, M, rows1, rowsB, agree, single_vs_batch, t_sim, Bmax, (two_vs_one, two_err)
    )
    print("\n" + report)
    if not args.no_write:
        write_results(args.results, report)
        log(f"wrote {args.results}")


def build_report(args, info, load0, load1, wall, N, M, rows1, rowsB, agree, single_vs_batch, t_sim, Bmax, two):
    j1, p1, k1 = rows1
    out = [f"Generated by `benchmarks/bench_insgnss.py` on {info['date']} (main `.venv`).", "", "| | |", "|---|---|"]
    for k in ("machine", "python", "jax devices", "jaxnav source", "versions"):
        out.append(f"| {k} | {info[k]} |")
    out.append(
        f"| load average (1/5/15 min) | start {load0[0]:.2f} / {load0[1]:.2f} / {load0[2]:.2f}, "
        f"end {load1[0]:.2f} / {load1[1]:.2f} / {load1[2]:.2f} |"
    )
    out.append(
        f"| repeats after the first call | jaxnav single {len(j1.runs)}, pyins {len(p1.runs)} (numba compiled "
        "beforehand: with 0 the warm first call is the run time), "
        f"jaxnav batches {args.repeats}; round-robin in shuffled order |"
    )
    out.append(f"| total wall time | {wall:.0f} s (data: setup + `simulate` of {Bmax} seeds {t_sim:.1f} s, untimed) |")
    out.append("")
    out.append(
        f"Workload: S0 (`make demo`), well specified (`unsensed_velocity_steps = false`), classic filter: "
        f"2000 s, {N} IMU increments at 100 Hz, {M} GPS position + velocity fixes at 1 Hz, float64. "
        "jaxnav: 18-state `loosely_coupled` (phi-angle ENU model, gyro constant + Markov drift, accel "
        "constant; Van Loan Phi/Qd per 1 s epoch). pyins 1.0.1: `run_feedback_filter`, 15 states "
        "(modified phi-angle NED model, gyro constant + random walk standing in for the Markov drift, "
        "accel constant), covariance propagated every 1 s. Both get the same increments, fixes and "
        "initial state (converted to NED/FRD for pyins). Data simulation and DataFrame building untimed."
    )
    out.append("")
    out.append("### Run time")
    out.append("")
    out.append(
        "| implementation | seeds | first call | compile | run min | run median | per run (min) | "
        "per IMU step (per run) | IMU steps/s (aggregate) | pyins / jaxnav per run | notes |"
    )
    out.append("|---|---|---|---|---|---|---|---|---|---|---|")
    p_per = p1.tmin
    rows = [(j1, 1), (p1, 1), (k1, 1)] + [(r, r.n) for r in rowsB]
    for r, n in rows:
        per = r.tmin / n
        comp = _fmt_t(r.compile_s) + ("" if r.name.startswith("jaxnav") else " (numba)")
        ratio = "—" if r is p1 else f"{p_per / per:.1f}"
        out.append(
            f"| {r.name.split(' B=')[0]} | {n} | {_fmt_t(r.first)} | {comp} | {_fmt_t(r.tmin)} | "
            f"{_fmt_t(r.tmed)} | {_fmt_t(per)} | {per / N * 1e6:.1f} µs | {_fmt_rate(n * N / r.tmin)} | {ratio} | {r.note} |"
        )
    out.append("")
    out.append(
        f"pyins over B seeds is a Python loop: B x {_fmt_t(p_per)} (e.g. {_fmt_t(p_per * rowsB[-2].n)} for "
        f"B = {rowsB[-2].n}, against {_fmt_t(rowsB[-2].tmin)} for jaxnav's vmapped batch). "
        f"The ratio column is pyins's single-run min over the row's per-run min (> 1: jaxnav faster). "
        f"{k1.name.split()[1]} against the per-sample loop, seed 0: max |Δ| {two[0] * 1e3:.3f} mm over the "
        f"fixes; its position RMS against the truth E / N / U {' / '.join(f'{x:.3f}' for x in two[1])} m."
    )
    out.append("")
    out.append("### Agreement with the truth (same seeds, per-run RMS over the fixes)")
    out.append("")
    out.append(
        "| seed | jaxnav pos RMS E / N / U m | pyins pos RMS E / N / U m | RMS(jaxnav - pyins) E / N / U m | "
        "max |jaxnav - pyins| m | jaxnav vel RMS E / N / U m/s | pyins vel RMS E / N / U m/s |"
    )
    out.append("|---|---|---|---|---|---|---|")
    f3 = lambda a, k=2: " / ".join(f"{x:.{k}f}" for x in a)
    for i, a in enumerate(agree):
        out.append(
            f"| {i} | {f3(a['j'])} | {f3(a['p'])} | {f3(a['d'])} | {a['maxd']:.2f} | {f3(a['vj'], 3)} | "
            f"{f3(a['vp'], 3)} |"
        )
    mj = np.mean([a["j"] for a in agree], 0)
    mp = np.mean([a["p"] for a in agree], 0)
    out.append(
        f"| mean | {f3(mj)} | {f3(mp)} | {f3(np.mean([a['d'] for a in agree], 0))} | "
        f"{np.mean([a['maxd'] for a in agree]):.2f} | {f3(np.mean([a['vj'] for a in agree], 0), 3)} | "
        f"{f3(np.mean([a['vp'] for a in agree], 0), 3)} |"
    )
    out.append("")
    out.append(
        "jaxnav: state after feedback at each fix; pyins: its trajectory one IMU sample (10 ms) after the "
        "fix (its stored row at the fix is the pre-feedback state); the last fix (never processed by "
        "pyins) is left out. GPS noise is 10 m / 0.1 m/s per axis, so both filters are expected well "
        "inside it; the difference between them comes from the different error models (Markov drift "
        "state vs random walk, phi-angle vs modified phi-angle, 18 vs 15 states) and different "
        "propagation details, not from the data. "
        f"jaxnav single call vs the same seed in the vmapped batch: max |Δ lat/lon/h| = {single_vs_batch:.1e}."
    )
    return "\n".join(out)


if __name__ == "__main__":
    main()
