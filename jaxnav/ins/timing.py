"""IMU-GNSS time offset from the yaw rate and the GNSS course rate (host side, numpy, float64).

A vehicle's turns show twice: in the gyro about the vertical and in the rate of change of the GNSS
course. :func:`estimate_time_offset` shifts the first against the second, maximises their
correlation coefficient over a grid of lags, refines the peak by a parabola through its
neighbours, and returns the offset with quality figures. It is the first guess.

The refinement maximises the filter's GNSS innovation log-likelihood over the offset
(:func:`likelihood_time_offset`: grids and a parabola, :func:`parabola_peak`) and, at the best
offset, over a linear clock drift (:func:`clock_drift`). Both take the log-likelihood as a callable
of the trial clock, so any filter run can be plugged in; :func:`offset_search_epochs` picks the GNSS
epochs that every trial scores.

It assumes the vehicle's body points along its velocity (wheeled vehicles: no sideslip). For a
pedestrian the path and the device's yaw are related by the gait, not a clock: on the handheld
walk_0827 set it returns -0.33 s (correlation 0.92) while the filter's likelihood peaks near 0 s.

Sign convention: ``offset_s`` is *added to the IMU times* to put them on the GNSS time scale,
t_gnss = t_imu + offset (an IMU that time-tags its samples 0.15 s late has offset -0.15 s).
"""

from __future__ import annotations

import math
from collections.abc import Callable
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
    lags_s: np.ndarray
    corr_curve: np.ndarray
    source: str


def _central(x, t):
    """Central differences (x[k+1] - x[k-1]) / (t[k+1] - t[k-1]) at interior points; NaN at the ends."""
    d = np.full(x.shape, np.nan)
    d[1:-1] = (x[2:] - x[:-2]) / (t[2:] - t[:-2]).reshape((-1,) + (1,) * (x.ndim - 1))
    return d


def estimate_time_offset(
    t_imu,
    w_b,
    t_gnss,
    v_enu=None,
    *,
    llh=None,
    f_b=None,
    up_b=None,
    max_offset_s: float = 1.0,
    step_s: float = 0.005,
    min_speed: float = 2.0,
) -> TimeOffset:
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
        raise ValueError(
            f"only {idx.size} usable GNSS epochs (moving faster than {min_speed} m/s inside the IMU "
            "span); need at least 10 with turns"
        )
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
    return TimeOffset(
        offset_s=tau,
        sigma_s=sigma,
        corr=corr(x),
        n_epochs=int(idx.size),
        turn_rate_rms=float(np.sqrt(np.mean(y**2))),
        at_bound=bool(at_bound),
        lags_s=lags,
        corr_curve=cc,
        source=source,
    )


#: fewest GNSS epochs the likelihood search needs inside the IMU span at every trial offset
MIN_SEARCH_EPOCHS = 10
#: a clock drift is flagged when the offset's change over the run exceeds this many of its sigmas...
DRIFT_SIGMAS = 3.0
#: ... and this, s (below it the 10 ms grid and its parabola do not resolve a change)
DRIFT_MIN_CHANGE_S = 0.005


def parabola_peak(x, ll) -> tuple[float, float]:
    """(maximiser, 1-sigma) of a log-likelihood on an even grid ``x`` (K,): parabola through the best three points.

    ll(x) ~ c - (x - x*)^2 / (2 sigma^2): x* = x_j + h (l_- - l_+) / (2 (l_- - 2 l_j + l_+)),
    sigma = h / sqrt(-(l_- - 2 l_j + l_+)); sigma is NaN at a grid edge or without curvature.
    """
    x, ll = np.asarray(x, float), np.asarray(ll, float)
    j = int(np.nanargmax(ll))
    best, sigma = float(x[j]), float("nan")
    if 0 < j < len(x) - 1:
        y0, y1, y2 = ll[j - 1 : j + 2]
        den = y0 - 2 * y1 + y2
        h = x[1] - x[0]
        if den < 0:
            best += 0.5 * (y0 - y2) / den * h
            sigma = float(h / math.sqrt(-den))
    return best, sigma


