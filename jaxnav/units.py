"""Unit constants and named converters for the edges of the library (configs, CLI, plots).

Inside jaxnav everything is SI (m, s, rad, m/s^2). Multiply a value given in an edge unit by
the constant to get SI; divide to go back. Example: ``0.1 * DEG_PER_HOUR`` is 0.1 deg/h in rad/s.
"""

from __future__ import annotations

import math

DEG = math.pi / 180.0  # rad per degree
ARCMIN = DEG / 60.0  # rad per arc-minute
ARCSEC = DEG / 3600.0  # rad per arc-second
HOUR = 3600.0  # s per hour
DEG_PER_HOUR = DEG / HOUR  # rad/s per deg/h
DEG_PER_SQRT_HOUR = DEG / math.sqrt(HOUR)  # rad/sqrt(s) per deg/sqrt(h) (angle random walk)
G0 = 9.80665  # standard gravity, m/s^2 (used only to express mg and ug)
MG = 1e-3 * G0  # m/s^2 per milli-g
UG = 1e-6 * G0  # m/s^2 per micro-g
MM = 1e-3  # m per millimetre
CM = 1e-2  # m per centimetre
DAY = 86400.0  # s per day
YEAR = 365.25 * DAY  # s per Julian year (daily-series velocities)
WEEK = 7 * DAY  # s per GPS week
MM_PER_YEAR = MM / YEAR  # m/s per mm/yr


def deg_to_rad(x):
    """Degrees -> radians."""
    return x * DEG


def rad_to_deg(x):
    """Radians -> degrees."""
    return x / DEG


def arcsec_to_rad(x):
    """Arc-seconds -> radians."""
    return x * ARCSEC


def deg_per_hour_to_rad_per_s(x):
    """Gyro drift in deg/h -> rad/s."""
    return x * DEG_PER_HOUR


def mg_to_mps2(x):
    """Accelerometer bias in milli-g -> m/s^2."""
    return x * MG


def mps_to_mm_per_year(x):
    """Velocity in m/s -> mm/yr (Julian year)."""
    return x / MM_PER_YEAR


# ----------------------------------------------------------------------------- IMU datasheet units
SQRT_HOUR = math.sqrt(HOUR)  # sqrt(s) per sqrt(h)
MPS_PER_SQRT_HOUR = 1.0 / SQRT_HOUR  # m/s/sqrt(s) per m/s/sqrt(h) (velocity random walk)
DEG_PER_HOUR_PER_SQRT_HOUR = DEG_PER_HOUR / SQRT_HOUR  # rad/s/sqrt(s) per deg/h/sqrt(h) (gyro bias random walk)
DEG_PER_SEC_PER_SQRT_HZ = DEG  # rad/sqrt(s) per deg/s/sqrt(Hz) (gyro noise density = angle random walk)
UG_PER_SQRT_HZ = UG  # m/s/sqrt(s) per ug/sqrt(Hz) (accelerometer noise density = velocity random walk)
PPM = 1e-6  # dimensionless per part per million (scale factors)


def deg_per_sqrt_hour_to_rad_per_sqrt_s(x):
    """Angle random walk in deg/sqrt(h) -> rad/sqrt(s)."""
    return x * DEG_PER_SQRT_HOUR


def rad_per_sqrt_s_to_deg_per_sqrt_hour(x):
    """Angle random walk in rad/sqrt(s) -> deg/sqrt(h)."""
    return x / DEG_PER_SQRT_HOUR


def mps_per_sqrt_hour_to_mps_per_sqrt_s(x):
    """Velocity random walk in m/s/sqrt(h) -> m/s/sqrt(s)."""
    return x * MPS_PER_SQRT_HOUR


def mps_per_sqrt_s_to_mps_per_sqrt_hour(x):
    """Velocity random walk in m/s/sqrt(s) -> m/s/sqrt(h)."""
    return x / MPS_PER_SQRT_HOUR


def rad_per_s_to_deg_per_hour(x):
    """Gyro drift in rad/s -> deg/h."""
    return x / DEG_PER_HOUR


def mps2_to_mg(x):
    """Accelerometer bias in m/s^2 -> milli-g."""
    return x / MG


def ug_to_mps2(x):
    """Accelerometer bias in micro-g -> m/s^2."""
    return x * UG


def mps2_to_ug(x):
    """Accelerometer bias in m/s^2 -> micro-g."""
    return x / UG


def ppm_to_ratio(x):
    """Scale factor in parts per million -> dimensionless."""
    return x * PPM


def ratio_to_ppm(x):
    """Dimensionless scale factor -> parts per million."""
    return x / PPM


def powerlaw_amplitude_to_mm_yr(a, kappa):
    """Power-law noise amplitude m s^(kappa/4) (SI) -> mm/yr^(-kappa/4), Hector's unit (Williams 2003).

    Args:
      a: amplitude, m / s^(-kappa/4).  kappa: spectral index (-1 flicker: mm/yr^0.25).
    """
    import numpy as _np

    return _np.asarray(a) * YEAR ** (-_np.asarray(kappa) / 4.0) / MM


def random_walk_to_mm_per_sqrt_yr(q):
    """Random-walk amplitude m/sqrt(s) -> mm/sqrt(yr)."""
    return q * math.sqrt(YEAR) / MM


def rad_per_s_per_sqrt_s_to_deg_per_hour_per_sqrt_hour(x):
    """Gyro rate random walk in rad/s/sqrt(s) -> deg/h/sqrt(h)."""
    return x / DEG_PER_HOUR_PER_SQRT_HOUR


def mps2_per_sqrt_s_to_mg_per_sqrt_hour(x):
    """Accelerometer rate random walk in m/s^2/sqrt(s) -> mg/sqrt(h)."""
    return x * SQRT_HOUR / MG
