"""Numeric text tables (KF-GINS text files, generic CSV) -> SI IMU and GNSS records, host side (numpy).

The shared core of :mod:`jaxnav.io._kfgins` and :mod:`jaxnav.io._csv`: split lines, pick columns,
read numbers, and turn rows into the records the other readers return
(:class:`jaxnav.io.ImuLog`, :class:`jaxnav.io.PosSolution`). Rules, the same for every table:

* Errors are :class:`jaxnav.io.ReaderError` naming the file and line: bytes that are not UTF-8,
  a NUL byte, a missing column, a field that is not a number, an infinite or impossible value
  (|specific force| > 1000 m/s^2, |rate| > 200 rad/s, |lat| > 90 deg, a standard deviation that is
  not positive), a time that does not increase.
* ``nan`` (any case) is a missing value: an IMU line with one is skipped and listed in
  ``ImuLog.skipped``; a GNSS epoch without its position or position sigma is dropped, a missing
  velocity leaves a NaN row in ``v_enu``; both counted in ``PosSolution.n_masked``.
"""

from __future__ import annotations

import math
import re

import numpy as np

from jaxnav.io._errors import HEIGHT_RANGE_M, SIGMA_MAX_M, ReaderError, text_lines
from jaxnav.io._imu import ACCEL_MAX, GYRO_MAX, ImuLog
from jaxnav.io._rtklib import GPST_RANGE_S, SECONDS_PER_WEEK, PosSolution

_ANY_SEP = re.compile(r"[,\s]+")


def split_fields(text: str, delimiter):
    """Fields of one line: ``delimiter`` None splits on runs of commas, blanks and tabs."""
    if delimiter is None:
        return [w for w in _ANY_SEP.split(text.strip()) if w]
    return [w.strip() for w in text.split(delimiter)]


def _is_number(w: str) -> bool:
    try:
        float(w)
        return True
    except ValueError:
        return False


def read_rows(path, columns: dict, *, delimiter, comment, header, n_fields=None):
    """Rows of the mapped columns as floats.

    Args:
      path: file.  columns: {key: 0-based index or header name}.  delimiter: str or None (any of
        ", \\t").  comment: prefix of comment lines (or None).  header: True (the first non-comment
        line names the columns), False, or None (True if a column is given by name or the first
        line holds no number at all).  n_fields: exact number of fields per line, or None.
    Returns:
      (values (R, K) float64 in the order of ``columns``, linenos (R,) int).
    """
    p = str(path)
    keys = list(columns)
    idx = None
    rows, linenos = [], []
    first = True
    for lineno, line in text_lines(p):
        s = line.strip()
        if not s or (comment and s.startswith(comment)):
            continue
        fields = split_fields(s, delimiter)
        if first:
            first = False
            is_header = header
            if is_header is None:
                is_header = any(isinstance(v, str) for v in columns.values()) or not any(map(_is_number, fields))
            if is_header:
                names = [f.strip().strip('"').strip() for f in fields]
                idx = []
                for k in keys:
                    c = columns[k]
                    if isinstance(c, str):
                        if c not in names:
                            raise ReaderError(
                                p, lineno, f"the header has no column {c!r} (for {k!r}); it has {names[:20]}"[:300]
                            )
                        idx.append(names.index(c))
                    else:
                        idx.append(int(c))
                continue
            if any(isinstance(v, str) for v in columns.values()):
                raise ReaderError(p, lineno, "columns are given by name but the file has no header line")
        if idx is None:
            idx = [int(columns[k]) for k in keys]
        if n_fields is not None and len(fields) != n_fields:
            raise ReaderError(p, lineno, f"{len(fields)} fields, expected {n_fields}")
        if len(fields) <= max(idx):
            raise ReaderError(p, lineno, f"{len(fields)} fields, the column map needs {max(idx) + 1}")
        vals = []
        for k, i in zip(keys, idx):
            w = fields[i]
            try:
                v = float(w)
            except (ValueError, OverflowError):
                raise ReaderError(
                    p, lineno, f"column {k!r} (field {i + 1}): cannot read {w[:40]!r} as a number"
                ) from None
            if math.isinf(v):
                raise ReaderError(p, lineno, f"column {k!r} (field {i + 1}) is {v} (not a finite number)")
            vals.append(v)
        rows.append(vals)
        linenos.append(lineno)
    if not rows:
        raise ReaderError(p, None, "no data records")
    return np.asarray(rows, np.float64).reshape(len(rows), len(keys)), np.asarray(linenos, np.int64)


