"""IMU noise densities as a datasheet gives them, in SI, and typical presets by grade.

:class:`ImuNoise` holds what a datasheet states: white noise (angle / velocity random walk), bias
instability as a first-order Gauss-Markov process (sigma, correlation time), bias random walk,
turn-on bias, scale-factor sigmas -- each in SI. :func:`imu_noise_from_datasheet` takes the usual
edge units (deg/sqrt(h), m/s/sqrt(h), deg/h, mg, ppm) through the named helpers of
:mod:`jaxnav.units`; :func:`imu_noise_to_datasheet` goes back (reports, configs).

Presets (:data:`NOISE_GRADES`, :func:`noise_preset`) are *representative round figures* chosen
within the ranges of the literature, not any product's specification; use your datasheet when you
have one:

* P. D. Groves, *Principles of GNSS, Inertial, and Multisensor Integrated Navigation Systems*,
  2nd ed., Artech House 2013, sect. 4.4 (accelerometer and gyro biases by grade, Tables 4.1 and
  4.2: marine/aviation ~0.01-0.1 mg and 0.001-0.01 deg/h, intermediate ~0.1-1 mg and ~0.1 deg/h,
  tactical 1-10 mg and 1-100 deg/h, automotive/consumer > 10 mg and > 100 deg/h uncalibrated;
  sect. 4.4.3 random noise; sect. 4.4.2 scale factors).
* N. El-Sheimy, A. Youssef, "Inertial sensors technologies for navigation applications: state of
  the art and future trends", Satellite Navigation 1:2 (2020), Table 1 (navigation grade gyro
  drift < 0.01 deg/h and accelerometer bias < 100 ug; tactical 1-10 deg/h and 1-5 mg; commercial
  0.1 deg/s and 0.1-1 mg).
* Typical MEMS datasheets: consumer (phone / u-blox-class 6-axis MEMS: gyro noise ~0.005-0.015
  deg/s/sqrt(Hz), i.e. 0.3-0.9 deg/sqrt(h); accelerometer ~100-200 ug/sqrt(Hz)); industrial
  (Xsens MTi / ADIS-class: ~0.1-0.4 deg/sqrt(h), in-run bias stability 2-10 deg/h).

=============  ==========  ==========  ========  ========  ======  =========  =======  =========
grade          ARW         VRW         gyro BI   accel BI  tau     gyro       accel    SF gyro /
               deg/sqrt h  m/s/sqrt h  deg/h     mg        s       turn-on    turn-on  accel
                                                                   deg/h      mg       ppm
=============  ==========  ==========  ========  ========  ======  =========  =======  =========
consumer       0.5         0.1         10        0.1       300     1000       30       5000/5000
industrial     0.15        0.04        3         0.03      600     50         3        1000/1000
tactical       0.05        0.02        1         0.02      1800    3          1        300/300
navigation     0.002       0.005       0.005     0.01      3600    0.01       0.025    5/50
=============  ==========  ==========  ========  ========  ======  =========  =======  =========

The bias random walk of the presets is zero (the in-run drift is carried by the Gauss-Markov
bias instability; a first-order Gauss-Markov process of sigma s and time tau has the driving
density s sqrt(2 / tau), which is what to enter as a random walk instead for a tau much longer
than the run).
"""

from __future__ import annotations

import math
from typing import NamedTuple

from jax.typing import ArrayLike

from jaxnav import units


class ImuNoise(NamedTuple):
    """IMU noise densities (SI; scalars or (3,) per axis; array leaves a tuner may differentiate).

    Attributes:
      gyro_arw: angle random walk, rad/sqrt(s) (= gyro white noise density, rad/s/sqrt(Hz)).
      accel_vrw: velocity random walk, m/s/sqrt(s) (= accelerometer noise density, m/s^2/sqrt(Hz)).
      gyro_bias_instability: steady-state sigma of the first-order Gauss-Markov gyro bias, rad/s.
      gyro_bias_tau: its correlation time, s.
      accel_bias_instability: the same for the accelerometers, m/s^2.  accel_bias_tau: s.
      gyro_bias_rw: gyro bias random walk density, rad/s/sqrt(s).
      accel_bias_rw: accelerometer bias random walk density, m/s^2/sqrt(s).
      gyro_bias_initial: turn-on (run-to-run) gyro bias sigma, rad/s (initial bias uncertainty).
      accel_bias_initial: turn-on accelerometer bias sigma, m/s^2.
      gyro_sf: gyro scale-factor sigma, dimensionless (1e-6 = 1 ppm).  accel_sf: the same.
      gyro_sf_rw, accel_sf_rw: scale-factor random walk densities, 1/sqrt(s).

    The simulator (:class:`jaxnav.sim.ScenarioConfig`), the error models (:meth:`jaxnav.ins.ErrorModel.Qc`,
    :func:`jaxnav.ins.lc_params`) and the ``jaxnav ins`` configs all take this record.
    """

    gyro_arw: ArrayLike
    accel_vrw: ArrayLike
    gyro_bias_instability: ArrayLike = 0.0
    gyro_bias_tau: ArrayLike = 3600.0
    accel_bias_instability: ArrayLike = 0.0
    accel_bias_tau: ArrayLike = 3600.0
    gyro_bias_rw: ArrayLike = 0.0
    accel_bias_rw: ArrayLike = 0.0
    gyro_bias_initial: ArrayLike = 0.0
    accel_bias_initial: ArrayLike = 0.0
    gyro_sf: ArrayLike = 0.0
    accel_sf: ArrayLike = 0.0
    gyro_sf_rw: ArrayLike = 0.0
    accel_sf_rw: ArrayLike = 0.0


