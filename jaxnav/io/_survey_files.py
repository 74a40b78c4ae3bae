"""Survey files of the S2 workflow (host side, csv module): RTK epoch logs, levelling, control points.

All three are comma-separated text with one header row; blank lines and lines starting with ``#``
are skipped; column order is free, extra columns are ignored. Angles are in degrees and heights
and coordinates in metres in the files, radians and metres in the returned arrays. Every error
names the file and line.

* **Epoch log** (what a CORS-RTK terminal records, S2 "Input"): one row per epoch, columns
  ``point, time, x, y, h, B, L, H, sigma_x, sigma_y, sigma_h``:
  point name; time (seconds, any origin, or ISO-8601 ``2014-11-17T09:30:02``, read as seconds since
  1980-01-06 in the same time scale); the terminal's local plane coordinates x (north) and y (east)
  and fitted (normal) height h, m; WGS-84 latitude B and longitude L, deg, and ellipsoidal height
  H, m; standard errors of x, y and h, m (``sigma_plane`` may replace ``sigma_x, sigma_y``: each
  is then sigma_plane / sqrt(2)). The epochs of a point form one block with increasing time.
  ``nan`` is accepted in a numeric field other than time (that epoch is masked by the filter and
  counted in :attr:`EpochLog.n_masked`); infinities and impossible values (``|B| > 90``, a
  negative sigma) are errors.
* **Levelling**: columns ``point, height``: the levelled normal height of each point, m.
* **Control points** (the connection survey): columns ``point, B, L, H, x, y, h``: WGS-84 B, L
  (deg) and H (m) and the reference-frame plane coordinates x, y and normal height h (m). Empty
  x, y (height-only control) or empty h (plane-only control) are allowed and read as NaN.

Errors are :class:`jaxnav.io.ReaderError` naming the file and line (bytes that are not UTF-8,
over-long fields and non-finite or impossible numbers included).
"""

from __future__ import annotations

import csv
import datetime as _dt
import math
import pathlib
from typing import NamedTuple

import numpy as np

from jaxnav.io._errors import HEIGHT_RANGE_M, PLANE_MAX_M, SIGMA_MAX_M, ReaderError, text_lines
from jaxnav.io._rtklib import GPS_EPOCH

EPOCH_COLUMNS = ("point", "time", "x", "y", "h", "B", "L", "H", "sigma_x", "sigma_y", "sigma_h")
LEVELLING_COLUMNS = ("point", "height")
CONTROL_COLUMNS = ("point", "B", "L", "H", "x", "y", "h")


class EpochLog(NamedTuple):
    """An RTK epoch log (S2 input); per-epoch arrays of length N, SI units.

    Attributes:
      path: the file read.  point: (N,) point names (str).  line: (N,) source line numbers.
      t: (N,) time, s.  x, y: (N,) terminal plane coordinates (north, east), m.
      h: (N,) terminal's fitted (normal) height, m.
      lat, lon: (N,) WGS-84 latitude, longitude, rad.  H: (N,) ellipsoidal height, m.
      sigma: (N, 3) standard errors of x, y, h, m.
      n_masked: epochs with a ``nan`` field (masked by the filter).
    """

    path: str
    point: np.ndarray
    line: np.ndarray
    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    h: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    H: np.ndarray
    sigma: np.ndarray
    n_masked: int = 0


class Levelling(NamedTuple):
    """Levelled normal heights. Attributes: path; point (P,) names; height (P,) m."""

    path: str
    point: np.ndarray
    height: np.ndarray


class ControlPoints(NamedTuple):
    """Control points of the connection survey.

    Attributes:
      path: the file read.  point: (C,) names.
      lat, lon: (C,) WGS-84 latitude, longitude, rad.  H: (C,) ellipsoidal height, m.
      x, y: (C,) reference-frame plane coordinates (north, east), m (NaN if not given).
      h: (C,) normal height, m (NaN if not given).
    """

    path: str
    point: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    H: np.ndarray
    x: np.ndarray
    y: np.ndarray
    h: np.ndarray