def check_times(t, linenos, path, *, what="time"):
    """Finite GPST-range times that strictly increase, else ReaderError at the first bad line."""
    bad = np.flatnonzero(~((t >= GPST_RANGE_S[0]) & (t <= GPST_RANGE_S[1])))
    if bad.size:
        k = int(bad[0])
        raise ReaderError(
            path,
            int(linenos[k]),
            f"{what} {t[k]:.6g} s is outside [0, {GPST_RANGE_S[1]:.6g}] s "
            "(GPST seconds since 1980, or seconds of week)",
        )
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        k = int(bad[0]) + 1
        raise ReaderError(
            path,
            int(linenos[k]),
            f"{what} {t[k]:.9g} s is not after the previous record's "
            f"{t[k - 1]:.9g} s (line {int(linenos[k - 1])}); times must increase",
        )


#: the largest gap (s) across a week rollover that :func:`unwrap_week` accepts as one
ROLLOVER_MAX_GAP_S = 3600.0


def unwrap_week(sow):
    """Seconds of week made continuous across week rollovers: where the time drops from the end of a
    week to the start of the next (the gap across the rollover, t[k] + 604800 - t[k-1], in (0, 1 h]),
    a week is added to it and all that follow; any other drop stays (and is reported as such)."""
    sow = np.asarray(sow, float)
    ok = np.isfinite(sow)
    x = sow[ok]
    if x.size < 2:
        return sow
    gap = x[1:] + SECONDS_PER_WEEK - x[:-1]
    jumps = np.concatenate([[0], np.cumsum((gap > 0) & (gap <= ROLLOVER_MAX_GAP_S))])
    out = sow.copy()
    out[ok] = x + jumps * SECONDS_PER_WEEK
    return out


def gps_time(sow, week, path, linenos):
    """GPST s since the GPS epoch from seconds of week and a week number (scalar or per row)."""
    sow = np.asarray(sow, float)
    if week is None:
        return sow
    w = np.broadcast_to(np.asarray(week, float), sow.shape)
    bad = np.flatnonzero(~((w >= 0) & (w <= 6500) & (w == np.round(w))))
    if bad.size:
        k = int(bad[0])
        raise ReaderError(path, int(linenos[k]), f"GPS week {w[k]:g} is not a whole number in [0, 6500]")
    return w * SECONDS_PER_WEEK + sow


def make_imu_log(path, t, w_b, f_b, linenos, skipped, timing) -> ImuLog:
    """Checked :class:`ImuLog` (times increase, rates and forces physically possible)."""
    check_times(t, linenos, path)
    for name, a, lim, unit in (("angular rate", w_b, GYRO_MAX, "rad/s"), ("specific force", f_b, ACCEL_MAX, "m/s^2")):
        bad = np.flatnonzero(np.any(~(np.abs(a) <= lim), axis=1))
        if bad.size:
            k = int(bad[0])
            raise ReaderError(
                path,
                int(linenos[k]),
                f"{name} {np.array2string(a[k], precision=4)} {unit} exceeds {lim:g} {unit}: not a measurement",
            )
    return ImuLog(
        path=str(path),
        t=t,
        f_b=f_b,
        w_b=w_b,
        counter=np.arange(t.size, dtype=np.int64),
        lineno=linenos,
        n_skipped_lines=len(skipped),
        skipped=tuple(skipped),
        timing=timing,
        t_start=float(t[0]),
    )


def increments_to_rates(t, dtheta, dv, path, linenos):
    """Rates from increments over (t[k-1], t[k]]; the first interval copies the second."""
    if t.size < 2:
        raise ReaderError(path, None, "increments need at least 2 samples (the interval comes from the times)")
    check_times(t, linenos, path)
    dt = np.diff(t)
    dt = np.concatenate([dt[:1], dt])
    with np.errstate(over="ignore"):  # an overflow to inf is caught as an impossible rate by make_imu_log
        return dtheta / dt[:, None], dv / dt[:, None]


def drop_missing_imu(vals, linenos):
    """Split off rows with a NaN; returns (vals, linenos, skipped list)."""
    miss = np.any(np.isnan(vals), axis=1)
    skipped = [(int(n), "missing value (nan)") for n in linenos[miss]]
    return vals[~miss], linenos[~miss], skipped


