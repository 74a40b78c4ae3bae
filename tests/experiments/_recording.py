"""A simulated car recording written as files, for ``jaxnav ins`` tests with known truth.

The IMU log is in the KF-GINS text format (GPS seconds of week, angle and velocity increments in the
*sensor* axes), the GNSS solution in the KF-GINS GNSS format (lat, lon, h, sigmas N/E/D), with a
known mounting (sensor attitude in the FRD vehicle frame), antenna lever arm and IMU time-tag error.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import jax
import numpy as np

from jaxnav import sim
from jaxnav.geodesy import enu_to_curvilinear
from jaxnav.ins import C_RFU_FRD, ImuNoise, mounting_from_rpy_deg
from jaxnav.ins.attitude import quat_to_dcm

WEEK = 2380
SOW0 = 345_600.0  # Thursday 00:00 GPST


class Recording(NamedTuple):
    imu_file: Any
    gnss_file: Any
    truth: Any  # sim.Trajectory (body = RFU vehicle frame)
    t_gnss: Any  # (M,) true GNSS epochs, s since the start
    tag_error_s: float  # IMU time tags = true time + tag_error_s


def car_spec():
    """A 200 s drive: 20 s standing, accelerations, turns both ways, a stop-and-go."""
    S = sim.Segment
    r = math.radians
    segs = (
        S("rest", duration=20.0),
        S("accelerate", duration=8.0, dspeed=12.0),
        S("cruise", hold=10.0),
        S("turn", duration=8.0, dheading=r(90.0)),
        S("cruise", hold=12.0),
        S("turn", duration=6.0, dheading=r(-60.0)),
        S("cruise", hold=10.0),
        S("accelerate", duration=6.0, dspeed=-12.0),
        S("rest", duration=8.0),
        S("accelerate", duration=6.0, dspeed=10.0),
        S("turn", duration=10.0, dheading=r(-120.0)),
        S("cruise", hold=14.0),
        S("turn", duration=8.0, dheading=r(75.0)),
        S("cruise", hold=20.0),
        S("turn", duration=6.0, dheading=r(40.0)),
        S("cruise", hold=48.0),
    )
    return sim.TrajectorySpec(lat=r(40.1), lon=r(-105.2), h=1600.0, heading=r(30.0), speed=0.0, segments=segs)


def short_car_spec():
    """A 110 s drive: 16 s standing, then accelerations and turns both ways at up to 12 m/s (no stop)."""
    S = sim.Segment
    r = math.radians
    segs = (
        S("rest", duration=16.0),
        S("accelerate", duration=6.0, dspeed=12.0),
        S("cruise", hold=8.0),
        S("turn", duration=6.0, dheading=r(90.0)),
        S("cruise", hold=10.0),
        S("turn", duration=6.0, dheading=r(-60.0)),
        S("cruise", hold=8.0),
        S("turn", duration=8.0, dheading=r(-120.0)),
        S("cruise", hold=12.0),
        S("turn", duration=6.0, dheading=r(75.0)),
        S("cruise", hold=24.0),
    )
    return sim.TrajectorySpec(lat=r(40.1), lon=r(-105.2), h=1600.0, heading=r(30.0), speed=0.0, segments=segs)


def walk_spec():
    """A 120 s walk at 1.4 m/s: 16 s standing, then straight legs joined by turns both ways (no stop)."""
    S = sim.Segment
    r = math.radians
    segs = (
        S("rest", duration=16.0),
        S("accelerate", duration=2.0, dspeed=1.4),
        S("cruise", hold=14.0),
        S("turn", duration=5.0, dheading=r(90.0)),
        S("cruise", hold=20.0),
        S("turn", duration=4.0, dheading=r(-90.0)),
        S("cruise", hold=15.0),
        S("turn", duration=6.0, dheading=r(180.0)),
        S("cruise", hold=38.0),
    )
    return sim.TrajectorySpec(lat=r(40.1), lon=r(-105.2), h=1600.0, heading=r(30.0), speed=0.0, segments=segs)


def write_car(
    folder,
    *,
    seed=0,
    mounting_rpy_deg=(3.0, -4.0, 100.0),
    lever_frd=(0.6, 0.3, -1.4),
    tag_error_s=-0.15,
    imu_rate=100.0,
    gnss_rate=2.0,
    pos_sigma=0.02,
    vel_sigma=0.03,
    vel_sigma_stated=None,
    vibration=1.0,
    spec=None,
    imu_start_s=0.0,
    gyro_white=math.radians(0.15) / 60,
    accel_white=0.04 / 60,
    gyro_bias=math.radians(5.0) / 3600,
    accel_bias=2e-3 * 9.81,
) -> Recording:
    """Simulate the car (industrial-grade IMU errors, RTK-level GNSS) and write ``imu.txt`` / ``gnss.txt``;
    ``vibration`` scales the engine and road vibration while moving (0: a perfectly smooth road);
    ``spec``: another :class:`jaxnav.sim.TrajectorySpec` (default :func:`car_spec`);
    ``imu_start_s``: the IMU log starts at this true time, s (GNSS starts at 1 s); ``gyro_white`` rad/sqrt(s),
    ``accel_white`` m/s/sqrt(s): the sensors' white noise densities (ARW, VRW), ``gyro_bias`` rad/s,
    ``accel_bias`` m/s^2: the 1-sigma of their constant biases; ``vel_sigma_stated``: the GNSS velocity sigma
    written to the file (default ``vel_sigma``, the simulated one)."""
    truth = sim.generate_trajectory(car_spec() if spec is None else spec, imu_rate_hz=imu_rate)
    dt = float(truth.dt)
    noise = ImuNoise(
        gyro_arw=gyro_white,
        accel_vrw=accel_white,
        gyro_bias_initial=gyro_bias,
        accel_bias_initial=accel_bias,
    )
    kg, ka, kn = jax.random.split(jax.random.PRNGKey(seed), 3)
    dth = np.array(sim.corrupt_increments(kg, truth.dtheta, dt, noise, "gyro")[0])
    dv = np.array(sim.corrupt_increments(ka, truth.dv, dt, noise, "accel")[0])
    # engine and road vibration while the car moves (zero-mean sinusoids: 0.3 m/s^2 at 23 Hz vertical,
    # 0.15 m/s^2 at 31 Hz lateral, 0.01 rad/s at 17 Hz in roll); none at standstill, engine off
    t_end = np.asarray(truth.t)
    moving = np.linalg.norm(np.asarray(truth.v_n)[1:], axis=1) > 0.05

    def vib(amp, hz):  # increment of amp sin(2 pi hz t) over (t_k, t_k+1]
        return (
            vibration
            * amp
            / (2 * np.pi * hz)
            * (np.cos(2 * np.pi * hz * t_end[:-1]) - np.cos(2 * np.pi * hz * t_end[1:]))
        )

    dv[:, 2] += np.where(moving, vib(0.3, 23.0), 0.0)
    dv[:, 0] += np.where(moving, vib(0.15, 31.0), 0.0)
    dth[:, 1] += np.where(moving, vib(0.01, 17.0), 0.0)
    # body (RFU vehicle) -> FRD vehicle -> sensor: v_s = C_vs^T C_frd_rfu v_b
    C_vs = mounting_from_rpy_deg(*mounting_rpy_deg)
    C_sb = C_vs.T @ C_RFU_FRD
    dth_s, dv_s = dth @ C_sb.T, dv @ C_sb.T
    t = np.asarray(truth.t)[1:]
    folder.mkdir(parents=True, exist_ok=True)
    imu_file = folder / "imu.txt"
    rows = np.column_stack([SOW0 + t + tag_error_s, dth_s, dv_s])[t >= imu_start_s - 1e-9]
    np.savetxt(imu_file, rows, fmt=["%.4f"] + ["%.12e"] * 6)
    # GNSS antenna: truth position + C_bn lever (RFU body), noise; at the GNSS rate from 1 s on
    step = int(round(1.0 / (gnss_rate * dt)))
    idx = np.arange(step, t.size + 1, step)
    pos = np.asarray(truth.pos)[idx]
    C = np.asarray(quat_to_dcm(np.asarray(truth.q_bn)[idx]))
    lever_b = C_RFU_FRD @ np.asarray(lever_frd, float)
    rng = np.random.default_rng(seed)
    enu = np.einsum("mij,j->mi", C, lever_b) + rng.normal(0.0, pos_sigma, (idx.size, 3))
    ant = pos + np.asarray(enu_to_curvilinear(pos, enu))
    w = np.asarray(truth.dtheta)[idx - 1] / dt
    v_ant = np.asarray(truth.v_n)[idx] + np.einsum("mij,mj->mi", C, np.cross(w, lever_b))
    v_ant = v_ant + rng.normal(0.0, vel_sigma, (idx.size, 3))
    gnss_file = folder / "gnss.txt"
    tg = np.asarray(truth.t)[idx]
    sd = np.tile([pos_sigma, pos_sigma, pos_sigma], (idx.size, 1))
    vsd = np.tile([vel_sigma if vel_sigma_stated is None else vel_sigma_stated] * 3, (idx.size, 1))
    # 13 columns: sow, lat, lon, h, vN, vE, vD, sdN, sdE, sdD, sdvN, sdvE, sdvD
    g = np.column_stack(
        [
            SOW0 + tg,
            np.degrees(ant[:, 0]),
            np.degrees(ant[:, 1]),
            ant[:, 2],
            v_ant[:, 1],
            v_ant[:, 0],
            -v_ant[:, 2],
            sd,
            vsd,
        ]
    )
    np.savetxt(gnss_file, g, fmt=["%.4f", "%.10f", "%.10f", "%.4f"] + ["%.5f"] * 9)
    return Recording(imu_file=imu_file, gnss_file=gnss_file, truth=truth, t_gnss=tg, tag_error_s=tag_error_s)


def car_config(
    rec: Recording,
    folder,
    *,
    time_offset="estimate",
    states=15,
    extra="",
    evaluate_extra="",
    noise=None,
    tune=None,
    evaluate="first_s = 60.0\noutage_s = 20.0\ngap_s = 40.0\nend_margin_s = 10.0",
    min_speed=3.0,
) -> str:
    """A ``jaxnav ins`` TOML for the recording (paths relative to ``folder``); ``evaluate_extra``: more
    ``[evaluate]`` keys (e.g. a reference trajectory), ``extra``: further sections; ``noise``: the
    ``[noise]`` keys instead of the industrial grade's with the simulated densities; ``tune``: the
    ``[tune]`` keys (default ``calibrate = false``: these runs test other things than calibration);
    ``evaluate``: the outage keys of ``[evaluate]``; ``min_speed``: ``alignment.min_speed_m_s``."""
    if noise is None:
        noise = (
            'grade = "industrial"\narw_deg_per_sqrt_h = 0.15\nvrw_m_per_s_per_sqrt_h = 0.04\n'
            "init_gyro_bias_deg_per_s = 0.01\ninit_accel_bias_mg = 5.0\ninit_attitude_deg = [1.0, 5.0]"
        )
    if tune is None:
        tune = "calibrate = false"
    text = f"""