def offset_search_epochs(t_gnss, t_imu, span: float, windows=None) -> dict:
    """The GNSS epochs every trial offset in [-``span``, ``span``] s can score, and counts.

    An epoch is used when it lies inside the IMU span (``t_imu`` (N,) s, before any offset) for every
    trial offset, so all trials score the same epochs; epochs inside ``windows`` (K, 2) s (GNSS
    withheld for an evaluation) widened by ``span`` are left out as well.

    Returns:
      dict: ``use`` (M,) bool, ``n_used``, ``n_dropped_at_span_edges`` (reachable by some trial but not
      by all), ``n_withheld`` (inside the IMU span at every trial, left out by ``windows``).
    """
    gt = np.asarray(t_gnss, float)
    t0, t1 = float(t_imu[0]), float(t_imu[-1])
    reach = (gt >= t0 - span - 1e-9) & (gt <= t1 + span)
    inside = (gt >= t0 + span + 1e-6) & (gt <= t1 - span - 1e-6)
    withheld = np.zeros(gt.size, bool)
    for a, b in np.asarray(() if windows is None else windows, float).reshape(-1, 2):
        withheld |= (gt >= a - span) & (gt < b + span)
    use = inside & ~withheld
    return {
        "use": use,
        "n_used": int(use.sum()),
        "n_dropped_at_span_edges": int((reach & ~inside).sum()),
        "n_withheld": int((inside & withheld).sum()),
    }


class LikelihoodOffset(NamedTuple):
    """Result of :func:`likelihood_time_offset`.

    Attributes:
      offset_s: the maximiser, s (added to the IMU times).  sigma_s: its 1-sigma from the curvature
        (independent innovations assumed: optimistic when GNSS errors are correlated in time), s;
        NaN at a grid edge.  at_edge: the maximum lies within 10 ms of +-span (widen the search).
      fine_s: (K,) the fine grid, s.  fine_loglik: (K,) its log-likelihoods.
    """

    offset_s: float
    sigma_s: float
    at_edge: bool
    fine_s: np.ndarray
    fine_loglik: np.ndarray


def likelihood_time_offset(
    loglik: Callable[[float], float],
    span: float,
    *,
    guess: float = 0.0,
    coarse_step: float = 0.05,
    fine_step: float = 0.01,
    fine_half: float = 0.05,
    progress: Callable[[str], Any] | None = None,
) -> LikelihoodOffset:
    """IMU-GNSS time offset maximising a filter's innovation log-likelihood over grids around a first guess.

    ``loglik(offset)`` (s -> log-likelihood of a run with the IMU times shifted by ``offset``) is
    evaluated on a ``coarse_step`` grid over +-``span`` (zero included) plus ``guess`` (e.g. the
    cross-correlation of :func:`estimate_time_offset`, when within the span), then on a ``fine_step``
    grid within +-``fine_half`` of the coarse best; :func:`parabola_peak` through the best three fine
    points refines the maximum and gives its 1-sigma. Every trial should score the same GNSS epochs
    (:func:`offset_search_epochs`). ``loglik`` may be called again with the same offset: memoise it
    when a run is expensive. All times in s; ``progress`` takes one line of text, or None.
    """
    coarse = np.union1d(
        np.round(np.arange(-span, span + 1e-9, coarse_step), 6), [round(guess, 6)] if abs(guess) <= span else []
    )
    for k, off in enumerate(coarse):
        loglik(off)
        if progress and (k % 10 == 0 or k == len(coarse) - 1):
            progress(f"time offset: coarse grid {k + 1}/{len(coarse)}")
    c_best = max((o for o in coarse), key=loglik)
    fine = np.round(c_best + np.arange(-fine_half, fine_half + 1e-9, fine_step), 6)
    fine = fine[np.abs(fine) <= span + 1e-9]
    ll = np.array([loglik(o) for o in fine])
    best, sigma = parabola_peak(fine, ll)
    return LikelihoodOffset(
        offset_s=best, sigma_s=sigma, at_edge=bool(abs(best) >= span - 0.01), fine_s=fine, fine_loglik=ll
    )


