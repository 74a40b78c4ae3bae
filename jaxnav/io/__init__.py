"""File readers (host side): RTKLIB solutions. Errors name the file and line."""

from jaxnav.io._rtklib import GPS_EPOCH, PosSolution, read_pos

__all__ = ["GPS_EPOCH", "PosSolution", "read_pos"]
