"""Readers for daily GNSS station position series (host side): NGL tenv3, SIO .neu, .col tables,
EarthScope/PBO (GAGE) ``.pos``.

Every reader returns a :class:`DailySeries` in SI units (m, s) with the local east, north, up
components in that order, whatever the file's order. Errors are :class:`jaxnav.io.ReaderError`
naming the file and the line. A position component written ``nan`` is a missing value: it stays
NaN (the filters mask it), its variance is set to 1 m^2 (never used) and it is counted in
:attr:`DailySeries.n_masked`; infinities and impossible values are errors.
"""

from __future__ import annotations

import pathlib
import re
from typing import Any, NamedTuple

import numpy as np

from jaxnav.io._errors import HEIGHT_RANGE_M, PLANE_MAX_M, SIGMA_MAX_M, ReaderError, text_lines
from jaxnav.units import CM, DEG, YEAR

#: decimal year of the time origin used for ``DailySeries.t`` (J2000.0 in Julian years)
T0_YEAR = 2000.0
_MJD_J2000 = 51544.5  # MJD of 2000-01-01 12:00
#: decimal years accepted (GNSS daily series; anything else is a corrupted time)
YEAR_RANGE = (1950.0, 2150.0)
_MJD_RANGE = (33282.0, 106314.0)  # the same span as MJD


class DailySeries(NamedTuple):
    """A daily station position series; per-epoch arrays of length N.

    Attributes:
      station: station name (from the file or the file name).
      path: the file read.  fmt: "tenv3", "neu", "col" or "pbo".
      t: (N,) s since J2000.0 (strictly increasing).
      year: (N,) decimal year, as in the file (or from the MJD for tenv3).
      enu: (N, 3) east, north, up offsets, m. For tenv3 they are relative to ``origin``.
      cov: (N, 3, 3) covariance of ``enu``, m^2 (correlations where the file gives them).
      origin: (3,) what was subtracted from the file's east/north/up (tenv3: the first epoch's
        easting from the reference meridian, northing from the equator, height), m; else zeros.
      llh: (N, 3) latitude rad, longitude rad (in [-pi, pi)), ellipsoidal height m; NaN if absent.
      reference_velocity: (3,) east, north, up velocity published in the file header, m/s
        (SIO .neu "slope" lines), else None.
      reference_velocity_sigma: (3,) its standard deviation, m/s, else None.
      n_masked: number of position components the file gave as ``nan`` (NaN in ``enu``).
      xyz: (N, 3) ECEF X, Y, Z, m, where the file gives them (PBO .pos), else None.
      cov_xyz: (N, 3, 3) their covariance, m^2 (PBO .pos), else None.
    """

    station: str
    path: str
    fmt: str
    t: np.ndarray
    year: np.ndarray
    enu: np.ndarray
    cov: np.ndarray
    origin: np.ndarray
    llh: np.ndarray
    reference_velocity: Any | None = None
    reference_velocity_sigma: Any | None = None
    n_masked: int = 0
    xyz: Any | None = None
    cov_xyz: Any | None = None


def year_to_seconds(year):
    """Decimal year -> s since J2000.0 (Julian years of 365.25 days)."""
    return (np.asarray(year, dtype=np.float64) - T0_YEAR) * YEAR


def _err(path, lineno, msg):
    return ReaderError(path, lineno, msg)


def _floats(words, path, lineno, what):
    try:
        return [float(w) for w in words]
    except ValueError as exc:
        raise _err(path, lineno, f"cannot read {what}: {exc}") from None


def _check_times(t, lines, path, rng, what):
    """Times finite and inside ``rng`` (the file's unit ``what``)."""
    bad = np.flatnonzero(~((t >= rng[0]) & (t <= rng[1])))
    if bad.size:
        i = int(bad[0])
        raise _err(path, lines[i], f"{what} {float(t[i])!r} is outside [{rng[0]:g}, {rng[1]:g}] (not a GNSS-era time)")


