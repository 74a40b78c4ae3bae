"""Benchmark jaxnav's strapdown mechanization against pyins's integrator on the same IMU increments.

A script, not a test. It runs in the *main* test environment ``.venv`` (pyins is a test extra
there: ``python-ins``), not in ``.venv-bench``:

    .venv/bin/python benchmarks/bench_ins.py                 # full run (~2-3 min), refreshes RESULTS.md
    .venv/bin/python benchmarks/bench_ins.py --quick         # smoke run (~30 s), writes nothing
    .venv/bin/python benchmarks/bench_ins.py --N 200000 --N-batch 20000 --batches 64,256 --repeats 5

Data: pyins's own simulator (``pyins.sim.generate_imu``, increment sensor) on the sine motion of
``tests/test_pyins.py`` (speed, heading, pitch, roll oscillating; level, 30 deg N, 200 m), 100 Hz.
Both mechanize the same raw increments, height held (pyins ``with_altitude=False``, jaxnav
``hold_height=True``), float64, converted NED/FRD -> ENU/RFU as the test derives.

Cases:
  (a) one trajectory of N samples (default 200 000 = 2000 s at 100 Hz), every state saved;
  (b) B trajectories sharing one IMU record of N_batch samples, each from its own initial state
      (a Monte Carlo over initial errors): jaxnav ``jit(vmap)`` over the initial state;
  (c) B trajectories each with its own IMU record (N_batch samples, the record plus per-trajectory
      gyro and accelerometer biases): jaxnav ``jit(vmap)`` over the initial state and the record.
  Batch cases keep every ``--save-every`` state (default 100: 1 Hz).

Implementations:
  jaxnav           ``jaxnav.ins.mechanize`` as a user calls it (host-side input validation included;
                   the coning/sculling corrections are inside its step). Batches: ``jax.jit(jax.vmap(...))``.
  jaxnav nav_every=K  the same call with ``nav_every=K`` (default 10): the two-speed mechanization, whose
                   navigation-frame terms (Earth and transport rate, gravity, Coriolis) are evaluated
                   once per K samples while attitude and velocity increments stay per sample; the
                   body-frame work runs as array operations, only N / K steps are sequential.
  pyins            what a pyins user calls: ``strapdown.compute_increments_from_imu`` (its coning and
                   sculling) + ``strapdown.Integrator(pva).integrate`` (numba loop, then a pandas
                   DataFrame with Euler angles).
  pyins kernel     the numba loop alone (``pyins._numba_integrate.integrate``) on increments corrected
                   beforehand (outputs allocated inside the timing): the floor of pyins's cost.
  In batch cases the pyins rows loop over trajectories; ``--extrapolate`` of them are timed and the
  time is scaled to B (a sequential loop has no batch effects).

Timing: the first call (trace + XLA compile for jaxnav, numba compile for pyins, plus one run) is
timed on its own with the persistent compilation cache off; "compile" is the first call minus the
median later call. Later calls: ``--repeats`` round-robin in a shuffled order, so drifting load on
the shared machine hits all alike; ``jax.block_until_ready`` on the outputs; min and median reported.
The ratio column is row time / jaxnav time (min): for the pyins rows, > 1 means jaxnav is faster.
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
from functools import partial
from pathlib import Path

import jax
import numpy as np
from _harness import cpu_model, git_revision, loadavg, write_section
from _harness import package_version as _version

import jaxnav

jaxnav.enable_x64()
jax.config.update("jax_enable_compilation_cache", False)

import jax.numpy as jnp
import pandas as pd
from pyins import sim, strapdown, transform
from pyins._numba_integrate import integrate as pyins_kernel

from jaxnav.ins import NavState, mechanize
from jaxnav.ins import attitude as att

warnings.filterwarnings("ignore", message="The copy keyword is deprecated")  # pandas 3 vs pyins 1.0.1

HERE = Path(__file__).resolve().parent
BEGIN = "<!-- BEGIN bench_ins results -->"
END = "<!-- END bench_ins results -->"
P = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])  # NED<->ENU, FRD<->RFU
DEG = np.pi / 180.0
LLA0 = (30.0, 114.0, 200.0)
DT = 0.01


# --------------------------------------------------------------------------------------- data
def simulate(n):
    """pyins sine-motion simulation with n increments at 100 Hz -> (traj, imu) DataFrames (n + 1 rows)."""
    t = np.arange(n + 1) * DT
    w = 2.0 * np.pi * t
    v_ned = np.stack([8.0 + 4.0 * np.sin(w / 60.0), 6.0 * np.sin(w / 90.0 + 0.5), 0.0 * t], 1)
    rph = np.stack([10.0 * np.sin(w / 20.0), 5.0 * np.sin(w / 30.0 + 1.0), 40.0 + 60.0 * np.sin(w / 120.0)], 1)
    return sim.generate_imu(t, np.array(LLA0), rph, v_ned, sensor_type="increment")


def nav0_from_pva(pva):
    C = P @ transform.mat_from_rph(pva[["roll", "pitch", "heading"]].to_numpy(float)) @ P
    return NavState(
        q_bn=att.dcm_to_quat(jnp.asarray(C)),
        v_n=jnp.asarray(P @ pva[["VN", "VE", "VD"]].to_numpy(float)),
        pos=jnp.asarray([pva.lat * DEG, pva.lon * DEG, pva.alt]),
    )


def pva_from_nav0(nav0):
    q = np.asarray(nav0.q_bn)
    C = P @ np.asarray(att.quat_to_dcm(jnp.asarray(q))) @ P
    rph = transform.mat_to_rph(C)
    v = P @ np.asarray(nav0.v_n)
    pos = np.asarray(nav0.pos)
    return pd.Series(
        {
            "lat": pos[0] / DEG,
            "lon": pos[1] / DEG,
            "alt": pos[2],
            "VN": v[0],
            "VE": v[1],
            "VD": v[2],
            "roll": rph[0],
            "pitch": rph[1],
            "heading": rph[2],
        }
    )


GYRO, ACC = ["gyro_x", "gyro_y", "gyro_z"], ["accel_x", "accel_y", "accel_z"]
THETA, DVC = ["theta_x", "theta_y", "theta_z"], ["dv_x", "dv_y", "dv_z"]


# --------------------------------------------------------------------------------------- pyins callables
def pyins_api(imu, pva):
    inc = strapdown.compute_increments_from_imu(imu, "increment")
    return strapdown.Integrator(pva, with_altitude=False).integrate(inc)


def pyins_kernel_run(dt, theta, dv, pva):
    n = theta.shape[0] + 1
    lla, vel, C = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3, 3))
    lla[0] = pva[["lat", "lon", "alt"]].to_numpy(float)
    vel[0] = pva[["VN", "VE", "VD"]].to_numpy(float)
    C[0] = transform.mat_from_rph(pva[["roll", "pitch", "heading"]].to_numpy(float))
    pyins_kernel(dt, lla, vel, C, theta, dv, 0, False)
    return lla, vel, C


# --------------------------------------------------------------------------------------- timing
def _block(x):
    return jax.block_until_ready(x)


class Row:
    def __init__(self, case, name, fn, steps, *, scale=1.0, note="", warm=False):
        self.case, self.name, self.fn, self.steps, self.scale, self.note = case, name, fn, steps, scale, note
        self.warm = warm  # already compiled by an earlier row (numba kernel shared by the pyins rows)
        self.first = None
        self.runs = []
        self.out = None

    def call(self):
        t0 = time.perf_counter()
        out = _block(self.fn())
        return time.perf_counter() - t0, out

    @property
    def tmin(self):
        return min(self.runs) * self.scale

    @property
    def tmed(self):
        return statistics.median(self.runs) * self.scale

    @property
    def compile_s(self):
        return max(self.first - statistics.median(self.runs), 0.0)


def run_rows(rows, repeats, log):
    for r in rows:
        r.first, r.out = r.call()
        log(f"  first call  {r.case} {r.name}: {r.first:.3f} s")
    order = [r for r in rows for _ in range(repeats)]
    random.Random(0).shuffle(order)
    for r in order:
        r.runs.append(r.call()[0])
    for r in rows:
        log(
            f"  {r.case} {r.name}: min {min(r.runs):.4f} s, median {statistics.median(r.runs):.4f} s"
            + (f" (x{r.scale:g} extrapolated)" if r.scale != 1.0 else "")
        )


# --------------------------------------------------------------------------------------- agreement
def horiz_diff_m(pos_a, pos_b):
    """Max horizontal distance (m) between [lat rad, lon rad, h] rows (local spherical approximation)."""
    R = 6378137.0
    dn = (pos_a[..., 0] - pos_b[..., 0]) * R
    de = (pos_a[..., 1] - pos_b[..., 1]) * R * np.cos(pos_b[..., 0])
    return float(np.max(np.hypot(dn, de)))


def pyins_pos(lla):
    return np.stack([lla[..., 0] * DEG, lla[..., 1] * DEG, lla[..., 2]], -1)


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
        "environment": sys.prefix,
    }


# --------------------------------------------------------------------------------------- report
def _fmt_t(s):
    if s >= 1.0:
        return f"{s:.2f} s"
    if s >= 1e-3:
        return f"{s * 1e3:.1f} ms"
    return f"{s * 1e6:.0f} µs"


def _fmt_rate(x):
    return f"{x / 1e6:.2f} M" if x >= 1e6 else f"{x / 1e3:.0f} k"


def build_report(args, cases, info, load0, load1, wall, checks):
    out = [
        f"Generated by `benchmarks/bench_ins.py` on {info['date']} (main `.venv`, not `.venv-bench`).",
        "",
        "| | |",
        "|---|---|",
    ]
    for k in ("machine", "python", "jax devices", "jaxnav source", "versions"):
        out.append(f"| {k} | {info[k]} |")
    out.append(
        f"| load average (1/5/15 min) | start {load0[0]:.2f} / {load0[1]:.2f} / {load0[2]:.2f}, "
        f"end {load1[0]:.2f} / {load1[1]:.2f} / {load1[2]:.2f} |"
    )
    out.append(
        f"| repeats | {2 * args.repeats} (single) / {args.repeats} (batches) per row after the first call, "
        "round-robin in shuffled order |"
    )
    out.append(f"| total wall time | {wall:.0f} s |")
    out.append("")
    out.append(
        "Data: pyins `sim.generate_imu` (increment sensor, 100 Hz) on the sine motion of `tests/test_pyins.py`, "
        "height held in both. Steps/s = IMU samples mechanized per second, summed over the batch "
        "(run min). Ratio = row time / jaxnav time (min); for the pyins rows > 1 means jaxnav is faster."
    )
    out.append("")
    for title, rows in cases:
        out.append(f"### {title}")
        out.append("")
        out.append(
            "| implementation | first call | compile | run min | run median | per step | steps/s | "
            "time / jaxnav (min) | notes |"
        )
        out.append("|---|---|---|---|---|---|---|---|---|")
        ref = next(r for r in rows if r.name == "jaxnav")
        for r in rows:
            per = r.tmin / r.steps
            if r.warm:
                first, comp = "—", "— (compiled earlier)"
            else:
                first = _fmt_t(r.first)
                comp = _fmt_t(r.compile_s) if r.name.startswith("jaxnav") else f"{_fmt_t(r.compile_s)} (numba)"
            ratio = "—" if r is ref else f"{r.tmin / ref.tmin:.2f}"
            out.append(
                f"| {r.name} | {first} | {comp} | {_fmt_t(r.tmin)} | {_fmt_t(r.tmed)} | "
                f"{per * 1e9:.0f} ns | {_fmt_rate(r.steps / r.tmin)} | {ratio} | {r.note} |"
            )
        out.append("")
    two = next(r.name for r in cases[0][1] if r.name.startswith("jaxnav nav_every"))
    out.append(
        "**Summary** (aggregate IMU steps per second, run min; ratio = pyins time / jaxnav time; "
        f"two-speed = `{two.split()[1]}`):"
    )
    out.append("")
    out.append(
        "| case | jaxnav steps/s | jaxnav two-speed steps/s | pyins steps/s | pyins kernel steps/s | "
        "pyins / jaxnav | pyins / two-speed | pyins kernel / two-speed |"
    )
    out.append("|---|---|---|---|---|---|---|---|")
    for title, rows in cases:
        by = {r.name: r for r in rows}
        j, t, a, k = by["jaxnav"], by[two], by["pyins"], by["pyins kernel"]
        out.append(
            f"| {title.split(',')[0]}{', ' + title.split(',')[1].strip() if title.startswith(('(b)', '(c)')) else ''} | "
            f"{_fmt_rate(j.steps / j.tmin)} | {_fmt_rate(t.steps / t.tmin)} | {_fmt_rate(a.steps / a.tmin)} | "
            f"{_fmt_rate(k.steps / k.tmin)} | {a.tmin / j.tmin:.2f} | {a.tmin / t.tmin:.2f} | {k.tmin / t.tmin:.2f} |"
        )
    out.append("")
    out.append("Checks (same run): " + "; ".join(checks) + ".")
    return "\n".join(out)


def write_results(path, report):
    write_section(path, report, BEGIN, END)


# --------------------------------------------------------------------------------------- main
def main(argv=None):
    p = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--N", type=int, default=200_000, help="samples of the single trajectory (default 200000)")
    p.add_argument("--N-batch", type=int, default=20_000, help="samples per trajectory in the batches (default 20000)")
    p.add_argument("--batches", default="64,256", help="batch sizes B (default 64,256)")
    p.add_argument("--save-every", type=int, default=100, help="keep every k-th state in the batches (default 100)")
    p.add_argument(
        "--repeats",
        type=int,
        default=5,
        help="timed calls per row after the first (default 5; twice that in the single case)",
    )
    p.add_argument(
        "--nav-every",
        type=int,
        default=10,
        help="samples per navigation-frame update in the two-speed rows (default 10: 0.1 s)",
    )
    p.add_argument(
        "--extrapolate", type=int, default=8, help="trajectories timed for the pyins batch loops (default 8)"
    )
    p.add_argument("--quick", action="store_true", help="N=20000, N_batch=5000, B=16, 2 repeats, writes nothing")
    p.add_argument("--results", default=str(HERE / "RESULTS.md"), help="results file (default benchmarks/RESULTS.md)")
    p.add_argument("--no-write", action="store_true", help="print the report only")
    p.add_argument("--seed", type=int, default=20240611)
    args = p.parse_args(argv)
    if args.quick:
        args.N, args.N_batch, args.batches, args.repeats, args.extrapolate = 20_000, 5_000, "16", 2, 4
        if "--results" not in (argv or sys.argv):
            args.no_write = True
    batches = [int(b) for b in args.batches.split(",")]
    if args.N_batch % args.save_every:
        p.error("--save-every must divide --N-batch")
    log = lambda m: print(m, flush=True)
    wall0 = time.perf_counter()
    load0 = loadavg()
    info = machine_info()
    log(f"bench_ins: {info['date']}; {info['machine']}; load {load0[0]:.2f}; {info['versions']}")

    # ---- data
    t0 = time.perf_counter()
    traj, imu = simulate(max(args.N, args.N_batch))
    log(f"simulated {len(imu) - 1} increments with pyins in {time.perf_counter() - t0:.1f} s")
    pva0 = traj.iloc[0]
    nav0 = nav0_from_pva(pva0)
    dth_all = imu[GYRO].to_numpy()[1:] @ P.T
    dv_all = imu[ACC].to_numpy()[1:] @ P.T
    inc_all = strapdown.compute_increments_from_imu(imu, "increment")
    cases, checks = [], []

    # ---- (a) single trajectory
    N = args.N
    dth, dv = jnp.asarray(dth_all[:N]), jnp.asarray(dv_all[:N])
    imu_a = imu.iloc[: N + 1]
    th_a = np.ascontiguousarray(inc_all[THETA].to_numpy()[:N])
    dvc_a = np.ascontiguousarray(inc_all[DVC].to_numpy()[:N])
    dts_a = np.ascontiguousarray(inc_all.dt.to_numpy()[:N])
    K = args.nav_every
    TWO = f"jaxnav nav_every={K}"
    log(f"(a) single trajectory, N = {N}")
    rows_a = [
        Row(
            "a",
            "jaxnav",
            lambda: mechanize(nav0, dth, dv, DT, hold_height=True).nav,
            N,
            note="`mechanize(..., hold_height=True)`, all states saved, host validation included",
        ),
        Row(
            "a",
            "pyins",
            lambda: pyins_api(imu_a, pva0),
            N,
            note="`compute_increments_from_imu` + `Integrator.integrate` (numba loop + DataFrame, Euler angles)",
        ),
        Row(
            "a",
            TWO,
            lambda: mechanize(nav0, dth, dv, DT, hold_height=True, nav_every=K).nav,
            N,
            note=f"two-speed: nav-frame terms once per {K} samples ({K * DT:g} s), all states saved, "
            "host validation included",
        ),
        Row(
            "a",
            "jaxnav (validate=False)",
            lambda: mechanize(nav0, dth, dv, DT, hold_height=True, validate=False).nav,
            N,
            note="the same without the host-side NaN/time checks of the inputs",
            warm=True,
        ),
        Row(
            "a",
            "pyins kernel",
            lambda: pyins_kernel_run(dts_a, th_a, dvc_a, pva0),
            N,
            note="numba loop only, increments corrected beforehand",
            warm=True,
        ),
    ]
    run_rows(rows_a, 2 * args.repeats, log)
    cases.append((f"(a) single trajectory, N = {N} samples ({N * DT:.0f} s at 100 Hz)", rows_a))
    res_a = rows_a[0].out
    lla_k = rows_a[4].out[0][1:]
    truth_a = pyins_pos(traj[["lat", "lon", "alt"]].to_numpy()[1 : N + 1])
    checks.append(
        f"(a) max horizontal error against pyins's true trajectory over {N * DT:.0f} s: jaxnav "
        f"{horiz_diff_m(np.asarray(res_a.pos), truth_a) * 1e3:.2f} mm, nav_every={K} "
        f"{horiz_diff_m(np.asarray(rows_a[2].out.pos), truth_a) * 1e3:.2f} mm; max horizontal "
        f"|jaxnav nav_every={K} - jaxnav| = "
        f"{horiz_diff_m(np.asarray(rows_a[2].out.pos), np.asarray(res_a.pos)) * 1e3:.3f} mm"
    )
    checks.append(
        f"(a) max horizontal |jaxnav - pyins| over {N * DT:.0f} s = "
        f"{horiz_diff_m(np.asarray(res_a.pos), pyins_pos(lla_k)) * 1e3:.2f} mm "
        f"(first-order start-of-interval terms in pyins, see tests/test_pyins.py)"
    )
    out_api = rows_a[1].out
    checks.append(
        f"pyins API = kernel: {horiz_diff_m(pyins_pos(out_api[['lat', 'lon', 'alt']].to_numpy()[1:]), pyins_pos(lla_k)):.1e} m"
    )

    # ---- batches
    S, Nb = args.save_every, args.N_batch
    rng = np.random.default_rng(args.seed)
    dth_b0, dv_b0 = jnp.asarray(dth_all[:Nb]), jnp.asarray(dv_all[:Nb])
    th_b0 = np.ascontiguousarray(inc_all[THETA].to_numpy()[:Nb])
    dvc_b0 = np.ascontiguousarray(inc_all[DVC].to_numpy()[:Nb])
    dts_b = np.ascontiguousarray(inc_all.dt.to_numpy()[:Nb])
    inc_b0 = inc_all.iloc[:Nb]

    def mech_b(n0, a, b, nav_every=1):
        return mechanize(n0, a, b, DT, save_every=S, hold_height=True, nav_every=nav_every).nav

    f_shared = jax.jit(jax.vmap(mech_b, in_axes=(0, None, None)))
    f_own = jax.jit(jax.vmap(mech_b, in_axes=(0, 0, 0)))
    mech_k = partial(mech_b, nav_every=K)
    f_shared_k = jax.jit(jax.vmap(mech_k, in_axes=(0, None, None)))
    f_own_k = jax.jit(jax.vmap(mech_k, in_axes=(0, 0, 0)))
    for B in batches:
        E = min(args.extrapolate, B)
        # initial states: 0.1 m/s velocity and 1 mrad attitude errors (trajectory 0 unperturbed)
        dq = att.rv_to_quat(jnp.asarray(rng.normal(0.0, 1e-3, (B, 3)) * (np.arange(B) > 0)[:, None]))
        navB = NavState(
            q_bn=att.quat_normalize(att.quat_mul(nav0.q_bn, dq)),
            v_n=nav0.v_n + jnp.asarray(rng.normal(0.0, 0.1, (B, 3)) * [1, 1, 0] * (np.arange(B) > 0)[:, None]),
            pos=jnp.tile(nav0.pos, (B, 1)),
        )
        pvas = [pva_from_nav0(jax.tree_util.tree_map(lambda x, i=i: x[i], navB)) for i in range(E)]
        # (b) shared record
        log(f"(b) B = {B} initial states, one IMU record, N = {Nb}")
        rows_b = [
            Row(
                "b",
                "jaxnav",
                lambda: f_shared(navB, dth_b0, dv_b0),
                B * Nb,
                note=f"`jit(vmap(mechanize))` over the initial state, save_every={S}",
            ),
            Row(
                "b",
                TWO,
                lambda: f_shared_k(navB, dth_b0, dv_b0),
                B * Nb,
                note=f"the same with `nav_every={K}` (the body-frame work is shared by the batch)",
            ),
            Row(
                "b",
                "pyins",
                lambda: [strapdown.Integrator(pv, with_altitude=False).integrate(inc_b0) for pv in pvas],
                B * Nb,
                scale=B / E,
                note=f"increments corrected once; Integrator loop, {E} of {B} timed, x{B / E:g}",
                warm=True,
            ),
            Row(
                "b",
                "pyins kernel",
                lambda: [pyins_kernel_run(dts_b, th_b0, dvc_b0, pv) for pv in pvas],
                B * Nb,
                scale=B / E,
                note=f"numba loop, {E} of {B} timed, x{B / E:g}",
                warm=True,
            ),
        ]
        run_rows(rows_b, args.repeats, log)
        cases.append((f"(b) B = {B} trajectories, one shared IMU record, N = {Nb} samples each", rows_b))
        nb = rows_b[0].out
        ref = np.asarray(res_a.pos)[S - 1 : Nb : S] if N >= Nb else None
        if ref is not None:
            checks.append(
                f"(b) B={B}: vmap trajectory 0 = single run: max |Δpos| "
                f"{np.abs(np.asarray(nb.pos[0]) - ref).max():.1e} (rad, rad, m)"
            )
        checks.append(
            f"(b) B={B}: max horizontal |nav_every={K} - per sample| over the batch "
            f"{max(horiz_diff_m(np.asarray(rows_b[1].out.pos[i]), np.asarray(nb.pos[i])) for i in range(B)) * 1e3:.3f} mm"
        )
        # (c) own record per trajectory: the record plus per-trajectory constant biases
        bg = rng.normal(0.0, 1e-6, (B, 1, 3))  # rad/s (~0.2 deg/h)
        ba = rng.normal(0.0, 1e-3, (B, 1, 3))  # m/s^2 (~0.1 mg)
        dthB = jnp.asarray(dth_all[:Nb][None] + bg * DT)
        dvB = jnp.asarray(dv_all[:Nb][None] + ba * DT)
        imus = []
        for i in range(E):
            im = imu.iloc[: Nb + 1].copy()
            im[GYRO] = im[GYRO].to_numpy() + (P @ bg[i, 0]) * DT
            im[ACC] = im[ACC].to_numpy() + (P @ ba[i, 0]) * DT
            imus.append(im)
        incs = [strapdown.compute_increments_from_imu(im, "increment") for im in imus]
        ker_in = [(np.ascontiguousarray(c[THETA].to_numpy()), np.ascontiguousarray(c[DVC].to_numpy())) for c in incs]
        log(f"(c) B = {B} trajectories, own IMU records, N = {Nb}")
        rows_c = [
            Row(
                "c",
                "jaxnav",
                lambda: f_own(navB, dthB, dvB),
                B * Nb,
                note=f"`jit(vmap(mechanize))` over initial state and record, save_every={S}",
            ),
            Row("c", TWO, lambda: f_own_k(navB, dthB, dvB), B * Nb, note=f"the same with `nav_every={K}`"),
            Row(
                "c",
                "pyins",
                lambda: [pyins_api(im, pv) for im, pv in zip(imus, pvas)],
                B * Nb,
                scale=B / E,
                note=f"per record: `compute_increments_from_imu` + `Integrator`, {E} of {B} timed, x{B / E:g}",
                warm=True,
            ),
            Row(
                "c",
                "pyins kernel",
                lambda: [pyins_kernel_run(dts_b, th, dvc, pv) for (th, dvc), pv in zip(ker_in, pvas)],
                B * Nb,
                scale=B / E,
                note=f"numba loop, {E} of {B} timed, x{B / E:g}",
                warm=True,
            ),
        ]
        run_rows(rows_c, args.repeats, log)
        cases.append((f"(c) B = {B} trajectories, each with its own IMU record, N = {Nb} samples each", rows_c))
        nc = rows_c[0].out
        lla_c = rows_c[3].out[-1][0][S : Nb + 1 : S]  # last timed trajectory, E - 1
        checks.append(
            f"(c) B={B}: max horizontal |jaxnav - pyins kernel| (trajectory {E - 1}, {Nb * DT:.0f} s) "
            f"{horiz_diff_m(np.asarray(nc.pos[E - 1]), pyins_pos(lla_c)) * 1e3:.2f} mm"
        )
        nb = nc = None  # free the batch outputs before the next section

    load1 = loadavg()
    wall = time.perf_counter() - wall0
    report = build_report(args, cases, info, load0, load1, wall, checks)
    print("\n" + report)
    if not args.no_write:
        write_results(args.results, report)
        log(f"\nwrote the bench_ins section of {args.results}")


if __name__ == "__main__":
    main()