[run]
name = "simulated car"

[imu]
file = "{rec.imu_file.name}"
format = "kf-gins"
gps_week = {WEEK}
mounting_rpy_deg = [3.0, -4.0, 100.0]
time_offset_s = {time_offset if isinstance(time_offset, float) else '"' + time_offset + '"'}
time_offset_search_s = 0.2

[gnss]
file = "{rec.gnss_file.name}"
format = "kf-gins"
gps_week = {WEEK}
lever_arm_frd_m = [0.6, 0.3, -1.4]
pos_sigma_floor_m = 0.02
vel_sigma_floor_m_s = 0.03

[noise]
states = {states}
{noise}

[alignment]
static_s = 15.0
heading = "gnss"
min_speed_m_s = {min_speed}

[evaluate]
{evaluate}
{evaluate_extra}

[tune]
{tune}
{extra}
"""
    p = folder / "car.toml"
    p.write_text(text, encoding="utf-8")
    return p


def write_truth_nav(rec: Recording, path, *, step: int = 1):
    """The recording's true IMU trajectory as a KF-GINS ``truth.nav`` (week, seconds of week, lat, lon deg,
    h m, vN vE vD m/s, roll pitch yaw deg of the vehicle frame), every ``step``-th sample."""
    tr = rec.truth
    pos = np.asarray(tr.pos)[::step]
    v = np.asarray(tr.v_n)[::step]
    e = np.asarray(tr.euler)[::step]  # [pitch, roll, yaw] of the RFU body in ENU
    t = np.asarray(tr.t)[::step]
    yaw = np.mod(-np.degrees(e[:, 2]), 360.0)
    rows = np.column_stack(
        [
            np.full(t.size, WEEK),
            SOW0 + t,
            np.degrees(pos[:, 0]),
            np.degrees(pos[:, 1]),
            pos[:, 2],
            v[:, 1],
            v[:, 0],
            -v[:, 2],
            np.degrees(e[:, 1]),
            np.degrees(e[:, 0]),
            yaw,
        ]
    )
    np.savetxt(path, rows, fmt=["%d", "%.4f", "%.10f", "%.10f", "%.4f"] + ["%.5f"] * 3 + ["%.6f"] * 3)
    return path
