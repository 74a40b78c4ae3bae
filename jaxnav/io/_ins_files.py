"""The files a ``jaxnav ins`` config names (:class:`jaxnav.io.InsConfig`), read by their format.

Each reader names the config key of anything wrong: a missing file, or for the ``csv`` format a column
map or unit the reader refuses; an unreadable line is a :class:`jaxnav.io.ReaderError` (FILE:LINE).
Times are GPST seconds since 1980-01-06 where the file gives a GPS week (``gps_week`` keys).
"""

from __future__ import annotations

import pathlib

import numpy as np

from jaxnav.io._csv import read_csv_series
from jaxnav.io._errors import ReaderError
from jaxnav.io._formats import read_gnss, read_imu, read_truth
from jaxnav.io._imu import ImuLog
from jaxnav.io._ins_config import InsConfig
from jaxnav.io._kfgins import read_kfgins_odometer
from jaxnav.io._rtklib import PosSolution
from jaxnav.io._truth import TruthTrajectory
from jaxnav.units import WEEK


def _exists(cfg: InsConfig, path: pathlib.Path | None, key: str) -> None:
    """FileNotFoundError naming the file and the config key unless ``path`` (if given) is a file."""
    if path is not None and not path.is_file():
        what = "a folder, not a file" if path.is_dir() else "no such file"
        raise FileNotFoundError(f"{path}: {what} ({cfg.path}: {key})")


def _csv(cfg: InsConfig, prefix: str, fmt: str, read):
    """``read()``; for the "csv" format, a ValueError about the column map or units (not a ReaderError)
    names the config keys ``{prefix}columns`` and ``{prefix}units``."""
    if fmt != "csv":
        return read()
    try:
        return read()
    except ReaderError:
        raise
    except ValueError as exc:
        raise ValueError(f"{cfg.path}: {prefix}columns / {prefix}units: {exc}") from None


def read_ins_inputs(cfg: InsConfig) -> tuple[ImuLog, PosSolution]:
    """(:class:`ImuLog`, :class:`PosSolution`) of the config's ``[imu]`` and ``[gnss]`` files (SI, sensor axes).

    Every file the config names (IMU, its time tag, GNSS, reference, odometer, heading) is checked to
    exist first, so that a wrong path fails before any work.

    Raises:
      jaxnav.io.ReaderError: naming file and line of anything unreadable.
      FileNotFoundError: a missing file (named, with its config key).
    """
    imu_c, g = cfg.imu, cfg.gnss
    for p, key in (
        (imu_c.file, "imu.file"),
        (g.file, "gnss.file"),
        (imu_c.tag, "imu.tag"),
        (cfg.evaluate.truth if cfg.evaluate is not None else None, "evaluate.truth"),
        (cfg.odometer.file if cfg.odometer is not None else None, "odometer.file"),
        (cfg.heading.file if cfg.heading is not None else None, "heading.file"),
    ):
        _exists(cfg, p, key)
    odo_col = cfg.odometer is not None and cfg.odometer.source == "imu"
    imu = _csv(
        cfg,
        "imu.",
        imu_c.format,
        lambda: read_imu(
            imu_c.file,
            imu_c.format,
            tag=imu_c.tag,
            columns=imu_c.columns,
            units=imu_c.units,
            delimiter=imu_c.delimiter,
            gps_week=imu_c.gps_week,
            odometer_column=odo_col,
        ),
    )
    pos = _csv(
        cfg,
        "gnss.",
        g.format,
        lambda: read_gnss(
            g.file,
            g.format,
            columns=g.columns,
            units=g.units,
            delimiter=g.delimiter,
            gps_week=g.gps_week,
            sigma_m=g.sigma_m,
        ),
    )
    return imu, pos


def read_ins_odometer(cfg: InsConfig) -> tuple[np.ndarray, np.ndarray] | None:
    """(t (R,) s on the IMU file's clock, speed (R,) m/s) of the ``[odometer]`` source (NaN: no reading), or None
    without an ``[odometer]`` section."""
    o = cfg.odometer
    if o is None:
        return None
    if o.source == "imu":
        return read_kfgins_odometer(cfg.imu.file, gps_week=cfg.imu.gps_week)
    d = _csv(
        cfg,
        "odometer.",
        "csv",
        lambda: read_csv_series(o.file, o.columns, o.units, kind="speed", delimiter=o.delimiter),
    )
    return (d["t"] if o.gps_week is None else d["t"] + o.gps_week * WEEK), d["speed"]


def read_ins_heading(cfg: InsConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray | None] | None:
    """(t (R,) s, heading (R,) rad clockwise from north, sigma (R,) rad or None) of the ``[heading]`` file, or None
    without a ``[heading]`` section; t on the file's own time scale, plus ``heading.gps_week`` weeks when given."""
    h = cfg.heading
    if h is None:
        return None
    d = _csv(
        cfg,
        "heading.",
        "csv",
        lambda: read_csv_series(h.file, h.columns, h.units, kind="heading", delimiter=h.delimiter),
    )
    return (d["t"] if h.gps_week is None else d["t"] + h.gps_week * WEEK), d["heading"], d["sigma"]


def read_ins_truth(cfg: InsConfig) -> TruthTrajectory | None:
    """The ``[evaluate] truth`` file as :class:`TruthTrajectory`, or None without one.

    Raises:
      FileNotFoundError: a missing file (named with the key).  jaxnav.io.ReaderError: FILE:LINE.
      ValueError: a column map the reader refuses (naming the config keys).
    """
    ev = cfg.evaluate
    if ev is None or ev.truth is None:
        return None
    _exists(cfg, ev.truth, "evaluate.truth")
    return _csv(
        cfg,
        "evaluate.truth_",
        ev.truth_format,
        lambda: read_truth(
            ev.truth, ev.truth_format, columns=ev.truth_columns, units=ev.truth_units, delimiter=ev.truth_delimiter
        ),
    )
