"""Real-data loosely coupled INS/GNSS: the rtklibexplorer ``walk_0827`` set with simulated GNSS outages.

Data (``rtklibexplorer/GNSS_IMU``, BSD-3): a handheld consumer MEMS IMU (~160 Hz, RTKLIB time
tags) next to an RTK receiver (RTKLIB ``.pos`` at 4 Hz, fixed Q=1 for the first ~87 s, float
afterwards). No independent truth exists, so the protocol is the one of the upstream project and
KF-GINS: after a convergence period, GNSS is withheld on windows (15 s off / 15 s on) and the
forward filter and the RTS smoother are scored against the withheld RTK-*fixed* positions.

Frames. The IMU sensor axes are not jaxnav's right-forward-up body frame. The upstream
configuration gives the IMU orientation as Euler angles (roll, pitch, yaw) = (180, 0, -90) deg
relative to a forward-right-down (FRD) body frame, C_frd_s = Rz(yaw) Ry(pitch) Rx(roll)
= [[0, -1, 0], [-1, 0, 0], [0, 0, -1]] (symmetric, so the active/passive reading does not
matter). With C_rfu_frd = [[0, 1, 0], [1, 0, 0], [0, 0, -1]]:

    C_bs = C_rfu_frd C_frd_s = diag(-1, -1, +1)        (right = -x_s, forward = -y_s, up = +z_s)

a 180 deg rotation about the sensor z axis (:data:`WALK_SENSOR_TO_BODY`). Checked on the data
(:func:`frame_check`): at rest the sensor reads +9.92 m/s^2 on +z_s (so body up = +z_s, tilt
~1 deg), and among the four yaw mountings about z that keep z up, diag(-1, -1, 1) gives the best
GNSS innovation log-likelihood over the walk (the forward axis is the walking direction).

Host-side glue (numpy) around :func:`jaxnav.io.load_walk`, :func:`jaxnav.ins.coarse_alignment`,
:func:`jaxnav.ins.loosely_coupled` and :func:`jaxnav.ins.smooth`; the figure is
:func:`jaxnav.plot.plot_walk`.
"""

from __future__ import annotations

import math
import pathlib
import time
from typing import Any, NamedTuple, Optional, Sequence

import numpy as np

from jaxnav.io import write_json
from jaxnav.geodesy import curvilinear_to_enu, enu_to_curvilinear
from jaxnav.ins import (
    LCParams,
    PVMeasurements,
    SensorBiases,
    coarse_alignment,
    error_model_Qc15,
    loosely_coupled,
    sensor_to_body_from_upstream,
    smooth,
)
from jaxnav.ins.attitude import quat_to_dcm, quat_to_euler
from jaxnav.io import WalkData, imu_increments, load_walk
from jaxnav.plot import plot_walk

#: Upstream walk_0827 IMU orientation (roll, pitch, yaw), deg, relative to a forward-right-down body frame.
WALK_UPSTREAM_ORIENTATION_DEG = (180.0, 0.0, -90.0)
#: Antenna lever arm (antenna minus IMU) in jaxnav's right-forward-up body frame, m: upstream IMU offset
#: (fwd, right, down) = (0, 0.05, 0) m with a zero GNSS offset gives (0, -0.05, 0) FRD = (-0.05, 0, 0) RFU.
WALK_LEVER_RFU = (-0.05, 0.0, 0.0)
#: C_bs of walk_0827 = diag(-1, -1, 1) (see the module docstring).
WALK_SENSOR_TO_BODY = sensor_to_body_from_upstream(*WALK_UPSTREAM_ORIENTATION_DEG)


def outage_windows(t_start: float, t_end: float, *, convergence_s: float = 40.0, off_s: float = 15.0,
                   on_s: float = 15.0) -> np.ndarray:
    """(K, 2) GNSS outage windows [a, b), s: the first at ``t_start + convergence_s``, then every
    ``off_s + on_s`` seconds; only windows that end before ``t_end`` are kept."""
    out = []
    a = t_start + convergence_s
    while a + off_s <= t_end:
        out.append((a, a + off_s))
        a += off_s + on_s
    return np.array(out, float).reshape(-1, 2)


