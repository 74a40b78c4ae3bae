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

The run itself is the shipped ``jaxnav ins`` config ``walk_0827``
(``jaxnav/experiments/configs/ins/walk_0827.toml``, processed by :mod:`jaxnav.experiments.ins_run`:
``run_ins(prepare(walk_config(data_root), imu=data.imu, pos=data.pos))``, ``data_root`` the folder holding
``rtklibexplorer-gnss-imu/``); this module keeps the set's reader
(:func:`load_walk`) and its frame check (:func:`frame_check`).
"""

from __future__ import annotations

import math
import pathlib
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from jaxnav.experiments.ins_run import filter_params, run_noise
from jaxnav.ins import (
    ERROR_MODEL_15,
    LCSave,
    SensorBiases,
    coarse_alignment,
    gnss_solution_measurements,
    gyro_course_rate_correlation,
    loosely_coupled,
    mounting_from_groves_deg,
    sensor_to_body,
)
from jaxnav.ins.attitude import quat_to_euler
from jaxnav.io import ImuLog, PosSolution, imu_increments, load_ins_config, read_pos, read_rtklib_imu


class WalkData(NamedTuple):
    """The walk recording: :class:`jaxnav.io.ImuLog` and :class:`jaxnav.io.PosSolution` (both GPST s since 1980)."""

    imu: ImuLog
    pos: PosSolution


def load_walk(data_dir) -> WalkData:
    """Read ``walk_0827`` (``imu_1730.csv`` + ``.tag``, ``gnss_1730_sf.pos``) from ``data_dir``.

    Args:
      data_dir: the ``walk_0827`` folder, or a folder holding it (the rtklibexplorer-gnss-imu set).
    Returns:
      :class:`WalkData` in SI units (IMU in the sensor axes).
    """
    d = pathlib.Path(data_dir)
    if (d / "walk_0827").is_dir():
        d = d / "walk_0827"
    imu = read_rtklib_imu(d / "imu_1730.csv", d / "imu_1730.csv.tag")
    return WalkData(imu=imu, pos=read_pos(d / "gnss_1730_sf.pos"))


#: Upstream walk_0827 IMU orientation (roll, pitch, yaw), deg, relative to a forward-right-down body frame.
WALK_UPSTREAM_ORIENTATION_DEG = (180.0, 0.0, -90.0)
#: Antenna lever arm (antenna minus IMU) in jaxnav's right-forward-up body frame, m: upstream IMU offset
#: (fwd, right, down) = (0, 0.05, 0) m with a zero GNSS offset gives (0, -0.05, 0) FRD = (-0.05, 0, 0) RFU.
WALK_LEVER_RFU = (-0.05, 0.0, 0.0)
#: C_bs of walk_0827 = diag(-1, -1, 1) (see the module docstring).
WALK_SENSOR_TO_BODY = sensor_to_body(mounting_from_groves_deg(*WALK_UPSTREAM_ORIENTATION_DEG))


#: the shipped ``jaxnav ins`` config of this recording
WALK_CONFIG = "walk_0827"


def walk_config(data_root=None):
    """The checked ``walk_0827`` config; ``data_root`` (the folder holding ``rtklibexplorer-gnss-imu/``) stands
    in for ``${JAXNAV_DATA}`` when given."""
    return load_ins_config(WALK_CONFIG, variables=None if data_root is None else {"JAXNAV_DATA": str(data_root)})


def frame_check(
    data,
    *,
    candidates: Sequence[float] | None = (0.0, 90.0, 180.0, 270.0),
    C_bs=WALK_SENSOR_TO_BODY,
    until_s: float = 40.0,
    cfg=None,
) -> dict:
    """Check a sensor -> body rotation on the data.

    Returns the specific force at rest in the body frame (m/s^2; must be ~ +g on up) and the innovation
    log-likelihood of the filter over the first ``until_s`` seconds (no outages) for the given C_bs
    followed by extra yaw rotations about body up of ``candidates`` deg (the right forward axis
    scores highest; a 180 deg error turns forward into backward).
    """
    if not isinstance(data, WalkData):
        data = load_walk(data)
    if cfg is None:
        cfg = walk_config(pathlib.Path(data.imu.path).resolve().parent.parent.parent)
    noise = run_noise(cfg)
    t0 = float(np.asarray(data.imu.t)[0])
    st = np.asarray(data.imu.t) <= t0 + 1.5
    f_rest = np.asarray(C_bs) @ np.asarray(data.imu.f_b)[st].mean(0)
    out = {
        "f_rest_body": f_rest,
        "w_rest_body": np.asarray(C_bs) @ np.asarray(data.imu.w_b)[st].mean(0),
        "loglik": {},
        "heading_minus_course_deg": {},
    }
    ps = data.pos
    w_up = (np.asarray(data.imu.w_b) @ np.asarray(C_bs).T)[:, 2]
    out["gyro_up_vs_course_rate_corr"] = gyro_course_rate_correlation(data.imu.t, w_up, ps.t, ps.v_enu)
    for yaw in candidates or ():
        c, s_ = math.cos(math.radians(yaw)), math.sin(math.radians(yaw))
        Rz = np.array([[c, -s_, 0], [s_, c, 0], [0, 0, 1]])
        C = Rz @ np.asarray(C_bs)
        t, dth, dv, dt = imu_increments(data.imu, C)
        n = t <= t0 + until_s
        t, dth, dv, dt = t[n], dth[n], dv[n], dt[n]
        al = coarse_alignment(t, dv / dt[:, None], dth / dt[:, None], data.pos)
        meas, _, _ = gnss_solution_measurements(data.pos, t, lever_rfu=WALK_LEVER_RFU)
        z3 = np.zeros(3)
        res = loosely_coupled(
            al.nav0,
            t,
            dth,
            dv,
            meas,
            filter_params(noise, al.nav0.pos, ERROR_MODEL_15),
            dt_imu=dt,
            biases0=SensorBiases(np.asarray(al.gyro_bias), z3, z3),
            error_model=ERROR_MODEL_15,
            save=LCSave(("nav",)),
        )
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
