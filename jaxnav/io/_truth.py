"""Readers of reference ("truth") trajectories to score a navigation solution against, host side.

* KF-GINS ``truth.nav`` (i2Nav-WHU KF-GINS and its awesome-gins-datasets): 11 fields separated by
  blanks, tabs or commas: GPS week; GPS seconds of week [s]; latitude, longitude [deg]; ellipsoidal
  height [m]; velocity north, east, down [m/s]; roll, pitch, yaw [deg] of the IMU/vehicle frame
  (forward-right-down) in the local north-east-down frame (yaw = heading, clockwise from north).
* CSV with a column map (as :func:`jaxnav.io.read_csv_gnss`): ``t`` (or ``week`` + ``tow``),
  ``lat``, ``lon``, ``h``; optional velocity ``ve vn vu`` (``vd`` for down); optional attitude
  ``roll pitch heading`` (``yaw`` for heading). Units: ``t``: s, ms, us, ns; ``angle``: deg or rad
  (latitude, longitude and attitude).

Values are converted to SI here (rad, m, m/s; velocity east-north-up). Malformed lines raise
:class:`jaxnav.io.ReaderError` naming file and line (see :mod:`jaxnav.io._tables`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from jaxnav import units as _u
from jaxnav.io._csv import _check_map
from jaxnav.io._errors import HEIGHT_RANGE_M, ReaderError
from jaxnav.io._tables import check_times, gps_time, read_rows, unwrap_week


class TruthTrajectory(NamedTuple):
    """A reference trajectory (SI).

    Attributes:
      path: the file.  t: (M,) s, GPST since the GPS epoch (``week`` given) or as the file's time column.
      pos: (M, 3) [lat rad, lon rad, h m] (ellipsoidal height).
      v_enu: (M, 3) east, north, up velocity, m/s (NaN where the file has none).
      rpy: (M, 3) roll, pitch, heading rad of the vehicle frame (FRD in NED; NaN where the file has none).
      lineno: (M,) line of each record.
    """

    path: str
    t: np.ndarray
    pos: np.ndarray
    v_enu: np.ndarray
    rpy: np.ndarray
    lineno: np.ndarray


_TIME = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}
_ANGLE = {"deg": _u.DEG, "rad": 1.0}


def _make(path, t, lat, lon, h, v, rpy, lines) -> TruthTrajectory:
    """Checked :class:`TruthTrajectory` (times increase; positions, velocities and angles possible)."""
    p = str(path)
    check_times(t, lines, p)
    for name, a, lo, hi in (
        ("latitude", np.degrees(lat), -90.0, 90.0),
        ("longitude", np.degrees(lon), -360.0, 360.0),
        ("height", h, *HEIGHT_RANGE_M),
    ):
        bad = np.flatnonzero(~((a >= lo) & (a <= hi)))
        if bad.size:
            k = int(bad[0])
            raise ReaderError(p, int(lines[k]), f"{name} {a[k]:g} is outside [{lo:g}, {hi:g}]")
    bad = np.flatnonzero(np.any(~(np.abs(v) <= 1e4) & ~np.isnan(v), axis=1))
    if bad.size:
        k = int(bad[0])
        raise ReaderError(p, int(lines[k]), f"velocity {v[k].tolist()} m/s is not possible (|v| > 1e4 m/s)")
    deg = np.degrees(rpy)
    for j, (name, lo, hi) in enumerate((("roll", -360.0, 360.0), ("pitch", -90.0, 90.0), ("heading", -360.0, 360.0))):
        bad = np.flatnonzero(~((deg[:, j] >= lo) & (deg[:, j] <= hi)) & ~np.isnan(deg[:, j]))
        if bad.size:
            k = int(bad[0])
            raise ReaderError(p, int(lines[k]), f"{name} {deg[k, j]:g} deg is outside [{lo:g}, {hi:g}] deg")
    return TruthTrajectory(path=p, t=t, pos=np.stack([lat, lon, h], -1), v_enu=v, rpy=rpy, lineno=lines)


def read_kfgins_truth(path) -> TruthTrajectory:
    """Read a KF-GINS ``truth.nav`` reference trajectory (11 fields, module docstring).

    Returns:
      :class:`TruthTrajectory` with ``t`` = week * 604800 + seconds of week (GPST since the GPS epoch).
    Raises:
      ReaderError: FILE:LINE for a line without 11 numbers, a time that does not increase, or an
        impossible value.
    """
    names = ("week", "sow", "lat", "lon", "h", "vn", "ve", "vd", "roll", "pitch", "yaw")
    vals, lines = read_rows(
        path, {k: i for i, k in enumerate(names)}, delimiter=None, comment="#", header=False, n_fields=11
    )
    c = {k: vals[:, i] for i, k in enumerate(names)}
    bad = np.flatnonzero(np.any(np.isnan(vals), axis=1))
    if bad.size:
        raise ReaderError(str(path), int(lines[bad[0]]), "a missing (nan) value; a reference trajectory has none")
    t = gps_time(c["sow"], c["week"], str(path), lines)
    v = np.stack([c["ve"], c["vn"], -c["vd"]], -1)
    rpy = np.stack([c["roll"], c["pitch"], c["yaw"]], -1) * _u.DEG
    return _make(path, t, c["lat"] * _u.DEG, c["lon"] * _u.DEG, c["h"], v, rpy, lines)


def read_csv_truth(
    path, columns: dict, units: dict | None = None, *, delimiter=",", comment="#", header=None
) -> TruthTrajectory:
    """Read a reference trajectory from a CSV table with a column map (module docstring).

    Args:
      path: the file.  columns: {quantity: 0-based index or header name}.
      units: {"t": s|ms|us|ns, "angle": deg|rad}; defaults s, deg.
      delimiter, comment, header: as :func:`jaxnav.io.read_csv_imu`.
    Returns:
      :class:`TruthTrajectory` (``t`` as the file's time column, or GPST since the GPS epoch from
      ``week`` + ``tow``).
    Raises:
      ValueError: for a bad column map or unit.
      ReaderError: FILE:LINE for a malformed line or an impossible value.
    """
    what = "read_csv_truth"
    allowed = ("t", "week", "tow", "lat", "lon", "h", "ve", "vn", "vu", "vd", "roll", "pitch", "heading", "yaw")
    _check_map(columns, allowed, what)
    if "t" in columns and ("week" in columns or "tow" in columns):
        raise ValueError(f"{what}: give either 't' or 'week' + 'tow'")
    if "t" not in columns and not ("week" in columns and "tow" in columns):
        raise ValueError(f"{what}: the column map needs 't' (or 'week' and 'tow')")
    for k in ("lat", "lon", "h"):
        if k not in columns:
            raise ValueError(f"{what}: the column map needs {k!r}")
    for a, b in (("vu", "vd"), ("heading", "yaw")):
        if a in columns and b in columns:
            raise ValueError(f"{what}: give {a!r} or {b!r}, not both")
    vz = "vd" if "vd" in columns else "vu"
    hd = "yaw" if "yaw" in columns else "heading"
    for group in (("ve", "vn", vz), ("roll", "pitch", hd)):
        have = [k in columns for k in group]
        if any(have) and not all(have):
            raise ValueError(f"{what}: map all of {list(group)} or none")
    extra = set(units or {}) - {"t", "angle"}
    if extra:
        raise ValueError(f"{what}: unknown unit keys {sorted(extra)} (known: t, angle)")
    tu, au = (units or {}).get("t", "s"), (units or {}).get("angle", "deg")
    if tu not in _TIME or au not in _ANGLE:
        raise ValueError(
            f"{what}: units t must be one of {list(_TIME)} and angle one of {list(_ANGLE)}, got t={tu!r}, angle={au!r}"
        )
    keys = list(columns)
    vals, lines = read_rows(path, {k: columns[k] for k in keys}, delimiter=delimiter, comment=comment, header=header)
    c = {k: vals[:, i] for i, k in enumerate(keys)}
    bad = np.flatnonzero(np.any(np.isnan(vals), axis=1))
    if bad.size:
        raise ReaderError(str(path), int(lines[bad[0]]), "a missing (nan) value; a reference trajectory has none")
    if "t" in c:
        t = c["t"] * _TIME[tu]
    else:
        t = gps_time(unwrap_week(c["tow"] * _TIME[tu]), c["week"], str(path), lines)
    R = t.size
    nan3 = np.full((R, 3), np.nan)
    v = nan3.copy() if "ve" not in c else np.stack([c["ve"], c["vn"], -c["vd"] if vz == "vd" else c["vu"]], -1)
    rpy = nan3.copy() if "roll" not in c else np.stack([c["roll"], c["pitch"], c[hd]], -1) * _ANGLE[au]
    a = _ANGLE[au]
    return _make(path, t, c["lat"] * a, c["lon"] * a, c["h"], v, rpy, lines)
