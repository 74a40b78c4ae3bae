"""IMU-GNSS time offset from the yaw rate and the GNSS course rate (host side, numpy, float64).

A vehicle's turns show twice: in the gyro about the vertical and in the rate of change of the GNSS
course. :func:`estimate_time_offset` shifts the first against the second, maximises their
correlation coefficient over a grid of lags, refines the peak by a parabola through its
neighbours, and returns the offset with quality figures. It is the first guess; a refinement by
the filter's innovation likelihood belongs to the caller (``jaxnav.tune``).

It assumes the vehicle's body points along its velocity (wheeled vehicles: no sideslip). For a
pedestrian the path and the device's yaw are related by the gait, not a clock: on the handheld
walk_0827 set it returns -0.33 s (correlation 0.92) while the filter's likelihood peaks near 0 s.

Sign convention: ``offset_s`` is *added to the IMU times* to put them on the GNSS time scale,
t_gnss = t_imu + offset (an IMU that time-tags its samples 0.15 s late has offset -0.15 s).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from jaxnav.geodesy import curvilinear_to_enu


class TimeOffset(NamedTuple):
    """Result of :func:`estimate_time_offset`.

    Attributes:
      offset_s: add to the IMU times, s.
      sigma_s: 1-sigma of ``offset_s`` from the least-squares fit of the GNSS course rate by the
        shifted IMU yaw rate (white residuals assumed: optimistic when the residuals are
        correlated; treat < 3x its value as agreement), s.
      corr: correlation coefficient of the two rates at the offset (1 = identical shapes); below
        ~0.7 the run has too few or too weak turns (or the wrong vertical axis).
      n_epochs: GNSS epochs used (moving, with both neighbours moving, inside the IMU span).
      turn_rate_rms: RMS of the GNSS course rate over those epochs, rad/s (how much turning the
        estimate rests on).
      at_bound: True if the peak is at the edge of the lag grid (``max_offset_s`` too small).
      lags_s: (L,) lag grid, s.  corr_curve: (L,) correlation coefficient at each lag.
      source: "velocity" (GNSS velocities) or "position" (velocities from differenced positions).
    """

    offset_s: float
    sigma_s: float
    corr: float
    n_epochs: int
    turn_rate_rms: float
    at_bound: bool
    lags_s: Any
    corr_curve: Any
    source: str


def _central(x, t):
    """Central differences (x[k+1] - x[k-1]) / (t[k+1] - t[k-1]) at interior points; NaN at the ends."""
    d = np.full(x.shape, np.nan)
    d[1:-1] = (x[2:] - x[:-2]) / (t[2:] - t[:-2]).reshape((-1,) + (1,) * (x.ndim - 1))
    return d


def estimate_time_offset(t_imu, w_b, t_gnss, v_enu=None, *, llh=None, f_b=None, up_b=None,
                         max_offset_s: float = 1.0, step_s: float = 0.005, min_speed: float = 2.0) -> TimeOffset:
    """Estimate the IMU-GNSS time offset by correlating the yaw rate with the GNSS course rate.

    1. Yaw rate r_I = w_b . u (counter-clockwise about up); u the body up axis: ``up_b``, else the
       direction of the mean specific force ``f_b`` (the vehicle's mean up), else body z (jaxnav's
       right-forward-up). Sample k is the mean rate over (t[k-1], t[k]] (jaxnav's increment
       convention), so the yaw angle psi(t[k]) = sum of w_k dt_k is exact at the sample times.
    2. GNSS course rate: chi = atan2(v_E, v_N) (clockwise), chi_dot = (v_N a_E - v_E a_N) / |v|^2
       with a the central difference of the velocities. Velocities are ``v_enu``, or (when
       None) central differences of the ``llh`` positions (local ENU).
    3. For each lag tau the IMU rate as the GNSS sees it is the same difference operator applied
       to the IMU yaw angle at t_gnss - tau: -(psi(t_{k+1} - tau) - psi(t_{k-1} - tau)) / (t_{k+1} -
       t_{k-1}) (with positions: to its mean over each velocity interval first), so both rates
       carry the same smoothing. The correlation coefficient over the epochs faster than
       ``min_speed`` (with both neighbours) is maximised over the grid ``-max_offset_s ..
       max_offset_s`` step ``step_s``; a parabola through the peak and its neighbours gives the
       sub-step offset; ``sigma_s`` from the Gauss-Newton normal equation of the fit
       chi_dot = a r_I(tau) + c.

    Args:
      t_imu: (N,) IMU times, s.  w_b: (N, 3) angular rate, rad/s (sensor or body axes).
      t_gnss: (M,) GNSS epochs, s (same time scale up to the offset).
      v_enu: (M, 3) GNSS velocity east/north/up, m/s, or None; NaN rows (missing velocities) are
        left out.  llh: (M, 3) [lat rad, lon rad, h m], used when ``v_enu`` is None or all NaN.
      f_b: (N, 3) specific force (same axes as ``w_b``), m/s^2, or None.  up_b: (3,) or None.
      max_offset_s: largest |offset| searched, s.  step_s: lag grid step, s.
      min_speed: GNSS epochs slower than this (m/s) are not used (the course is noise there).
    Returns:
      :class:`TimeOffset`.
    Raises:
      ValueError: for wrong shapes, no velocities and no positions, or fewer than 10 usable epochs.
    """
    t_imu = np.asarray(t_imu, float)
    w_b = np.asarray(w_b, float)
    t_g = np.asarray(t_gnss, float)
    if t_imu.ndim != 1 or w_b.shape != (t_imu.size, 3) or t_imu.size < 3:
        raise ValueError(f"t_imu (N,) and w_b (N, 3) expected (N >= 3), got {t_imu.shape} and {w_b.shape}")
    if t_g.ndim != 1 or t_g.size < 3:
        raise ValueError(f"t_gnss must be (M,) with M >= 3, got {t_g.shape}")
    if not (max_offset_s > 0 and step_s > 0 and step_s < max_offset_s):
        raise ValueError(f"need 0 < step_s < max_offset_s, got step_s={step_s}, max_offset_s={max_offset_s}")
    if up_b is not None:
        u = np.asarray(up_b, float).reshape(3)
    elif f_b is not None:
        f_b = np.asarray(f_b, float)
        if f_b.shape != w_b.shape:
            raise ValueError(f"f_b {f_b.shape} must have the shape of w_b {w_b.shape}")
        u = np.nanmean(f_b, 0)
    else:
        u = np.array([0.0, 0.0, 1.0])
    u = u / np.linalg.norm(u)
    r_imu = w_b @ u
    dt = np.diff(t_imu)
    psi = np.concatenate([[0.0], np.cumsum(r_imu[1:] * dt)])  # yaw angle at the sample times, rad
    # GNSS velocity and course rate
    source = "velocity"
    v = None if v_enu is None else np.asarray(v_enu, float)
    if v is not None and v.shape != (t_g.size, 3):
        raise ValueError(f"v_enu must be (M, 3) = ({t_g.size}, 3), got {v.shape}")
    if v is None or not np.any(np.all(np.isfinite(v[:, :2]), axis=1)):
        if llh is None:
            raise ValueError("estimate_time_offset needs finite GNSS velocities v_enu or positions llh")
        pos = np.asarray(llh, float)
        if pos.shape != (t_g.size, 3):
            raise ValueError(f"llh must be (M, 3) = ({t_g.size}, 3), got {pos.shape}")
        enu = np.asarray(curvilinear_to_enu(pos[0], pos - pos[0]))
        v = _central(enu, t_g)
        source = "position"
    a = _central(v, t_g)
    sp2 = v[:, 0] ** 2 + v[:, 1] ** 2
    with np.errstate(invalid="ignore", divide="ignore"):
        chi_dot = (v[:, 1] * a[:, 0] - v[:, 0] * a[:, 1]) / sp2
    fast = np.isfinite(sp2) & (sp2 > min_speed**2)
    ok = fast & np.isfinite(chi_dot)
    ok[1:-1] &= fast[:-2] & fast[2:]
    ok[[0, -1]] = False
    if source == "position":  # velocities from positions k-1..k+1: their neighbours must be usable too
        ok[2:-2] &= np.isfinite(v[1:-3, 0]) & np.isfinite(v[3:-1, 0])
        ok[:2] = ok[-2:] = False
    # every lag must find IMU data around each used epoch
    span = 2 * np.max(np.diff(t_g)) + max_offset_s + step_s
    ok &= (t_g - span >= t_imu[0]) & (t_g + span <= t_imu[-1])
    idx = np.flatnonzero(ok)
    if idx.size < 10:
        raise ValueError(f"only {idx.size} usable GNSS epochs (moving faster than {min_speed} m/s inside the IMU "
                         "span); need at least 10 with turns")
    y = chi_dot[idx]

    def imu_rate(tau):
        """The IMU's clockwise course rate at the used epochs for the lag tau (same operators as GNSS)."""
        tt = t_g - tau
        if source == "velocity":
            p = np.interp(tt, t_imu, psi)
        else:  # mean yaw over each central-difference interval of the positions
            Psi = np.concatenate([[0.0], np.cumsum(0.5 * (psi[1:] + psi[:-1]) * dt)])
            P = np.interp(tt, t_imu, Psi)
            p = np.full(t_g.shape, np.nan)
            p[1:-1] = (P[2:] - P[:-2]) / (t_g[2:] - t_g[:-2])
        return -_central(p, t_g)[idx]

    def corr(x):
        xc, yc = x - x.mean(), y - y.mean()
        den = math.sqrt(float(xc @ xc) * float(yc @ yc))
        return float(xc @ yc) / den if den > 0 else 0.0

    n = int(round(max_offset_s / step_s))
    lags = np.arange(-n, n + 1) * step_s
    cc = np.array([corr(imu_rate(tau)) for tau in lags])
    k = int(np.argmax(cc))
    at_bound = k in (0, lags.size - 1)
    tau = float(lags[k])
    if not at_bound:
        c0, c1, c2 = cc[k - 1], cc[k], cc[k + 1]
        den = c0 - 2 * c1 + c2
        if den < 0:
            tau += step_s * 0.5 * (c0 - c2) / den
    x = imu_rate(tau)
    A = np.stack([x, np.ones_like(x)], 1)
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    res = y - A @ coef
    h = 0.5 * step_s
    dx = (imu_rate(tau + h) - imu_rate(tau - h)) / (2 * h)
    s2 = float(res @ res) / max(idx.size - 3, 1)
    J = coef[0] * (dx - dx.mean())  # d(model)/d tau, with the intercept profiled out
    sigma = math.sqrt(s2 / float(J @ J)) if float(J @ J) > 0 else math.inf
    return TimeOffset(offset_s=tau, sigma_s=sigma, corr=corr(x), n_epochs=int(idx.size),
                      turn_rate_rms=float(np.sqrt(np.mean(y**2))), at_bound=bool(at_bound), lags_s=lags,
                      corr_curve=cc, source=source)
