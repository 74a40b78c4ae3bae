"""Readers for the KF-GINS text formats (i2Nav-WHU KF-GINS and its awesome-gins-datasets), host side.

Formats as documented by KF-GINS (README "Data format"); fields separated by blanks, tabs or commas:

* IMU, 7 columns: GPS seconds of week [s]; angle increments x, y, z [rad]; velocity increments
  x, y, z [m/s] over the interval that ends at the time tag. IMU axes forward-right-down (KF-GINS'
  IMU frame), returned *as in the file*: the mounting C_vs is the identity for such a file
  (``sensor_to_body(mounting_from_rpy(0, 0, 0))`` turns it into jaxnav's right-forward-up body).
  An 8th column (odometer speed, m/s) is allowed with ``n_columns=8``; :func:`read_kfgins_imu` ignores
  it, :func:`read_kfgins_odometer` reads it.
* GNSS, 7 columns: GPS seconds of week [s]; latitude, longitude [deg]; ellipsoidal height [m];
  position standard deviations north, east, down [m]. 13 columns add the velocity north, east,
  down [m/s] after the height and its standard deviations [m/s] at the end (the layout KF-GINS'
  loader reads: position sigmas in columns 8-10 when there are 13).

Units are converted here; see :mod:`jaxnav.io._tables` for the error and missing-value rules.
"""

from __future__ import annotations

import numpy as np

from jaxnav.io._errors import ReaderError, text_lines
from jaxnav.io._imu import ImuLog
from jaxnav.io._rtklib import PosSolution
from jaxnav.io._tables import (
    drop_missing_imu,
    gps_time,
    increments_to_rates,
    make_imu_log,
    make_pos_solution,
    read_rows,
    split_fields,
    unwrap_week,
)


def _first_record_fields(path) -> int:
    """Number of fields of the first non-comment line (0: none)."""
    for _, line in text_lines(str(path)):
        t = line.strip()
        if t and not t.startswith("#"):
            return len(split_fields(t, None))
    return 0


def read_kfgins_imu(path, *, gps_week=None, n_columns: int = 7) -> ImuLog:
    """Read a KF-GINS IMU text file (time, angle and velocity increments).

    The increments become rates over their intervals: w_b = dtheta / dt, f_b = dv / dt with
    dt = t[k] - t[k-1] (the first interval copies the second), so that
    :func:`jaxnav.io.imu_increments` gives the file's increments back. A data gap leaves one long
    interval (the rates of the sample after it are then too small: check ``np.diff(log.t)``).

    Args:
      path: the file.
      gps_week: GPS week of the data's start: ``t`` is then GPST s since the GPS epoch (to match
        :func:`read_kfgins_gnss` with the same week or RTKLIB solutions); None keeps seconds of week.
        A week rollover inside the file (the time drops from the end of a week to the start of the
        next, with at most 1 h between the two records) adds a week to the records after it.
      n_columns: fields per line, 7 (default) or 8 (with the odometer column, ignored); None: as many as
        the first record has (7 or 8), every line the same.
    Returns:
      :class:`jaxnav.io.ImuLog` (``counter`` = sample index, ``timing`` = "increments", axes as in the file).
    Raises:
      ReaderError: FILE:LINE for a malformed line (see :mod:`jaxnav.io._tables`); lines with ``nan``
        are skipped and listed in ``skipped``.
      ValueError: for an ``n_columns`` other than 7 or 8.
    """
    if n_columns is None:
        n_columns = _first_record_fields(path)
        if n_columns not in (7, 8):
            raise ReaderError(
                str(path),
                None,
                f"the first record has {n_columns} fields; a KF-GINS IMU file has 7 (or 8 with the odometer)",
            )
    if n_columns not in (7, 8):
        raise ValueError(f"n_columns must be 7 or 8, got {n_columns!r}")
    cols = {k: i for i, k in enumerate(("t", "dthx", "dthy", "dthz", "dvx", "dvy", "dvz"))}
    vals, lines = read_rows(path, cols, delimiter=None, comment="#", header=False, n_fields=n_columns)
    vals, lines, skipped = drop_missing_imu(vals, lines)
    if not lines.size:
        raise ReaderError(str(path), None, "every IMU record has a missing (nan) value")
    t = gps_time(unwrap_week(vals[:, 0]), gps_week, str(path), lines)
    w_b, f_b = increments_to_rates(t, vals[:, 1:4], vals[:, 4:7], str(path), lines)
    return make_imu_log(path, t, w_b, f_b, lines, skipped, "increments")


