"""IMU, GNSS and reference-trajectory files by format name: the readers behind ``jaxnav ins`` and ``jaxnav allan``."""

from __future__ import annotations

from jaxnav.io._csv import read_csv_gnss, read_csv_imu
from jaxnav.io._imu import ImuLog, read_rtklib_imu
from jaxnav.io._kfgins import read_kfgins_gnss, read_kfgins_imu
from jaxnav.io._rtklib import PosSolution, read_pos
from jaxnav.io._truth import TruthTrajectory, read_csv_truth, read_kfgins_truth

#: IMU file formats of :func:`read_imu`: raw RTKLIB-logged CSV (+ time tag), KF-GINS text, CSV with a column map
IMU_FORMATS = ("rtklib-csv", "kf-gins", "csv")
#: GNSS solution formats of :func:`read_gnss`: RTKLIB ``.pos``, KF-GINS text, CSV with a column map
GNSS_FORMATS = ("rtklib-pos", "kf-gins", "csv")
#: reference-trajectory formats of :func:`read_truth`: KF-GINS ``truth.nav``, CSV with a column map
TRUTH_FORMATS = ("kf-gins", "csv")


def _check(fmt: str, formats: tuple, what: str) -> None:
    if fmt not in formats:
        raise ValueError(f"unknown {what} format {fmt!r}; choose from {', '.join(formats)}")


def read_imu(
    path,
    fmt: str,
    *,
    tag=None,
    t_start=None,
    columns=None,
    units=None,
    delimiter=",",
    gps_week=None,
    odometer_column: bool = False,
) -> ImuLog:
    """An IMU log in one of :data:`IMU_FORMATS` as :class:`ImuLog` (SI, sensor axes).

    Args:
      path: the IMU file.  fmt: its format.
      tag, t_start: "rtklib-csv": the RTKLIB time-tag file, or the time (s) of the first sample
        when there is none (:func:`read_rtklib_imu`).
      columns, units, delimiter: "csv": column map and units (:func:`read_csv_imu`).
      gps_week: "kf-gins": the GPS week of the seconds-of-week column.
      odometer_column: "kf-gins": True, every line has the eighth (odometer) column; False, 7 or 8
        columns, as the first record has (:func:`read_kfgins_imu` with ``n_columns=None``).
    Raises:
      ValueError: an unknown format, or "csv" without a column map; ReaderError: naming file and line.
    """
    _check(fmt, IMU_FORMATS, "IMU")
    if fmt == "rtklib-csv":
        return read_rtklib_imu(path, tag, t_start=t_start)
    if fmt == "kf-gins":
        return read_kfgins_imu(path, gps_week=gps_week, n_columns=8 if odometer_column else None)
    if not columns:
        raise ValueError("format csv needs a column map (t=0, gx=1, ...)")
    return read_csv_imu(path, columns, units, delimiter=delimiter)


def read_gnss(path, fmt: str, *, columns=None, units=None, delimiter=",", gps_week=None, sigma_m=None) -> PosSolution:
    """A GNSS position solution in one of :data:`GNSS_FORMATS` as :class:`PosSolution`.

    Args:
      path: the solution file.  fmt: its format.
      columns, units, delimiter, sigma_m: "csv": column map, units and the sigma (m) where the file has
        none (:func:`read_csv_gnss`).
      gps_week: "kf-gins": the GPS week of the seconds-of-week column.
    Raises:
      ValueError: an unknown format, or "csv" without a column map; ReaderError: naming file and line.
    """
    _check(fmt, GNSS_FORMATS, "GNSS")
    if fmt == "rtklib-pos":
        return read_pos(path)
    if fmt == "kf-gins":
        return read_kfgins_gnss(path, gps_week=gps_week)
    if not columns:
        raise ValueError("format csv needs a column map (t=0, lat=1, ...)")
    return read_csv_gnss(path, columns, units, delimiter=delimiter, sigma_m=sigma_m)


def read_truth(path, fmt: str, *, columns=None, units=None, delimiter=",") -> TruthTrajectory:
    """A reference trajectory in one of :data:`TRUTH_FORMATS` as :class:`TruthTrajectory`.

    Args:
      path: the reference file.  fmt: its format.
      columns, units, delimiter: "csv": column map and units (:func:`read_csv_truth`).
    Raises:
      ValueError: an unknown format, or "csv" without a column map; ReaderError: naming file and line.
    """
    _check(fmt, TRUTH_FORMATS, "reference-trajectory")
    if fmt == "kf-gins":
        return read_kfgins_truth(path)
    if not columns:
        raise ValueError("format csv needs a column map (t=0, lat=1, ...)")
    return read_csv_truth(path, columns, units, delimiter=delimiter)
