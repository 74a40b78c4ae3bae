"""Generic CSV readers for IMU and GNSS logs with a column map and units, host side (numpy).

A column map names, for each quantity, its 0-based field index or its header name::

    read_csv_imu("imu.csv", columns={"t": 0, "gx": 1, "gy": 2, "gz": 3, "ax": 4, "ay": 5, "az": 6},
                 units={"t": "s", "gyro": "deg/s", "accel": "g"})

IMU quantities: time ``t`` (or ``week`` + ``tow``), and either rates ``gx gy gz`` / specific
forces ``ax ay az`` or increments ``dthx dthy dthz`` / ``dvx dvy dvz``. Units (edge units converted
here): ``t``: s, ms, us, ns; ``gyro``: rad/s, deg/s (rates) or rad, deg (increments); ``accel``:
m/s^2, g, mg (specific force) or m/s (increments).

Times must be on the GNSS solution's time scale (GPST seconds since the GPS epoch for RTKLIB
``.pos`` files; a constant IMU-GNSS offset is the caller's ``time_offset_s``), or GPS week +
seconds of week columns.

GNSS quantities: ``t`` (or ``week`` + ``tow``), ``lat``, ``lon``, ``h`` (ellipsoidal, m), sigmas
``sd_e sd_n sd_u`` (m; ``sd_d`` may stand for ``sd_u``), optional velocity ``ve vn vu`` (m/s;
``vd`` for down), its sigmas ``sd_ve sd_vn sd_vu``, quality ``q`` and ``ns``. Units: ``t`` as
above, ``angle``: deg or rad.

Aiding series (:func:`read_csv_series`): ``t`` (or ``week`` + ``tow``) and ``speed`` (m/s or km/h),
or ``heading`` (deg or rad, clockwise from north) with an optional ``sigma`` in the same unit.

See :mod:`jaxnav.io._tables` for the error and missing-value rules.
"""

from __future__ import annotations

import numpy as np

from jaxnav import units as _u
from jaxnav.io._errors import ReaderError
from jaxnav.io._imu import ImuLog
from jaxnav.io._rtklib import PosSolution
from jaxnav.io._tables import (
    drop_missing_imu,
    gps_time,
    increments_to_rates,
    make_imu_log,
    make_pos_solution,
    read_rows,
)

_TIME = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}
_GYRO_RATE = {"rad/s": 1.0, "deg/s": _u.DEG}
_GYRO_INC = {"rad": 1.0, "deg": _u.DEG}
_ACCEL_RATE = {"m/s^2": 1.0, "m/s2": 1.0, "g": _u.G0, "mg": _u.MG}
_ACCEL_INC = {"m/s": 1.0}
_ANGLE = {"deg": 1.0, "rad": 1.0 / _u.DEG}  # to degrees (the record builder takes degrees)
_RATES, _INCS = ("gx", "gy", "gz", "ax", "ay", "az"), ("dthx", "dthy", "dthz", "dvx", "dvy", "dvz")


def _check_map(columns, allowed, what):
    if not isinstance(columns, dict) or not columns:
        raise ValueError(f"{what}: columns must be a non-empty dict {{quantity: index or header name}}")
    for k, v in columns.items():
        if k not in allowed:
            raise ValueError(f"{what}: unknown column key {k!r}; known: {', '.join(allowed)}")
        if isinstance(v, bool) or not isinstance(v, (int, str)) or (isinstance(v, int) and v < 0):
            raise ValueError(f"{what}: column {k!r} must be a 0-based index >= 0 or a header name, got {v!r}")


def _unit(units, key, table, default, what):
    u = (units or {}).get(key, default)
    if u not in table:
        raise ValueError(f"{what}: unit {key}={u!r} is not one of {', '.join(table)}")
    return table[u]