def _masked_positions(enu, sig, lines, path, limits, corr=None):
    """Check positions and sigmas; NaN positions are missing values (masked, counted).

    Args:
      enu: (N, 3) m.  sig: (N, 3) m.  lines: (N,) line numbers.  limits: (3,) largest |e|, |n|, |u|, m.
      corr: optional (N, 3) correlations en, eu, nu.
    Returns:
      (sig, corr, n_masked) with the masked components' sigma 1 m and their correlations 0.
    Raises:
      ReaderError: an infinite or impossible position, a bad sigma of a present component, a
        correlation outside [-1, 1].
    """
    miss = np.isnan(enu)
    for name, j in (("east", 0), ("north", 1), ("up", 2)):
        bad = np.flatnonzero(~miss[:, j] & ~(np.abs(enu[:, j]) <= limits[j]))
        if bad.size:
            i = int(bad[0])
            raise _err(path, lines[i], f"{name} = {float(enu[i, j]):g} m is not finite or beyond {limits[j]:g} m")
    sig = np.where(miss, 1.0, sig)
    bad = np.flatnonzero(~np.all(np.isfinite(sig) & (sig > 0) & (sig <= SIGMA_MAX_M), axis=1))
    if bad.size:
        i = int(bad[0])
        raise _err(path, lines[i], f"sigmas must be positive, finite and <= {SIGMA_MAX_M:g} m, got {sig[i].tolist()}")
    if corr is not None:
        pair_miss = np.stack([miss[:, 0] | miss[:, 1], miss[:, 0] | miss[:, 2], miss[:, 1] | miss[:, 2]], axis=1)
        corr = np.where(pair_miss, 0.0, corr)
        bad = np.flatnonzero(~np.all(np.abs(corr) <= 1.0, axis=1))
        if bad.size:
            raise _err(path, lines[int(bad[0])], f"correlations must lie in [-1, 1], got {corr[bad[0]].tolist()}")
    return sig, corr, int(miss.sum())


_MONTHS = {
    m: i + 1 for i, m in enumerate(("JAN", "FEB", "MAR", "APR", "MAY", "JUN", "JUL", "AUG", "SEP", "OCT", "NOV", "DEC"))
}
_MJD_GPS0 = 44244.0  # MJD of the GPS time origin, 1980-01-06
#: largest antenna height (tenv3 column ``_ant(m)``) accepted, m
ANTENNA_HEIGHT_MAX_M = 100.0
#: largest disagreement accepted between a record's calendar date and its MJD (or decimal year), days
DATE_TOLERANCE_DAYS = 2.0


def _mjd_of_date(y, m, d):
    """MJD of the Gregorian date y-m-d at 0 h (integers), or None if no such date."""
    import datetime as _dt

    try:
        return float((_dt.date(y, m, d) - _dt.date(1858, 11, 17)).days)
    except (ValueError, OverflowError):
        return None


def _check_column(v, lines, path, lo, hi, what, unit=""):
    """Every value of the (N,) column ``v`` finite and in [lo, hi], else a ReaderError at its line."""
    bad = np.flatnonzero(~((v >= lo) & (v <= hi)))
    if bad.size:
        i = int(bad[0])
        raise _err(path, lines[i], f"{what} = {float(v[i])!r}{unit} is not finite or outside [{lo:g}, {hi:g}]{unit}")


def _check_mjd_agrees(mjd_date, mjd, lines, path, what, tol_days=DATE_TOLERANCE_DAYS, ref="MJD", unit="days"):
    """The (N,) time from a record's calendar columns agrees with its ``ref`` column within ``tol_days``
    (both in ``unit``)."""
    bad = np.flatnonzero(~(np.abs(mjd_date - mjd) <= tol_days))
    if bad.size:
        i = int(bad[0])
        raise _err(
            path,
            lines[i],
            f"{what} disagrees with the {ref} {float(mjd[i]):.4f} by more than "
            f"{tol_days:.4g} {unit} (a corrupted date or time)",
        )


def _check_field_count(w, expected, first, path, lineno, names):
    """A record has exactly one of the ``expected`` field counts, and the same count as the file's first
    record (``first``: (count, line) or None); returns the (count, line) to compare later records with."""
    n = len(w)
    if n not in expected:
        want = " or ".join(str(k) for k in expected)
        raise _err(path, lineno, f"expected {want} fields ({names}), found {n}")
    if first is not None and n != first[0]:
        raise _err(path, lineno, f"{n} fields where line {first[1]} has {first[0]} (a column added or lost)")
    return first or (n, lineno)


def _check_increasing(t, lines, path):
    d = np.diff(t)
    bad = np.flatnonzero(~(d > 0))
    if bad.size:
        i = int(bad[0]) + 1
        raise _err(
            path,
            lines[i],
            f"time {float(t[i])!r} does not increase (previous epoch {float(t[i - 1])!r}, line {lines[i - 1]})",
        )