def read_kfgins_odometer(path, *, gps_week=None):
    """The odometer column (8th field, m/s) of a KF-GINS IMU file with its time tags.

    Args:
      path: the file (8 fields per line).  gps_week: as :func:`read_kfgins_imu` (the same value gives the
        same time scale as the IMU log).
    Returns:
      (t (R,) s, speed (R,) m/s); a ``nan`` speed is kept (no reading at that tag).
    Raises:
      ReaderError: FILE:LINE for a line without 8 fields, a missing time, or times that do not increase.
    """
    vals, lines = read_rows(path, {"t": 0, "speed": 7}, delimiter=None, comment="#", header=False, n_fields=8)
    if not lines.size:
        raise ReaderError(str(path), None, "no data records")
    tt = unwrap_week(vals[:, 0])
    bad = np.flatnonzero(~np.isfinite(tt))
    if bad.size:
        raise ReaderError(str(path), int(lines[bad[0]]), "missing time tag")
    t = gps_time(tt, gps_week, str(path), lines)
    back = np.flatnonzero(np.diff(t) <= 0)
    if back.size:
        raise ReaderError(str(path), int(lines[back[0] + 1]), "the time does not increase")
    return t, vals[:, 1]


def read_kfgins_gnss(path, *, gps_week=None, quality: int = 1) -> PosSolution:
    """Read a KF-GINS GNSS position text file (7 or 13 columns, module docstring).

    Args:
      path: the file.
      gps_week: GPS week of the start: ``t`` in GPST s since the GPS epoch; None keeps seconds of
        week (a week rollover inside the file is unwrapped, as in :func:`read_kfgins_imu`).
      quality: the ``q`` given to every epoch (the format has no quality flag; 1 = "fixed" makes
        every epoch pass a fixed-only selection, so set it to what the solution is).
    Returns:
      :class:`jaxnav.io.PosSolution` (ENU covariance from the N/E/D sigmas; ``ns`` 0; ``age`` and
      ``ratio`` NaN; ``v_enu`` NaN without the velocity columns; ``n_masked`` counts ``nan`` values).
    Raises:
      ReaderError: FILE:LINE for a malformed line, a line with another column count than the
        first one's (7 or 13), an impossible value, or times that do not increase.
    """
    n = None
    for lineno, line in text_lines(str(path)):
        s = line.strip()
        if s and not s.startswith("#"):
            n = len(split_fields(s, None))
            if n not in (7, 13):
                raise ReaderError(str(path), lineno, f"{n} fields; a KF-GINS GNSS file has 7 or 13")
            break
    if n is None:
        raise ReaderError(str(path), None, "no data records")
    names = (
        ("t", "lat", "lon", "h")
        + (("vn", "ve", "vd") if n == 13 else ())
        + ("sdn", "sde", "sdd")
        + (("sdvn", "sdve", "sdvd") if n == 13 else ())
    )
    vals, lines = read_rows(
        path, {k: i for i, k in enumerate(names)}, delimiter=None, comment="#", header=False, n_fields=n
    )
    c = {k: vals[:, i] for i, k in enumerate(names)}
    if not np.isfinite(quality) or quality != int(quality) or not 0 <= quality <= 7:
        raise ValueError(f"quality must be a whole number in [0, 7], got {quality!r}")
    tt = unwrap_week(c["t"])
    ok = np.isfinite(tt)
    tt[ok] = gps_time(tt[ok], gps_week, str(path), lines[ok])
    sd = np.stack([c["sde"], c["sdn"], c["sdd"]], 1)
    v = sv = None
    if n == 13:
        v = np.stack([c["ve"], c["vn"], -c["vd"]], 1)
        sv = np.stack([c["sdve"], c["sdvn"], c["sdvd"]], 1)
    return make_pos_solution(
        path, tt, c["lat"], c["lon"], c["h"], sd, v, sv, np.full(tt.size, int(quality)), None, lines
    )
