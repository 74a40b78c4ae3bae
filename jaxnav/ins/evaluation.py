"""Scoring a navigation solution against a reference trajectory (host side, numpy).

The two series are brought to common epochs by linear interpolation of the denser one at the
epochs of the sparser one (:func:`trajectory_errors`; attitude angles unwrapped first; epochs whose
neighbours in the interpolated series are further apart than ``max_gap`` are left out). Errors are
*solution minus reference*: position in the local east-north-up frame at the reference point (m,
first order: :func:`jaxnav.geodesy.curvilinear_to_enu`), velocity east-north-up (m/s), roll, pitch
and heading (rad, each wrapped to [-pi, pi)). :func:`error_statistics` reduces them over the whole
run and inside outage windows: RMS and maxima, the outage protocol of KF-GINS-style evaluations
(per outage the largest 3-D position error -- the drift since GNSS was lost -- and the RMS of those
maxima over the outages), and where the solution's covariance is given the normalised estimation
error squared NEES = e^T P^-1 e of the position (expected 3; Bar-Shalom, Li, Kirubarajan,
*Estimation with Applications to Tracking and Navigation*, 2001, sect. 5.4.2) and the share of
errors inside +-3 sigma (expected 99.73 % per component for a consistent Gaussian estimate).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from jaxnav.geodesy import curvilinear_to_enu
from jaxnav.ins.attitude import quat_to_roll_pitch_heading
from jaxnav.ins.likelihood import antenna_enu
from jaxnav.units import WEEK

#: chi-square quantile of 3 degrees of freedom at 99.73 % (the 3-sigma probability): a position
#: NEES below it is inside the 3-sigma ellipsoid
NEES3_99_73 = 14.1564


class TrajectoryErrors(NamedTuple):
    """Solution minus reference at common epochs (SI).

    Attributes:
      t: (K,) s, the epochs scored.
      pos_enu: (K, 3) m.
      vel_enu: (K, 3) m/s, NaN where either series has no velocity.
      att: (K, 3) roll, pitch, heading error, rad in [-pi, pi), NaN where either has none.
      sig_pos_enu, sig_vel, sig_att: (K, 3) the solution's 1-sigma (NaN where not given).
      nees_pos: (K,) position NEES (NaN without a covariance).
      window: (K,) int, the outage window an epoch falls in (-1: none).
      n_dropped: epochs of the sparser series left out (outside the other's span or across one of its gaps).
      at: "solution" or "reference": whose epochs were scored.
    """

    t: np.ndarray
    pos_enu: np.ndarray
    vel_enu: np.ndarray
    att: np.ndarray
    sig_pos_enu: np.ndarray
    sig_vel: np.ndarray
    sig_att: np.ndarray
    nees_pos: np.ndarray
    window: np.ndarray
    n_dropped: int
    at: str


def wrap_angle(a):
    """Angles (rad) wrapped to [-pi, pi)."""
    return (np.asarray(a, float) + math.pi) % (2.0 * math.pi) - math.pi


def _interp(t_new, t, y, *, angle=False):
    """Linear interpolation of (N, ...) ``y`` at ``t_new`` along axis 0 (angles unwrapped first, then wrapped)."""
    y = np.asarray(y, float)
    flat = y.reshape(y.shape[0], -1)
    if angle:
        flat = np.where(np.isnan(flat), np.nan, np.unwrap(np.nan_to_num(flat), axis=0))
    out = np.stack([np.interp(t_new, t, flat[:, j]) for j in range(flat.shape[1])], -1)
    out = out.reshape((len(t_new),) + y.shape[1:])
    return wrap_angle(out) if angle else out


def trajectory_errors(
    t_sol,
    pos_sol,
    v_sol,
    rpy_sol,
    t_ref,
    pos_ref,
    v_ref=None,
    rpy_ref=None,
    *,
    cov_pos_enu=None,
    sig_vel=None,
    sig_att=None,
    windows=None,
    at: str = "sparser",
    max_gap: float | None = None,
) -> TrajectoryErrors:
    """Errors of a solution against a reference at common epochs (module docstring).

    Args:
      t_sol: (N,) s, increasing.  pos_sol: (N, 3) [lat rad, lon rad, h m].  v_sol: (N, 3) ENU m/s or None.
      rpy_sol: (N, 3) roll, pitch, heading rad or None.
      t_ref, pos_ref, v_ref, rpy_ref: the same of the reference (M epochs, on the same time scale).
      cov_pos_enu: (N, 3, 3) the solution's ENU position covariance, m^2, or None.
      sig_vel, sig_att: (N, 3) the solution's velocity (m/s) and roll/pitch/heading (rad) 1-sigma, or None.
      windows: (W, 2) outage windows [start, end) s, or None.
      at: "solution", "reference", or "sparser" (default: the series with fewer epochs in the common span).
      max_gap: s; an epoch is scored only if the interpolated series has samples within this on both
        sides (default 5 times its median step).
    Returns:
      :class:`TrajectoryErrors`.
    Raises:
      ValueError: for shapes that do not match, times that do not increase, or no common epoch.
    """
    t_sol, t_ref = np.asarray(t_sol, float), np.asarray(t_ref, float)
    N, M = t_sol.size, t_ref.size
    nan = lambda n: np.full((n, 3), np.nan)
    pos_sol, pos_ref = np.asarray(pos_sol, float), np.asarray(pos_ref, float)
    v_sol = nan(N) if v_sol is None else np.asarray(v_sol, float)
    v_ref = nan(M) if v_ref is None else np.asarray(v_ref, float)
    rpy_sol = nan(N) if rpy_sol is None else np.asarray(rpy_sol, float)
    rpy_ref = nan(M) if rpy_ref is None else np.asarray(rpy_ref, float)
    for name, a, n in (
        ("pos_sol", pos_sol, N),
        ("v_sol", v_sol, N),
        ("rpy_sol", rpy_sol, N),
        ("pos_ref", pos_ref, M),
        ("v_ref", v_ref, M),
        ("rpy_ref", rpy_ref, M),
    ):
        if a.shape != (n, 3):
            raise ValueError(f"{name} must have shape ({n}, 3), got {a.shape}")
    for name, t in (("t_sol", t_sol), ("t_ref", t_ref)):
        if t.size < 2 or not np.all(np.diff(t) > 0):
            raise ValueError(f"{name} must hold at least 2 increasing times")
    cov = None if cov_pos_enu is None else np.asarray(cov_pos_enu, float)
    if cov is not None and cov.shape != (N, 3, 3):
        raise ValueError(f"cov_pos_enu must have shape ({N}, 3, 3), got {cov.shape}")
    sv = nan(N) if sig_vel is None else np.asarray(sig_vel, float)
    sa = nan(N) if sig_att is None else np.asarray(sig_att, float)
    lo, hi = max(t_sol[0], t_ref[0]), min(t_sol[-1], t_ref[-1])
    if at == "sparser":
        at = (
            "solution"
            if np.count_nonzero((t_sol >= lo) & (t_sol <= hi)) <= np.count_nonzero((t_ref >= lo) & (t_ref <= hi))
            else "reference"
        )
    if at not in ("solution", "reference"):
        raise ValueError(f"at must be 'solution', 'reference' or 'sparser', got {at!r}")
    t_at, t_in = (t_sol, t_ref) if at == "solution" else (t_ref, t_sol)
    gap = float(max_gap) if max_gap is not None else 5.0 * float(np.median(np.diff(t_in)))
    j = np.searchsorted(t_in, t_at)
    inside = (t_at >= t_in[0]) & (t_at <= t_in[-1])
    jl, jr = np.clip(j - 1, 0, t_in.size - 1), np.clip(j, 0, t_in.size - 1)
    exact = t_in[jr] == t_at
    ok = inside & (exact | ((t_in[jr] - t_in[jl]) <= gap))
    if not ok.any():
        raise ValueError("the solution and the reference have no common epoch (different time scales?)")
    te = t_at[ok]
    if at == "solution":
        ps, vs, rs = pos_sol[ok], v_sol[ok], rpy_sol[ok]
        pr, vr = _interp(te, t_ref, pos_ref), _interp(te, t_ref, v_ref)
        rr = _interp(te, t_ref, rpy_ref, angle=True)
        c, svv, saa = (None if cov is None else cov[ok]), sv[ok], sa[ok]
    else:
        pr, vr, rr = pos_ref[ok], v_ref[ok], rpy_ref[ok]
        ps, vs = _interp(te, t_sol, pos_sol), _interp(te, t_sol, v_sol)
        rs = _interp(te, t_sol, rpy_sol, angle=True)
        c = None if cov is None else _interp(te, t_sol, cov)
        svv, saa = _interp(te, t_sol, sv), _interp(te, t_sol, sa)
    e_pos = np.asarray(curvilinear_to_enu(pr, ps - pr))
    e_att = wrap_angle(rs - rr)
    if c is None:
        nees = np.full(te.size, np.nan)
        sp = nan(te.size)
    else:
        nees = np.einsum("ki,ki->k", e_pos, np.linalg.solve(c, e_pos[..., None])[..., 0])
        sp = np.sqrt(np.clip(np.diagonal(c, axis1=-2, axis2=-1), 0.0, None))
    win = np.full(te.size, -1, int)
    if windows is not None:
        for k, (a, b) in enumerate(np.asarray(windows, float).reshape(-1, 2)):
            win[(te >= a) & (te < b)] = k
    return TrajectoryErrors(
        t=te,
        pos_enu=e_pos,
        vel_enu=vs - vr,
        att=e_att,
        sig_pos_enu=sp,
        sig_vel=svv,
        sig_att=saa,
        nees_pos=nees,
        window=win,
        n_dropped=int(np.count_nonzero(~ok)),
        at=at,
    )


class NoCommonEpochError(ValueError):
    """A solution and a reference trajectory that share no time span (:func:`solution_errors`)."""


def solution_errors(t, nav, covs, truth, idx, *, windows=None) -> TrajectoryErrors:
    """Errors of an INS solution, with its own sigmas, against a reference trajectory (:func:`trajectory_errors`).

    The solution is a filter's or smoother's navigation state at its epochs; an epoch that occurs twice (a
    GNSS and a pseudo-measurement update at one time) counts once, the first. A reference timed in GPST
    seconds since the GPS epoch is put on seconds of week when the solution is (an IMU file without a
    GPS week).

    Args:
      t: (N,) s.  nav: :class:`jaxnav.ins.NavState` at ``t`` (body RFU, nav ENU).
      covs: (N, n, n) error covariances of the model with index ``idx`` (:class:`ErrorStateIndex`).
      truth: the reference: ``t`` (M,) s, ``pos`` (M, 3) [lat rad, lon rad, h m], ``v_enu`` (M, 3) m/s,
        ``rpy`` (M, 3) rad (e.g. :class:`jaxnav.io.TruthTrajectory`).
      windows: (W, 2) outage windows s, or None.
    Raises:
      NoCommonEpochError (a ValueError): the two spans do not overlap (the message gives both).
      ValueError: what :func:`trajectory_errors` raises.
    """
    t, first = np.unique(np.asarray(t, float), return_index=True)
    pos = np.asarray(nav.pos, float)[first]
    v = np.asarray(nav.v_n, float)[first]
    P = np.asarray(covs, float)[first]
    rpy = np.asarray(quat_to_roll_pitch_heading(np.asarray(nav.q_bn)), float)[first]
    tt = np.asarray(truth.t, float)
    if t[0] < 2 * WEEK <= tt[0]:
        tt = tt - math.floor(tt[0] / WEEK) * WEEK
    if tt[-1] < t[0] or tt[0] > t[-1]:
        raise NoCommonEpochError(
            f"the reference spans [{tt[0]:.3f}, {tt[-1]:.3f}] s, the solution [{t[0]:.3f}, {t[-1]:.3f}] s: no "
            "common epoch (another time scale? the reference must be in GPST like the GNSS solution)"
        )
    sd = np.sqrt(np.clip(np.diagonal(P, axis1=-2, axis2=-1), 0.0, None))
    return trajectory_errors(
        t,
        pos,
        v,
        rpy,
        tt,
        truth.pos,
        truth.v_enu,
        truth.rpy,
        cov_pos_enu=position_cov_enu(P, pos, idx),
        sig_vel=sd[:, idx.dv],
        sig_att=attitude_sigmas(P, rpy[:, 2], idx),
        windows=windows,
    )


def _rms(x, *, finite_only: bool = True):
    """Root mean square of ``x`` (NaN when empty); ``finite_only``: NaN/inf entries left out (else they propagate)."""
    x = np.asarray(x, float)
    if finite_only:
        x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x**2))) if x.size else float("nan")


def _max(x):
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    return float(np.max(x)) if x.size else float("nan")


def _share(e, s):
    """Share of finite (error, sigma) pairs with |e| <= 3 sigma (all components pooled)."""
    e, s = np.asarray(e, float).ravel(), np.asarray(s, float).ravel()
    ok = np.isfinite(e) & np.isfinite(s)
    return float(np.mean(np.abs(e[ok]) <= 3.0 * s[ok])) if ok.any() else float("nan")


def _block(e: TrajectoryErrors, sel) -> dict:
    """Statistics of the selected epochs (keys with unit suffixes, SI)."""
    p, v, a = e.pos_enu[sel], e.vel_enu[sel], e.att[sel]
    h, d3 = np.hypot(p[:, 0], p[:, 1]), np.linalg.norm(p, axis=1)
    v3 = np.linalg.norm(v, axis=1)
    out = {"n_epochs": int(np.count_nonzero(sel))}
    for j, c in enumerate("enu"):
        out[f"pos_{c}_rms_m"] = _rms(p[:, j])
    out.update(pos_h_rms_m=_rms(h), pos_h_max_m=_max(h), pos_3d_rms_m=_rms(d3), pos_3d_max_m=_max(d3))
    for j, c in enumerate("enu"):
        out[f"vel_{c}_rms_m_s"] = _rms(v[:, j])
    out.update(vel_3d_rms_m_s=_rms(v3), vel_3d_max_m_s=_max(v3))
    for j, c in enumerate(("roll", "pitch", "heading")):
        out[f"{c}_rms_rad"] = _rms(a[:, j])
        out[f"{c}_max_abs_rad"] = _max(np.abs(a[:, j]))
    nees = e.nees_pos[sel]
    out["nees_pos_mean"] = float(np.nanmean(nees)) if np.isfinite(nees).any() else float("nan")
    out["share_nees_pos_within_3_sigma"] = (
        float(np.mean(nees[np.isfinite(nees)] <= NEES3_99_73)) if np.isfinite(nees).any() else float("nan")
    )
    out["share_pos_within_3_sigma"] = _share(p, e.sig_pos_enu[sel])
    out["share_vel_within_3_sigma"] = _share(v, e.sig_vel[sel])
    out["share_att_within_3_sigma"] = _share(a, e.sig_att[sel])
    return out


def error_statistics(e: TrajectoryErrors, n_windows: int | None = None) -> dict:
    """Whole-run and in-outage statistics and the outage protocol of :class:`TrajectoryErrors`.

    Returns a dict (SI; unit in each key): ``all`` and ``outages`` (:func:`_block` of the epochs:
    RMS per ENU component, horizontal and 3-D RMS and maximum of position and velocity, RMS and
    largest |error| of roll, pitch, heading, mean position NEES, shares within 3 sigma), and
    ``outage_protocol``: ``max_3d_drift_m`` and ``max_h_drift_m`` per window (NaN without an epoch),
    ``rms_of_max_3d_drift_m``, ``mean_of_max_3d_drift_m``, ``rms_of_max_h_drift_m``, ``n_windows``,
    ``n_scored_windows``.
    """
    W = int(n_windows if n_windows is not None else (e.window.max() + 1 if e.window.size else 0))
    m3, mh, _ = outage_drift_maxima(e, W)
    scored = np.isfinite(m3)
    return {
        "n_epochs": int(e.t.size),
        "n_dropped_epochs": int(e.n_dropped),
        "scored_at": e.at,
        "all": _block(e, np.ones(e.t.size, bool)),
        "outages": _block(e, e.window >= 0),
        "outage_protocol": {
            "n_windows": W,
            "n_scored_windows": int(scored.sum()),
            "max_3d_drift_m": m3.tolist(),
            "max_h_drift_m": mh.tolist(),
            "rms_of_max_3d_drift_m": _rms(m3[scored]) if scored.any() else float("nan"),
            "mean_of_max_3d_drift_m": float(np.mean(m3[scored])) if scored.any() else float("nan"),
            "rms_of_max_h_drift_m": _rms(mh[scored]) if scored.any() else float("nan"),
        },
    }


def outage_drift_maxima(e: TrajectoryErrors, n_windows: int) -> tuple:
    """Per outage window the largest 3-D and horizontal position error (the drift since GNSS was lost).

    Args:
      e: :class:`TrajectoryErrors` whose ``window`` labels the epochs inside the outages (0 .. W-1).
      n_windows: W, the number of windows (a window without a scored epoch gets NaN).
    Returns:
      (max_3d (W,) m, max_h (W,) m, n_epochs (W,) int: the epochs scored in each window).
    """
    W = int(n_windows)
    d3 = np.linalg.norm(e.pos_enu, axis=1)
    dh = np.hypot(e.pos_enu[:, 0], e.pos_enu[:, 1])
    m3 = np.full(W, np.nan)
    mh = np.full(W, np.nan)
    n = np.zeros(W, int)
    for k in range(W):
        s = e.window == k
        n[k] = int(np.count_nonzero(s))
        if n[k]:
            m3[k], mh[k] = float(np.max(d3[s])), float(np.max(dh[s]))
    return m3, mh, n


# ----------------------------------------------------------------------------- GNSS outage protocol
def outage_windows(
    t_start: float,
    t_end: float,
    *,
    first_s: float = 40.0,
    outage_s: float = 15.0,
    gap_s: float = 45.0,
    end_margin_s: float = 30.0,
) -> np.ndarray:
    """(K, 2) simulated GNSS outage windows [a, b), s, of the outage protocol.

    The first starts ``first_s`` after ``t_start`` (the filter's convergence); GNSS is back for
    ``gap_s`` between windows of ``outage_s``; a window is kept if it ends at least
    ``end_margin_s`` before ``t_end``. All arguments in s.
    """
    out, a = [], t_start + first_s
    while a + outage_s <= t_end - end_margin_s:
        out.append((a, a + outage_s))
        a += outage_s + gap_s
    return np.array(out, float).reshape(-1, 2)


def shifted_outage_windows(
    t_start: float,
    t_end: float,
    *,
    shifts: int = 1,
    shift_s: float | None = None,
    first_s: float = 40.0,
    outage_s: float = 15.0,
    gap_s: float = 45.0,
    end_margin_s: float = 30.0,
) -> list:
    """The outage protocol repeated with shifted starts: one :func:`outage_windows` schedule per shift.

    Schedule k (k = 0 .. ``shifts`` - 1) is :func:`outage_windows` with its first window starting
    ``first_s + k shift_s`` after ``t_start``, so schedule 0 is the unshifted protocol and, with the
    default ``shift_s = (outage_s + gap_s) / shifts``, the schedules' starts tile one outage period:
    every part of the trajectory after ``first_s`` (up to the end margin) is bridged by some shift
    when ``shift_s <= outage_s``. Each schedule is meant for its own run (GNSS withheld on its
    windows only); a schedule can have one window fewer than another where the end margin cuts it.

    Args:
      t_start, t_end: the span, s.  shifts: number of schedules (>= 1).  shift_s: step between
        consecutive schedules' starts, s (> 0; default ``(outage_s + gap_s) / shifts``).
      first_s, outage_s, gap_s, end_margin_s: as :func:`outage_windows`, s.
    Returns:
      list of ``shifts`` (K_k, 2) arrays of windows [a, b), s.
    Raises:
      ValueError: ``shifts`` < 1 or ``shift_s`` <= 0.
    """
    if int(shifts) != shifts or shifts < 1:
        raise ValueError(f"shifts must be an integer >= 1, got {shifts!r}")
    step = (outage_s + gap_s) / shifts if shift_s is None else float(shift_s)
    if not step > 0.0:
        raise ValueError(f"shift_s must be > 0, got {shift_s!r}")
    return [
        outage_windows(
            t_start, t_end, first_s=first_s + k * step, outage_s=outage_s, gap_s=gap_s, end_margin_s=end_margin_s
        )
        for k in range(int(shifts))
    ]


def pool_drifts(maxima) -> dict:
    """Statistics of per-outage maximum drifts pooled over several outage schedules (shifted starts).

    Args:
      maxima: a sequence (one entry per schedule) of (K_k,) per-outage maximum drifts, m; NaN marks
        an outage without a scored epoch (left out of the statistics and counted).
    Returns:
      dict: ``n_outages`` (outages with a drift), ``n_unscored`` (NaN ones), ``rms_m``, ``mean_m``,
      ``max_m`` of the drifts (NaN when there is none).
    """
    x = np.concatenate([np.asarray(m, float).reshape(-1) for m in maxima]) if len(maxima) else np.zeros(0)
    ok = np.isfinite(x)
    v = x[ok]
    return {
        "n_outages": int(v.size),
        "n_unscored": int(np.count_nonzero(~ok)),
        "rms_m": _rms(v),
        "mean_m": float(np.mean(v)) if v.size else float("nan"),
        "max_m": float(np.max(v)) if v.size else float("nan"),
    }


def pooled_outage_drifts(max_h, max_3d=None) -> dict:
    """The shifted-outage statistics of one solution: :func:`pool_drifts` of its horizontal (and 3-D)
    per-outage maximum drifts over all schedules.

    Args:
      max_h: sequence of (K_k,) horizontal per-outage maxima, m (NaN: not scored), one per schedule
        (e.g. ``OutageScores.fwd_max`` of each shifted run, or :func:`outage_drift_maxima`'s ``max_h``).
      max_3d: the same of the 3-D maxima (against a reference trajectory), or None.
    Returns:
      dict: ``n_outages``, ``n_unscored_outages``, ``rms_of_max_h_drift_m``, ``mean_of_max_h_drift_m``,
      ``max_of_max_h_drift_m``, and with ``max_3d`` the same ``..._3d_...`` keys.
    """
    h = pool_drifts(max_h)
    out = {"n_outages": h["n_outages"], "n_unscored_outages": h["n_unscored"]}
    for tag, p in (("h", h),) + ((("3d", pool_drifts(max_3d)),) if max_3d is not None else ()):
        out[f"rms_of_max_{tag}_drift_m"] = p["rms_m"]
        out[f"mean_of_max_{tag}_drift_m"] = p["mean_m"]
        out[f"max_of_max_{tag}_drift_m"] = p["max_m"]
    return out


def training_windows(windows, t_end: float, outage_s: float) -> np.ndarray:
    """(J, 2) outage windows for fitting, disjoint from the evaluation ``windows`` (K, 2), s.

    One window of ``outage_s`` (at most the gap) centred in every GNSS-on gap between two
    evaluation windows, so a fit never scores the fixes the evaluation withholds; with a single
    evaluation window, one of up to ``outage_s`` starting 0.5 s after it (ending 1 s before
    ``t_end``). Windows shorter than 1 s are dropped.
    """
    w = np.asarray(windows, float).reshape(-1, 2)
    out = []
    for (_, b0), (a1, _) in zip(w[:-1], w[1:]):
        L = min(outage_s, a1 - b0)
        mid = 0.5 * (b0 + a1)
        if L > 1.0:
            out.append((mid - L / 2, mid + L / 2))
    if not out and w.size:
        L = min(outage_s, t_end - w[-1, 1] - 1.0)
        if L > 1.0:
            out.append((w[-1, 1] + 0.5, w[-1, 1] + 0.5 + L))
    return np.asarray(out, float).reshape(-1, 2)


def in_windows(t, windows) -> np.ndarray:
    """(M,) bool: which times ``t`` (M,) s fall inside any window [a, b) of ``windows`` (K, 2) s."""
    t = np.asarray(t, float)
    inside = np.zeros(t.shape, bool)
    for a, b in np.asarray(windows, float).reshape(-1, 2):
        inside |= (t >= a) & (t < b)
    return inside


class OutageScores(NamedTuple):
    """Horizontal errors of a forward and a smoothed solution against withheld fixed GNSS positions, m.

    Attributes:
      windows: (K, 2) outage windows, s (GPST).  n_ref: (K,) fixed epochs scored per window.
      fwd_max, sm_max: (K,) max horizontal error per outage (NaN where no fixed epoch).
      fwd_rms, sm_rms: (K,) RMS horizontal error per outage.
      fwd_rms_all, sm_rms_all: RMS over all scored epochs of all outages.
      fwd_max_mean, sm_max_mean: mean of the per-outage maxima.
      fwd_rms_outside: RMS horizontal error of the forward solution against fixed epochs *outside*
        the outages (sanity: should be cm-level).
      t, err_fwd, err_sm: (M,) epoch times and horizontal errors (NaN where not a fixed reference).
      sig_fwd, sig_sm: (M,) the solutions' own horizontal 1-sigma (sqrt of the east + north variances), m.
      withheld: (M,) bool.  runtime_s: wall time of the run that produced the solutions, s.
      figure: path of a figure of the scores, or None.  n_nonfinite_nav: NaN count in the navigation outputs.
    """

    windows: np.ndarray
    n_ref: np.ndarray
    fwd_max: np.ndarray
    sm_max: np.ndarray
    fwd_rms: np.ndarray
    sm_rms: np.ndarray
    fwd_rms_all: float
    sm_rms_all: float
    fwd_max_mean: float
    sm_max_mean: float
    fwd_rms_outside: float
    t: np.ndarray
    err_fwd: np.ndarray
    err_sm: np.ndarray
    withheld: np.ndarray
    runtime_s: float
    figure: str | None
    n_nonfinite_nav: int
    sig_fwd: np.ndarray | None = None
    sig_sm: np.ndarray | None = None


def score_outages(
    t, err_f, err_s, fixed, withheld, outages, *, runtime_s=float("nan"), n_nonfinite=0, sig_f=None, sig_s=None
) -> OutageScores:
    """Per-window and overall horizontal error statistics (m) at the fixed epochs inside the outages.

    Args:
      t: (M,) GNSS epochs, s.  err_f, err_s: (M,) horizontal errors of the forward and smoothed
        solutions, m.  fixed: (M,) bool fixed-quality reference epochs.  withheld: (M,) bool.
      outages: (K, 2) windows, s.  sig_f, sig_s: (M,) the solutions' horizontal 1-sigma, m, or None.
    Returns:
      :class:`OutageScores` (a NaN error propagates into its window's statistics).
    """
    t = np.asarray(t, float)
    outages = np.asarray(outages, float).reshape(-1, 2)
    e_f = np.where(fixed, err_f, np.nan)
    e_s = np.where(fixed, err_s, np.nan)
    rms = lambda x: _rms(x, finite_only=False)
    K = outages.shape[0]
    n_ref = np.zeros(K, int)
    st = {k: np.full(K, np.nan) for k in ("fm", "sm", "fr", "sr")}
    for k, (a, b) in enumerate(outages):
        s = (t >= a) & (t < b) & fixed
        n_ref[k] = int(s.sum())
        if n_ref[k]:
            st["fm"][k], st["sm"][k] = e_f[s].max(), e_s[s].max()
            st["fr"][k], st["sr"][k] = rms(e_f[s]), rms(e_s[s])
    sc = withheld & fixed
    return OutageScores(
        windows=outages,
        n_ref=n_ref,
        fwd_max=st["fm"],
        sm_max=st["sm"],
        fwd_rms=st["fr"],
        sm_rms=st["sr"],
        fwd_rms_all=rms(e_f[sc]),
        sm_rms_all=rms(e_s[sc]),
        fwd_max_mean=float(np.nanmean(st["fm"])) if np.any(n_ref) else float("nan"),
        sm_max_mean=float(np.nanmean(st["sm"])) if np.any(n_ref) else float("nan"),
        fwd_rms_outside=rms(e_f[~withheld & fixed]),
        t=t,
        err_fwd=e_f,
        err_sm=e_s,
        withheld=withheld,
        runtime_s=runtime_s,
        figure=None,
        n_nonfinite_nav=n_nonfinite,
        sig_fwd=sig_f,
        sig_sm=sig_s,
    )


class RunTracks(NamedTuple):
    """Antenna positions of a loosely coupled run at its GNSS epochs, local ENU around ``pos0``, m.

    Attributes:
      gnss_epochs: (M,) int index of the GNSS epochs among the filter's epochs (the others are
        pseudo-measurement epochs: ZUPT, NHC, odometer).
      enu_ref: (M, 3) the GNSS positions.  enu_fwd, enu_sm: (M, 3) the forward and smoothed solutions
        moved to the GNSS times and out to the antenna (:func:`jaxnav.ins.antenna_enu`).
      pos0: (3,) the ENU origin [lat rad, lon rad, h m].
    """

    gnss_epochs: np.ndarray
    enu_ref: np.ndarray
    enu_fwd: np.ndarray
    enu_sm: np.ndarray
    pos0: np.ndarray


def run_tracks(result, smoothed_nav, meas, pos0) -> RunTracks:
    """:class:`RunTracks` of a run: forward (``result``, :class:`jaxnav.ins.LCResult` saving ``nav``) and smoothed
    (``smoothed_nav``, :func:`jaxnav.ins.smooth`, (E, ...) at the filter's E epochs) solutions at the M epochs of
    ``meas`` (:class:`jaxnav.ins.PVMeasurements`) with its lever arm, ENU around ``pos0`` (3,) rad, rad, m."""
    ep = result.epochs
    g = np.nonzero(np.asarray(ep.gnss_row) >= 0)[0]
    at_g = lambda tree: type(tree)(*(np.asarray(a)[g] for a in tree))
    pos0 = np.asarray(pos0, float)
    t_nav, t, lev = np.asarray(ep.t_nav)[g], np.asarray(meas.t), np.asarray(meas.lever)
    return RunTracks(
        gnss_epochs=g,
        enu_ref=np.asarray(curvilinear_to_enu(pos0, np.asarray(meas.pos) - pos0)),
        enu_fwd=np.asarray(antenna_enu(at_g(ep.nav), t_nav, t, lev, pos0)),
        enu_sm=np.asarray(antenna_enu(at_g(smoothed_nav), t_nav, t, lev, pos0)),
        pos0=pos0,
    )


def score_run(
    result, smoothed_nav, smoothed_covs, meas, fixed, withheld, windows, idx, pos0, *, runtime_s=float("nan")
) -> tuple[RunTracks, OutageScores | None]:
    """A loosely coupled run on the GNSS outage protocol: its :class:`RunTracks` and :func:`score_outages` of the
    horizontal antenna errors at the fixed epochs withheld in ``windows`` (None without a window).

    Args:
      result: :class:`jaxnav.ins.LCResult` saving ``nav`` and ``covs``.  smoothed_nav, smoothed_covs: its RTS
        solution (:func:`jaxnav.ins.smooth`).  meas: the :class:`jaxnav.ins.PVMeasurements` (M epochs) it ran on.
      fixed: (M,) bool fixed-quality reference epochs.  withheld: (M,) bool epochs withheld from the filter.
      windows: (K, 2) outage windows, s.  idx: the error model's state indices.  pos0: (3,) ENU origin.
      runtime_s: the run's wall time, s (reported).
    """
    tr = run_tracks(result, smoothed_nav, meas, pos0)
    if not np.shape(windows)[0]:
        return tr, None
    g = tr.gnss_epochs
    ep = result.epochs
    nonfinite = int(sum(np.count_nonzero(~np.isfinite(np.asarray(a))) for a in (*ep.nav, *smoothed_nav)))
    return tr, score_outages(
        np.asarray(meas.t),
        np.hypot(*(tr.enu_fwd - tr.enu_ref)[:, :2].T),
        np.hypot(*(tr.enu_sm - tr.enu_ref)[:, :2].T),
        fixed,
        withheld,
        windows,
        runtime_s=runtime_s,
        n_nonfinite=nonfinite,
        sig_f=horizontal_sigma(np.asarray(ep.covs)[g], np.asarray(ep.nav.pos)[g], idx),
        sig_s=horizontal_sigma(np.asarray(smoothed_covs)[g], np.asarray(smoothed_nav.pos)[g], idx),
    )


def outage_statistics(sc: OutageScores) -> dict:
    """:class:`OutageScores` as a results.json block: overall and per-window horizontal errors (m) of the
    forward and smoothed solutions, and the share of scored outage epochs within 3 of their own sigma.

    The share compares the horizontal error r with 3 sigma_h, sigma_h = sqrt(var_E + var_N). For a circular
    2-D Gaussian (per-axis sigma s = sigma_h / sqrt 2) P(r < 3 sigma_h) = 1 - exp(-9) = 99.99 %, and
    P(r < 3 s) = 1 - exp(-4.5) = 98.9 %. A window without a fixed reference epoch has NaN errors with
    a ``<key>_null_reason``.

    Returns:
      dict with unit-suffixed keys (``forward_rms_h_m``, ..., ``windows``: one dict per window).
    """
    per = []
    for k, (a, b) in enumerate(sc.windows):
        w = (sc.t >= a) & (sc.t < b) & np.isfinite(sc.err_fwd)
        per.append(
            {
                "window": k + 1,
                "gpst_start_s": float(a),
                "gpst_end_s": float(b),
                "n_fixed_epochs": int(sc.n_ref[k]),
                "forward_rms_h_m": float(sc.fwd_rms[k]),
                "forward_max_h_m": float(sc.fwd_max[k]),
                "smoothed_rms_h_m": float(sc.sm_rms[k]),
                "smoothed_max_h_m": float(sc.sm_max[k]),
                "forward_sigma_h_at_end_m": float(sc.sig_fwd[w][-1]) if w.any() else float("nan"),
                "smoothed_sigma_h_max_m": float(np.max(sc.sig_sm[w])) if w.any() else float("nan"),
            }
        )
        if not sc.n_ref[k]:
            per[-1].update(
                {
                    f"{key}_null_reason": "no fixed GNSS epoch in the window"
                    for key in ("forward_rms_h_m", "forward_max_h_m", "smoothed_rms_h_m", "smoothed_max_h_m")
                }
            )
        if not w.any():
            per[-1].update(
                {
                    f"{key}_null_reason": "no scored epoch in the window"
                    for key in ("forward_sigma_h_at_end_m", "smoothed_sigma_h_max_m")
                }
            )
    sc_w = sc.withheld & np.isfinite(sc.err_fwd)
    within_f = float(np.mean(sc.err_fwd[sc_w] <= 3 * sc.sig_fwd[sc_w])) if sc_w.any() else float("nan")
    within_s = float(np.mean(sc.err_sm[sc_w] <= 3 * sc.sig_sm[sc_w])) if sc_w.any() else float("nan")
    return {
        "forward_rms_h_m": sc.fwd_rms_all,
        "forward_max_h_m": float(np.nanmax(sc.fwd_max)) if np.any(sc.n_ref) else float("nan"),
        "smoothed_rms_h_m": sc.sm_rms_all,
        "smoothed_max_h_m": float(np.nanmax(sc.sm_max)) if np.any(sc.n_ref) else float("nan"),
        "forward_rms_h_outside_outages_m": sc.fwd_rms_outside,
        "forward_share_within_3_sigma_h": within_f,
        "smoothed_share_within_3_sigma_h": within_s,
        "n_windows": int(len(sc.windows)),
        "n_scored_windows": int(np.count_nonzero(sc.n_ref)),
        "windows": per,
    }


# ----------------------------------------------------------------------------- sigmas from error covariances
def position_sigmas_enu(covs, pos, idx) -> np.ndarray:
    """(M, 3) east, north, up 1-sigma, m, of error covariances (M, n, n) at positions ``pos`` (M, 3)
    [lat rad, lon rad, h m]; ``idx``: the model's :class:`jaxnav.ins.error_model.ErrorStateIndex`
    (its ``dpos`` block is (dlat rad, dlon rad, dh m)). Cross terms are ignored."""
    P = np.asarray(covs)
    sd = np.sqrt(np.clip(np.diagonal(P, axis1=-2, axis2=-1)[:, idx.dpos], 0.0, None))
    return np.abs(np.asarray(curvilinear_to_enu(np.asarray(pos), sd)))


def horizontal_sigma(covs, pos, idx) -> np.ndarray:
    """(M,) horizontal 1-sigma sqrt(var_E + var_N), m; arguments as :func:`position_sigmas_enu`."""
    s = position_sigmas_enu(covs, pos, idx)
    return np.hypot(s[:, 0], s[:, 1])


def position_cov_enu(covs, pos, idx) -> np.ndarray:
    """(M, 3, 3) ENU position covariance, m^2: the ``idx.dpos`` block of ``covs`` (M, n, n) mapped by the
    Jacobian of (dlat, dlon, dh) -> ENU at ``pos`` (M, 3) [lat rad, lon rad, h m]."""
    pos = np.asarray(pos, float)
    J = np.stack([np.asarray(curvilinear_to_enu(pos, np.broadcast_to(e, pos.shape))) for e in np.eye(3)], -1)
    Pp = np.asarray(covs)[:, idx.dpos, idx.dpos]
    return np.einsum("mij,mjk,mlk->mil", J, Pp, J)


def attitude_sigmas(covs, heading, idx) -> np.ndarray:
    """(M, 3) 1-sigma of roll, pitch, heading, rad, of error covariances (M, n, n).

    The tilt covariance about east/north (the first two states of ``idx.phi``) projected on the
    forward and right axes at ``heading`` (M,) rad (clockwise from north); heading from the tilt
    about up (the third).
    """
    P = np.asarray(covs)
    e, n, u = range(idx.phi.start, idx.phi.start + 3)
    f = np.stack([np.sin(heading), np.cos(heading)], -1)  # forward in (east, north)
    r = np.stack([np.cos(heading), -np.sin(heading)], -1)  # right
    T = P[:, e : n + 1, e : n + 1]
    var = lambda w: np.einsum("mi,mij,mj->m", w, T, w)
    return np.sqrt(np.clip(np.stack([var(f), var(r), P[:, u, u]], -1), 0.0, None))