#: preset names, best last
NOISE_GRADES = ("consumer", "industrial", "tactical", "navigation")


def imu_noise_from_datasheet(
    *,
    arw_deg_per_sqrt_h,
    vrw_mps_per_sqrt_h,
    gyro_bias_instability_deg_per_h=0.0,
    gyro_bias_tau_s=3600.0,
    accel_bias_instability_mg=0.0,
    accel_bias_tau_s=3600.0,
    gyro_bias_rw_deg_per_h_per_sqrt_h=0.0,
    accel_bias_rw_mps2_per_sqrt_h=0.0,
    gyro_bias_initial_deg_per_h=0.0,
    accel_bias_initial_mg=0.0,
    gyro_sf_ppm=0.0,
    accel_sf_ppm=0.0,
    gyro_sf_rw_ppm_per_sqrt_h=0.0,
    accel_sf_rw_ppm_per_sqrt_h=0.0,
) -> ImuNoise:
    """:class:`ImuNoise` from datasheet units (the edge: configs, CLI).

    Args (keyword only; edge units in the names): ARW deg/sqrt(h); VRW m/s/sqrt(h); gyro bias
    instability deg/h and its correlation time s; accelerometer bias instability mg and its time s;
    gyro bias random walk deg/h/sqrt(h); accelerometer bias random walk m/s^2/sqrt(h); turn-on
    biases deg/h and mg; scale factors ppm; scale-factor random walks ppm/sqrt(h).
    Returns:
      :class:`ImuNoise` in SI.
    Raises:
      ValueError: for a negative or non-finite value, or a non-positive correlation time.
    """
    vals = dict(
        arw_deg_per_sqrt_h=arw_deg_per_sqrt_h,
        vrw_mps_per_sqrt_h=vrw_mps_per_sqrt_h,
        gyro_bias_instability_deg_per_h=gyro_bias_instability_deg_per_h,
        accel_bias_instability_mg=accel_bias_instability_mg,
        gyro_bias_rw_deg_per_h_per_sqrt_h=gyro_bias_rw_deg_per_h_per_sqrt_h,
        accel_bias_rw_mps2_per_sqrt_h=accel_bias_rw_mps2_per_sqrt_h,
        gyro_bias_initial_deg_per_h=gyro_bias_initial_deg_per_h,
        accel_bias_initial_mg=accel_bias_initial_mg,
        gyro_sf_ppm=gyro_sf_ppm,
        accel_sf_ppm=accel_sf_ppm,
        gyro_sf_rw_ppm_per_sqrt_h=gyro_sf_rw_ppm_per_sqrt_h,
        accel_sf_rw_ppm_per_sqrt_h=accel_sf_rw_ppm_per_sqrt_h,
    )
    for k, v in vals.items():
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
            raise ValueError(f"{k} must be a finite number >= 0, got {v!r}")
    for k, v in (("gyro_bias_tau_s", gyro_bias_tau_s), ("accel_bias_tau_s", accel_bias_tau_s)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise ValueError(f"{k} must be a finite number > 0, got {v!r}")
    return ImuNoise(
        gyro_arw=units.deg_per_sqrt_hour_to_rad_per_sqrt_s(float(arw_deg_per_sqrt_h)),
        accel_vrw=units.mps_per_sqrt_hour_to_mps_per_sqrt_s(float(vrw_mps_per_sqrt_h)),
        gyro_bias_instability=units.deg_per_hour_to_rad_per_s(float(gyro_bias_instability_deg_per_h)),
        gyro_bias_tau=float(gyro_bias_tau_s),
        accel_bias_instability=units.mg_to_mps2(float(accel_bias_instability_mg)),
        accel_bias_tau=float(accel_bias_tau_s),
        gyro_bias_rw=float(gyro_bias_rw_deg_per_h_per_sqrt_h) * units.DEG_PER_HOUR_PER_SQRT_HOUR,
        accel_bias_rw=float(accel_bias_rw_mps2_per_sqrt_h) / units.SQRT_HOUR,
        gyro_bias_initial=units.deg_per_hour_to_rad_per_s(float(gyro_bias_initial_deg_per_h)),
        accel_bias_initial=units.mg_to_mps2(float(accel_bias_initial_mg)),
        gyro_sf=units.ppm_to_ratio(float(gyro_sf_ppm)),
        accel_sf=units.ppm_to_ratio(float(accel_sf_ppm)),
        gyro_sf_rw=units.ppm_to_ratio(float(gyro_sf_rw_ppm_per_sqrt_h)) / units.SQRT_HOUR,
        accel_sf_rw=units.ppm_to_ratio(float(accel_sf_rw_ppm_per_sqrt_h)) / units.SQRT_HOUR,
    )


def imu_noise_to_datasheet(noise: ImuNoise) -> dict:
    """The inverse of :func:`imu_noise_from_datasheet`: a dict of edge-unit floats (reports, configs)."""
    f = float
    return {
        "arw_deg_per_sqrt_h": f(units.rad_per_sqrt_s_to_deg_per_sqrt_hour(noise.gyro_arw)),
        "vrw_mps_per_sqrt_h": f(units.mps_per_sqrt_s_to_mps_per_sqrt_hour(noise.accel_vrw)),
        "gyro_bias_instability_deg_per_h": f(units.rad_per_s_to_deg_per_hour(noise.gyro_bias_instability)),
        "gyro_bias_tau_s": f(noise.gyro_bias_tau),
        "accel_bias_instability_mg": f(units.mps2_to_mg(noise.accel_bias_instability)),
        "accel_bias_tau_s": f(noise.accel_bias_tau),
        "gyro_bias_rw_deg_per_h_per_sqrt_h": f(noise.gyro_bias_rw / units.DEG_PER_HOUR_PER_SQRT_HOUR),
        "accel_bias_rw_mps2_per_sqrt_h": f(noise.accel_bias_rw * units.SQRT_HOUR),
        "gyro_bias_initial_deg_per_h": f(units.rad_per_s_to_deg_per_hour(noise.gyro_bias_initial)),
        "accel_bias_initial_mg": f(units.mps2_to_mg(noise.accel_bias_initial)),
        "gyro_sf_ppm": f(units.ratio_to_ppm(noise.gyro_sf)),
        "accel_sf_ppm": f(units.ratio_to_ppm(noise.accel_sf)),
        "gyro_sf_rw_ppm_per_sqrt_h": f(units.ratio_to_ppm(noise.gyro_sf_rw * units.SQRT_HOUR)),
        "accel_sf_rw_ppm_per_sqrt_h": f(units.ratio_to_ppm(noise.accel_sf_rw * units.SQRT_HOUR)),
    }


_PRESETS = {  # edge units, see the module table
    "consumer": dict(
        arw_deg_per_sqrt_h=0.5,
        vrw_mps_per_sqrt_h=0.1,
        gyro_bias_instability_deg_per_h=10.0,
        accel_bias_instability_mg=0.1,
        gyro_bias_tau_s=300.0,
        accel_bias_tau_s=300.0,
        gyro_bias_initial_deg_per_h=1000.0,
        accel_bias_initial_mg=30.0,
        gyro_sf_ppm=5000.0,
        accel_sf_ppm=5000.0,
    ),
    "industrial": dict(
        arw_deg_per_sqrt_h=0.15,
        vrw_mps_per_sqrt_h=0.04,
        gyro_bias_instability_deg_per_h=3.0,
        accel_bias_instability_mg=0.03,
        gyro_bias_tau_s=600.0,
        accel_bias_tau_s=600.0,
        gyro_bias_initial_deg_per_h=50.0,
        accel_bias_initial_mg=3.0,
        gyro_sf_ppm=1000.0,
        accel_sf_ppm=1000.0,
    ),
    "tactical": dict(
        arw_deg_per_sqrt_h=0.05,
        vrw_mps_per_sqrt_h=0.02,
        gyro_bias_instability_deg_per_h=1.0,
        accel_bias_instability_mg=0.02,
        gyro_bias_tau_s=1800.0,
        accel_bias_tau_s=1800.0,
        gyro_bias_initial_deg_per_h=3.0,
        accel_bias_initial_mg=1.0,
        gyro_sf_ppm=300.0,
        accel_sf_ppm=300.0,
    ),
    "navigation": dict(
        arw_deg_per_sqrt_h=0.002,
        vrw_mps_per_sqrt_h=0.005,
        gyro_bias_instability_deg_per_h=0.005,
        accel_bias_instability_mg=0.01,
        gyro_bias_tau_s=3600.0,
        accel_bias_tau_s=3600.0,
        gyro_bias_initial_deg_per_h=0.01,
        accel_bias_initial_mg=0.025,
        gyro_sf_ppm=5.0,
        accel_sf_ppm=50.0,
    ),
}


def noise_preset(grade: str) -> ImuNoise:
    """Representative :class:`ImuNoise` of a grade: one of :data:`NOISE_GRADES` (module table and sources).

    Raises:
      ValueError: for an unknown grade (naming the known ones).
    """
    if grade not in _PRESETS:
        raise ValueError(f"unknown IMU grade {grade!r}; known: {', '.join(NOISE_GRADES)}")
    return imu_noise_from_datasheet(**_PRESETS[grade])


def nearest_grade(arw) -> str:
    """The grade of :data:`NOISE_GRADES` whose preset ARW is nearest to ``arw`` (rad/sqrt(s)) in log scale."""
    return min(NOISE_GRADES, key=lambda g: abs(math.log(max(float(arw), 1e-30) / float(noise_preset(g).gyro_arw))))
