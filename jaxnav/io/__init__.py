"""File readers (host side): RTKLIB solutions, raw IMU logs with RTKLIB time tags.

Errors name the file and line; units are converted to SI here, at the edge.
"""

from jaxnav.io._imu import STANDARD_GRAVITY, ImuLog, TimeTags, read_rtklib_imu, read_rtklib_tag
from jaxnav.io._rtklib import GPS_EPOCH, PosSolution, read_pos

__all__ = ["GPS_EPOCH", "ImuLog", "PosSolution", "STANDARD_GRAVITY", "TimeTags", "read_pos", "read_rtklib_imu",
           "read_rtklib_tag"]