def walk_measurements(pos_sol, t_imu, outages=(), *, lever=WALK_LEVER_RFU, pos_sigma_floor: float = 0.02,
                      vel_sigma_floor: float = 0.05, use_velocity: bool = True, qualities=(1, 2)):
    """GNSS position/velocity measurements inside the IMU span, masked inside the outage windows.

    Epochs inside an outage are kept with an all-False mask, so the filter reports its free-inertial
    prediction there (and the smoother its estimate). Position covariance: the ``.pos`` ENU covariance
    with the standard deviations floored at ``pos_sigma_floor`` (m; handheld antenna, time-tag error);
    velocity: the ``.pos`` velocity covariance floored at ``vel_sigma_floor`` (m/s).

    Args:
      pos_sol: :class:`jaxnav.io.PosSolution`.  t_imu: (N,) IMU times, s.  outages: (K, 2) windows, s.
      lever: (3,) antenna lever arm, body frame, m.  qualities: ``.pos`` Q values used.
    Returns:
      (:class:`jaxnav.ins.PVMeasurements`, index (M,) of the kept .pos epochs, withheld (M,) bool).
    """
    t_imu = np.asarray(t_imu, float)
    gt = np.asarray(pos_sol.t, float)
    dt0 = t_imu[1] - t_imu[0]
    keep = np.nonzero((gt > t_imu[0] - dt0 + 1e-6) & (gt <= t_imu[-1]))[0]
    t = gt[keep]
    M = keep.size
    pos = np.stack([np.asarray(pos_sol.lat)[keep], np.asarray(pos_sol.lon)[keep], np.asarray(pos_sol.h)[keep]], -1)
    vel = np.asarray(pos_sol.v_enu, float)[keep]
    R = np.zeros((M, 6, 6))

    def floored(c, floor):
        c = np.array(c, float)
        d = np.sqrt(np.clip(np.diagonal(c, axis1=-2, axis2=-1), 0, None))
        s = np.maximum(d, floor) / np.where(d > 0, d, 1.0)
        c = c * s[:, :, None] * s[:, None, :]
        for i in range(3):
            c[:, i, i] = np.maximum(c[:, i, i], floor**2)
        return c

    R[:, :3, :3] = floored(np.asarray(pos_sol.cov_enu)[keep], pos_sigma_floor)
    vc = np.asarray(pos_sol.vcov_enu, float)[keep]
    R[:, 3:, 3:] = floored(np.where(np.isfinite(vc), vc, 1.0), vel_sigma_floor)
    q = np.asarray(pos_sol.q)[keep]
    ok = np.isin(q, np.asarray(qualities))
    withheld = np.zeros(M, bool)
    for a, b in np.asarray(outages, float).reshape(-1, 2):
        withheld |= (t >= a) & (t < b)
    mask = np.zeros((M, 6), bool)
    mask[:, :3] = (ok & ~withheld)[:, None]
    if use_velocity:
        mask[:, 3:] = (ok & ~withheld)[:, None] & np.isfinite(vel)
    vel = np.where(np.isfinite(vel), vel, 0.0)
    lev = np.broadcast_to(np.asarray(lever, float), (M, 3)).copy()
    return PVMeasurements(t=t, pos=pos, vel=vel, R=R, mask=mask, lever=lev), keep, withheld


class WalkNoise(NamedTuple):
    """15-state noise settings for the walk's consumer MEMS IMU (all SI).

    Defaults, and why:
      gyro_arw 1e-3 rad/sqrt(s) (3.4 deg/sqrt(h)): the sensor's white noise at rest is ~0.2 deg/sqrt(h)
        (0.0005 rad/s std at 160 Hz); the 15-state model has no bias random walk, so the density is
        inflated ~15x to cover the in-run bias instability of a consumer gyro and handheld vibration.
      accel_vrw 0.02 m/s/sqrt(s) (1.2 m/s/sqrt(h)): white noise at rest ~0.001 m/s/sqrt(s), inflated
        for walking vibration, scale-factor error (|f| = 9.92 at rest vs g = 9.80) and bias drift.
      att0: [roll/pitch, yaw] initial 1-sigma, rad: 1 deg from levelling (0.1 m/s^2 accel bias ~
        0.6 deg), 10 deg for the GNSS-course heading of a handheld device.
      vel0 0.1 m/s; pos0 0.05 m (the first RTK fix);
      gyro_bias0 0.002 rad/s (0.11 deg/s): residual after the static-start estimate (consumer
        gyros shift by this much with motion/temperature).
      accel_bias0 0.15 m/s^2: consumer accelerometer bias + the 1.2 % excess at rest.
    """

    gyro_arw: float = 1e-3
    accel_vrw: float = 0.02
    att0: tuple = (math.radians(1.0), math.radians(10.0))
    vel0: float = 0.1
    pos0: float = 0.05
    gyro_bias0: float = 0.002
    accel_bias0: float = 0.15


