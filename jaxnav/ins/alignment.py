"""Static coarse alignment and IMU mounting rotations (host side, numpy).

:func:`coarse_alignment` initialises a loosely coupled run that starts at rest: levelling from the
mean specific force, gyro bias from the mean rate, heading from the GNSS course once walking.
:func:`sensor_to_body_from_upstream` turns an upstream (Groves-style, forward-right-down) IMU
orientation into the sensor -> right-forward-up body rotation C_bs.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from jaxnav.geodesy import WGS84, curvilinear_to_enu
from jaxnav.ins.attitude import euler_to_dcm, euler_to_quat, heading_to_yaw
from jaxnav.ins.mechanization import NavState

_C_RFU_FRD = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


def sensor_to_body_from_upstream(roll_deg: float, pitch_deg: float, yaw_deg: float) -> np.ndarray:
    """DCM C_bs (sensor -> jaxnav right-forward-up body) from an upstream (Groves-style) IMU orientation.

    The upstream orientation is (roll, pitch, yaw) of the sensor relative to a forward-right-down
    body frame, C_frd_s = Rz(yaw) Ry(pitch) Rx(roll); then C_bs = C_rfu_frd C_frd_s.

    Args:
      roll_deg, pitch_deg, yaw_deg: the upstream orientation, deg.
    Returns:
      (3, 3) C_bs; entries below 1e-12 in magnitude are set to zero.
    """
    r, p, y = np.radians([roll_deg, pitch_deg, yaw_deg])
    rx = np.array([[1, 0, 0], [0, np.cos(r), -np.sin(r)], [0, np.sin(r), np.cos(r)]])
    ry = np.array([[np.cos(p), 0, np.sin(p)], [0, 1, 0], [-np.sin(p), 0, np.cos(p)]])
    rz = np.array([[np.cos(y), -np.sin(y), 0], [np.sin(y), np.cos(y), 0], [0, 0, 1]])
    C = _C_RFU_FRD @ (rz @ ry @ rx)
    C[np.abs(C) < 1e-12] = 0.0
    return C


class Alignment(NamedTuple):
    """Result of :func:`coarse_alignment`.

    Attributes:
      nav0: :class:`jaxnav.ins.NavState` at ``t_imu[0] - dt[0]``.  gyro_bias: (3,) rad/s, body.
      att0: (3,) [pitch, roll, yaw] rad at the start.  t_static: end of the static window used, s.
      t_heading: time of the GNSS course used for heading, s.  course: that course (heading), rad.
      yaw_change: gyro-integrated yaw change from the start to ``t_heading``, rad.
    """

    nav0: Any
    gyro_bias: Any
    att0: Any
    t_static: float
    t_heading: float
    course: float
    yaw_change: float


def coarse_alignment(t, f_b, w_b, pos_sol, *, static_s: float = 1.5, min_speed: float = 0.5,
                     course_s: float = 2.0) -> Alignment:
    """Coarse alignment for a static start followed by walking (host side, numpy).

    1. Levelling: the mean specific force over the first ``static_s`` seconds gives pitch =
       atan2(f_y, hypot(f_x, f_z)), roll = atan2(-f_x, f_z) (jaxnav convention: f_b = g C_bn^T e_U).
       The mean gyro output there, less the Earth rate, initialises the gyro bias.
    2. Heading: the GNSS course atan2(v_E, v_N) averaged over ``course_s`` seconds from the first
       epoch whose horizontal speed (from the ``.pos`` velocity, or finite differences) exceeds
       ``min_speed``; the body is assumed to point along the walking direction. It is carried back
       to the start by the bias-corrected vertical rate (attitude-only strapdown with the levelled
       roll/pitch): yaw0 = yaw(course) - integral of the yaw rate.
    3. Position: the first GNSS epoch (the start is static), velocity zero.

    Args:
      t: (N,) IMU times (GPST s).  f_b, w_b: (N, 3) body-frame specific force (m/s^2) and rate
        (rad/s), already rotated to right-forward-up.  pos_sol: :class:`jaxnav.io.PosSolution`.
      static_s: length of the static window at the start, s.  min_speed: walking threshold, m/s.
      course_s: averaging time of the course, s.
    Returns:
      :class:`Alignment`.
    Raises:
      ValueError: if no GNSS epoch after the IMU start is faster than ``min_speed``.
    """
    t = np.asarray(t, float)
    f_b = np.asarray(f_b, float)
    w_b = np.asarray(w_b, float)
    st = t <= t[0] + static_s
    f = f_b[st].mean(0)
    pitch = math.atan2(f[1], math.hypot(f[0], f[2]))
    roll = math.atan2(-f[0], f[2])
    # position/course from GNSS
    gt = np.asarray(pos_sol.t, float)
    i0 = int(np.searchsorted(gt, t[0]))
    lat0, lon0, h0 = float(pos_sol.lat[i0]), float(pos_sol.lon[i0]), float(pos_sol.h[i0])
    v = np.asarray(pos_sol.v_enu, float)
    if not np.all(np.isfinite(v[:, :2])):
        pos0 = np.array([lat0, lon0, h0])
        pos = np.stack([np.asarray(pos_sol.lat), np.asarray(pos_sol.lon), np.asarray(pos_sol.h)], -1)
        enu = np.asarray(curvilinear_to_enu(pos0, pos - pos0))
        v = np.gradient(enu, gt, axis=0)
    speed = np.hypot(v[:, 0], v[:, 1])
    moving = np.nonzero((speed > min_speed) & (gt > t[0]))[0]
    if moving.size == 0:
        raise ValueError(f"no GNSS epoch faster than {min_speed} m/s: cannot align the heading")
    j = int(moving[0])
    sel = (gt >= gt[j]) & (gt <= gt[j] + course_s) & (gt <= t[-1])
    ve, vn = v[sel, 0].mean(), v[sel, 1].mean()
    course = math.atan2(ve, vn)
    t_head = float(gt[sel].mean())
    # gyro bias: mean rate at rest less the Earth rate seen in the body frame (yaw irrelevant here)
    C_lvl = np.asarray(euler_to_dcm(np.array([pitch, roll, 0.0])))
    w_ie_n = WGS84.omega * np.array([0.0, math.cos(lat0), math.sin(lat0)])
    gyro_bias = w_b[st].mean(0) - C_lvl.T @ w_ie_n
    # attitude-only strapdown (yaw 0 at the start) up to t_head: yaw change
    dt = np.diff(t, prepend=t[0] - (t[1] - t[0]))
    C = C_lvl.copy()
    for k in np.nonzero(t <= t_head)[0]:
        phi = (w_b[k] - gyro_bias) * dt[k]
        a = np.linalg.norm(phi)
        K = np.array([[0, -phi[2], phi[1]], [phi[2], 0, -phi[0]], [-phi[1], phi[0], 0]])
        s = np.sinc(a / np.pi)
        c = 0.5 if a < 1e-8 else (1 - math.cos(a)) / a**2
        C = C @ (np.eye(3) + s * K + c * K @ K)
    yaw_change = math.atan2(-C[0, 1], C[1, 1])
    yaw0 = float(heading_to_yaw(course)) - yaw_change
    yaw0 = math.atan2(math.sin(yaw0), math.cos(yaw0))
    att0 = np.array([pitch, roll, yaw0])
    nav0 = NavState(q_bn=np.asarray(euler_to_quat(att0)), v_n=np.zeros(3), pos=np.array([lat0, lon0, h0]))
    return Alignment(nav0=nav0, gyro_bias=gyro_bias, att0=att0, t_static=float(t[st][-1]),
                     t_heading=t_head, course=course, yaw_change=yaw_change)