def clock_drift(
    loglik: Callable[[float, float], float],
    offset: float,
    t_gnss,
    span: float,
    *,
    step_o: float = 0.01,
    step_c: float = 0.02,
    widen_hint: str = "widen the search span",
) -> dict:
    """IMU clock drift by the innovation likelihood of a linear clock error.

    The IMU times become t + o + c (t - t_ref) / T (t_ref the middle, T the span of the GNSS epochs
    ``t_gnss``): o is the offset at mid-run, c its change over the run, d = c / T the drift (s/s). Every
    trial is a whole run with one consistent clock (offsets fitted to separate halves of one-offset runs
    are pulled towards the run's offset: a mistimed half spoils the state the other starts from). From
    (``offset``, 0) a grid of ``step_o`` x ``step_c`` is walked (|o| + |c| / 2 within ``span``, so every
    trial scores the same epochs) by Newton steps: a quadratic ll = a + g^T x + x^T H x / 2 through six grid
    points around x (x, x +- one step in o and in c, x + one step in both), x moved to the grid point nearest
    its maximum -H^-1 g until that lies within one step; (o, c) = that maximum, their covariance -H^-1
    (independent innovations assumed: optimistic, as the offset's sigma). Flagged significant when |c|
    exceeds :data:`DRIFT_SIGMAS` sigmas and :data:`DRIFT_MIN_CHANGE_S`. Cost: three runs beyond the offset
    search when there is no drift, three to six per Newton step otherwise.

    Args:
      loglik: (o s, c s) -> log-likelihood of the run.  offset: the one-offset estimate, s.
      t_gnss: (M,) the search's GNSS epoch times, s.  span: the search half-width, s.
      widen_hint: what the note says to do when the clock model reaches the edge of the span.
    Returns:
      dict: ``offset_mid_s``, ``change_s``, ``change_sigma_s``, ``drift_s_per_s``,
      ``drift_sigma_s_per_s``, ``windows`` (the model's offset at the mean epoch time of each half),
      ``significant``, ``warning`` (when significant); ``note`` only when it cannot be estimated.
    """
    tg = np.asarray(t_gnss, float)
    T = float(tg[-1] - tg[0])
    if tg.size < 2 * MIN_SEARCH_EPOCHS or T <= 0:
        return {"note": "not estimated: too few GNSS epochs"}
    ok = lambda o, c: abs(o) + 0.5 * abs(c) <= span + 1e-9
    key = lambda o, c: (round(o, 6), round(c, 6))
    ll = lambda x: loglik(*x)
    x = key(round(offset / step_o) * step_o, 0.0)
    stencil = ((0, 0), (-1, 0), (1, 0), (0, -1), (0, 1), (1, 1))  # the fewest points that fix a 2-D quadratic
    nbrs = lambda x: [key(x[0] + i * step_o, x[1] + j * step_c) for i, j in stencil]
    S = np.diag([step_o, step_c])
    for _ in range(12):
        pts = nbrs(x)
        if not all(ok(*y) for y in pts):
            return {"note": f"not estimated: the clock model reaches the edge of the search span; {widen_hint}"}
        u = np.array([((y[0] - x[0]) / step_o, (y[1] - x[1]) / step_c) for y in pts])
        A = np.column_stack(
            [np.ones(len(pts)), u[:, 0], u[:, 1], 0.5 * u[:, 0] ** 2, u[:, 0] * u[:, 1], 0.5 * u[:, 1] ** 2]
        )
        coef = np.linalg.solve(A, np.array([ll(y) for y in pts]))
        H = np.array([[coef[3], coef[4]], [coef[4], coef[5]]])
        if not np.all(np.linalg.eigvalsh(H) < 0):  # not concave here: step to the best stencil point
            up = max(pts, key=ll)
            if up == x:
                return {
                    "note": "not estimated: the likelihood has no maximum in offset and drift (too little dynamics)"
                }
            x = up
            continue
        du = np.linalg.solve(H, -coef[1:3])  # the maximum, in grid steps from x
        if np.all(np.abs(du) <= 1.0):
            break
        x = key(
            x[0] + float(np.clip(np.round(du[0]), -5, 5)) * step_o,
            x[1] + float(np.clip(np.round(du[1]), -5, 5)) * step_c,
        )
    else:
        return {"note": "not estimated: the Newton steps did not settle"}
    est = np.array(x) + S @ du
    cov = S @ np.linalg.inv(-H) @ S
    o, c = float(est[0]), float(est[1])
    sc = float(np.sqrt(cov[1, 1]))
    t_ref = 0.5 * (tg[0] + tg[-1])
    wins = []
    for h in (tg < t_ref, tg >= t_ref):
        f = (float(np.mean(tg[h])) - t_ref) / T
        wins.append(
            {
                "t_start_s": float(tg[h][0]),
                "t_end_s": float(tg[h][-1]),
                "t_mean_s": float(np.mean(tg[h])),
                "n_epochs": int(h.sum()),
                "offset_s": o + c * f,
                "sigma_s": float(np.sqrt(max(cov[0, 0] + 2 * f * cov[0, 1] + f * f * cov[1, 1], 0.0))),
            }
        )
    sig = bool(abs(c) > DRIFT_SIGMAS * sc and abs(c) > DRIFT_MIN_CHANGE_S)
    out = {
        "method": "innovation log-likelihood of a linear clock error t + o + c (t - t_mid) / T: Newton steps "
        f"on a {step_o * 1e3:g} ms x {step_c * 1e3:g} ms grid, quadratic through six points around the "
        "best (sigmas from its curvature, optimistic as the offset's); windows: the model's offset at "
        "each half's mean epoch",
        "offset_mid_s": o,
        "change_s": c,
        "change_sigma_s": sc,
        "drift_s_per_s": c / T,
        "drift_sigma_s_per_s": sc / T,
        "windows": wins,
        "significant": sig,
    }
    if sig:
        out["warning"] = (
            f"the IMU-GNSS time offset changes over the run by {c * 1e3:+.0f} +- {sc * 1e3:.0f} ms "
            f"({c / T * 1e6:+.0f} +- {sc / T * 1e6:.0f} ppm clock drift: {wins[0]['offset_s']:+.3f} s in "
            f"the first half, {wins[1]['offset_s']:+.3f} s in the second); one offset fits neither end: "
            "re-tag the IMU (e.g. from GNSS time pulses) or process shorter pieces"
        )
    return out


