"""Reader of the rtklibexplorer ``walk_0827`` recording (handheld MEMS IMU + RTK ``.pos``), host side."""

from __future__ import annotations

import pathlib
from typing import Any, NamedTuple

from jaxnav.io._imu import read_rtklib_imu
from jaxnav.io._rtklib import read_pos


class WalkData(NamedTuple):
    """The walk recording: :class:`jaxnav.io.ImuLog` and :class:`jaxnav.io.PosSolution` (both GPST s since 1980)."""

    imu: Any
    pos: Any


def load_walk(data_dir) -> WalkData:
    """Read ``walk_0827`` (``imu_1730.csv`` + ``.tag``, ``gnss_1730_sf.pos``) from ``data_dir``.

    Args:
      data_dir: the ``walk_0827`` folder, or a folder holding it (the rtklibexplorer-gnss-imu set).
    Returns:
      :class:`WalkData` in SI units (IMU in the sensor axes).
    """
    d = pathlib.Path(data_dir)
    if (d / "walk_0827").is_dir():
        d = d / "walk_0827"
    imu = read_rtklib_imu(d / "imu_1730.csv", d / "imu_1730.csv.tag")
    return WalkData(imu=imu, pos=read_pos(d / "gnss_1730_sf.pos"))