def _cov(sig, corr=None):
    """(N, 3, 3) covariance from (N, 3) sigmas and optional (N, 3) correlations en, eu, nu."""
    c = np.zeros(sig.shape[:1] + (3, 3))
    for i in range(3):
        c[:, i, i] = sig[:, i] ** 2
    if corr is not None:
        for (i, j), r in zip(((0, 1), (0, 2), (1, 2)), corr.T):
            c[:, i, j] = c[:, j, i] = r * sig[:, i] * sig[:, j]
    return c


def _data_lines(path):
    """(lineno, words) of the non-empty, non-comment lines (strict UTF-8)."""
    for lineno, line in text_lines(path):
        s = line.strip()
        if s and not s.startswith("#"):
            yield lineno, s.split()


def read_tenv3(path) -> DailySeries:
    """Read a Nevada Geodetic Laboratory ``.tenv3`` daily series (east/north/up in metres).

    Columns: site, date, decimal year, MJD, GPS week, day, reference longitude, east integer and
    fraction, north integer and fraction, up integer and fraction, antenna height, sig_e, sig_n,
    sig_u, corr_en, corr_eu, corr_nu, latitude, longitude, height. Positions are integer +
    fraction (the integer part may be re-initialised after a jump; the sum is what counts). Time
    is taken from the MJD (exact days); longitudes such as -268.9 are wrapped to [-180, 180).
    A record has exactly 23 fields (or 20, without latitude, longitude and height), as many as the
    header line and the first record; the date, decimal year, GPS week and day must agree with the
    MJD, the reference longitude lie within +-360 deg and the antenna height within
    +-:data:`ANTENNA_HEIGHT_MAX_M`.

    Args:
      path: file path.
    Returns:
      :class:`DailySeries` (fmt "tenv3").
    Raises:
        ReaderError: naming file and line of a record with another number of fields, a non-numeric
        field, a date disagreeing with the MJD, a non-UTF-8 byte, an infinite or impossible value (latitude beyond 90 deg, MJD outside
        1950-2150), a bad sigma, a correlation outside [-1, 1], or time not increasing; or no
        records. ``nan`` positions are masked and counted (module docstring).
    """
    path = pathlib.Path(path)
    rows, lines, station, first, dates = [], [], None, None, []
    for lineno, w in _data_lines(path):
        if w[0] == "site" or w[0].startswith("site"):
            if len(w) in (20, 23):
                first = first or (len(w), lineno)  # the header names the columns every record has
            continue  # header line
        first = _check_field_count(
            w,
            (20, 23),
            first,
            path,
            lineno,
            "site YYMMMDD yyyy.yyyy MJD week d reflon "
            "e0 east n0 north u0 up ant sig_e sig_n sig_u corr_en corr_eu corr_nu "
            "[latitude longitude height]",
        )
        station = station or w[0]
        rows.append(_floats(w[2:20] + (w[20:23] if len(w) == 23 else ["nan"] * 3), path, lineno, "the numeric columns"))
        m = re.fullmatch(r"(\d\d)([A-Za-z]{3})(\d\d)", w[1])
        d = None
        if m and m.group(2).upper() in _MONTHS:
            yy = int(m.group(1))
            d = _mjd_of_date(yy + (1900 if yy >= 50 else 2000), _MONTHS[m.group(2).upper()], int(m.group(3)))
        if d is None:
            raise _err(path, lineno, f"date {w[1][:20]!r} is not a date YYMMMDD (e.g. 95MAY19)")
        dates.append(d)
        lines.append(lineno)
    if not rows:
        raise ReaderError(path, None, "no data records")
    a = np.asarray(rows)
    a = np.concatenate([a[:, :2], a[:, 5:]], axis=1)  # drop week, day, reflon (checked here) for the indices below
    raw = np.asarray(rows)
    year, mjd = a[:, 0], a[:, 1]
    _check_times(mjd, lines, path, _MJD_RANGE, "MJD")
    _check_times(year, lines, path, YEAR_RANGE, "decimal year")
    _check_mjd_agrees(np.asarray(dates), mjd, lines, path, "the date (column 2)", 0.5)
    _check_mjd_agrees(_MJD_J2000 + (year - T0_YEAR) * YEAR / 86400.0, mjd, lines, path, "the decimal year")
    with np.errstate(over="ignore", invalid="ignore"):
        bad = np.flatnonzero(~(raw[:, 2] * 7.0 + raw[:, 3] == np.floor(mjd - _MJD_GPS0)) | ~(np.abs(raw[:, 3]) <= 6))
    if bad.size:
        i = int(bad[0])
        raise _err(
            path,
            lines[i],
            f"GPS week {raw[i, 2]!r} and day {raw[i, 3]!r} disagree with the MJD "
            f"{float(mjd[i]):.4f} (a corrupted date)",
        )
    _check_column(raw[:, 4], lines, path, -360.0, 360.0, "reference longitude", " deg")
    _check_column(a[:, 8], lines, path, -ANTENNA_HEIGHT_MAX_M, ANTENNA_HEIGHT_MAX_M, "antenna height", " m")
    t = (mjd - _MJD_J2000) * 86400.0
    _check_increasing(t, lines, path)
    e, n, u = a[:, 2] + a[:, 3], a[:, 4] + a[:, 5], a[:, 6] + a[:, 7]
    enu = np.stack([e, n, u], axis=1)
    sig, corr, n_masked = _masked_positions(
        enu, a[:, 9:12], lines, path, (PLANE_MAX_M, PLANE_MAX_M, max(map(abs, HEIGHT_RANGE_M))), a[:, 12:15]
    )
    for j, name, lim in ((15, "latitude", 90.0), (16, "longitude", 360.0)):
        bad = np.flatnonzero(~np.isnan(a[:, j]) & ~(np.abs(a[:, j]) <= lim))
        if bad.size:
            raise _err(path, lines[int(bad[0])], f"{name} = {float(a[bad[0], j]):g} deg is beyond +-{lim:g} deg")
    bad = np.flatnonzero(~np.isnan(a[:, 17]) & ~((a[:, 17] >= HEIGHT_RANGE_M[0]) & (a[:, 17] <= HEIGHT_RANGE_M[1])))
    if bad.size:
        raise _err(path, lines[int(bad[0])], f"height = {float(a[bad[0], 17]):g} m is outside {list(HEIGHT_RANGE_M)} m")
    ok = np.all(np.isfinite(enu), axis=1)
    if not ok.any():
        raise ReaderError(path, None, "every record has a missing (nan) position component")
    origin = enu[int(np.argmax(ok))].copy()  # the first complete epoch
    lon = (a[:, 16] + 180.0) % 360.0 - 180.0
    llh = np.stack([a[:, 15] * DEG, lon * DEG, a[:, 17]], axis=1)
    return DailySeries(
        station=station,
        path=str(path),
        fmt="tenv3",
        t=t,
        year=year,
        enu=enu - origin,
        cov=_cov(sig, corr),
        origin=origin,
        llh=llh,
        n_masked=n_masked,
    )


