"""File readers (host side): RTKLIB solutions, raw IMU logs with RTKLIB time tags, daily station
series (NGL tenv3, SIO .neu, .col tables).

Errors name the file and line; units are converted to SI here, at the edge.
"""

from jaxnav.io._daily import DailySeries, read_col, read_daily, read_neu, read_tenv3, year_to_seconds
from jaxnav.io._imu import STANDARD_GRAVITY, ImuLog, TimeTags, read_rtklib_imu, read_rtklib_tag
from jaxnav.io._rtklib import GPS_EPOCH, PosSolution, read_pos
from jaxnav.io._survey_files import (
    ControlPoints,
    EpochLog,
    Levelling,
    read_control_points,
    read_epoch_log,
    read_levelling,
    write_control_points,
    write_epoch_log,
    write_levelling,
)

__all__ = ["GPS_EPOCH", "ImuLog", "PosSolution", "STANDARD_GRAVITY", "TimeTags", "read_pos", "read_rtklib_imu",
           "read_rtklib_tag", "ControlPoints", "EpochLog", "Levelling", "read_control_points", "read_epoch_log",
           "read_levelling", "write_control_points", "write_epoch_log", "write_levelling"]