def _rows(path, required, alternatives=None):
    """Yield (line number, {column: text}) for the data rows; check the header."""
    path = pathlib.Path(path)
    alternatives = alternatives or {}
    # one line at a time: a quoted field cannot run over lines, and every error names its line
    header, cols = None, None
    for lineno, text in text_lines(path):
        try:
            row = next(csv.reader([text]), [])
        except csv.Error as exc:
            raise ReaderError(path, lineno, f"not a CSV line ({exc})") from None
        if not row or not "".join(row).strip() or row[0].lstrip().startswith("#"):
            continue
        row = [c.strip() for c in row]
        if header is None:
            header = row
            cols = {name: i for i, name in enumerate(header)}
            missing = [
                c
                for c in required
                if c not in cols and not (c in alternatives and all(a in cols for a in alternatives[c]))
            ]
            if missing:
                raise ReaderError(
                    path, lineno, f"header lacks column(s) {missing}; expected {list(required)}, found {header}"[:300]
                )
            if len(set(header)) != len(header):
                raise ReaderError(path, lineno, f"header names a column twice: {header}"[:300])
            continue
        if len(row) != len(header):
            raise ReaderError(path, lineno, f"{len(row)} fields, the header has {len(header)}")
        yield lineno, {name: row[i] for name, i in cols.items()}
    if header is None:
        raise ReaderError(path, None, "empty file (no header line)")


def _float(text, path, lineno, name, allow_empty=False, *, missing=False, lo=-math.inf, hi=math.inf):
    """The number in column ``name``; ``allow_empty``: "" is NaN; ``missing``: "nan" is NaN too;
    otherwise finite and in [lo, hi], else :class:`ReaderError`."""
    if text == "" and allow_empty:
        return math.nan
    try:
        v = float(text)
    except ValueError:
        raise ReaderError(path, lineno, f"column {name!r}: cannot read {text[:40]!r} as a number") from None
    if math.isnan(v) and (missing or allow_empty):
        return v
    if not math.isfinite(v):
        raise ReaderError(path, lineno, f"column {name!r}: {text[:40]!r} is not a finite number")
    if not lo <= v <= hi:
        raise ReaderError(path, lineno, f"column {name!r}: {v:g} is outside [{lo:g}, {hi:g}]")
    return v


#: ranges of the numeric columns (file units: m, deg)
_LIMITS = {
    "x": (-PLANE_MAX_M, PLANE_MAX_M),
    "y": (-PLANE_MAX_M, PLANE_MAX_M),
    "h": HEIGHT_RANGE_M,
    "B": (-90.0, 90.0),
    "L": (-360.0, 360.0),
    "H": HEIGHT_RANGE_M,
    "height": HEIGHT_RANGE_M,
}
#: the largest |time| in seconds accepted (about 300 years from any origin)
TIME_MAX_S = 1e10


def _time(text, path, lineno):
    try:
        t = float(text)
    except ValueError:
        t = None
    if t is not None:
        if not (math.isfinite(t) and abs(t) <= TIME_MAX_S):
            raise ReaderError(
                path, lineno, f"column 'time': {text[:40]!r} is not a finite time within +-{TIME_MAX_S:g} s"
            )
        return t
    try:
        d = _dt.datetime.fromisoformat(text)
        if d.tzinfo is not None:
            d = d.replace(tzinfo=None) - d.utcoffset()
        return (d - GPS_EPOCH).total_seconds()
    except (ValueError, OverflowError):
        raise ReaderError(
            path, lineno, f"column 'time': {text[:40]!r} is neither seconds nor an ISO-8601 date-time"
        ) from None


