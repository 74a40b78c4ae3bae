"""Standstill (zero-velocity) detection on the IMU alone: the SHOE GLRT and a threshold detector.

Both return a boolean per IMU sample for ZUPT / zero-angular-rate updates. Pure jnp (jit, vmap;
the noise levels and the threshold are array leaves of :class:`StandstillParams`); the window
and the minimum run length are static sample counts. :func:`detection_scores` and
:func:`standstill_intervals` are host-side helpers for reports.

SHOE detector (Skog, Händel, Nilsson, Rantakokko, "Zero-velocity detection -- an algorithm
evaluation", IEEE Trans. Biomed. Eng. 57(11), 2010, eq. 8-10): for the window Omega_n of W samples

    T_n = 1/W sum_{k in Omega_n} ( |f_k - g mean(f)/|mean(f)||^2 / sigma_a^2 + |w_k|^2 / sigma_w^2 ),

the generalized likelihood ratio of "at rest" (specific force of magnitude g along a fixed
direction, zero rate, white noise sigma_a, sigma_w per sample) against "moving"; at rest its
expected value is about (6 W - 2) / W ~ 6 (six unit-variance noise terms per sample, two degrees
of freedom absorbed by the estimated direction of gravity), so a threshold of a few tens
separates rest from walking or driving when the sigmas are the sensor's. Here the window is
centred on the sample, clamped at the ends.
"""

from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

#: standard gravity, m/s^2 (the default magnitude; pass the local normal gravity for better)
G0 = 9.80665


class StandstillParams(NamedTuple):
    """Settings of :func:`shoe_statistic` / :func:`detect_standstill` (array leaves).

    Attributes:
      sigma_a: accelerometer white-noise std per sample at rest, m/s^2 (VRW / sqrt(dt), plus the
        vibration of a parked engine if any).
      sigma_w: gyro white-noise std per sample, rad/s (ARW / sqrt(dt)).
      threshold: the test threshold gamma on T_n (dimensionless); rest where T_n < gamma.
      g: gravity magnitude, m/s^2 (an accelerometer scale error shows as motion: use the
        measured |f| at rest, or the local normal gravity); NaN: its estimate over each window.
    """

    sigma_a: ArrayLike = 0.05
    sigma_w: ArrayLike = 0.01
    threshold: ArrayLike = 30.0
    g: ArrayLike = G0


def _shift_sum(x, before: int, after: int):
    """sum_{j = n - before}^{n + after} x_j (clamped at the ends) and the sample count, per n; by
    cumulative sums and static slices (no index constants: compile time does not grow with N)."""
    N = x.shape[0]
    before, after = min(before, N), min(after, N - 1)
    c = jnp.concatenate([jnp.zeros((1,) + x.shape[1:], x.dtype), jnp.cumsum(x, 0)], 0)  # (N + 1,)
    hi = jnp.concatenate([c[after + 1 :], jnp.repeat(c[-1:], after, axis=0)], 0)  # c[min(n + after + 1, N)]
    lo = jnp.concatenate([jnp.repeat(c[:1], before, axis=0), c[: N - before]], 0)  # c[max(n - before, 0)]
    n = jnp.arange(N)
    cnt = jnp.minimum(n + after + 1, N) - jnp.maximum(n - before, 0)
    return hi - lo, cnt