def walk_params(nav0, noise: WalkNoise = WalkNoise()):
    """:class:`jaxnav.ins.LCParams` (15 states) from :class:`WalkNoise` at the start position ``nav0.pos`` (3,)."""
    sd = np.concatenate([
        [noise.att0[0], noise.att0[0], noise.att0[1]],
        [noise.vel0] * 3,
        np.asarray(enu_to_curvilinear(np.asarray(nav0.pos, float), np.full(3, noise.pos0))),
        [noise.gyro_bias0] * 3,
        [noise.accel_bias0] * 3,
    ])
    return LCParams(P0=np.diag(sd**2), Qc=np.asarray(error_model_Qc15(noise.gyro_arw, noise.accel_vrw)),
                    tau_markov=300.0, R_scale=1.0)


class OutageScores(NamedTuple):
    """Scores of one run against the withheld RTK-fixed positions (horizontal, m).

    Attributes:
      windows: (K, 2) outage windows, s (GPST).  n_ref: (K,) fixed epochs scored per window.
      fwd_max, sm_max: (K,) max horizontal error per outage (NaN where no fixed epoch).
      fwd_rms, sm_rms: (K,) RMS horizontal error per outage.
      fwd_rms_all, sm_rms_all: RMS over all scored epochs of all outages.
      fwd_max_mean, sm_max_mean: mean of the per-outage maxima.
      fwd_rms_outside: RMS horizontal error of the forward filter against fixed epochs *outside*
        the outages (sanity: should be cm-level).
      t, err_fwd, err_sm: (M,) epoch times and horizontal errors (NaN where not a fixed reference).
      withheld: (M,) bool.  runtime_s: wall time of filter + smoother (incl. compilation).
      figure: path of the figure, or None.  n_nonfinite_nav: NaN count in the navigation outputs.
    """

    windows: Any
    n_ref: Any
    fwd_max: Any
    sm_max: Any
    fwd_rms: Any
    sm_rms: Any
    fwd_rms_all: float
    sm_rms_all: float
    fwd_max_mean: float
    sm_max_mean: float
    fwd_rms_outside: float
    t: Any
    err_fwd: Any
    err_sm: Any
    withheld: Any
    runtime_s: float
    figure: Optional[str]
    n_nonfinite_nav: int


def _antenna_enu(nav, t_nav, t, lever, pos0):
    """(M, 3) antenna ENU (m, around pos0 (3,)) of per-epoch nav states extrapolated to the epoch times."""
    pos = np.asarray(nav.pos)
    enu = np.asarray(curvilinear_to_enu(pos0, pos - pos0))
    C = np.asarray(quat_to_dcm(np.asarray(nav.q_bn)))
    v = np.asarray(nav.v_n)
    return enu + (np.asarray(t) - np.asarray(t_nav))[:, None] * v + np.einsum("mij,mj->mi", C, lever)


