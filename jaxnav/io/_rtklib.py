"""Readers for RTKLIB solution files (.pos), host side (numpy); units converted at this edge."""

from __future__ import annotations

import datetime as _dt
import math
import pathlib
from typing import NamedTuple

import numpy as np

from jaxnav.io._errors import HEIGHT_RANGE_M, ReaderError, text_lines
from jaxnav.units import WEEK

GPS_EPOCH = _dt.datetime(1980, 1, 6)
SECONDS_PER_WEEK = WEEK
#: GPST accepted, s since the GPS epoch: 1980-01-06 .. 2100-01-01 (anything else is a corrupted time)
GPST_RANGE_S = (0.0, (_dt.datetime(2100, 1, 1) - GPS_EPOCH).total_seconds())
#: solution quality flags RTKLIB writes
Q_RANGE = (0, 7)


class PosSolution(NamedTuple):
    """An RTKLIB position solution; per-epoch arrays of length N, SI units, ENU order.

    Attributes:
      path: the file read.
      t: (N,) GPS time, seconds since the GPS epoch 1980-01-06 (GPST, no leap seconds).
      lat, lon: (N,) geodetic latitude and longitude, rad (WGS-84 / the solution's datum).
      h: (N,) ellipsoidal height, m.
      q: (N,) int solution quality (1 fix, 2 float, 3 sbas, 4 dgps, 5 single, 6 ppp).
      ns: (N,) int number of satellites.
      cov_enu: (N, 3, 3) position covariance in east, north, up, m^2 (RTKLIB writes sdne, sdeu,
        sdun as signed square roots: c = sign(s) s^2).
      age: (N,) differential age, s (NaN if absent).  ratio: (N,) ambiguity ratio (NaN if absent).
      v_enu: (N, 3) velocity east, north, up, m/s (NaN if the file has no velocity columns).
      vcov_enu: (N, 3, 3) velocity covariance, (m/s)^2 (NaN if absent).
      n_masked: number of missing (``nan``) values the file gave: epochs without a position are
        dropped, missing velocities are NaN rows of ``v_enu`` (the KF-GINS and CSV readers; 0 for
        ``.pos``, which has no missing values).
    """

    path: str
    t: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    h: np.ndarray
    q: np.ndarray
    ns: np.ndarray
    cov_enu: np.ndarray
    age: np.ndarray
    ratio: np.ndarray
    v_enu: np.ndarray
    vcov_enu: np.ndarray
    n_masked: int = 0

    def take(self, sel) -> PosSolution:
        """The epochs ``sel`` ((N,) bool mask or index array) of this solution; ``path`` and ``n_masked`` kept."""
        n = np.shape(self.t)[0]
        rows = {f: np.asarray(v)[sel] for f, v in zip(self._fields, self) if np.ndim(v) >= 1 and np.shape(v)[0] == n}
        return self._replace(**rows)


def _signed_sq(s):
    return np.sign(s) * s * s


def _cov_enu(sn, se, su, sne, seu, sun):
    """(N, 3, 3) ENU covariance from RTKLIB's N/E/U standard deviations and signed roots."""
    c = np.empty(sn.shape + (3, 3))
    c[:, 0, 0], c[:, 1, 1], c[:, 2, 2] = se**2, sn**2, su**2
    c[:, 0, 1] = c[:, 1, 0] = _signed_sq(sne)
    c[:, 0, 2] = c[:, 2, 0] = _signed_sq(seu)
    c[:, 1, 2] = c[:, 2, 1] = _signed_sq(sun)
    return c


def _parse_time(words, path, lineno):
    """GPST from 'YYYY/MM/DD HH:MM:SS.sss' or 'WEEK TOW'; returns (seconds, words consumed)."""
    try:
        if "/" in words[0]:
            date = _dt.datetime.strptime(words[0], "%Y/%m/%d")
            hh, mm, ss = words[1].split(":")
            h, m, s = int(hh), int(mm), float(ss)
            if not (0 <= h < 24 and 0 <= m < 60 and 0.0 <= s < 61.0):
                raise ValueError(f"time of day {words[1]} out of range")
            sec = (date - GPS_EPOCH).total_seconds() + h * 3600 + m * 60 + s
        else:
            week, tow = int(words[0]), float(words[1])
            if not 0.0 <= tow < SECONDS_PER_WEEK:
                raise ValueError(f"seconds of week {words[1]} outside [0, 604800)")
            sec = week * SECONDS_PER_WEEK + tow
    except (ValueError, IndexError, OverflowError) as exc:
        raise ReaderError(
            path, lineno, f"cannot read the GPST time from {' '.join(words[:2])[:60]!r} ({exc})"
        ) from None
    if not GPST_RANGE_S[0] <= sec <= GPST_RANGE_S[1]:
        raise ReaderError(path, lineno, f"GPST time {' '.join(words[:2])[:60]!r} is before 1980-01-06 or after 2100")
    return sec, 2