_SLOPE = re.compile(r"slope\s*1:\s*([-+0-9.eE]+)\s*\+/-\s*([-+0-9.eE]+)\s*m/yr")
_COMP = re.compile(r"^#\s*([neu])\s+component")


def read_neu(path) -> DailySeries:
    """Read a SIO (Scripps) cleaned ``.neu`` series: decimal year, year, day, dN, dE, dU, sN, sE, sU (m).

    ``#`` header lines are comments; the "slope 1: v +/- s m/yr" lines under the "n/e/u component"
    headings become :attr:`DailySeries.reference_velocity` (reordered to east, north, up; m/s).

    Args:
      path: file path.
    Returns:
      :class:`DailySeries` (fmt "neu"); the station name is the file name up to the first
      non-letter (``bjfsCleanUnf.neu`` -> "BJFS").
    Raises:
      ReaderError: naming file and line of a record without exactly 9 numeric columns, a year and
        day of year (whole numbers) disagreeing with the decimal year, a non-UTF-8 byte,
        an infinite or impossible value, a bad sigma, or time not increasing; or no records.
        ``nan`` positions are masked and counted.
    """
    path = pathlib.Path(path)
    rows, lines = [], []
    slopes, comp = {}, None
    for lineno, line in text_lines(path):
        s = line.strip()
        if not s:
            continue
        if s.startswith("#"):
            m = _COMP.match(s)
            if m:
                comp = m.group(1)
            m = _SLOPE.search(s)
            if m and comp is not None:
                v = _floats(m.groups(), path, lineno, "the slope")
                if all(np.isfinite(v)) and v[1] >= 0:
                    slopes[comp] = tuple(v)
            continue
        w = s.split()
        _check_field_count(w, (9,), None, path, lineno, "year, yyyy, doy, dN, dE, dU, sN, sE, sU")
        rows.append(_floats(w[:9], path, lineno, "the numeric columns"))
        lines.append(lineno)
    if not rows:
        raise ReaderError(path, None, "no data records")
    a = np.asarray(rows)
    year = a[:, 0]
    _check_times(year, lines, path, YEAR_RANGE, "decimal year")
    _check_column(a[:, 1], lines, path, *YEAR_RANGE, "year (column 2)")
    _check_column(a[:, 2], lines, path, 1.0, 366.0, "day of year (column 3)")
    bad = np.flatnonzero((a[:, 1] != np.round(a[:, 1])) | (a[:, 2] != np.round(a[:, 2])))
    if bad.size:
        raise _err(
            path, lines[int(bad[0])], f"year {a[bad[0], 1]!r} and day of year {a[bad[0], 2]!r} must be whole numbers"
        )
    _check_mjd_agrees(
        a[:, 1] + (a[:, 2] - 0.5) / 365.25,
        year,
        lines,
        path,
        "the year and day of year (columns 2, 3)",
        DATE_TOLERANCE_DAYS / 365.25,
        "decimal year",
        "years",
    )
    t = year_to_seconds(year)
    _check_increasing(t, lines, path)
    enu = a[:, [4, 3, 5]]
    sig, _, n_masked = _masked_positions(enu, a[:, [7, 6, 8]], lines, path, (PLANE_MAX_M,) * 3)
    ref = ref_s = None
    if set(slopes) == {"n", "e", "u"}:
        ref = np.array([slopes[c][0] for c in "enu"]) / YEAR
        ref_s = np.array([slopes[c][1] for c in "enu"]) / YEAR
    station = re.match(r"[A-Za-z0-9]{4}", path.name)
    return DailySeries(
        station=(station.group(0) if station else path.stem).upper(),
        path=str(path),
        fmt="neu",
        t=t,
        year=year,
        enu=enu,
        cov=_cov(sig),
        origin=np.zeros(3),
        llh=np.full((len(t), 3), np.nan),
        reference_velocity=ref,
        reference_velocity_sigma=ref_s,
        n_masked=n_masked,
    )


