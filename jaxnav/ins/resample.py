"""Aiding readings on their own clock put onto the IMU samples (host side, numpy): the per-sample inputs
of the odometer and heading aids (:func:`jaxnav.ins.odometer`, :func:`jaxnav.ins.heading`)."""

from __future__ import annotations

import numpy as np


def interpolate_on_samples(t_read, values, t_imu, *, max_gap_factor: float = 3.0) -> np.ndarray:
    """Readings ``values`` (R,) at times ``t_read`` (R,) s, linear at the IMU sample times ``t_imu`` (N,) s.

    NaN outside the readings' span and inside a gap between usable (finite) readings longer than
    ``max_gap_factor`` times the median reading interval (a missing reading widens the gap around it).
    Returns (N,) in the readings' unit.
    """
    t_read, values, t_imu = (np.asarray(a, float) for a in (t_read, values, t_imu))
    if t_read.shape != values.shape or t_read.ndim != 1:
        raise ValueError(f"t_read {t_read.shape} and values {values.shape} must both be (R,)")
    ok = np.isfinite(values) & np.isfinite(t_read)
    out = np.full(t_imu.shape, np.nan)
    if ok.sum() < 2:
        return out
    med = float(np.median(np.diff(t_read))) if t_read.size > 1 else 0.0
    to, so = t_read[ok], values[ok]
    j = np.clip(np.searchsorted(to, t_imu, side="right"), 1, to.size - 1)
    gap = to[j] - to[j - 1]
    valid = (t_imu >= to[0]) & (t_imu <= to[-1]) & (gap <= max_gap_factor * med + 1e-9)
    out[valid] = np.interp(t_imu[valid], to, so)
    return out


def nearest_samples(t_read, t_imu) -> tuple[np.ndarray, np.ndarray]:
    """The IMU sample nearest each reading: (index (R,) into ``t_imu`` (N,), ok (R,) bool).

    A reading is ok when that sample lies within one median IMU interval of it (readings outside the IMU
    span or in its gaps are not). Times in s.
    """
    t_read, t_imu = np.asarray(t_read, float), np.asarray(t_imu, float)
    j = np.clip(np.searchsorted(t_imu, t_read), 1, t_imu.size - 1)
    j = np.where(np.abs(t_imu[j - 1] - t_read) < np.abs(t_imu[j] - t_read), j - 1, j)
    dt = float(np.median(np.diff(t_imu)))
    return j, np.abs(t_imu[j] - t_read) <= dt