def _time_columns(columns, what):
    if "t" in columns:
        if "week" in columns or "tow" in columns:
            raise ValueError(f"{what}: give either 't' or 'week' + 'tow'")
        return ("t",)
    if "week" in columns and "tow" in columns:
        return ("week", "tow")
    raise ValueError(f"{what}: the column map needs 't' (or 'week' and 'tow')")


def _times(c, tcols, tscale, path, lines):
    if tcols == ("t",):
        return c["t"] * tscale
    t = c["tow"] * tscale
    ok = np.isfinite(t) & np.isfinite(c["week"])
    out = np.full(t.shape, np.nan)
    out[ok] = gps_time(t[ok], c["week"][ok], path, lines[ok])
    return out


def read_csv_imu(path, columns: dict, units: dict | None = None, *, delimiter=",", comment="#", header=None) -> ImuLog:
    """Read an IMU log from a CSV (or blank-separated, ``delimiter=None``) table with a column map.

    Args:
      path: the file.  columns: {quantity: index or header name} (module docstring).
      units: {"t": ..., "gyro": ..., "accel": ...}; defaults s, rad/s (rad for increments), m/s^2 (m/s).
      delimiter: field separator; None splits on runs of blanks, tabs and commas.
      comment: lines starting with it are skipped (None: none).
      header: True / False / None (auto: a header line if a column is given by name or the first
        line holds no number). The header line must not start with ``comment``.
    Returns:
      :class:`jaxnav.io.ImuLog` in SI, sensor axes as in the file (``timing`` "csv", ``counter`` =
      sample index). Increments are turned into rates over (t[k-1], t[k]] (first copies second).
    Raises:
      ValueError: for a bad column map or unit.
      ReaderError: FILE:LINE for a malformed line (lines with ``nan`` are skipped and counted).
    """
    what = "read_csv_imu"
    allowed = ("t", "week", "tow") + _RATES + _INCS
    _check_map(columns, allowed, what)
    tcols = _time_columns(columns, what)
    rate_keys = [k for k in _RATES if k in columns]
    inc_keys = [k for k in _INCS if k in columns]
    if sorted(rate_keys) == sorted(_RATES) and not inc_keys:
        inc = False
    elif sorted(inc_keys) == sorted(_INCS) and not rate_keys:
        inc = True
    else:
        raise ValueError(f"{what}: map all of {_RATES} (rates) or all of {_INCS} (increments), not a mix")
    tscale = _unit(units, "t", _TIME, "s", what)
    gs = _unit(units, "gyro", _GYRO_INC if inc else _GYRO_RATE, "rad" if inc else "rad/s", what)
    as_ = _unit(units, "accel", _ACCEL_INC if inc else _ACCEL_RATE, "m/s" if inc else "m/s^2", what)
    extra = set(units or {}) - {"t", "gyro", "accel"}
    if extra:
        raise ValueError(f"{what}: unknown unit keys {sorted(extra)} (known: t, gyro, accel)")
    keys = list(tcols) + (list(_INCS) if inc else list(_RATES))
    vals, lines = read_rows(path, {k: columns[k] for k in keys}, delimiter=delimiter, comment=comment, header=header)
    vals, lines, skipped = drop_missing_imu(vals, lines)
    if not lines.size:
        raise ReaderError(str(path), None, "every IMU record has a missing (nan) value")
    c = {k: vals[:, i] for i, k in enumerate(keys)}
    t = _times(c, tcols, tscale, str(path), lines)
    with np.errstate(over="ignore"):  # an overflow to inf is caught as an impossible value by make_imu_log
        g = np.stack([c[k] for k in (_INCS[:3] if inc else _RATES[:3])], 1) * gs
        a = np.stack([c[k] for k in (_INCS[3:] if inc else _RATES[3:])], 1) * as_
    if inc:
        g, a = increments_to_rates(t, g, a, str(path), lines)
    return make_imu_log(path, t, g, a, lines, skipped, "csv")