_COL_NAMES = {"ns": 1, "ew": 0, "ud": 2}


def read_col(path) -> DailySeries:
    """Read a column table with a header naming the columns, e.g. the Houston GOM20 ``.col`` files.

    Header: ``Decimal-Year NS(cm) EW(cm) UD(cm) sigma-NS(cm) sigma-EW(cm) sigma-UD(cm)`` (any
    order; units ``(m)``, ``(cm)`` or ``(mm)`` in each name). Converted to metres here.

    Args:
      path: file path.
    Returns:
      :class:`DailySeries` (fmt "col"); the station is the file name before the first "_".
    Raises:
      ReaderError: naming file and line of a missing header or column, a record with the wrong
        number of columns, a non-numeric field, a non-UTF-8 byte, an infinite or impossible value,
        a bad sigma or time not increasing. ``nan`` positions are masked and counted.
    """
    path = pathlib.Path(path)
    header, rows, lines = None, [], []
    units = {"m": 1.0, "cm": CM, "mm": 1e-3}
    for lineno, w in _data_lines(path):
        if header is None:
            if not re.match(r"[A-Za-z]", w[0]):
                raise _err(path, lineno, "expected a header line naming the columns (Decimal-Year NS(cm) ...)")
            header, hline = [h.lower() for h in w], lineno
            idx, scale = {}, {}
            for i, h in enumerate(header):
                m = re.match(r"(sigma-)?(ns|ew|ud)\((m|cm|mm)\)$", h)
                if m:
                    key = ("s" if m.group(1) else "") + m.group(2)
                    idx[key], scale[key] = i, units[m.group(3)]
                elif "year" in h:
                    idx["year"] = i
            need = ["year", "ns", "ew", "ud", "sns", "sew", "sud"]
            missing = [k for k in need if k not in idx]
            if missing:
                names = {
                    "year": "Decimal-Year",
                    "ns": "NS(unit)",
                    "ew": "EW(unit)",
                    "ud": "UD(unit)",
                    "sns": "sigma-NS(unit)",
                    "sew": "sigma-EW(unit)",
                    "sud": "sigma-UD(unit)",
                }
                raise _err(path, hline, f"header lacks the column(s) {[names[k] for k in missing]}")
            continue
        if len(w) != len(header):
            raise _err(path, lineno, f"expected {len(header)} columns as in the header (line {hline}), found {len(w)}")
        rows.append(_floats(w, path, lineno, "the numeric columns"))
        lines.append(lineno)
    if header is None or not rows:
        raise ReaderError(path, None, "no header or no data records")
    a = np.asarray(rows)
    year = a[:, idx["year"]]
    _check_times(year, lines, path, YEAR_RANGE, "decimal year")
    t = year_to_seconds(year)
    _check_increasing(t, lines, path)
    enu = np.stack([a[:, idx[k]] * scale[k] for k in ("ew", "ns", "ud")], axis=1)
    sig = np.stack([a[:, idx[k]] * scale[k] for k in ("sew", "sns", "sud")], axis=1)
    sig, _, n_masked = _masked_positions(enu, sig, lines, path, (PLANE_MAX_M,) * 3)
    return DailySeries(
        station=path.name.split("_")[0].split(".")[0].upper(),
        path=str(path),
        fmt="col",
        t=t,
        year=year,
        enu=enu,
        cov=_cov(sig),
        origin=np.zeros(3),
        llh=np.full((len(t), 3), np.nan),
        n_masked=n_masked,
    )