def read_epoch_log(path) -> EpochLog:
    """Read an RTK epoch log (format in the module docstring; S2 "Input").

    Args:
      path: CSV file.
    Returns:
      :class:`EpochLog`.
    Raises:
      ReaderError: (a ValueError) naming file and line, for a missing column, a malformed,
        infinite or impossible field, a point whose epochs are not one block, or time not
        increasing within a point.
      FileNotFoundError: if the file does not exist.
    """
    path = pathlib.Path(path)
    alt = {"sigma_x": ("sigma_plane",), "sigma_y": ("sigma_plane",)}
    recs, seen, last = [], {}, None
    for lineno, r in _rows(path, EPOCH_COLUMNS, alt):
        name = r["point"]
        if not name:
            raise ReaderError(path, lineno, "empty point name")
        t = _time(r["time"], path, lineno)
        if name != last:
            if name in seen:
                raise ReaderError(
                    path,
                    lineno,
                    f"point {name!r} continues after other points (its epochs "
                    f"began on line {seen[name][0]}); keep each point's epochs in "
                    "one block",
                )
            seen[name] = (lineno, t)
        elif not t > seen[name][1]:
            raise ReaderError(
                path,
                lineno,
                f"time {r['time']} of point {name!r} is not after the previous "
                f"epoch's (times must increase within a point)",
            )
        seen[name] = (seen[name][0], t)
        last = name
        vals = [
            _float(r[c], path, lineno, c, missing=True, lo=_LIMITS[c][0], hi=_LIMITS[c][1])
            for c in ("x", "y", "h", "B", "L", "H")
        ]
        sig = dict(lo=0.0, hi=SIGMA_MAX_M, missing=True)
        if "sigma_x" in r and "sigma_y" in r:
            sx, sy = (
                _float(r["sigma_x"], path, lineno, "sigma_x", **sig),
                _float(r["sigma_y"], path, lineno, "sigma_y", **sig),
            )
        else:
            sx = sy = _float(r["sigma_plane"], path, lineno, "sigma_plane", **sig) / math.sqrt(2.0)
        sh = _float(r["sigma_h"], path, lineno, "sigma_h", **sig)
        for v, c in ((sx, "sigma_x"), (sy, "sigma_y"), (sh, "sigma_h")):
            if not v > 0 and not math.isnan(v):
                raise ReaderError(path, lineno, f"column {c!r} must be positive, got {v}")
        recs.append((name, lineno, t, *vals, sx, sy, sh))
    if not recs:
        raise ReaderError(path, None, "no epochs after the header")
    a = np.array([rec[2:] for rec in recs], dtype=np.float64)
    n_masked = int(np.sum(np.any(np.isnan(a), axis=1)))
    return EpochLog(
        path=str(path),
        point=np.array([rec[0] for rec in recs]),
        line=np.array([rec[1] for rec in recs]),
        t=a[:, 0],
        x=a[:, 1],
        y=a[:, 2],
        h=a[:, 3],
        lat=np.radians(a[:, 4]),
        lon=np.radians(a[:, 5]),
        H=a[:, 6],
        sigma=a[:, 7:10],
        n_masked=n_masked,
    )


def write_epoch_log(path, point, t, x, y, h, lat, lon, H, sigma) -> pathlib.Path:
    """Write an RTK epoch log that :func:`read_epoch_log` reads (time in seconds, B/L in degrees).

    Args:
      path: file to write.  point: (N,) names.  t: (N,) s.  x, y, h: (N,) m.
      lat, lon: (N,) rad.  H: (N,) m.  sigma: (N, 3) standard errors of x, y, h, m.
    Returns:
      the path.
    """
    path = pathlib.Path(path)
    sigma = np.asarray(sigma)
    with path.open("w", encoding="utf-8", newline="") as fh:
        fh.write("# RTK epoch log (jaxnav S2 format): time s, x y h H m, B L deg, sigmas m\n")
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(EPOCH_COLUMNS)
        for k in range(len(t)):
            w.writerow(
                [
                    point[k],
                    f"{t[k]:.3f}",
                    f"{x[k]:.4f}",
                    f"{y[k]:.4f}",
                    f"{h[k]:.4f}",
                    f"{math.degrees(lat[k]):.10f}",
                    f"{math.degrees(lon[k]):.10f}",
                    f"{H[k]:.4f}",
                    f"{sigma[k, 0]:.4f}",
                    f"{sigma[k, 1]:.4f}",
                    f"{sigma[k, 2]:.4f}",
                ]
            )
    return path