def make_pos_solution(path, t, lat_deg, lon_deg, h, sd_enu, v_enu, sd_venu, q, ns, linenos) -> PosSolution:
    """Checked :class:`PosSolution` with missing values masked and counted (module docstring).

    Args: t (R,) s; lat_deg, lon_deg (R,) deg; h (R,) m; sd_enu (R, 3) m; v_enu (R, 3) m/s or None;
    sd_venu (R, 3) m/s or None; q, ns (R,) or None; linenos (R,).
    """
    p = str(path)
    pos_miss = np.isnan(t) | np.isnan(lat_deg) | np.isnan(lon_deg) | np.isnan(h) | np.any(np.isnan(sd_enu), axis=1)
    n_masked = int(pos_miss.sum())
    keep = ~pos_miss
    if not keep.any():
        raise ReaderError(p, None, "every record has a missing (nan) position or position sigma")
    t, lat_deg, lon_deg, h = t[keep], lat_deg[keep], lon_deg[keep], h[keep]
    sd_enu, linenos = sd_enu[keep], linenos[keep]
    check_times(t, linenos, p)
    for name, a, lo, hi in (
        ("latitude", lat_deg, -90.0, 90.0),
        ("longitude", lon_deg, -360.0, 360.0),
        ("height", h, *HEIGHT_RANGE_M),
    ):
        bad = np.flatnonzero(~((a >= lo) & (a <= hi)))
        if bad.size:
            k = int(bad[0])
            raise ReaderError(p, int(linenos[k]), f"{name} {a[k]:g} is outside [{lo:g}, {hi:g}]")
    bad = np.flatnonzero(np.any(~((sd_enu > 0) & (sd_enu <= SIGMA_MAX_M)), axis=1))
    if bad.size:
        k = int(bad[0])
        raise ReaderError(
            p,
            int(linenos[k]),
            f"position standard deviations {sd_enu[k].tolist()} m must be positive and <= {SIGMA_MAX_M:g} m",
        )
    R = t.size
    cov = np.zeros((R, 3, 3))
    for i in range(3):
        cov[:, i, i] = sd_enu[:, i] ** 2
    vcov = np.full((R, 3, 3), np.nan)
    if v_enu is None:
        v = np.full((R, 3), np.nan)
    else:
        v = np.asarray(v_enu, float)[keep]
        sv = None if sd_venu is None else np.asarray(sd_venu, float)[keep]
        vm = np.any(np.isnan(v), axis=1) | (np.any(np.isnan(sv), axis=1) if sv is not None else False)
        n_masked += int(vm.sum())
        v[vm] = np.nan
        bad = np.flatnonzero(~vm & np.any(~(np.abs(v) <= 1e4), axis=1))
        if bad.size:
            k = int(bad[0])
            raise ReaderError(p, int(linenos[k]), f"velocity {v[k].tolist()} m/s exceeds 1e4 m/s")
        if sv is not None:
            bad = np.flatnonzero(~vm & np.any(~((sv > 0) & (sv <= 1e4)), axis=1))
            if bad.size:
                k = int(bad[0])
                raise ReaderError(
                    p,
                    int(linenos[k]),
                    f"velocity standard deviations {sv[k].tolist()} m/s must be positive and <= 1e4 m/s",
                )
            vcov[:] = 0.0
            for i in range(3):
                vcov[:, i, i] = np.where(vm, np.nan, sv[:, i] ** 2)
            vcov[vm] = np.nan
    qq = np.full(R, 1, int) if q is None else np.asarray(q)[keep]
    nn = np.zeros(R, int) if ns is None else np.asarray(ns)[keep]
    for name, a, lo, hi in (("Q", qq, 0, 7), ("ns", nn, 0, 1000)):
        bad = np.flatnonzero(~((a >= lo) & (a <= hi) & (a == np.round(a))))
        if bad.size:
            k = int(bad[0])
            raise ReaderError(p, int(linenos[k]), f"{name} = {a[k]:g} is not a whole number in [{lo}, {hi}]")
    return PosSolution(
        path=p,
        t=t,
        lat=np.radians(lat_deg),
        lon=np.radians(lon_deg),
        h=h,
        q=qq.astype(int),
        ns=nn.astype(int),
        cov_enu=cov,
        age=np.full(R, np.nan),
        ratio=np.full(R, np.nan),
        v_enu=v,
        vcov_enu=vcov,
        n_masked=n_masked,
    )