_PBO_TITLE = "PBO Station Position Time Series"


def read_pbo_pos(path) -> DailySeries:
    """Read an EarthScope/PBO (GAGE, UNAVCO) daily position series ``.pos`` (format version 1.1).

    Header lines up to ``End Field Description`` (the station from ``4-character ID:``), one
    line starting with ``*`` naming the fields, then records of 25 fields: YYYYMMDD, HHMMSS, MJD,
    X, Y, Z, Sx, Sy, Sz, Rxy, Rxz, Ryz (ECEF, m), NLat, Elong (deg), Height (m), dN, dE, dU
    (from the header's NEU reference position, m), Sn, Se, Su, Rne, Rnu, Reu, Soln. The local
    offsets come with their full covariance (sigmas and the three correlations, reordered to
    east, north, up); the ECEF coordinates and their full covariance are kept in
    :attr:`DailySeries.xyz` and :attr:`DailySeries.cov_xyz`. Time is taken from the MJD.

    Args:
      path: file path.
    Returns:
      :class:`DailySeries` (fmt "pbo"), ``origin`` zeros (the offsets are the file's).
    Raises:
      ReaderError: naming file and line of a first line that is not the PBO title (e.g. an
        RTKLIB .pos: use ``jaxnav rtk``), a record without exactly 25 fields, a YYYYMMDD HHMMSS
        disagreeing with the MJD by more than a minute, a non-numeric field,
        a non-UTF-8 byte, an infinite or impossible value, a bad sigma, a correlation outside
        [-1, 1] or time not increasing; or no records. ``nan`` offsets are masked and counted.
    """
    path = pathlib.Path(path)
    rows, lines, station, in_header, first = [], [], None, True, True
    first_rec, dates = None, []
    for lineno, line in text_lines(path):
        s = line.strip()
        if first:
            first = False
            if not s.startswith(_PBO_TITLE):
                raise _err(
                    path,
                    lineno,
                    f"not an EarthScope/PBO daily .pos file: the first line should be "
                    f"'{_PBO_TITLE}' (an RTKLIB solution .pos goes to `jaxnav rtk`)",
                )
            continue
        if not s:
            continue
        if in_header:
            if s.startswith("4-character ID"):
                station = s.split(":", 1)[1].strip() or None
            if s.startswith("*") or s.startswith("End Field Description"):
                in_header = not s.startswith("*")
            continue
        w = s.split()
        first_rec = _check_field_count(
            w,
            (25,),
            first_rec,
            path,
            lineno,
            "YYYYMMDD HHMMSS MJD X Y Z Sx Sy Sz Rxy Rxz Ryz NLat Elong Height dN dE dU Sn Se Su Rne Rnu Reu Soln",
        )
        rows.append(_floats(w[2:24], path, lineno, "the numeric fields"))
        dd, hh = w[0], w[1]
        d = None
        if len(dd) == 8 and dd.isdigit() and len(hh) == 6 and hh.isdigit():
            d = _mjd_of_date(int(dd[:4]), int(dd[4:6]), int(dd[6:]))
            hs = (int(hh[:2]), int(hh[2:4]), int(hh[4:]))
            if d is None or hs[0] > 23 or hs[1] > 59 or hs[2] > 60:
                d = None
            else:
                d += (hs[0] * 3600 + hs[1] * 60 + hs[2]) / 86400.0
        if d is None:
            raise _err(path, lineno, f"date and time {dd[:20]!r} {hh[:20]!r} are not YYYYMMDD HHMMSS")
        dates.append(d)
        lines.append(lineno)
    if not rows:
        raise ReaderError(path, None, "no data records")
    a = np.asarray(rows)  # columns: 0 MJD, 1-3 XYZ, 4-6 sXYZ, 7-9 rXY rXZ rYZ, 10-12 lat lon h, 13-15 dN dE dU,
    #                        16-18 sN sE sU, 19-21 rNE rNU rEU
    mjd = a[:, 0]
    _check_times(mjd, lines, path, _MJD_RANGE, "MJD")
    _check_mjd_agrees(np.asarray(dates), mjd, lines, path, "YYYYMMDD HHMMSS", 60.0 / 86400.0)
    t = (mjd - _MJD_J2000) * 86400.0
    _check_increasing(t, lines, path)
    enu = a[:, [14, 13, 15]]
    corr_enu = np.stack([a[:, 19], a[:, 21], a[:, 20]], axis=1)  # en = ne, eu, nu
    sig, corr, n_masked = _masked_positions(enu, a[:, [17, 16, 18]], lines, path, (PLANE_MAX_M,) * 3, corr_enu)
    xyz = a[:, 1:4]
    bad = np.flatnonzero(~np.all(np.abs(xyz) <= PLANE_MAX_M, axis=1))
    if bad.size:
        raise _err(
            path, lines[int(bad[0])], f"X, Y, Z = {xyz[bad[0]].tolist()} m are not finite or beyond {PLANE_MAX_M:g} m"
        )
    sxyz, cxyz, _ = _masked_positions(np.zeros_like(xyz), a[:, 4:7], lines, path, (1.0,) * 3, a[:, 7:10])
    for j, name, lim in ((10, "latitude", 90.0), (11, "longitude", 360.0)):
        bad = np.flatnonzero(~(np.abs(a[:, j]) <= lim))
        if bad.size:
            raise _err(path, lines[int(bad[0])], f"{name} = {float(a[bad[0], j]):g} deg is beyond +-{lim:g} deg")
    bad = np.flatnonzero(~((a[:, 12] >= HEIGHT_RANGE_M[0]) & (a[:, 12] <= HEIGHT_RANGE_M[1])))
    if bad.size:
        raise _err(path, lines[int(bad[0])], f"height = {float(a[bad[0], 12]):g} m is outside {list(HEIGHT_RANGE_M)} m")
    lon = (a[:, 11] + 180.0) % 360.0 - 180.0
    llh = np.stack([a[:, 10] * DEG, lon * DEG, a[:, 12]], axis=1)
    year = T0_YEAR + t / YEAR
    return DailySeries(
        station=station or path.name[:4].upper(),
        path=str(path),
        fmt="pbo",
        t=t,
        year=year,
        enu=enu,
        cov=_cov(sig, corr),
        origin=np.zeros(3),
        llh=llh,
        n_masked=n_masked,
        xyz=xyz,
        cov_xyz=_cov(sxyz, cxyz),
    )


def read_daily(path) -> DailySeries:
    """Read a daily series, choosing the reader by suffix: ``.tenv3``, ``.neu``, ``.col``, ``.pos``
    (EarthScope/PBO daily series).

    Raises:
      ReaderError: unknown suffix (naming the file), or any reader error.
    """
    path = pathlib.Path(path)
    readers = {".tenv3": read_tenv3, ".neu": read_neu, ".col": read_col, ".pos": read_pbo_pos}
    if path.suffix.lower() not in readers:
        raise ReaderError(path, None, f"unknown daily-series format {path.suffix!r}; expected one of {sorted(readers)}")
    return readers[path.suffix.lower()](path)