def _unique_points(path, rows):
    seen = {}
    for lineno, r in rows:
        name = r["point"]
        if not name:
            raise ReaderError(path, lineno, "empty point name")
        if name in seen:
            raise ReaderError(path, lineno, f"point {name!r} repeats line {seen[name]}")
        seen[name] = lineno
        yield lineno, r


def read_levelling(path) -> Levelling:
    """Read levelled normal heights (columns ``point, height``, m).

    Raises:
      ReaderError: naming file and line (missing column, malformed, non-finite or impossible
        number, repeated point).
    """
    path = pathlib.Path(path)
    names, hs = [], []
    for lineno, r in _unique_points(path, _rows(path, LEVELLING_COLUMNS)):
        names.append(r["point"])
        hs.append(_float(r["height"], path, lineno, "height", lo=HEIGHT_RANGE_M[0], hi=HEIGHT_RANGE_M[1]))
    if not names:
        raise ReaderError(path, None, "no points after the header")
    return Levelling(path=str(path), point=np.array(names), height=np.array(hs))


def write_levelling(path, point, height) -> pathlib.Path:
    """Write a levelling file (``point, height``)."""
    path = pathlib.Path(path)
    with path.open("w", encoding="utf-8", newline="") as fh:
        fh.write("# levelling (jaxnav S2 format): height = levelled (normal) height, m\n")
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(LEVELLING_COLUMNS)
        for p, hh in zip(point, height):
            w.writerow([p, f"{hh:.4f}"])
    return path


def read_control_points(path) -> ControlPoints:
    """Read the control points of the connection survey (columns ``point, B, L, H, x, y, h``).

    Raises:
      ReaderError: naming file and line (missing column, malformed, non-finite or impossible
        number -- ``K2,inf,...`` -- repeated point). Empty (or ``nan``) x, y, h are "not given".
    """
    path = pathlib.Path(path)
    names, vals = [], []
    for lineno, r in _unique_points(path, _rows(path, CONTROL_COLUMNS)):
        names.append(r["point"])
        v = [_float(r[c], path, lineno, c, lo=_LIMITS[c][0], hi=_LIMITS[c][1]) for c in ("B", "L", "H")]
        v += [
            _float(r[c], path, lineno, c, allow_empty=True, lo=_LIMITS[c][0], hi=_LIMITS[c][1]) for c in ("x", "y", "h")
        ]
        if (math.isnan(v[3])) != (math.isnan(v[4])):
            raise ReaderError(path, lineno, "give both x and y or neither")
        vals.append(v)
    if not names:
        raise ReaderError(path, None, "no points after the header")
    a = np.array(vals, dtype=np.float64)
    return ControlPoints(
        path=str(path),
        point=np.array(names),
        lat=np.radians(a[:, 0]),
        lon=np.radians(a[:, 1]),
        H=a[:, 2],
        x=a[:, 3],
        y=a[:, 4],
        h=a[:, 5],
    )


def write_control_points(path, point, lat, lon, H, x, y, h) -> pathlib.Path:
    """Write a control-point file (B, L in degrees from ``lat, lon`` in rad; NaN written empty)."""
    path = pathlib.Path(path)
    fmt = lambda v, f: "" if not math.isfinite(v) else format(v, f)
    with path.open("w", encoding="utf-8", newline="") as fh:
        fh.write(
            "# control points (jaxnav S2 format): B L deg and H ellipsoidal height m (WGS-84); x north, y east "
            "m in the local grid and h normal height m (empty: not given)\n"
        )
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(CONTROL_COLUMNS)
        for k in range(len(point)):
            w.writerow(
                [
                    point[k],
                    f"{math.degrees(lat[k]):.10f}",
                    f"{math.degrees(lon[k]):.10f}",
                    fmt(H[k], ".4f"),
                    fmt(x[k], ".4f"),
                    fmt(y[k], ".4f"),
                    fmt(h[k], ".4f"),
                ]
            )
    return path