def read_csv_gnss(
    path,
    columns: dict,
    units: dict | None = None,
    *,
    delimiter=",",
    comment="#",
    header=None,
    quality: int = 1,
    sigma_m=None,
) -> PosSolution:
    """Read GNSS positions (and velocities) from a CSV table with a column map.

    Args:
      path: the file.  columns: {quantity: index or header name} (module docstring).
      units: {"t": s|ms|us|ns, "angle": deg|rad}; defaults s, deg.
      delimiter, comment, header: as :func:`read_csv_imu`.
      quality: ``q`` of every epoch when the map has no ``q`` column.
      sigma_m: (3,) east, north, up position sigma, m, for every epoch when the map has no sigma
        columns (one of the two is required).
    Returns:
      :class:`jaxnav.io.PosSolution` (``ns`` 0 without an ``ns`` column; ``age``/``ratio`` NaN;
      ``n_masked`` counts ``nan`` values).
    Raises:
      ValueError: for a bad column map, unit, ``quality`` or ``sigma_m``.
      ReaderError: FILE:LINE for a malformed line or an impossible value.
    """
    what = "read_csv_gnss"
    allowed = (
        "t",
        "week",
        "tow",
        "lat",
        "lon",
        "h",
        "sd_e",
        "sd_n",
        "sd_u",
        "sd_d",
        "ve",
        "vn",
        "vu",
        "vd",
        "sd_ve",
        "sd_vn",
        "sd_vu",
        "sd_vd",
        "q",
        "ns",
    )
    _check_map(columns, allowed, what)
    tcols = _time_columns(columns, what)
    for k in ("lat", "lon", "h"):
        if k not in columns:
            raise ValueError(f"{what}: the column map needs {k!r}")
    up = "sd_d" if "sd_d" in columns else "sd_u"
    if "sd_d" in columns and "sd_u" in columns:
        raise ValueError(f"{what}: give 'sd_u' or 'sd_d', not both")
    sig_keys = ["sd_e", "sd_n", up]
    have_sig = [k in columns for k in sig_keys]
    if any(have_sig) and not all(have_sig):
        raise ValueError(f"{what}: map all three position sigmas {sig_keys} or none")
    if not any(have_sig):
        if sigma_m is None:
            raise ValueError(f"{what}: no sigma columns: give sigma_m=(east, north, up) in m")
        sg = np.asarray(sigma_m, float).reshape(-1)
        if sg.shape != (3,) or not np.all((sg > 0) & np.isfinite(sg)):
            raise ValueError(f"{what}: sigma_m must be 3 positive finite numbers, got {sigma_m!r}")
    vz = "vd" if "vd" in columns else "vu"
    if "vd" in columns and "vu" in columns:
        raise ValueError(f"{what}: give 'vu' or 'vd', not both")
    vel_keys = ["ve", "vn", vz]
    have_v = [k in columns for k in vel_keys]
    if any(have_v) and not all(have_v):
        raise ValueError(f"{what}: map all three velocities {vel_keys} or none")
    svz = "sd_vd" if "sd_vd" in columns else "sd_vu"
    sv_keys = ["sd_ve", "sd_vn", svz]
    have_sv = [k in columns for k in sv_keys]
    if any(have_sv) and not (all(have_sv) and all(have_v)):
        raise ValueError(f"{what}: velocity sigmas need all three of {sv_keys} and the velocities")
    if not (isinstance(quality, (int, np.integer)) and 0 <= int(quality) <= 7):
        raise ValueError(f"{what}: quality must be a whole number in [0, 7], got {quality!r}")
    tscale = _unit(units, "t", _TIME, "s", what)
    ascale = _unit(units, "angle", _ANGLE, "deg", what)
    extra = set(units or {}) - {"t", "angle"}
    if extra:
        raise ValueError(f"{what}: unknown unit keys {sorted(extra)} (known: t, angle)")
    keys = [k for k in columns]
    vals, lines = read_rows(path, {k: columns[k] for k in keys}, delimiter=delimiter, comment=comment, header=header)
    c = {k: vals[:, i] for i, k in enumerate(keys)}
    t = _times(c, tcols, tscale, str(path), lines)
    R = t.size
    sd = np.stack([c[k] for k in sig_keys], 1) if all(have_sig) else np.broadcast_to(sg, (R, 3)).copy()
    v = sv = None
    if all(have_v):
        v = np.stack([c["ve"], c["vn"], -c["vd"] if vz == "vd" else c["vu"]], 1)
        if all(have_sv):
            sv = np.stack([c[k] for k in sv_keys], 1)
    q = c["q"] if "q" in c else np.full(R, int(quality))
    ns = c.get("ns")
    return make_pos_solution(path, t, c["lat"] * ascale, c["lon"] * ascale, c["h"], sd, v, sv, q, ns, lines)


