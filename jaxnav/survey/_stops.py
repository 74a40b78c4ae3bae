"""Stops of a cadastral survey (S3 step 2): the five stop kinds, the user stop list and its
checks (its CSV files: :mod:`jaxnav.io`), the three data classes, and a static/dynamic detector.

Stop kinds (S3): known-coordinate point (control point: E, N, U known), known-position point
(horizontal position known), levelling-correction point (height known), zero-velocity-update
point, target (unknown) point. Every stop is static, so every stop also gives a zero-velocity
observation.

Data classes (S3 step 2): class 1 = the static data at any stop; class 2 = the dynamic data
between stops; class 3 = a target stop whose previous stop is a known-coordinate point.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from jaxnav.geodesy import curvilinear_to_enu
from jaxnav.ins.standstill import StandstillParams, shoe_statistic

KNOWN_COORDINATE, KNOWN_POSITION, LEVELLING, ZUPT, TARGET = range(5)
#: stop kind names, index = code
STOP_KINDS = ("known_coordinate", "known_position", "levelling", "zupt", "target")
#: data classes (per sample): 0 before the first / after the last stop, 1 static, 2 dynamic
CLASS_STATIC, CLASS_DYNAMIC = 1, 2


class StopList(NamedTuple):
    """A survey's stops (host-side numpy), K rows in time order.

    Attributes:
      t_start, t_end: (K,) stop span, s (IMU time scale).
      kind: (K,) int codes into :data:`STOP_KINDS`.
      pos: (K, 3) known [lat rad, lon rad, h m] (NaN where not known for that kind).
      sigma: (K, 3) standard deviation of the known E, N, U coordinates, m.
      name: tuple of K point names.
    """

    t_start: jax.Array
    t_end: jax.Array
    kind: jax.Array
    pos: jax.Array
    sigma: jax.Array
    name: tuple


def make_stop_list(t_start, t_end, kind, pos=None, sigma=None, name=None) -> StopList:
    """Build and shape-check a :class:`StopList` (kinds as codes or names)."""
    t_start = np.asarray(t_start, float).reshape(-1)
    t_end = np.asarray(t_end, float).reshape(-1)
    K = t_start.shape[0]
    kind = np.array([STOP_KINDS.index(k) if isinstance(k, str) else int(k) for k in np.atleast_1d(kind)], np.int64)
    pos = np.full((K, 3), np.nan) if pos is None else np.asarray(pos, float)
    sigma = np.full((K, 3), 0.01) if sigma is None else np.asarray(sigma, float)
    name = tuple(f"P{i}" for i in range(K)) if name is None else tuple(name)
    for nm, a, shp in (
        ("t_end", t_end, (K,)),
        ("kind", kind, (K,)),
        ("pos", np.asarray(pos), (K, 3)),
        ("sigma", sigma, (K, 3)),
    ):
        if np.shape(a) != shp:
            raise ValueError(f"stop list: {nm} has shape {np.shape(a)}; expected {shp} for {K} stops")
    if len(name) != K:
        raise ValueError(f"stop list: {len(name)} names for {K} stops")
    return StopList(t_start=t_start, t_end=t_end, kind=kind, pos=np.asarray(pos, float), sigma=sigma, name=name)


def validate_stops(stops: StopList, t_first: float, t_last: float) -> None:
    """Check a stop list against the IMU data's time span and the S3 processing rules.

    Raises:
      ValueError: if the stops are not in time order or overlap, a stop lies outside
        [t_first, t_last] (the data's span: the stop list does not belong to this data), or a
        target point has no known-coordinate point before it (forward navigation starts at one).
    """
    K = len(stops.t_start)
    if K == 0:
        raise ValueError("the stop list is empty")
    lo, hi = float(np.min(stops.t_start)), float(np.max(stops.t_end))
    if lo < t_first - 1e-9 or hi > t_last + 1e-9:
        raise ValueError(
            f"the stop list spans [{lo:.3f}, {hi:.3f}] s but the IMU data spans [{t_first:.3f}, "
            f"{t_last:.3f}] s: the stop list does not match this data (time scale or file?)"
        )
    if np.any(np.diff(stops.t_start) <= 0) or np.any(stops.t_start[1:] < stops.t_end[:-1]):
        i = int(np.argmax((np.diff(stops.t_start) <= 0) | (stops.t_start[1:] < stops.t_end[:-1])))
        raise ValueError(f"stops {stops.name[i]!r} and {stops.name[i + 1]!r} are not in time order or overlap")
    seen_known = False
    for i in range(K):
        if stops.kind[i] == KNOWN_COORDINATE:
            seen_known = True
        elif stops.kind[i] == TARGET and not seen_known:
            raise ValueError(
                f"target point {stops.name[i]!r} (t = {stops.t_start[i]:.3f} s) has no known-coordinate "
                "point before it: forward navigation to a target starts at a known-coordinate point"
            )


class DataClasses(NamedTuple):
    """Output of :func:`classify`.

    Attributes:
      sample_class: (N,) int8, 1 static (class 1), 2 dynamic between stops (class 2), 0 outside.
      stop_of_sample: (N,) int, index of the stop a static sample belongs to (-1 otherwise).
      class3: (K,) bool, target stops whose previous stop is a known-coordinate point (class 3).
      prev_known: (K,) int, last known-coordinate stop before each stop (-1 if none).
      next_known: (K,) int, first known-coordinate stop after each stop (-1 if none).
    """

    sample_class: jax.Array
    stop_of_sample: jax.Array
    class3: jax.Array
    prev_known: jax.Array
    next_known: jax.Array


def classify(stops: StopList, t_imu) -> DataClasses:
    """Split the IMU samples into the three S3 data classes (host side).

    A sample (ending at t_imu[i]) is static when t_start < t_imu[i] <= t_end of a stop.
    """
    t = np.asarray(t_imu, float)
    K = len(stops.t_start)
    j = np.searchsorted(stops.t_start, t, side="left") - 1  # last stop starting before t
    jj = np.clip(j, 0, K - 1)
    static = (j >= 0) & (t <= stops.t_end[jj])
    stop_of = np.where(static, jj, -1)
    inside = (t > stops.t_start[0]) & (t <= stops.t_end[-1])
    cls = np.where(static, CLASS_STATIC, np.where(inside, CLASS_DYNAMIC, 0)).astype(np.int8)
    known = stops.kind == KNOWN_COORDINATE
    prev_known = np.full(K, -1)
    next_known = np.full(K, -1)
    last = -1
    for i in range(K):
        prev_known[i] = last
        if known[i]:
            last = i
    nxt = -1
    for i in range(K - 1, -1, -1):
        next_known[i] = nxt
        if known[i]:
            nxt = i
    class3 = np.zeros(K, bool)
    class3[1:] = (stops.kind[1:] == TARGET) & known[:-1]
    return DataClasses(
        sample_class=cls, stop_of_sample=stop_of, class3=class3, prev_known=prev_known, next_known=next_known
    )


# ------------------------------------------------------------------------------------------
# static/dynamic detector


class DetectorParams(NamedTuple):
    """Tunable detector parameters (array leaves).

    Attributes:
      sigma_a: accelerometer noise std per sample, m/s^2.  sigma_g: gyro noise std, rad/s.
      threshold: test threshold on the statistic (dimensionless; ~1 when static).
      gravity: local gravity magnitude, m/s^2; NaN (default): unknown, replaced by its maximum-
        likelihood estimate |mean f| over the window (then an accelerometer bias along gravity
        does not count as motion).
    """

    sigma_a: ArrayLike = 0.02
    sigma_g: ArrayLike = 2e-3
    threshold: ArrayLike = 3.0
    gravity: ArrayLike = float("nan")


def stance_statistic(f_b, w_b, params: DetectorParams = DetectorParams(), *, window: int = 50):
    """Generalized-likelihood-ratio static test statistic (stance hypothesis, "SHOE" detector).

    T_k = 1/W sum_{i in window} ( |f_i - g u_k|^2 / sigma_a^2 + |w_i|^2 / sigma_g^2 ),
    u_k = mean(f) / |mean(f)| over the window: :func:`jaxnav.ins.shoe_statistic` with windows of W
    samples starting W // 2 before each sample (shifted inside the record at its ends). With g
    unknown its ML estimate |mean f| turns the accelerometer term into the moving variance sum
    |f_i - mean f|^2.

    Args:
      f_b: (N, 3) specific force, m/s^2.  w_b: (N, 3) angular rate, rad/s.
      params: :class:`DetectorParams`.  window: static window length, samples.
    Returns:
      (N,) statistic T_k (static where below the threshold).
    """
    p = StandstillParams(sigma_a=params.sigma_a, sigma_w=params.sigma_g, threshold=params.threshold, g=params.gravity)
    return shoe_statistic(jnp.asarray(f_b), jnp.asarray(w_b), p, window=window, edges="shift")


def static_spans(static, t, *, min_duration: float = 2.0, min_gap: float = 0.5):
    """Runs of a boolean static mask as (K, 2) [t_start, t_end] spans (host side).

    Gaps shorter than ``min_gap`` inside a stop are closed first, then static runs shorter
    than ``min_duration`` are dropped. A span covers the samples' intervals (t[i-1], t[i]].
    """
    s = np.asarray(static, bool).copy()
    t = np.asarray(t, float)
    dt0 = t[1] - t[0] if t.size > 1 else 0.0
    t_prev = np.concatenate([[t[0] - dt0], t[:-1]])

    def runs(mask):
        d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
        return np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1

    a, b = runs(~s)
    for i0, i1 in zip(a, b):
        if i0 > 0 and i1 < len(s) - 1 and t[i1] - t_prev[i0] < min_gap:
            s[i0 : i1 + 1] = True
    a, b = runs(s)
    spans = [(t_prev[i0], t[i1]) for i0, i1 in zip(a, b) if t[i1] - t_prev[i0] >= min_duration]
    return np.array(spans, float).reshape(-1, 2)


class DetectionResult(NamedTuple):
    """Output of :func:`detect_stops`: statistic (N,), static mask (N,), spans (K, 2) s."""

    statistic: np.ndarray
    static: np.ndarray
    spans: np.ndarray


def detect_stops(
    t,
    f_b,
    w_b,
    params: DetectorParams = DetectorParams(),
    *,
    window: int = 50,
    min_duration: float = 2.0,
    min_gap: float = 0.5,
) -> DetectionResult:
    """Static/dynamic segmentation: GLRT statistic, threshold, then span clean-up (S3 step 2).

    Args:
      t: (N,) sample times, s.  f_b, w_b: (N, 3) specific force (m/s^2) and rate (rad/s).
      params: :class:`DetectorParams`.  window: static, samples.
      min_duration: shortest stop kept, s.  min_gap: motion gaps shorter than this are closed, s.
    Returns:
      :class:`DetectionResult`.
    """
    T = stance_statistic(jnp.asarray(f_b), jnp.asarray(w_b), params, window=window)
    static = np.asarray(T < params.threshold)
    return DetectionResult(
        statistic=np.asarray(T),
        static=static,
        spans=static_spans(static, t, min_duration=min_duration, min_gap=min_gap),
    )


class MatchScore(NamedTuple):
    """Stop-detection scores: precision = matched detections / detections, recall = matched true
    stops / true stops (a match overlaps by at least ``min_overlap`` of the true stop and each
    span matches at most once); sample_precision/sample_recall on the per-sample labels;
    start_error/end_error: (n_matched,) detected minus true boundary times, s."""

    precision: float
    recall: float
    n_true: int
    n_detected: int
    n_matched: int
    sample_precision: float
    sample_recall: float
    start_error: np.ndarray
    end_error: np.ndarray


def match_stops(detected, true, *, min_overlap: float = 0.5, t=None, static=None) -> MatchScore:
    """Score detected stop spans against the true ones (host side)."""
    det = np.asarray(detected, float).reshape(-1, 2)
    tru = np.asarray(true, float).reshape(-1, 2)
    used = np.zeros(len(det), bool)
    se, ee = [], []
    for a, b in tru:
        ov = np.minimum(det[:, 1], b) - np.maximum(det[:, 0], a)
        ov = np.where(used, -np.inf, ov)
        if len(det) and ov.max() >= min_overlap * (b - a):
            k = int(np.argmax(ov))
            used[k] = True
            se.append(det[k, 0] - a)
            ee.append(det[k, 1] - b)
    nm = int(used.sum())
    sp = sr = float("nan")
    if t is not None and static is not None:
        t = np.asarray(t, float)
        truth = np.zeros(t.shape, bool)
        for a, b in tru:
            truth |= (t > a) & (t <= b)
        st = np.asarray(static, bool)
        sp = float((st & truth).sum() / max(st.sum(), 1))
        sr = float((st & truth).sum() / max(truth.sum(), 1))
    return MatchScore(
        precision=nm / max(len(det), 1),
        recall=nm / max(len(tru), 1),
        n_true=len(tru),
        n_detected=len(det),
        n_matched=nm,
        sample_precision=sp,
        sample_recall=sr,
        start_error=np.array(se),
        end_error=np.array(ee),
    )


def detection_scores(static, t, true_spans, *, min_duration: float = 2.0, min_gap: float = 0.5) -> dict:
    """Stop-detection scores over Monte Carlo runs: :func:`static_spans` of each run, :func:`match_stops`.

    Args:
      static: (S, N) bool per-sample static decisions of S runs.  t: (N,) sample times, s.
      true_spans: (K, 2) true stops [start, end], s.  min_duration, min_gap: of :func:`static_spans`, s.
    Returns:
      dict: ``precision_mean``, ``recall_mean``, ``precision_min``, ``recall_min``,
      ``sample_precision_mean``, ``sample_recall_mean``, ``boundary_error_s_mean_abs`` (mean |detected -
      true| start and end time over the matched stops, s), ``n_true_stops``.
    """
    true_spans = np.asarray(true_spans, float).reshape(-1, 2)
    scores = [
        match_stops(static_spans(st, t, min_duration=min_duration, min_gap=min_gap), true_spans, t=t, static=st)
        for st in np.asarray(static, bool)
    ]
    return {
        "precision_mean": float(np.mean([s.precision for s in scores])),
        "recall_mean": float(np.mean([s.recall for s in scores])),
        "precision_min": float(np.min([s.precision for s in scores])),
        "recall_min": float(np.min([s.recall for s in scores])),
        "sample_precision_mean": float(np.mean([s.sample_precision for s in scores])),
        "sample_recall_mean": float(np.mean([s.sample_recall for s in scores])),
        "boundary_error_s_mean_abs": float(
            np.mean(np.abs(np.concatenate([np.concatenate([s.start_error, s.end_error]) for s in scores])))
        ),
        "n_true_stops": len(true_spans),
    }


def stop_records(stops: StopList) -> list[dict]:
    """JSON-ready records of a stop list: one {"name", "kind" (a :data:`STOP_KINDS` name), "t_start", "t_end" (s)} per stop."""
    return [
        {
            "name": stops.name[k],
            "kind": STOP_KINDS[stops.kind[k]],
            "t_start": float(stops.t_start[k]),
            "t_end": float(stops.t_end[k]),
        }
        for k in range(len(stops.t_start))
    ]


def horizontal_speed(t, pos):
    """Horizontal speed along a geodetic track (e.g. RTK positions), from central differences of its local E, N.

    Args:
      t: (N,) s, increasing.  pos: (N, 3) [lat rad, lon rad, h m] (E, N about the first position).
    Returns:
      (N,) m/s.
    """
    t, pos = np.asarray(t, float), np.asarray(pos, float)
    enu = np.asarray(curvilinear_to_enu(pos[0], pos - pos[0]))
    v = np.gradient(enu, t, axis=0)
    return np.hypot(v[:, 0], v[:, 1])
