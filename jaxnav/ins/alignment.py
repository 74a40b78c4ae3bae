"""Static coarse alignment (host side, numpy + one jitted scan).

:func:`coarse_alignment` initialises a loosely coupled run that starts at rest: levelling from the
mean specific force, gyro bias from the mean rate, heading by gyrocompassing where the gyros are
good enough, else from the GNSS course once moving, or a given heading / attitude. The returned
:class:`Alignment` records which heading method was used and its predicted accuracy.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxnav.geodesy import WGS84, curvilinear_to_enu, enu_to_curvilinear
from jaxnav.ins.attitude import euler_to_dcm, euler_to_quat, heading_to_yaw, quat_mul, quat_to_dcm, rv_to_quat
from jaxnav.ins.mechanization import NavState

#: heading methods :func:`coarse_alignment` reports
HEADING_METHODS = ("gnss_course", "gyrocompass", "given")


class Alignment(NamedTuple):
    """Result of :func:`coarse_alignment`.

    Attributes:
      nav0: :class:`jaxnav.ins.NavState` at ``t_imu[0] - dt[0]``.  gyro_bias: (3,) rad/s, body.
      att0: (3,) [pitch, roll, yaw] rad at the start.  t_static: end of the static window used, s.
      t_heading: time the heading refers to, s (the GNSS course time; ``t[0]`` otherwise).
      course: the GNSS course (heading) used, rad (NaN if none).
      yaw_change: gyro-integrated yaw change from the start to ``t_heading``, rad (0 if none).
      heading_method: "gnss_course", "gyrocompass" or "given".
      heading_sigma: predicted 1-sigma of the initial heading, rad (gyrocompass: the criterion's
        prediction; NaN for "gnss_course" and "given").
      gyrocompass_sigma: the criterion's predicted gyrocompass heading 1-sigma, rad (whatever method
        was used; inf at the poles).
      gyro_arw: angle random walk used in the criterion, rad/sqrt(s) (given, or from the data).
      n_static: number of IMU samples in the static window.
    """

    nav0: NavState
    gyro_bias: np.ndarray
    att0: np.ndarray
    t_static: float
    t_heading: float
    course: float
    yaw_change: float
    heading_method: str = "gnss_course"
    heading_sigma: float = math.nan
    gyrocompass_sigma: float = math.nan
    gyro_arw: float = math.nan
    n_static: int = 0


@jax.jit
def _attitude_only(q0, dtheta):
    """Attitude-only strapdown q_{k+1} = q_k (x) q(dtheta_k); returns the final q."""

    def step(q, phi):
        return quat_mul(q, rv_to_quat(phi)), None

    q, _ = jax.lax.scan(step, q0, dtheta)
    return q


def _yaw_change(pitch, roll, w_b, dt, bias, sel, lat):
    """Yaw change (rad) over the samples ``sel`` of the bias-corrected rate, less the Earth rate's
    vertical part (a left rotation about the navigation up axis: exactly additive in yaw)."""
    if not np.any(sel):
        return 0.0
    q0 = jnp.asarray(np.asarray(euler_to_quat(jnp.asarray([pitch, roll, 0.0]))))
    dth = jnp.asarray((w_b[sel] - bias) * dt[sel, None])
    C = np.asarray(quat_to_dcm(_attitude_only(q0, dth)))
    span = float(np.sum(dt[sel]))
    y = math.atan2(-C[0, 1], C[1, 1]) - WGS84.omega * math.sin(lat) * span
    return math.atan2(math.sin(y), math.cos(y))


def _gnss_velocity(pos_sol, lat0, lon0, h0):
    gt = np.asarray(pos_sol.t, float)
    v = np.asarray(pos_sol.v_enu, float)
    if not np.all(np.isfinite(v[:, :2])):
        pos0 = np.array([lat0, lon0, h0])
        pos = np.stack([np.asarray(pos_sol.lat), np.asarray(pos_sol.lon), np.asarray(pos_sol.h)], -1)
        enu = np.asarray(curvilinear_to_enu(pos0, pos - pos0))
        v = np.gradient(enu, gt, axis=0)
    return gt, v


def coarse_alignment(
    t,
    f_b,
    w_b,
    pos_sol=None,
    *,
    static_s: float = 1.5,
    min_speed: float = 0.5,
    course_s: float = 2.0,
    heading="gnss",
    position=None,
    attitude=None,
    gyro_arw=None,
    gyro_bias_sigma: float = 0.0,
    max_gyrocompass_sigma: float = math.radians(1.0),
    lever_rfu=None,
) -> Alignment:
    """Coarse alignment for a static start (host side, numpy).

    1. Levelling (Groves 2013, ch. 5, initialization and alignment): the mean specific
       force over the first ``static_s`` seconds gives pitch = atan2(f_y, hypot(f_x, f_z)),
       roll = atan2(-f_x, f_z) (jaxnav convention: f_b = g C_bn^T e_U, body right-forward-up).
    2. Heading, by ``heading``:

       * ``"gyrocompass"``: the mean rate in the levelled frame is the Earth rate turned by the
         yaw, w_L = Rz(yaw)^T (0, W cos(lat), W sin(lat)), so yaw = atan2(w_L,x, w_L,y).
         A horizontal gyro bias b is indistinguishable from the Earth rate at rest and the white
         noise averages down over the window T, so the heading error is
         ``sigma_psi = sqrt(b^2 + N^2 / T) / (W cos(lat))`` (W = 7.292e-5 rad/s, N the angle
         random walk: ``gyro_arw``, or the static window's sample scatter std(w) sqrt(dt), which
         vibration only inflates; b = ``gyro_bias_sigma``, which the data cannot show: pass the
         datasheet's bias instability).
       * ``"auto"``: ``"gyrocompass"`` if that predicted sigma_psi <= ``max_gyrocompass_sigma``
         (default 1 deg), else ``"gnss"``. A navigation-grade IMU (0.002 deg/sqrt(h), 0.01 deg/h)
         passes within seconds at mid latitudes; a consumer MEMS (0.3 deg/sqrt(h), 10 deg/h) never.
       * ``"gnss"`` (default): the GNSS course atan2(v_E, v_N), averaged over ``course_s`` seconds
         from the first epoch faster than ``min_speed`` (``.pos`` velocity, or finite differences of
         the positions); the body is assumed to point along the velocity (no sideslip). It is
         carried back to the start by the bias-corrected gyro (attitude-only strapdown from the
         levelled attitude, less the vertical Earth rate): yaw0 = yaw(course) - yaw change.
       * a number: the given initial heading at ``t[0]``, rad clockwise from north.
       ``attitude`` (3,) [pitch, roll, yaw] rad overrides levelling and heading ("given").
    3. Gyro bias: the mean static rate less the Earth rate in the body frame, C_bn^T w_ie^n, with
       the final attitude (with gyrocompassing its horizontal part is zero by construction).
    4. Position: ``position`` (lat rad, lon rad, h m) or the first GNSS epoch at or after ``t[0]``;
       velocity zero. A GNSS position is the antenna's: with ``lever_rfu`` it is moved to the IMU,
       p_imu = p_ant - C_bn l (first order, :func:`jaxnav.geodesy.enu_to_curvilinear`).

    Args:
      t: (N,) IMU times (s).  f_b, w_b: (N, 3) body-frame specific force (m/s^2) and rate (rad/s),
        already rotated to right-forward-up (:func:`jaxnav.ins.sensor_to_body`).
      pos_sol: :class:`jaxnav.io.PosSolution` (needed for the position unless ``position`` is
        given, and for ``heading="gnss"``).
      static_s: length of the static window at the start, s.  min_speed: moving threshold, m/s.
      course_s: averaging time of the course, s.
      heading: "gnss", "auto", "gyrocompass" or a heading (rad).  position: (3,) or None.
      attitude: (3,) [pitch, roll, yaw] rad or None.
      gyro_arw: rad/sqrt(s) or None (from the data).  gyro_bias_sigma: rad/s.
      max_gyrocompass_sigma: rad, the ``"auto"`` criterion's bound.
      lever_rfu: (3,) GNSS antenna minus IMU in the body frame (RFU), m, or None (the GNSS position as is).
    Returns:
      :class:`Alignment`.
    Raises:
      ValueError: for wrong shapes, fewer than 2 static samples, an unknown ``heading``, no position,
        or (``"gnss"``) no GNSS epoch after the IMU start faster than ``min_speed``.
    """
    t = np.asarray(t, float)
    f_b = np.asarray(f_b, float)
    w_b = np.asarray(w_b, float)
    if t.ndim != 1 or f_b.shape != (t.size, 3) or w_b.shape != (t.size, 3):
        raise ValueError(
            f"coarse_alignment: t (N,), f_b and w_b (N, 3) expected, got {t.shape}, {f_b.shape}, {w_b.shape}"
        )
    if t.size < 2:
        raise ValueError("coarse_alignment needs at least 2 IMU samples")
    if isinstance(heading, str):
        if heading not in ("gnss", "auto", "gyrocompass"):
            raise ValueError(f"heading must be 'gnss', 'auto', 'gyrocompass' or a number (rad), got {heading!r}")
    else:
        heading = float(heading)
        if not math.isfinite(heading):
            raise ValueError(f"a given heading must be finite, got {heading}")
    dt = np.diff(t, prepend=t[0] - (t[1] - t[0]))
    st = t <= t[0] + static_s
    n_static = int(st.sum())
    if n_static < 2:
        raise ValueError(f"the static window of {static_s} s holds {n_static} IMU sample(s); at least 2 needed")
    # position
    if position is not None:
        lat0, lon0, h0 = (float(x) for x in np.asarray(position, float).reshape(3))
    elif pos_sol is not None:
        gt = np.asarray(pos_sol.t, float)
        i0 = int(np.searchsorted(gt, t[0]))
        if i0 >= gt.size:
            raise ValueError("no GNSS epoch at or after the IMU start: give position=(lat, lon, h)")
        lat0, lon0, h0 = float(pos_sol.lat[i0]), float(pos_sol.lon[i0]), float(pos_sol.h[i0])
    else:
        raise ValueError("coarse_alignment needs pos_sol or position=(lat rad, lon rad, h m)")
    w_ie_n = WGS84.omega * np.array([0.0, math.cos(lat0), math.sin(lat0)])
    w_mean = w_b[st].mean(0)
    # the gyrocompassing criterion
    T = float(np.sum(dt[st]))
    arw = float(gyro_arw) if gyro_arw is not None else float(np.mean(w_b[st].std(0)) * math.sqrt(np.median(dt[st])))
    horiz = WGS84.omega * abs(math.cos(lat0))
    gc_sigma = math.sqrt(float(gyro_bias_sigma) ** 2 + arw**2 / T) / horiz if horiz > 0 else math.inf
    # levelling
    if attitude is not None:
        att = np.asarray(attitude, float).reshape(3)
        pitch, roll = float(att[0]), float(att[1])
    else:
        f = f_b[st].mean(0)
        pitch = math.atan2(f[1], math.hypot(f[0], f[2]))
        roll = math.atan2(-f[0], f[2])
    C_lvl = np.asarray(euler_to_dcm(np.array([pitch, roll, 0.0])))
    course, t_head, yaw_change, sigma = math.nan, float(t[0]), 0.0, math.nan
    if attitude is not None:
        method, yaw0 = "given", float(att[2])
    elif not isinstance(heading, str):
        method, yaw0 = "given", float(heading_to_yaw(heading))
    elif heading == "gyrocompass" or (heading == "auto" and gc_sigma <= max_gyrocompass_sigma):
        w_L = C_lvl @ w_mean
        method, yaw0, sigma = "gyrocompass", math.atan2(w_L[0], w_L[1]), gc_sigma
    else:
        if pos_sol is None:
            raise ValueError("heading='gnss' needs pos_sol")
        method = "gnss_course"
        gt, v = _gnss_velocity(pos_sol, lat0, lon0, h0)
        speed = np.hypot(v[:, 0], v[:, 1])
        moving = np.nonzero((speed > min_speed) & (gt > t[0]) & (gt <= t[-1]))[0]
        if moving.size == 0:
            raise ValueError(f"no GNSS epoch faster than {min_speed} m/s: cannot align the heading")
        j = int(moving[0])
        sel = (gt >= gt[j]) & (gt <= gt[j] + course_s) & (gt <= t[-1])
        ve, vn = v[sel, 0].mean(), v[sel, 1].mean()
        course = math.atan2(ve, vn)
        t_head = float(gt[sel].mean())
        through = t <= t_head
        # bias with the levelled attitude (yaw 0), the yaw, then the bias again with that yaw
        bias = w_mean - C_lvl.T @ w_ie_n
        for _ in range(2):
            yaw_change = _yaw_change(pitch, roll, w_b, dt, bias, through, lat0)
            yaw0 = float(heading_to_yaw(course)) - yaw_change
            C_bn = np.asarray(euler_to_dcm(np.array([pitch, roll, yaw0])))
            bias = w_mean - C_bn.T @ w_ie_n
    yaw0 = math.atan2(math.sin(yaw0), math.cos(yaw0))
    att0 = np.array([pitch, roll, yaw0])
    C_bn = np.asarray(euler_to_dcm(att0))
    gyro_bias = w_mean - C_bn.T @ w_ie_n
    q0 = np.asarray(euler_to_quat(att0))
    pos0 = np.array([lat0, lon0, h0])
    if lever_rfu is not None and position is None:
        lever = np.asarray(np.asarray(quat_to_dcm(q0)) @ np.asarray(lever_rfu, float))
        pos0 = pos0 - np.asarray(enu_to_curvilinear(pos0, lever))
    nav0 = NavState(q_bn=q0, v_n=np.zeros(3), pos=pos0)
    return Alignment(
        nav0=nav0,
        gyro_bias=gyro_bias,
        att0=att0,
        t_static=float(t[st][-1]),
        t_heading=t_head,
        course=course,
        yaw_change=yaw_change,
        heading_method=method,
        heading_sigma=sigma,
        gyrocompass_sigma=gc_sigma,
        gyro_arw=arw,
        n_static=n_static,
    )