def run_walk(data, *, C_bs=WALK_SENSOR_TO_BODY, noise: WalkNoise = WalkNoise(), convergence_s: float = 40.0,
             off_s: float = 15.0, on_s: float = 15.0, outages=None, lever=WALK_LEVER_RFU,
             use_velocity: bool = True, out_dir=None, fig_name: str = "walk_outages.png") -> tuple[OutageScores, dict]:
    """Run the 15-state LC filter and the RTS smoother on the walk with simulated outages; score them.

    Args:
      data: :class:`jaxnav.io.WalkData` (or a directory for :func:`jaxnav.io.load_walk`).
      C_bs: (3, 3) sensor -> body DCM.  noise: :class:`WalkNoise`.
      convergence_s, off_s, on_s: outage protocol (:func:`outage_windows` from the IMU start), s, unless
        ``outages`` (K, 2) is given explicitly.
      out_dir: if given, the figure (:func:`jaxnav.plot.plot_walk`) is written there.
    Returns:
      (:class:`OutageScores`, extras dict with "alignment", "result", "meas", "smoothed_nav", "enu_ref").
    """
    if not isinstance(data, WalkData):
        data = load_walk(data)
    t, dth, dv, dt = imu_increments(data.imu, C_bs)
    align = coarse_alignment(t, dv / dt[:, None], dth / dt[:, None], data.pos)
    if outages is None:
        outages = outage_windows(t[0], t[-1], convergence_s=convergence_s, off_s=off_s, on_s=on_s)
    outages = np.asarray(outages, float).reshape(-1, 2)
    meas, keep, withheld = walk_measurements(data.pos, t, outages, lever=lever, use_velocity=use_velocity)
    params = walk_params(align.nav0, noise)
    z3 = np.zeros(3)
    b0 = SensorBiases(gyro=np.asarray(align.gyro_bias), markov=z3, accel=z3)
    t_run = time.perf_counter()
    res = loosely_coupled(align.nav0, t, dth, dv, meas, params, dt_imu=dt, biases0=b0, n_states=15,
                          save=("nav", "biases", "covs", "pred_covs", "Phi", "corrections"))
    sm_nav, sm_b, sm_P = smooth(res, n_states=15)
    np.asarray(sm_nav.pos)
    runtime = time.perf_counter() - t_run
    ep = res.epochs
    pos0 = np.array([float(x) for x in align.nav0.pos])
    lev = np.asarray(meas.lever)
    enu_f = _antenna_enu(ep.nav, ep.t_nav, meas.t, lev, pos0)
    enu_s = _antenna_enu(sm_nav, ep.t_nav, meas.t, lev, pos0)
    ps = data.pos
    pos_ref = np.stack([np.asarray(ps.lat)[keep], np.asarray(ps.lon)[keep], np.asarray(ps.h)[keep]], -1)
    enu_ref = np.asarray(curvilinear_to_enu(pos0, pos_ref - pos0))
    fixed = np.asarray(ps.q)[keep] == 1
    e_f = np.hypot(*(enu_f - enu_ref)[:, :2].T)
    e_s = np.hypot(*(enu_s - enu_ref)[:, :2].T)
    e_f = np.where(fixed, e_f, np.nan)
    e_s = np.where(fixed, e_s, np.nan)
    K = outages.shape[0]
    n_ref = np.zeros(K, int)
    stats = {k: np.full(K, np.nan) for k in ("fm", "sm", "fr", "sr")}
    for k, (a, b) in enumerate(outages):
        s = (meas.t >= a) & (meas.t < b) & fixed
        n_ref[k] = int(s.sum())
        if n_ref[k]:
            stats["fm"][k], stats["sm"][k] = e_f[s].max(), e_s[s].max()
            stats["fr"][k] = math.sqrt(np.mean(e_f[s] ** 2))
            stats["sr"][k] = math.sqrt(np.mean(e_s[s] ** 2))
    sc = withheld & fixed
    out_fixed = ~withheld & fixed
    nonfinite = int(sum(np.count_nonzero(~np.isfinite(np.asarray(a))) for a in (*ep.nav, *sm_nav)))

    def _rms(x):
        return float(np.sqrt(np.mean(x**2))) if x.size else float("nan")

    scores = OutageScores(
        windows=outages, n_ref=n_ref, fwd_max=stats["fm"], sm_max=stats["sm"], fwd_rms=stats["fr"],
        sm_rms=stats["sr"], fwd_rms_all=_rms(e_f[sc]), sm_rms_all=_rms(e_s[sc]),
        fwd_max_mean=float(np.nanmean(stats["fm"])) if np.any(n_ref) else float("nan"),
        sm_max_mean=float(np.nanmean(stats["sm"])) if np.any(n_ref) else float("nan"),
        fwd_rms_outside=_rms(e_f[out_fixed]), t=np.asarray(meas.t), err_fwd=e_f, err_sm=e_s, withheld=withheld,
        runtime_s=runtime, figure=None, n_nonfinite_nav=nonfinite)
    extras = dict(alignment=align, result=res, meas=meas, smoothed_nav=sm_nav, smoothed_biases=sm_b,
                  enu_fwd=enu_f, enu_sm=enu_s, enu_ref=enu_ref, fixed=fixed)
    if out_dir is not None:
        fig = plot_walk(scores, extras, pathlib.Path(out_dir) / fig_name)
        scores = scores._replace(figure=str(fig))
    return scores, extras


def write_walk_scores(out_dir, scores: OutageScores) -> pathlib.Path:
    """Write :class:`OutageScores` as ``out_dir/scores.json`` (arrays as lists; units as in the record)."""
    path = pathlib.Path(out_dir) / "scores.json"
    write_json(path, scores._asdict())
    return path


def format_walk(scores: OutageScores) -> str:
    """The per-outage and overall horizontal errors of :func:`run_walk` as text (m)."""
    lines = [f"walk set, {len(scores.windows)} simulated GNSS outages of 15 s scored against withheld RTK-fixed fixes"]
    for k, (w, n) in enumerate(zip(scores.windows, scores.n_ref)):
        lines.append(f"  outage {k + 1} [{w[0]:.1f}, {w[1]:.1f}] s, {int(n)} fixed epochs: max horizontal error "
                     f"forward {scores.fwd_max[k]:.2f} m, smoothed {scores.sm_max[k]:.2f} m")
    lines.append(f"  RMS over outages: forward {scores.fwd_rms_all:.2f} m, smoothed {scores.sm_rms_all:.2f} m; "
                 f"forward outside outages {scores.fwd_rms_outside:.3f} m")
    return "\n".join(lines)