def _centred_sum(x, window: int):
    """Sum over a centred window of ``window`` samples (clamped at the ends) and the sample count."""
    s, cnt = _shift_sum(x, (window - 1) // 2, window // 2)
    return s, cnt.astype(x.dtype)


def _check(f_b, w_b, window):
    if jnp.ndim(f_b) != 2 or jnp.shape(f_b)[1] != 3 or jnp.shape(f_b) != jnp.shape(w_b):
        raise ValueError(f"f_b {jnp.shape(f_b)} and w_b {jnp.shape(w_b)} must both be (N, 3)")
    if int(window) < 1:
        raise ValueError(f"window must be >= 1 sample, got {window}")


def _full_sum(x, window: int):
    """Sum over a window of ``window`` samples starting ``window // 2`` before the sample, shifted
    inside the record at the ends (every sum has ``window`` samples when N >= window)."""
    N = x.shape[0]
    c = jnp.concatenate([jnp.zeros((1,) + x.shape[1:], x.dtype), jnp.cumsum(x, 0)], 0)  # (N + 1,)
    if N <= window:
        return jnp.repeat(c[-1:], N, axis=0), jnp.full((N,), float(N), x.dtype)
    b, a = window // 2, window - 1 - window // 2
    hi = jnp.concatenate([jnp.repeat(c[window : window + 1], b, axis=0), c[window:], jnp.repeat(c[-1:], a, axis=0)], 0)
    lo = jnp.concatenate(
        [jnp.repeat(c[:1], b, axis=0), c[: N - window + 1], jnp.repeat(c[N - window : N - window + 1], a, axis=0)], 0
    )
    return hi - lo, jnp.full((N,), float(window), x.dtype)


@partial(jax.jit, static_argnames=("window", "edges"))
def shoe_statistic(f_b, w_b, params: StandstillParams = StandstillParams(), *, window: int = 20, edges: str = "clamp"):
    """SHOE GLRT statistic T_n per sample (module docstring; Skog et al. 2010).

    With ``params.g`` NaN the gravity magnitude is replaced by its maximum-likelihood estimate
    |mean f| over the window, which turns the accelerometer term into sum |f_k - mean f|^2 (an
    accelerometer bias along gravity then does not count as motion).

    Args:
      f_b: (N, 3) specific force, m/s^2.  w_b: (N, 3) angular rate, rad/s (any body axes).
      params: :class:`StandstillParams`.  window: W, samples (static).
      edges: "clamp" (window centred on the sample, (W-1)//2 before, shortened at the record's
        ends) or "shift" (W//2 before, kept at W samples by shifting it inside the record).
    Returns:
      (N,) T_n, dimensionless (rest where below ``params.threshold``).
    """
    _check(f_b, w_b, window)
    if edges not in ("clamp", "shift"):
        raise ValueError(f"edges must be 'clamp' or 'shift', got {edges!r}")
    wsum = _centred_sum if edges == "clamp" else _full_sum
    sf, n = wsum(f_b, window)
    sff, _ = wsum(jnp.sum(f_b * f_b, 1), window)
    sww, _ = wsum(jnp.sum(w_b * w_b, 1), window)
    g = jnp.asarray(params.g, f_b.dtype)
    g = jnp.where(jnp.isfinite(g), g, jnp.linalg.norm(sf, axis=1) / n)
    # sum |f_k - g u|^2 = sum |f_k|^2 - 2 g |sum f_k| + n g^2  (u = sum f / |sum f|)
    acc = jnp.maximum(sff - 2.0 * g * jnp.linalg.norm(sf, axis=1) + n * g * g, 0.0)
    return (acc / params.sigma_a**2 + sww / params.sigma_w**2) / n


def keep_runs(d, min_samples: int):
    """(N,) bool ``d`` with its runs of True shorter than ``min_samples`` dropped (binary opening)."""
    return _min_run(jnp.asarray(d), int(min_samples))


def _min_run(d, m: int):
    """Keep only runs of True at least ``m`` samples long (binary opening with a length-m segment)."""
    if m <= 1:
        return d
    ahead, _ = _shift_sum(d.astype(jnp.int32), 0, m - 1)  # True samples among n .. n+m-1
    full = ahead == m  # erosion: a full run of m starts at n (counts are clamped at the end)
    behind, _ = _shift_sum(full.astype(jnp.int32), m - 1, 0)  # dilation: one starts in n-m+1 .. n
    return behind > 0


@partial(jax.jit, static_argnames=("window", "min_samples"))
def detect_standstill(
    f_b, w_b, params: StandstillParams = StandstillParams(), *, window: int = 20, min_samples: int = 1
):
    """Boolean standstill flag per IMU sample: SHOE T_n < threshold, runs shorter than ``min_samples`` dropped.

    Args:
      f_b, w_b: (N, 3) m/s^2, rad/s.  params: :class:`StandstillParams`.
      window: SHOE window, samples.  min_samples: shortest standstill kept, samples.
    Returns:
      (N,) bool.
    """
    return _min_run(shoe_statistic(f_b, w_b, params, window=window) < params.threshold, int(min_samples))


@partial(jax.jit, static_argnames=("window", "min_samples"))
def threshold_standstill(f_b, w_b, accel_std_max, gyro_max, *, window: int = 20, min_samples: int = 1):
    """Threshold detector: moving std of |f| below ``accel_std_max`` (m/s^2) and moving RMS of |w|
    below ``gyro_max`` (rad/s), over a centred window of ``window`` samples; runs shorter than
    ``min_samples`` dropped (the magnitude/variance tests of Skog et al. 2010, sect. II).

    Args:
      f_b, w_b: (N, 3) m/s^2, rad/s.  accel_std_max: m/s^2.  gyro_max: rad/s.
    Returns:
      (N,) bool.
    """
    _check(f_b, w_b, window)
    a = jnp.linalg.norm(f_b, axis=1)
    s1, n = _centred_sum(a, window)
    s2, _ = _centred_sum(a * a, window)
    var = jnp.maximum(s2 / n - (s1 / n) ** 2, 0.0)
    ww, _ = _centred_sum(jnp.sum(w_b * w_b, 1), window)
    d = (var < jnp.square(accel_std_max)) & (ww / n < jnp.square(gyro_max))
    return _min_run(d, int(min_samples))


def standstill_intervals(t, detected):
    """(K, 2) [t_start, t_end] of the runs of a per-sample flag (host side; a run covers the sample
    times from its first to its last sample)."""
    d = np.asarray(detected, bool)
    t = np.asarray(t, float)
    e = np.diff(np.concatenate([[0], d.astype(np.int8), [0]]))
    a, b = np.flatnonzero(e == 1), np.flatnonzero(e == -1) - 1
    return np.stack([t[a], t[b]], 1) if a.size else np.zeros((0, 2))


def runs_touching(d, anchor):
    """(N,) bool: the runs of True in ``d`` that contain at least one ``anchor`` sample (host side)."""
    d, anchor = np.asarray(d, bool), np.asarray(anchor, bool)
    if d.shape != anchor.shape:
        raise ValueError(f"d {d.shape} and anchor {anchor.shape} must have the same shape")
    run = np.cumsum(np.concatenate([[d[0]], d[1:] & ~d[:-1]])) if d.size else np.zeros(0, int)
    hit = np.zeros(int(run.max(initial=0)) + 1, bool)
    hit[run[d & anchor]] = True
    return d & hit[run]


class DetectionScores(NamedTuple):
    """Per-sample scores of a detector: precision = TP / (TP + FP), recall = TP / (TP + FN)
    (NaN when undefined), and the counts."""

    precision: float
    recall: float
    tp: int
    fp: int
    fn: int
    tn: int


def detection_scores(detected, truth) -> DetectionScores:
    """Per-sample precision and recall of ``detected`` (N,) bool against ``truth`` (N,) bool (host side)."""
    d = np.asarray(detected, bool)
    s = np.asarray(truth, bool)
    if d.shape != s.shape:
        raise ValueError(f"detected {d.shape} and truth {s.shape} must have the same shape")
    tp, fp = int(np.sum(d & s)), int(np.sum(d & ~s))
    fn, tn = int(np.sum(~d & s)), int(np.sum(~d & ~s))
    return DetectionScores(
        precision=tp / (tp + fp) if tp + fp else float("nan"),
        recall=tp / (tp + fn) if tp + fn else float("nan"),
        tp=tp,
        fp=fp,
        fn=fn,
        tn=tn,
    )


#: platform presets of the standstill detector: SHOE window (s), shortest standstill kept (s), the
#: margin on the quiet-period quantile of T_n that sets the threshold (see :func:`quiet_threshold`),
#: whether GNSS motion vetoes a standstill (not on a foot: the foot rests in every step while the
#: antenna moves on), and whether a standstill must touch a GNSS-static sample (a smooth cruise
#: looks at rest to the IMU, so where GNSS cannot check, e.g. in an outage, a vehicle gets no ZUPT)
PLATFORMS = {
    "foot": {"window_s": 0.03, "min_s": 0.05, "margin": 3.0, "gnss_veto": False, "need_gnss_static": False},
    "handheld": {"window_s": 0.3, "min_s": 1.0, "margin": 2.0, "gnss_veto": True, "need_gnss_static": True},
    "car": {"window_s": 1.0, "min_s": 2.0, "margin": 1.5, "gnss_veto": True, "need_gnss_static": True},
    "rover": {"window_s": 1.0, "min_s": 2.0, "margin": 1.5, "gnss_veto": True, "need_gnss_static": True},
}


def gnss_speed_test(t, pos_enu, vel_enu, R, pos_ok, vel_ok):
    """Normalised GNSS speed q = sqrt(v^T C_v^-1 v) per epoch (host side).

    Where the solution carries a velocity (``vel_ok``) it is used with its covariance; elsewhere the
    velocity is the position difference to the neighbouring usable epoch, (p_{i+1} - p_{i-1}) /
    (t_{i+1} - t_{i-1}) over the nearest usable epochs on each side (one side at the ends), with
    C_v = (C_p,a + C_p,b) / dt^2. At rest q^2 ~ chi^2(3); q is NaN where no usable epoch exists.

    Args:
      t: (M,) s.  pos_enu: (M, 3) positions in a local ENU frame, m.  vel_enu: (M, 3) m/s.
      R: (M, 6, 6) covariance of [pos ENU (m), vel ENU (m/s)].  pos_ok, vel_ok: (M,) bool.
    Returns:
      (q (M,), speed (M,) m/s, speed sigma (M,) m/s: sqrt(trace C_v / 3)).
    """
    t = np.asarray(t, float)
    M = t.size
    p, v, R = np.asarray(pos_enu, float), np.asarray(vel_enu, float), np.asarray(R, float)
    if p.shape != (M, 3) or v.shape != (M, 3) or R.shape != (M, 6, 6):
        raise ValueError(
            f"t {t.shape}, pos_enu {p.shape}, vel_enu {v.shape}, R {R.shape}: need (M,), (M, 3), (M, 3), (M, 6, 6)"
        )
    pos_ok = np.asarray(pos_ok, bool) & np.all(np.isfinite(p), 1)
    vel_ok = np.asarray(vel_ok, bool) & np.all(np.isfinite(v), 1)
    vv, C = np.full((M, 3), np.nan), np.full((M, 3, 3), np.nan)
    vv[vel_ok], C[vel_ok] = v[vel_ok], R[vel_ok, 3:, 3:]
    ip = np.flatnonzero(pos_ok)
    if ip.size >= 2:
        need = ~vel_ok & pos_ok
        k = np.searchsorted(ip, np.flatnonzero(need))  # position of each epoch in the usable list
        a, b = ip[np.maximum(k - 1, 0)], ip[np.minimum(k + 1, ip.size - 1)]
        dt = t[b] - t[a]
        good = dt > 0
        i = np.flatnonzero(need)[good]
        a, b, dt = a[good], b[good], dt[good]
        vv[i] = (p[b] - p[a]) / dt[:, None]
        C[i] = (R[a, :3, :3] + R[b, :3, :3]) / dt[:, None, None] ** 2
    q = np.full(M, np.nan)
    ok = np.all(np.isfinite(vv), 1) & np.all(np.isfinite(C.reshape(M, 9)), 1)
    if ok.any():
        q[ok] = np.sqrt(np.einsum("mi,mi->m", vv[ok], np.linalg.solve(C[ok], vv[ok][..., None])[..., 0]))
    sig = np.sqrt(np.trace(C, axis1=1, axis2=2) / 3.0)
    return q, np.linalg.norm(vv, axis=1), sig


def gnss_motion_labels(t_imu, t_gnss, q, *, k_moving: float = 3.0, q_static: float = 2.8, max_gap_s: float = 1.5):
    """Per-IMU-sample GNSS labels from the normalised speeds ``q`` of :func:`gnss_speed_test` (host side).

    The neighbours of a sample are the usable GNSS epochs just before and just after it, if within
    ``max_gap_s``. A sample is *moving* when it has a neighbour and every neighbour has q >
    ``k_moving`` (two epochs must agree where there are two: at rest a single epoch beyond 3 sigma
    has a probability of 3 %, two in a row 0.1 %), and *static* when both neighbours exist and
    have q < ``q_static`` (default sqrt(chi^2_3(0.95)) = 2.8: a speed within its own 95 %
    uncertainty of zero); samples far from any epoch get neither label.

    Args:
      t_imu: (N,) s.  t_gnss: (M,) s, increasing.  q: (M,) normalised speed (NaN: not usable).
    Returns:
      (moving (N,) bool, static (N,) bool, covered (N,) bool: usable epochs within ``max_gap_s`` on both sides).
    """
    t_imu, t_gnss, q = np.asarray(t_imu, float), np.asarray(t_gnss, float), np.asarray(q, float)
    if t_gnss.shape != q.shape:
        raise ValueError(f"t_gnss {t_gnss.shape} and q {q.shape} must have the same shape")
    use = np.isfinite(q)
    tg, qg = t_gnss[use], q[use]
    N = t_imu.size
    if tg.size == 0:
        return np.zeros(N, bool), np.zeros(N, bool), np.zeros(N, bool)
    j = np.searchsorted(tg, t_imu)
    jb, ja = np.clip(j - 1, 0, tg.size - 1), np.clip(j, 0, tg.size - 1)
    near_b = (t_imu - tg[jb] <= max_gap_s) & (tg[jb] <= t_imu + 1e-9)
    near_a = (tg[ja] - t_imu <= max_gap_s) & (tg[ja] >= t_imu - 1e-9)
    mb, ma = qg[jb] > k_moving, qg[ja] > k_moving
    moving = (near_b | near_a) & (mb | ~near_b) & (ma | ~near_a)
    static = near_b & near_a & (qg[jb] < q_static) & (qg[ja] < q_static)
    return moving, static, near_b & near_a


def quiet_threshold(stat, quiet, *, margin: float = 2.0, quantile: float = 0.95, min_samples: int = 20):
    """SHOE threshold from the recording's own quiet samples: gamma = margin * Q_quantile(T_n | quiet).

    The statistic's spread at rest depends on the true noise (and a running engine), not only on the
    configured sigmas, so the threshold is placed above its observed distribution over samples known
    to be at rest (GNSS-static, the declared static start). Returns NaN when fewer than
    ``min_samples`` quiet samples exist (the caller then uses its fixed threshold).

    Args:
      stat: (N,) T_n.  quiet: (N,) bool.
    Returns:
      gamma (float, dimensionless) or NaN.
    """
    s, qm = np.asarray(stat, float), np.asarray(quiet, bool)
    if s.shape != qm.shape:
        raise ValueError(f"stat {s.shape} and quiet {qm.shape} must have the same shape")
    v = s[qm & np.isfinite(s)]
    if v.size < max(int(min_samples), 1):
        return float("nan")
    return float(margin * np.quantile(v, quantile))


class CheckedStandstill(NamedTuple):
    """Result of :func:`gnss_checked_standstill` (host side, per IMU sample unless noted).

    Attributes:
      detected: (N,) bool, the standstills kept.  stat: (N,) SHOE statistic T_n.
      raw: (N,) bool, T_n below the threshold (runs of at least ``min_samples``), before any GNSS check.
      moving, static, covered: (N,) bool GNSS labels (:func:`gnss_motion_labels`; all False without GNSS;
        ``moving`` also False on platforms without the GNSS veto).
      vetoed: (N,) bool, IMU standstills GNSS says are moving.  unconfirmed: (N,) bool, standstills
        dropped for touching no GNSS-static sample.
      threshold: gamma used.  threshold_source: "quiet periods", "fallback (too few quiet samples)" or "given".
      quiet_samples: samples the threshold was taken over.  window: SHOE window, samples.
      min_samples: shortest standstill kept, samples.  min_s: the same, s.  g: gravity used, m/s^2.
      scores, imu_only_scores: :class:`DetectionScores` of ``detected`` and ``raw`` against the
        GNSS-static labels where GNSS brackets the sample (``covered``).
    """

    detected: np.ndarray
    stat: np.ndarray
    raw: np.ndarray
    moving: np.ndarray
    static: np.ndarray
    covered: np.ndarray
    vetoed: np.ndarray
    unconfirmed: np.ndarray
    threshold: float
    threshold_source: str
    quiet_samples: int
    window: int
    min_samples: int
    min_s: float
    g: float
    scores: DetectionScores
    imu_only_scores: DetectionScores


def standstill_summary(r: CheckedStandstill, t, rate_hz: float) -> dict:
    """The numbers of a :func:`gnss_checked_standstill` run for a report (results.json): detector settings
    used, samples / intervals / seconds the GNSS check vetoed or left unconfirmed, and the precision and
    recall of the kept and the IMU-only standstills against the GNSS-static labels.

    Args:
      r: the detection.  t: (N,) s, the IMU sample times.  rate_hz: IMU rate, Hz.
    """
    sc, sc_imu = r.scores, r.imu_only_scores
    n_vetoed = int(np.count_nonzero(r.vetoed))
    return {
        "window_samples": r.window,
        "min_s": r.min_s,
        "threshold": r.threshold,
        "threshold_source": r.threshold_source,
        "quiet_samples": r.quiet_samples,
        "vetoed_samples": n_vetoed,
        "vetoed_intervals": int(standstill_intervals(t, r.vetoed).shape[0]),
        "vetoed_s": float(n_vetoed / rate_hz),
        "unconfirmed_samples": int(np.count_nonzero(r.unconfirmed)),
        "unconfirmed_intervals": int(standstill_intervals(t, r.unconfirmed).shape[0]),
        "gnss_static_samples": int(np.count_nonzero(r.static)),
        "gnss_moving_samples": int(np.count_nonzero(r.moving)),
        "scored_samples": int(np.count_nonzero(r.covered)),
        "precision": sc.precision,
        "recall": sc.recall,
        "tp": sc.tp,
        "fp": sc.fp,
        "fn": sc.fn,
        "tn": sc.tn,
        "imu_only_precision": sc_imu.precision,
        "imu_only_recall": sc_imu.recall,
    }


def gnss_checked_standstill(
    t,
    f_b,
    w_b,
    *,
    sigma_a: float,
    sigma_w: float,
    platform: str = "car",
    static_s: float = 0.0,
    window=None,
    min_s=None,
    threshold="auto",
    fallback_threshold: float = 60.0,
    t_gnss=None,
    q_gnss=None,
    k_moving: float = 3.0,
    max_gap_s: float = 1.5,
    rate_hz=None,
) -> CheckedStandstill:
    """Standstill per IMU sample: SHOE GLRT, a threshold from the quiet periods, and a GNSS check (host side).

    Gravity for the test is the mean |f| over the first ``static_s`` seconds (absorbs a scale error).
    The platform preset (:data:`PLATFORMS`) gives the window, the shortest standstill and the threshold
    margin unless ``window`` (samples) or ``min_s`` (s) are given. Quiet samples are the GNSS-static ones
    (:func:`gnss_motion_labels` on the normalised speeds ``q_gnss`` (M,) of :func:`gnss_speed_test` at
    ``t_gnss`` (M,) s) and the declared static start; with ``threshold = "auto"`` gamma is
    :func:`quiet_threshold` over them (``fallback_threshold``, by default 10 times the rest expectation 6
    of T_n, when too few exist), else the number given. Samples where GNSS says the platform moves are
    vetoed on platforms whose preset asks for it, and there a standstill must also touch a GNSS-static
    sample (one wholly inside a GNSS gap is dropped as unconfirmed).

    Args:
      t: (N,) s.  f_b, w_b: (N, 3) specific force m/s^2 and angular rate rad/s, body axes.
      sigma_a: accelerometer noise per sample at rest, m/s^2.  sigma_w: gyro noise per sample, rad/s.
      max_gap_s: GNSS epochs further than this from a sample do not label it (at least 0.3 s is used).
      rate_hz: IMU rate, Hz, for the preset durations (default: from the median step of ``t``).
    Returns:
      :class:`CheckedStandstill`.
    """
    t = np.asarray(t, float)
    f, w = np.asarray(f_b, float), np.asarray(w_b, float)
    if f.shape != (t.size, 3) or w.shape != (t.size, 3):
        raise ValueError(f"t {t.shape}, f_b {f.shape}, w_b {w.shape}: need (N,), (N, 3), (N, 3)")
    if platform not in PLATFORMS:
        raise ValueError(f"platform must be one of {sorted(PLATFORMS)}, got {platform!r}")
    pf = PLATFORMS[platform]
    st = t <= t[0] + static_s
    g = float(np.mean(np.linalg.norm(f[st], axis=1)))
    rate = float(rate_hz) if rate_hz is not None else 1.0 / float(np.median(np.diff(t)))
    window = int(window) if window is not None else max(1, int(round(pf["window_s"] * rate)))
    min_s = float(pf["min_s"] if min_s is None else min_s)
    m = max(1, int(round(min_s * rate)))
    stat = np.asarray(
        shoe_statistic(f, w, StandstillParams(sigma_a=sigma_a, sigma_w=sigma_w, threshold=1.0, g=g), window=window)
    )
    N = t.size
    moving, static, covered = np.zeros(N, bool), np.zeros(N, bool), np.zeros(N, bool)
    gnss = t_gnss is not None
    if gnss:
        moving, static, covered = gnss_motion_labels(
            t, t_gnss, q_gnss, k_moving=k_moving, max_gap_s=max(max_gap_s, 0.3)
        )
    quiet = (static | st) & ~moving
    if threshold == "auto":
        gamma = quiet_threshold(stat, quiet, margin=pf["margin"], min_samples=m)
        source = "quiet periods" if np.isfinite(gamma) else "fallback (too few quiet samples)"
        gamma = gamma if np.isfinite(gamma) else fallback_threshold
    else:
        gamma, source = float(threshold), "given"
    raw = np.asarray(keep_runs(stat < gamma, m))
    if not pf["gnss_veto"]:
        moving = np.zeros(N, bool)
    vetoed = raw & moving
    det = np.asarray(keep_runs(raw & ~moving, m))
    unconfirmed = np.zeros(N, bool)
    if pf["need_gnss_static"] and gnss and static.any():
        kept = runs_touching(det, static)
        unconfirmed, det = det & ~kept, kept
    return CheckedStandstill(
        detected=det,
        stat=stat,
        raw=raw,
        moving=moving,
        static=static,
        covered=covered,
        vetoed=vetoed,
        unconfirmed=unconfirmed,
        threshold=float(gamma),
        threshold_source=source,
        quiet_samples=int(np.count_nonzero(quiet)),
        window=window,
        min_samples=m,
        min_s=min_s,
        g=g,
        scores=detection_scores(det[covered], static[covered]),
        imu_only_scores=detection_scores(raw[covered], static[covered]),
    )