_SPEED = {"m/s": 1.0, "km/h": 1.0 / 3.6}
_HEADING = {"rad": 1.0, "deg": _u.DEG}
_SERIES = {"speed": ("speed",), "heading": ("heading", "sigma")}


def read_csv_series(
    path, columns: dict, units: dict | None = None, *, kind: str = "speed", delimiter=",", comment="#", header=None
) -> dict:
    """Read a time series that aids the filter (wheel speed, heading) from a CSV table with a column map.

    Args:
      path: the file.  columns: {quantity: index or header name}: ``t`` (or ``week`` + ``tow``) and, for
        ``kind = "speed"``, ``speed``; for ``kind = "heading"``, ``heading`` and optionally ``sigma``.
      units: {"t": s|ms|us|ns, "speed": m/s|km/h, "heading": deg|rad} (defaults s, m/s, deg; the sigma of
        a heading takes the heading's unit).
      kind: "speed" or "heading".  delimiter, comment, header: as :func:`read_csv_imu`.
    Returns:
      {"t": (R,) s, "speed": (R,) m/s} or {"t", "heading": (R,) rad, "sigma": (R,) rad or None}; a ``nan``
      value is kept (no reading at that time).
    Raises:
      ValueError: for a bad column map, unit or kind.
      ReaderError: FILE:LINE for a malformed line, a missing time, times that do not increase, a
        negative heading sigma.
    """
    what = "read_csv_series"
    if kind not in _SERIES:
        raise ValueError(f"{what}: kind must be one of {list(_SERIES)}, got {kind!r}")
    _check_map(columns, ("t", "week", "tow") + _SERIES[kind], what)
    tcols = _time_columns(columns, what)
    if _SERIES[kind][0] not in columns:
        raise ValueError(f"{what}: the column map needs {_SERIES[kind][0]!r}")
    tscale = _unit(units, "t", _TIME, "s", what)
    vscale = _unit(units, kind, _SPEED if kind == "speed" else _HEADING, "m/s" if kind == "speed" else "deg", what)
    extra = set(units or {}) - {"t", kind}
    if extra:
        raise ValueError(f"{what}: unknown unit keys {sorted(extra)} (known: t, {kind})")
    keys = list(tcols) + [k for k in _SERIES[kind] if k in columns]
    vals, lines = read_rows(path, {k: columns[k] for k in keys}, delimiter=delimiter, comment=comment, header=header)
    if not lines.size:
        raise ReaderError(str(path), None, "no data records")
    c = {k: vals[:, i] for i, k in enumerate(keys)}
    t = _times(c, tcols, tscale, str(path), lines)
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise ReaderError(str(path), int(lines[bad[0]]), "missing time")
    back = np.flatnonzero(np.diff(t) <= 0)
    if back.size:
        raise ReaderError(str(path), int(lines[back[0] + 1]), "the time does not increase")
    out = {"t": t, kind: c[kind] * vscale}
    if kind == "heading":
        sg = c["sigma"] * vscale if "sigma" in c else None
        if sg is not None and np.any(sg < 0):
            raise ReaderError(str(path), int(lines[np.flatnonzero(sg < 0)[0]]), "negative heading sigma")
        out["sigma"] = sg
    return out