def search_time_offset(
    loglik: Callable[[float, float], float],
    span: float,
    t_imu,
    w_b,
    f_b,
    t_gnss,
    llh,
    v_enu=None,
    *,
    coarse_step: float = 0.05,
    fine_step: float = 0.01,
    min_corr: float = 0.5,
    progress: Callable[[str], Any] | None = None,
    widen_hint: str = "widen the search span",
) -> dict:
    """IMU-GNSS time offset and clock drift of a recording by a filter's innovation likelihood.

    First guess :func:`estimate_time_offset` (yaw rate against GNSS course rate, lags up to
    max(1, ``span`` + 0.5) s), kept when its correlation exceeds ``min_corr``, else 0 (it assumes the body
    points along the velocity, which a handheld device does not); then :func:`likelihood_time_offset` over
    +-``span`` (grids of ``coarse_step`` and ``fine_step`` s) and :func:`clock_drift` at the best offset. ``loglik`` is memoised here (trial clocks rounded to 1 us); ``progress`` gets the
    stages and a warning when the offset is at the edge of the search or the drift significant.

    Args:
      loglik: (o s, c s) -> log-likelihood of the run with IMU times t + o + c (t - t_ref) / T (t_ref
        the middle, T the span of ``t_gnss``), scoring the same GNSS epochs at every trial
        (:func:`offset_search_epochs`).  span: search half-width, s.
      t_imu: (N,) s.  w_b, f_b: (N, 3) body rate rad/s and specific force m/s^2 (right-forward-up).
      t_gnss: (M,) s, the epochs the trials score.  llh: (M, 3) rad, rad, m.  v_enu: (M, 3) m/s or None.
      widen_hint: what the warnings say to do at the edge of the span.
    Returns:
      dict: the first guess (``first_guess``, and when used ``first_guess_s``, ``first_guess_sigma_s``,
      ``first_guess_corr``, ``first_guess_epochs``), ``method``, ``grid_s`` and ``loglik`` (the
      zero-drift trials), ``offset_s``, ``sigma_s``, ``sigma_method``, ``at_search_edge``, ``drift``
      (:func:`clock_drift`).
    """
    v = None if v_enu is None else np.asarray(v_enu, float)
    info: dict = {}
    try:
        est = estimate_time_offset(
            t_imu,
            w_b,
            t_gnss,
            v if v is not None and np.all(np.isfinite(v)) else None,
            llh=llh,
            f_b=f_b,
            max_offset_s=max(1.0, span + 0.5),
        )
        guess = float(est.offset_s)
        info.update(
            first_guess="yaw rate vs GNSS course rate cross-correlation",
            first_guess_s=guess,
            first_guess_sigma_s=float(est.sigma_s),
            first_guess_corr=float(est.corr),
            first_guess_epochs=int(est.n_epochs),
        )
        if not est.corr > min_corr:
            raise ValueError(f"weak correlation {est.corr:.2f}")
    except ValueError as exc:  # too few turns or epochs: search around zero
        guess = 0.0
        info.update(first_guess=f"0 (cross-correlation not usable: {exc})")
    cache: dict = {}

    def memo(off, change=0.0):
        key = (round(float(off), 6), round(float(change), 6))
        if key not in cache:
            cache[key] = float(loglik(*key))
        return cache[key]

    res = likelihood_time_offset(
        memo, span, guess=guess, coarse_step=coarse_step, fine_step=fine_step, progress=progress
    )
    drift = clock_drift(memo, res.offset_s, t_gnss, span, widen_hint=widen_hint)
    grid = np.array(sorted(k[0] for k in cache if k[1] == 0.0))
    info.update(
        method=f"innovation log-likelihood: {coarse_step * 1e3:g} ms grid over +-{span:g} s, "
        f"{fine_step * 1e3:g} ms grid around its best, parabolic refinement",
        grid_s=grid,
        loglik=np.array([cache[(g, 0.0)] for g in grid]),
        offset_s=res.offset_s,
        sigma_s=res.sigma_s,
        sigma_method="curvature of the log-likelihood parabola through the best three fine-grid points "
        "(treats the innovations as independent: optimistic when GNSS errors are correlated "
        "in time)",
        at_search_edge=res.at_edge,
        drift=drift,
    )
    if progress and res.at_edge:
        progress(
            f"warning: the time offset {res.offset_s:+.3f} s is at the edge of the search (+-{span} s): {widen_hint}"
        )
    if progress and drift.get("significant"):
        progress(f"warning: {drift['warning']}")
    return info