def frame_check(data, *, candidates: Optional[Sequence[float]] = (0.0, 90.0, 180.0, 270.0),
                C_bs=WALK_SENSOR_TO_BODY, until_s: float = 40.0) -> dict:
    """Check a sensor -> body rotation on the data.

    Returns the specific force at rest in the body frame (m/s^2; must be ~ +g on up) and the innovation
    log-likelihood of the filter over the first ``until_s`` seconds (no outages) for the given C_bs
    followed by extra yaw rotations about body up of ``candidates`` deg (the right forward axis
    scores highest; a 180 deg error turns forward into backward).
    """
    if not isinstance(data, WalkData):
        data = load_walk(data)
    t0 = float(np.asarray(data.imu.t)[0])
    st = np.asarray(data.imu.t) <= t0 + 1.5
    f_rest = np.asarray(C_bs) @ np.asarray(data.imu.f_b)[st].mean(0)
    out = {"f_rest_body": f_rest, "w_rest_body": np.asarray(C_bs) @ np.asarray(data.imu.w_b)[st].mean(0),
           "loglik": {}, "heading_minus_course_deg": {}}
    # gyro sign: body-up rate (device held roughly level) against the GNSS course rate while walking;
    # yaw (counter-clockwise) rate = -heading rate, so the correlation must be strongly positive
    ps = data.pos
    gt = np.asarray(ps.t, float)
    v = np.asarray(ps.v_enu, float)
    walk = (np.hypot(v[:, 0], v[:, 1]) > 0.5) & (gt > t0) & (gt < float(np.asarray(data.imu.t)[-1]))
    course = np.unwrap(np.arctan2(v[walk, 0], v[walk, 1]))
    tw = gt[walk]
    w_up = (np.asarray(data.imu.w_b) @ np.asarray(C_bs).T)[:, 2]
    edges = np.arange(tw[0], tw[-1], 1.0)
    ti = np.asarray(data.imu.t)
    g_rate, c_rate = [], []
    for a in edges[:-1]:
        si = (ti >= a) & (ti < a + 1.0)
        sg = (tw >= a) & (tw < a + 1.0)
        if sg.sum() >= 3 and np.all(np.diff(tw[sg]) < 0.3) and si.any():
            g_rate.append(w_up[si].mean())
            c_rate.append(-np.polyfit(tw[sg] - a, course[sg], 1)[0])
    out["gyro_up_vs_course_rate_corr"] = float(np.corrcoef(g_rate, c_rate)[0, 1])
    for yaw in candidates or ():
        c, s_ = math.cos(math.radians(yaw)), math.sin(math.radians(yaw))
        Rz = np.array([[c, -s_, 0], [s_, c, 0], [0, 0, 1]])
        C = Rz @ np.asarray(C_bs)
        t, dth, dv, dt = imu_increments(data.imu, C)
        n = t <= t0 + until_s
        t, dth, dv, dt = t[n], dth[n], dv[n], dt[n]
        al = coarse_alignment(t, dv / dt[:, None], dth / dt[:, None], data.pos)
        meas, _, _ = walk_measurements(data.pos, t)
        z3 = np.zeros(3)
        res = loosely_coupled(al.nav0, t, dth, dv, meas, walk_params(al.nav0), dt_imu=dt,
                              biases0=SensorBiases(np.asarray(al.gyro_bias), z3, z3), n_states=15, save=("nav",))
        out["loglik"][yaw] = float(res.loglik)
        # converged device heading minus the velocity course while walking (median over epochs after
        # 20 s): the forward axis points along the walk if this is small
        ep = res.epochs
        head = -np.degrees(np.asarray(quat_to_euler(ep.nav.q_bn))[:, 2])
        vn = np.asarray(ep.nav.v_n)
        crs = np.degrees(np.arctan2(vn[:, 0], vn[:, 1]))
        w = (np.hypot(vn[:, 0], vn[:, 1]) > 0.6) & (np.asarray(meas.t) > t0 + 20.0)
        d = (head - crs + 180.0) % 360.0 - 180.0
        out["heading_minus_course_deg"][yaw] = float(np.median(d[w])) if w.any() else float("nan")
    return out