#: per-column checks of a record: (low, high) after reading, in the file's units
_COLUMN_RANGES = {
    "latitude(deg)": (-90.0, 90.0),
    "longitude(deg)": (-360.0, 360.0),
    "height(m)": HEIGHT_RANGE_M,
    "Q": Q_RANGE,
    "ns": (0, 1000),
    "sdn(m)": (0.0, 1e4),
    "sde(m)": (0.0, 1e4),
    "sdu(m)": (0.0, 1e4),
    "sdne(m)": (-1e4, 1e4),
    "sdeu(m)": (-1e4, 1e4),
    "sdun(m)": (-1e4, 1e4),
    "age(s)": (-1e6, 1e6),
    "ratio": (0.0, 1e9),
    "ve(m/s)": (-1e4, 1e4),
    "vn(m/s)": (-1e4, 1e4),
    "vu(m/s)": (-1e4, 1e4),
    "sdvn": (0.0, 1e4),
    "sdve": (0.0, 1e4),
    "sdvu": (0.0, 1e4),
    "sdvne": (-1e4, 1e4),
    "sdveu": (-1e4, 1e4),
    "sdvun": (-1e4, 1e4),
}


def _check_record(vals, header, path, lineno):
    """ReaderError naming the column of the first non-finite or impossible value of a record."""
    for name, v in zip(header[1:], vals):
        if not math.isfinite(v):
            raise ReaderError(path, lineno, f"column {name} is {v} (not a finite number)")
        rng = _COLUMN_RANGES.get(name)
        if rng is not None and not rng[0] <= v <= rng[1]:
            raise ReaderError(path, lineno, f"column {name} = {v:g} is outside [{rng[0]:g}, {rng[1]:g}]")
        if name in ("Q", "ns") and v != int(v):
            raise ReaderError(path, lineno, f"column {name} = {v:g} is not an integer")


def read_pos(path) -> PosSolution:
    """Read an RTKLIB ``.pos`` file with geodetic (lat/lon/height) output.

    Handles both time formats (calendar GPST and GPS week + seconds), files with and without
    the velocity columns, and comment/header lines starting with '%'. Angles are converted to
    radians, the covariances to ENU matrices.

    Args:
      path: file path.
    Returns:
      :class:`PosSolution`.
    Raises:
      ReaderError: (a ValueError) naming the file and line of any unreadable record (bytes that
        are not UTF-8 included), a non-finite or impossible value (latitude beyond 90 deg, a
        negative standard deviation, a time before 1980 or after 2100), a record whose time is
        not after the previous one, a missing header or header column, or a non-geodetic (e.g.
        ECEF x/y/z) solution file.
      FileNotFoundError: if the file does not exist.
    """
    path = pathlib.Path(path)
    header = None
    rows, linenos = [], []
    for lineno, line in text_lines(path):
        s = line.strip()
        if not s:
            continue
        if s.startswith("%"):
            if "GPST" in s and ("latitude" in s or "x-ecef" in s):
                if "x-ecef" in s:
                    raise ReaderError(
                        path,
                        lineno,
                        "ECEF (x-ecef) solutions are not supported; write the solution with lat/lon/height output",
                    )
                header = s.lstrip("%").split()
                missing = [c for c in ("latitude(deg)", "longitude(deg)", "height(m)", "Q") if c not in header]
                if missing:
                    raise ReaderError(path, lineno, f"the header line lacks the column(s) {missing}")
                if header[0] != "GPST" or len(set(header)) != len(header):
                    raise ReaderError(path, lineno, "the header line must start with GPST and name each column once")
            continue
        if header is None:
            raise ReaderError(path, lineno, "data before the '%  GPST latitude(deg) ...' header line")
        words = s.split()
        t, k = _parse_time(words, path, lineno)
        ncols = len(header) - 1  # 'GPST' is one header word but one or two data words
        vals = words[k:]
        if len(vals) != ncols:
            raise ReaderError(path, lineno, f"expected {ncols} values after the time, found {len(vals)}")
        try:
            nums = [float(v) for v in vals]
        except ValueError as exc:
            raise ReaderError(path, lineno, str(exc)[:120]) from None
        _check_record(nums, header, path, lineno)
        rows.append([t] + nums)
        if len(rows) > 1 and not t > rows[-2][0]:
            raise ReaderError(
                path,
                lineno,
                f"time {' '.join(words[:2])} is not after the previous "
                f"record's (line {linenos[-1]}); epochs must increase",
            )
        linenos.append(lineno)
    if header is None:
        raise ReaderError(path, None, "no '%  GPST latitude(deg) ...' header line found")
    if not rows:
        raise ReaderError(path, None, "no solution records")
    a = np.asarray(rows, dtype=np.float64)
    col = {name: i for i, name in enumerate(header)}

    def get(name, default=math.nan):
        return a[:, col[name]] if name in col else np.full(len(a), default)

    cov = _cov_enu(
        get("sdn(m)"), get("sde(m)"), get("sdu(m)"), get("sdne(m)", 0.0), get("sdeu(m)", 0.0), get("sdun(m)", 0.0)
    )
    v = np.stack([get("ve(m/s)"), get("vn(m/s)"), get("vu(m/s)")], axis=1)
    vcov = _cov_enu(get("sdvn"), get("sdve"), get("sdvu"), get("sdvne"), get("sdveu"), get("sdvun"))
    return PosSolution(
        path=str(path),
        t=a[:, 0],
        lat=np.radians(get("latitude(deg)")),
        lon=np.radians(get("longitude(deg)")),
        h=get("height(m)"),
        q=get("Q").astype(int),
        ns=get("ns").astype(int),
        cov_enu=cov,
        age=get("age(s)"),
        ratio=get("ratio"),
        v_enu=v,
        vcov_enu=vcov,
    )
