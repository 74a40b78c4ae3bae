"""The ``jaxnav ins`` configuration: one TOML file describes a recording and how to process it.

Every key is checked before any file is read (type, range, allowed values, unknown keys named);
file paths are relative to the config file, and ``${JAXNAV_DATA}`` (or any ``${VAR}``) in a path
is replaced from the environment (the shipped configs use it to find ``../shared/data``); a path
that starts with a variable whose value is relative is taken against the working directory.
Units are the datasheet units a user has at hand (deg, deg/sqrt(h), m/s/sqrt(h), deg/h, mg, s, m);
:func:`load_ins_config` converts them to SI once, here, and the rest of the pipeline sees SI only.

Frames (stated once, used everywhere):
  vehicle frame: forward-right-down (FRD); ``lever_arm_frd_m`` is the GNSS antenna minus the IMU
  in it; ``mounting_rpy_deg`` = (roll, pitch, yaw) is the attitude of the sensor frame in it, so
  that C_vehicle_sensor = Rz(yaw) Ry(pitch) Rx(roll) maps a vector in sensor axes to vehicle axes.
  Groves-style configs (e.g. the upstream project of the walk set, ``imu_misalign``) apply the
  transpose of that product as sensor-to-body; give such angles as ``mounting_groves_rpy_deg``.
  Inside jaxnav the body frame is right-forward-up (RFU): C_bs = C_rfu_frd C_vehicle_sensor.
"""

from __future__ import annotations

import math
import pathlib
from typing import NamedTuple

import numpy as np

from jaxnav._config import ConfigError, ConfigTable, load_toml
from jaxnav.ins.allan import imu_noise_from_allan
from jaxnav.ins.calibration import TUNABLE
from jaxnav.ins.mounting import mounting_from_dcm, mounting_from_groves_deg, mounting_from_rpy_deg
from jaxnav.ins.noise import NOISE_GRADES, nearest_grade
from jaxnav.io._formats import GNSS_FORMATS, IMU_FORMATS, TRUTH_FORMATS
from jaxnav.units import DEG, DEG_PER_HOUR, DEG_PER_SQRT_HOUR, HOUR, MG

__all__ = [
    "INS_CONFIG_DIR",
    "INS_CONFIG_RANGES",
    "INS_NOISE_KEYS",
    "InsConfig",
    "find_ins_config",
    "load_ins_config",
    "noise_in_config_units",
    "noise_toml",
    "NOISE_TOML_SHORT_S",
]

#: folder of the shipped ``jaxnav ins`` configs (``jaxnav ins NAME`` finds ``NAME.toml`` here); they ship
#: beside the experiments that run them
INS_CONFIG_DIR = pathlib.Path(__file__).parents[1] / "experiments" / "configs" / "ins"

#: error-state counts of :func:`jaxnav.ins.error_model_for`
STATE_CHOICES = (15, 18, 21)

_NUM = (int, float)

#: plausible range [lo, hi] of every numeric key, in the key's own (config) unit: a value outside is a
#: typing slip or a unit mix-up, refused before anything is read (documented in docs/guide/ins.md)
INS_CONFIG_RANGES = {
    "imu.time_offset_s": (-10.0, 10.0),
    "imu.time_offset_search_s": (1e-3, 10.0),
    "gnss.pos_sigma_floor_m": (0.0, 100.0),
    "gnss.vel_sigma_floor_m_s": (0.0, 100.0),
    "gnss.gate_probability": (0.5, 1.0 - 1e-12),
    "noise.arw_deg_per_sqrt_h": (1e-5, 30.0),
    "noise.vrw_m_per_s_per_sqrt_h": (1e-5, 30.0),
    "noise.gyro_bias_instability_deg_per_h": (1e-5, 1e4),
    "noise.accel_bias_instability_mg": (1e-5, 100.0),
    "noise.bias_correlation_time_s": (0.1, 1e7),
    "noise.accel_bias_correlation_time_s": (0.1, 1e7),
    "noise.gyro_bias_rw_deg_per_h_per_sqrt_h": (1e-7, 1e4),
    "noise.accel_bias_rw_mg_per_sqrt_h": (1e-7, 100.0),
    "noise.init_velocity_m_s": (1e-4, 100.0),
    "noise.init_position_m": (1e-4, 1e4),
    "noise.init_gyro_bias_deg_per_s": (1e-7, 10.0),
    "noise.init_accel_bias_mg": (1e-4, 1000.0),
    "noise.init_gyro_scale_ppm": (1e-2, 1e5),
    "noise.init_accel_scale_ppm": (1e-2, 1e5),
    "alignment.static_s": (1e-2, 3600.0),
    "alignment.min_speed_m_s": (1e-2, 100.0),
    "alignment.course_s": (1e-2, 600.0),
    "constraints.zupt_sigma_m_s": (1e-5, 10.0),
    "constraints.zupt_rate_hz": (1e-3, 1000.0),
    "constraints.zaru_density_deg_per_sqrt_h": (1e-5, 1e3),
    "constraints.nhc_sigma_m_s": (1e-5, 100.0),
    "constraints.nhc_rate_hz": (1e-3, 1000.0),
    "constraints.detector_threshold": (1e-6, 1e12),
    "constraints.detector_sigma_a_m_s2": (1e-6, 100.0),
    "constraints.detector_sigma_w_deg_s": (1e-6, 1000.0),
    "constraints.detector_min_s": (0.0, 3600.0),
    "constraints.zupt_gnss_k": (0.5, 100.0),
    "odometer.sigma_m_s": (1e-4, 10.0),
    "odometer.rate_hz": (1e-3, 1000.0),
    "odometer.init_scale_sigma_ppm": (1.0, 5e5),
    "heading.sigma_deg": (1e-3, 180.0),
    "heading.rate_hz": (1e-3, 1000.0),
    "evaluate.outage_s": (0.1, 3600.0),
    "evaluate.first_s": (0.0, 1e6),
    "evaluate.gap_s": (0.1, 1e5),
    "evaluate.end_margin_s": (0.0, 1e5),
    "evaluate.shifts": (1, 100),
    "evaluate.shift_s": (0.1, 1e5),
    "tune.calibrate_steps": (1.0, 1e4),
}


class ImuSection(NamedTuple):
    """[imu], SI. ``mounting``: (3, 3) C_vehicle_sensor (FRD vehicle <- sensor)."""

    file: pathlib.Path
    format: str
    tag: pathlib.Path | None
    columns: dict | None
    units: dict | None
    mounting: np.ndarray
    mounting_source: str
    time_offset_s: float | str  # s, or "estimate"
    time_offset_search_s: float
    gps_week: int | None = None
    delimiter: str | None = ","


class GnssSection(NamedTuple):
    """[gnss], SI. ``lever_arm_frd``: (3,) antenna minus IMU, FRD vehicle frame, m."""

    file: pathlib.Path
    format: str
    columns: dict | None
    units: dict | None
    lever_arm_frd: np.ndarray
    use_velocity: bool
    fixed_only: bool
    pos_sigma_floor: float
    vel_sigma_floor: float
    gate_probability: float | None
    gps_week: int | None = None
    delimiter: str | None = ","
    sigma_m: float | None = None
    gate_max_run: int = 10


class NoiseSection(NamedTuple):
    """[noise], SI; None where the grade's preset value is used.

    Noise densities (fields of :class:`jaxnav.ins.ImuNoise`, :data:`INS_NOISE_KEYS`):
    arw rad/sqrt(s), vrw m/s/sqrt(s), bias instabilities rad/s and m/s^2 with their
    correlation times s (``bias_correlation_time``: gyro, and accelerometer unless
    ``bias_correlation_time_accel`` is given), bias random walks rad/s/sqrt(s) and m/s^2/sqrt(s),
    initial scale-factor sigmas (dimensionless; 21 states).
    Initial 1-sigma: attitude (roll/pitch, heading) rad, velocity m/s, position m, biases rad/s, m/s^2.
    """

    grade: str | None
    states: int
    arw: float | None
    vrw: float | None
    gyro_bias_instability: float | None
    accel_bias_instability: float | None
    bias_correlation_time: float | None
    gyro_bias_rw: float | None
    accel_bias_rw: float | None
    init_attitude: tuple
    init_velocity: float
    init_position: float
    init_gyro_bias: float | None
    init_accel_bias: float | None
    bias_correlation_time_accel: float | None = None
    init_gyro_scale: float | None = None
    init_accel_scale: float | None = None


class AlignmentSection(NamedTuple):
    """[alignment]: static window s, heading ("gnss" | "gyrocompass" | "auto" | a value in rad), speed m/s;
    ``attitude``: None or (3,) [roll, pitch, heading] rad of the vehicle at the start, as given."""

    static_s: float
    heading: float | str
    min_speed: float
    course_s: float
    attitude: np.ndarray | None


class ConstraintSection(NamedTuple):
    """[constraints]: ZUPT ("auto" | False) with ZARU, NHC, their sigmas and rates, and the standstill
    detector (SHOE GLRT, :func:`jaxnav.ins.detect_standstill`) settings, SI."""

    zupt: str | bool
    zupt_sigma: float
    zupt_rate_hz: float
    zaru: bool
    zaru_density: float
    nhc: bool
    nhc_sigma: float
    nhc_rate_hz: float
    nhc_lever_frd: np.ndarray
    detector_window: int | None  # samples, or None: the platform's window (seconds) at the IMU rate
    detector_threshold: float | str  # "auto" (from the recording's quiet periods) or a number
    detector_sigma_a: float
    detector_sigma_w: float
    detector_min_s: float | None  # s, or None: the platform's
    platform: str = "handheld"  # [run] platform: a key of jaxnav.ins.standstill.PLATFORMS
    zupt_gnss_k: float = 3.0  # no ZUPT/ZARU where the GNSS speed exceeds this many of its sigmas


class OdometerSection(NamedTuple):
    """[odometer]: wheel speed from the KF-GINS IMU file's 8th column (``source`` "imu") or a CSV (``source``
    "csv": ``file``, ``columns``, ``units``, ``delimiter``, ``gps_week`` as :func:`jaxnav.io.read_csv_series`
    takes them), on the IMU's clock; ``sigma`` m/s, ``rate_hz`` updates per second, ``lever_arm_frd`` (3,) the
    wheel contact point minus the IMU, FRD vehicle frame, m; ``estimate_scale``: carry the scale-factor
    error state, initial 1-sigma ``init_scale_sigma`` (dimensionless)."""

    source: str
    file: pathlib.Path | None
    columns: dict | None
    units: dict | None
    delimiter: str | None
    gps_week: int | None
    sigma: float
    rate_hz: float
    lever_arm_frd: np.ndarray
    estimate_scale: bool
    init_scale_sigma: float


class HeadingSection(NamedTuple):
    """[heading]: heading of the vehicle's forward axis (clockwise from north) from a CSV (``file``, ``columns``
    t (or week + tow), heading, optional sigma; ``units`` t, heading deg|rad; ``delimiter``; ``gps_week``) on
    the GNSS time scale; ``sigma`` rad for readings without their own, ``rate_hz`` updates per second."""

    file: pathlib.Path
    columns: dict
    units: dict | None
    delimiter: str | None
    gps_week: int | None
    sigma: float
    rate_hz: float


class EvaluateSection(NamedTuple):
    """[evaluate]: simulated outages of ``outage_s`` from ``first_s`` after the start, GNSS back on for
    ``gap_s`` between them, the last ending at least ``end_margin_s`` before the end (all s);
    ``outages`` False: none (a truth-only evaluation). ``truth``: a reference trajectory file (or
    None) in ``truth_format`` ("kf-gins": ``truth.nav``; "csv": with ``truth_columns``,
    ``truth_units``, ``truth_delimiter`` as :func:`jaxnav.io.read_csv_truth` takes them).
    ``shifts``: the protocol repeated with the outage schedule shifted by ``k shift_s``, k = 0 ..
    shifts - 1, each shift its own run (:func:`jaxnav.ins.shifted_outage_windows`); ``shift_s``
    (s) defaults to ``(outage_s + gap_s) / shifts``."""

    outage_s: float
    first_s: float
    gap_s: float
    end_margin_s: float
    outages: bool = True
    truth: pathlib.Path | None = None
    truth_format: str = "kf-gins"
    truth_columns: dict | None = None
    truth_units: dict | None = None
    truth_delimiter: str | None = ","
    shifts: int = 1
    shift_s: float | None = None


class TuneSection(NamedTuple):
    """[tune]: parameters tuned by ``--tune`` (names of :data:`TUNABLE`), L-BFGS evaluations (``steps``),
    gradient mode, and the loss: "innovations" (GNSS innovation likelihood over the run) or "outages"
    (predictive likelihood of fixes withheld on training windows between the evaluation windows).
    ``calibrate``: the default noise self-calibration, "auto" (only when the GNSS position or velocity
    NIS of the configured noise is outside its band, or too many epochs lie beyond the gate), True
    (always) or False (never); ``calibrate_steps``: its L-BFGS evaluations."""

    params: tuple
    steps: int
    mode: str
    loss: str = "innovations"
    calibrate: str | bool = "auto"
    calibrate_steps: int = 12


class InsConfig(NamedTuple):
    """A checked ``jaxnav ins`` configuration (SI units).

    Attributes:
      path: the config file.  name: a title for outputs (``[run] name``, default: the file stem).
      imu, gnss, noise, alignment, constraints: the sections.  evaluate: None or the outage protocol.
      tune: the ``--tune`` settings.  raw: the TOML as read (echoed into results.json).
      odometer: None or the wheel-speed input.
    """

    path: pathlib.Path
    name: str
    imu: ImuSection
    gnss: GnssSection
    noise: NoiseSection
    alignment: AlignmentSection
    constraints: ConstraintSection
    evaluate: EvaluateSection | None
    tune: TuneSection
    raw: dict
    odometer: OdometerSection | None = None
    heading: HeadingSection | None = None


class _Reader(ConfigTable):
    """One section of a ``jaxnav ins`` config: :class:`jaxnav.io.ConfigTable` with the plausible :data:`INS_CONFIG_RANGES`."""

    def __init__(self, path, d: dict, section: str, variables=None):
        super().__init__(d, section, source=path, error=ConfigError, plausible=INS_CONFIG_RANGES, variables=variables)


def _delimiter(r: _Reader):
    """``delimiter``: a one-character string, or "whitespace" (blanks, tabs and commas), default ","."""
    v = r.get("delimiter", str, ",")
    if v == "whitespace":
        return None
    if len(v) != 1:
        r.fail("delimiter", f"must be one character or 'whitespace', got {v!r}")
    return v


_SECTIONS = ("run", "imu", "gnss", "noise", "alignment", "constraints", "odometer", "heading", "evaluate", "tune")


def _imu(path, d, variables=None) -> ImuSection:
    r = _Reader(path, d, "imu", variables)
    fmt = r.get("format", str, "rtklib-csv", choices=IMU_FORMATS)
    f = r.file("file")
    tag = r.file("tag", required=False)
    if tag is not None and fmt != "rtklib-csv":
        r.fail("tag", f"is only used with format = 'rtklib-csv', not {fmt!r}")
    cols, units = r.get("columns", dict, None), r.get("units", dict, None)
    if fmt == "csv" and cols is None:
        r.fail("columns", "is required for format = 'csv' (a table like {t = 0, gx = 1, ...})")
    if fmt != "csv" and (cols is not None or units is not None):
        r.fail("columns" if cols is not None else "units", f"is only used with format = 'csv', not {fmt!r}")
    week = r.get("gps_week", int, None, lo=0, hi=5000)
    delim = _delimiter(r)
    given = [k for k in ("mounting_rpy_deg", "mounting_groves_rpy_deg", "mounting_dcm") if k in d]
    if len(given) > 1:
        r.fail(given[1], f"conflicts with {given[0]}: give the mounting once")
    if "mounting_dcm" in d:
        r.used.add("mounting_dcm")
        v = d["mounting_dcm"]
        try:
            C = np.asarray(v, float)
        except (TypeError, ValueError):
            C = np.zeros(0)
        if C.shape != (3, 3) or not np.all(np.isfinite(C)):
            r.fail("mounting_dcm", f"must be a 3x3 list of numbers, got {v!r}")
        try:
            mounting = mounting_from_dcm(C)
        except ValueError as exc:
            r.fail("mounting_dcm", f"must be a rotation (orthonormal, determinant +1): {exc}")
        src = "mounting_dcm (C_vehicle_sensor, FRD)"
    elif "mounting_groves_rpy_deg" in d:
        mounting = mounting_from_groves_deg(*r.get("mounting_groves_rpy_deg", "vec3"))
        src = "mounting_groves_rpy_deg (Groves Euler_to_CTM, transposed)"
    else:
        mounting = mounting_from_rpy_deg(*r.get("mounting_rpy_deg", "vec3", np.zeros(3)))
        src = "mounting_rpy_deg (Rz Ry Rx, FRD vehicle <- sensor)"
    off = d.get("time_offset_s", 0.0)
    r.used.add("time_offset_s")
    if off != "estimate":
        off = r.get("time_offset_s", float, 0.0, lo=-10.0, hi=10.0)
    search = r.get("time_offset_search_s", float, 0.5, lo=0.0, lo_open=True, hi=10.0)
    r.done()
    return ImuSection(
        file=f,
        format=fmt,
        tag=tag,
        columns=cols,
        units=units,
        mounting=mounting,
        mounting_source=src,
        time_offset_s=off,
        time_offset_search_s=search,
        gps_week=week,
        delimiter=delim,
    )


def _gnss(path, d, variables=None) -> GnssSection:
    r = _Reader(path, d, "gnss", variables)
    fmt = r.get("format", str, "rtklib-pos", choices=GNSS_FORMATS)
    f = r.file("file")
    cols, units = r.get("columns", dict, None), r.get("units", dict, None)
    if fmt == "csv" and cols is None:
        r.fail("columns", "is required for format = 'csv'")
    if fmt != "csv" and (cols is not None or units is not None):
        r.fail("columns" if cols is not None else "units", f"is only used with format = 'csv', not {fmt!r}")
    week = r.get("gps_week", int, None, lo=0, hi=5000)
    delim = _delimiter(r)
    sig = r.get("sigma_enu_m", "vec3", None)
    if sig is not None and (fmt != "csv" or np.any(sig <= 0)):
        r.fail("sigma_enu_m", "is only used with format = 'csv' and must be 3 positive numbers (m)")
    lever = r.get("lever_arm_frd_m", "vec3", np.zeros(3))
    if np.max(np.abs(lever)) > 100.0:
        r.fail("lever_arm_frd_m", f"= {lever.tolist()} m: a lever arm beyond 100 m is not plausible")
    gate = d.get("gate_probability", 0.9999)
    r.used.add("gate_probability")
    if gate is not False:
        gate = r.get("gate_probability", float, 0.9999, lo=0.5, hi=1.0 - 1e-12)
    else:
        gate = None
    g = GnssSection(
        file=f,
        format=fmt,
        columns=cols,
        units=units,
        lever_arm_frd=lever,
        use_velocity=r.get("use_velocity", bool, True),
        fixed_only=r.get("fixed_only", bool, False),
        pos_sigma_floor=r.get("pos_sigma_floor_m", float, 0.02, lo=0.0),
        vel_sigma_floor=r.get("vel_sigma_floor_m_s", float, 0.05, lo=0.0),
        gate_probability=gate,
        gps_week=week,
        delimiter=delim,
        sigma_m=sig,
        gate_max_run=r.get("gate_max_run", int, 10, lo=1, hi=1_000_000),
    )
    r.done()
    return g


def _noise(path, d) -> NoiseSection:
    r = _Reader(path, d, "noise")
    grade = r.get("grade", str, None, choices=NOISE_GRADES)
    states = r.get("states", int, 15, choices=STATE_CHOICES)

    def opt(key, scale):
        v = r.get(key, float, None, lo=0.0, lo_open=True)
        return None if v is None else v * scale

    densities = {field: opt(key, scale) for key, (field, _, scale, _) in INS_NOISE_KEYS.items()}
    n = NoiseSection(
        grade=grade,
        states=states,
        init_attitude=tuple(float(x) * DEG for x in _pair(r, "init_attitude_deg", (1.0, 10.0))),
        init_velocity=r.get("init_velocity_m_s", float, 0.1, lo=0.0, lo_open=True),
        init_position=r.get("init_position_m", float, 0.05, lo=0.0, lo_open=True),
        **densities,
    )
    if grade is None and (n.arw is None or n.vrw is None):
        r.fail("grade", "is required unless arw_deg_per_sqrt_h and vrw_m_per_s_per_sqrt_h are both given")
    for key, used in NOISE_KEY_STATES.items():  # a density the chosen model has no state for is not silently dropped
        if key in d and states not in used:
            r.fail(
                key,
                f"is used only with states = {' or '.join(str(k) for k in used)} (the error states that "
                f"model it); with states = {states} it would be ignored: set states or remove the key",
            )
    r.done()
    return n


#: ``[noise]`` keys of :class:`jaxnav.ins.ImuNoise` values: key -> (:class:`NoiseSection` field, ``ImuNoise``
#: field, SI value of the key's unit, the unit); the one table for reading the keys and writing them back
INS_NOISE_KEYS = {
    "arw_deg_per_sqrt_h": ("arw", "gyro_arw", DEG_PER_SQRT_HOUR, "deg/sqrt(h)"),
    "vrw_m_per_s_per_sqrt_h": ("vrw", "accel_vrw", 1.0 / math.sqrt(HOUR), "m/s/sqrt(h)"),
    "gyro_bias_instability_deg_per_h": ("gyro_bias_instability", "gyro_bias_instability", DEG_PER_HOUR, "deg/h"),
    "accel_bias_instability_mg": ("accel_bias_instability", "accel_bias_instability", MG, "mg"),
    "bias_correlation_time_s": ("bias_correlation_time", "gyro_bias_tau", 1.0, "s"),
    "accel_bias_correlation_time_s": ("bias_correlation_time_accel", "accel_bias_tau", 1.0, "s"),
    "gyro_bias_rw_deg_per_h_per_sqrt_h": (
        "gyro_bias_rw",
        "gyro_bias_rw",
        DEG_PER_HOUR / math.sqrt(HOUR),
        "deg/h/sqrt(h)",
    ),
    "accel_bias_rw_mg_per_sqrt_h": ("accel_bias_rw", "accel_bias_rw", MG / math.sqrt(HOUR), "mg/sqrt(h)"),
    "init_gyro_bias_deg_per_s": ("init_gyro_bias", "gyro_bias_initial", DEG, "deg/s"),
    "init_accel_bias_mg": ("init_accel_bias", "accel_bias_initial", MG, "mg"),
    "init_gyro_scale_ppm": ("init_gyro_scale", "gyro_sf", 1e-6, "ppm"),
    "init_accel_scale_ppm": ("init_accel_scale", "accel_sf", 1e-6, "ppm"),
}


def noise_in_config_units(imu, keys=tuple(INS_NOISE_KEYS)) -> dict:
    """``[noise]`` values of an :class:`jaxnav.ins.ImuNoise` in the config's units, keyed as the config is.

    Args:
      imu: the noise (SI; a field may be per axis).  keys: the ``[noise]`` keys wanted (of :data:`INS_NOISE_KEYS`).
    Returns:
      {key: float, or a list for a per-axis field}.
    Raises:
      ValueError: a key that is not in :data:`INS_NOISE_KEYS`.
    """
    bad = [k for k in keys if k not in INS_NOISE_KEYS]
    if bad:
        raise ValueError(f"not [noise] keys: {bad}; expected some of {list(INS_NOISE_KEYS)}")
    out = {}
    for k in keys:
        v = np.asarray(getattr(imu, INS_NOISE_KEYS[k][1]), float) / INS_NOISE_KEYS[k][2]
        out[k] = float(v) if v.ndim == 0 else v.tolist()
    return out


#: a recording shorter than this (s) is warned about in the TOML: its bias terms are bounds at short taus
NOISE_TOML_SHORT_S = 3600.0


def noise_toml(gyro, accel, *, source: str) -> str:
    """A ``[noise]`` section for a ``jaxnav ins`` config from the Allan fits of the gyro and the accelerometer
    (:func:`jaxnav.ins.allan_noise_fit` records; the largest axis of each term), as TOML text.

    Keys and units are those of :func:`jaxnav.io.load_ins_config`; a value outside the config's
    plausible range (:data:`INS_CONFIG_RANGES`) is written commented out, with the reason, and so are the bias
    terms of a recording shorter than :data:`NOISE_TOML_SHORT_S`. ``grade`` is the
    preset nearest in ARW: it supplies the initial (turn-on) bias and scale-factor sigmas, which a
    static recording cannot measure; the values below override its densities.
    """
    n = imu_noise_from_allan(gyro, accel, reduce=np.max)
    notes = {
        "arw_deg_per_sqrt_h": "gyro white noise",
        "vrw_m_per_s_per_sqrt_h": "accelerometer white noise",
        "gyro_bias_instability_deg_per_h": "Gauss-Markov sigma = 1.075 B (its Allan peak at the 0.664 B floor)",
        "bias_correlation_time_s": "gyro: tau of the Allan minimum / 1.893",
        "accel_bias_instability_mg": "Gauss-Markov sigma = 1.075 B",
        "accel_bias_correlation_time_s": "accelerometer: tau of the Allan minimum / 1.893",
        "gyro_bias_rw_deg_per_h_per_sqrt_h": "rate random walk (used with states = 21)",
        "accel_bias_rw_mg_per_sqrt_h": "rate random walk (used with states = 21)",
    }
    values = noise_in_config_units(n, tuple(notes))
    lines = [
        f"# [noise] from the Allan variance of {source} (jaxnav allan): the largest of the three axes;",
        "# a term the recording could not resolve is given its 2-sigma upper bound (see results.json)",
    ]
    dur = gyro.n * gyro.dt
    if dur < NOISE_TOML_SHORT_S:
        lines += [
            f"# only {dur:.0f} s of data (taus up to {float(gyro.taus[-1]):.3g} s): the bias instability, its "
            "correlation time and the rate random walk",
            "# are bounds or weak estimates here, written commented out (the grade's values stand); "
            "record an hour or longer to measure them",
        ]
    lines += [
        "[noise]",
        f'grade = "{nearest_grade(n.gyro_arw)}"  # nearest preset in ARW: turn-on bias and scale-factor '
        "sigmas (not measurable from a static recording)",
    ]
    for key, what in notes.items():
        lo, hi = INS_CONFIG_RANGES[f"noise.{key}"]
        v = values[key]
        if dur < NOISE_TOML_SHORT_S and not key.startswith(("arw", "vrw")):
            lines.append(f"# {key} = {v:.4g}  # {what}")
        elif math.isfinite(v) and lo <= v <= hi and v > 0:
            lines.append(f"{key} = {v:.4g}  # {what}")
        else:
            lines.append(f"# {key} = {v:.4g}  # {what}; outside the config's range [{lo:g}, {hi:g}], left to the grade")
    return "\n".join(lines) + "\n"


#: [noise] keys that only some state counts use (the others need no such entry: every model uses them)
NOISE_KEY_STATES = {
    "gyro_bias_instability_deg_per_h": (18, 21),
    "bias_correlation_time_s": (18, 21),
    "accel_bias_instability_mg": (21,),
    "accel_bias_correlation_time_s": (21,),
    "gyro_bias_rw_deg_per_h_per_sqrt_h": (21,),
    "accel_bias_rw_mg_per_sqrt_h": (21,),
    "init_gyro_scale_ppm": (21,),
    "init_accel_scale_ppm": (21,),
}


def _pair(r: _Reader, key, default):
    r.used.add(key)
    v = r.data.get(key, list(default))
    if (
        not isinstance(v, list)
        or len(v) != 2
        or not all(isinstance(x, _NUM) and not isinstance(x, bool) and 0 < x < 360 for x in v)
    ):
        r.fail(key, f"must be [roll/pitch, heading] 1-sigma in deg, each in (0, 360), got {v!r}")
    return v


def _alignment(path, d) -> AlignmentSection:
    r = _Reader(path, d, "alignment")
    h = d.get("heading", "gnss")
    r.used.add("heading")
    if isinstance(h, str):
        if h not in ("gnss", "gyrocompass", "auto"):
            r.fail("heading", f"must be 'gnss', 'gyrocompass', 'auto' or a heading in deg, got {h!r}")
    else:
        h = r.get("heading", float, lo=-360.0, hi=360.0) * DEG
    att = r.get("attitude_deg", "vec3", None)  # [roll, pitch, heading] of the vehicle at the start
    a = AlignmentSection(
        static_s=r.get("static_s", float, 1.5, lo=0.0, lo_open=True, hi=3600.0),
        heading=h,
        min_speed=r.get("min_speed_m_s", float, 0.5, lo=0.0, lo_open=True),
        course_s=r.get("course_s", float, 2.0, lo=0.0, lo_open=True),
        attitude=None if att is None else att * DEG,
    )
    r.done()
    return a


def _constraints(path, d, platform="handheld") -> ConstraintSection:
    r = _Reader(path, d, "constraints")
    th = d.get("detector_threshold", "auto")
    if th != "auto":
        th = r.get("detector_threshold", float, lo=0.0, lo_open=True)
    r.used.add("detector_threshold")
    z = d.get("zupt", False)
    r.used.add("zupt")
    if z not in ("auto", False):
        r.fail("zupt", f"must be 'auto' or false, got {z!r}")
    pos = dict(lo=0.0, lo_open=True)
    c = ConstraintSection(
        zupt=z,
        zupt_sigma=r.get("zupt_sigma_m_s", float, 0.02, **pos),
        zupt_rate_hz=r.get("zupt_rate_hz", float, 5.0, **pos),
        zaru=r.get("zaru", bool, False),
        zaru_density=r.get("zaru_density_deg_per_sqrt_h", float, 1.0, **pos) * DEG_PER_SQRT_HOUR,
        nhc=r.get("nhc", bool, False),
        nhc_sigma=r.get("nhc_sigma_m_s", float, 0.1, **pos),
        nhc_rate_hz=r.get("nhc_rate_hz", float, 10.0, **pos),
        nhc_lever_frd=_lever(r, "nhc_lever_frd_m"),
        detector_window=r.get("detector_window", int, None, lo=3, hi=100_000),
        detector_threshold=th,
        detector_sigma_a=r.get("detector_sigma_a_m_s2", float, 0.05, **pos),
        detector_sigma_w=r.get("detector_sigma_w_deg_s", float, 0.57, **pos) * DEG,
        detector_min_s=r.get("detector_min_s", float, None, lo=0.0),
        platform=platform,
        zupt_gnss_k=r.get("zupt_gnss_k", float, 3.0, **pos),
    )
    r.done()
    return c


def _odometer(path, d, imu: ImuSection, variables=None) -> OdometerSection:
    r = _Reader(path, d, "odometer", variables)
    src = r.get("source", str, choices=("imu", "csv"))
    f = r.file("file", required=False)
    cols, units = r.get("columns", dict, None), r.get("units", dict, None)
    week = r.get("gps_week", int, None, lo=0, hi=5000)
    delim = _delimiter(r)
    if src == "imu":
        if imu.format != "kf-gins":
            r.fail(
                "source",
                f"= 'imu' reads the odometer column of a KF-GINS IMU file, but imu.format = "
                f"{imu.format!r}: give source = 'csv' with file = ...",
            )
        for k in ("file", "columns", "units", "gps_week", "delimiter"):
            if k in d:
                r.fail(k, "is only used with source = 'csv'")
    else:
        if f is None:
            r.fail("file", "is required for source = 'csv'")
        cols = {"t": 0, "speed": 1} if cols is None else cols
        for k, v in cols.items():
            if k not in ("t", "week", "tow", "speed"):
                r.fail("columns", f"has unknown key {k!r}; known: ['t', 'week', 'tow', 'speed']")
            if isinstance(v, bool) or not isinstance(v, (int, str)) or (isinstance(v, int) and v < 0):
                r.fail("columns", f"{k} must be a 0-based column index >= 0 or a header name, got {v!r}")
        for k, v in (units or {}).items():
            allowed = {"t": ("s", "ms", "us", "ns"), "speed": ("m/s", "km/h")}
            if k not in allowed or v not in allowed[k]:
                r.fail("units", f"{k} = {v!r}: expected t in {list(allowed['t'])} or speed in {list(allowed['speed'])}")
    pos = dict(lo=0.0, lo_open=True)
    o = OdometerSection(
        source=src,
        file=f,
        columns=cols,
        units=units,
        delimiter=delim,
        gps_week=week,
        sigma=r.get("sigma_m_s", float, 0.1, **pos),
        rate_hz=r.get("rate_hz", float, 2.0, **pos),
        lever_arm_frd=_lever(r, "lever_arm_frd_m"),
        estimate_scale=r.get("estimate_scale", bool, True),
        init_scale_sigma=r.get("init_scale_sigma_ppm", float, 2e4, **pos) * 1e-6,
    )
    r.done()
    return o


def _heading(path, d, variables=None) -> HeadingSection:
    r = _Reader(path, d, "heading", variables)
    f = r.file("file")
    cols = r.get("columns", dict, None) or {"t": 0, "heading": 1}
    for k, v in cols.items():
        if k not in ("t", "week", "tow", "heading", "sigma"):
            r.fail("columns", f"has unknown key {k!r}; known: ['t', 'week', 'tow', 'heading', 'sigma']")
        if isinstance(v, bool) or not isinstance(v, (int, str)) or (isinstance(v, int) and v < 0):
            r.fail("columns", f"{k} must be a 0-based column index >= 0 or a header name, got {v!r}")
    units = r.get("units", dict, None)
    for k, v in (units or {}).items():
        allowed = {"t": ("s", "ms", "us", "ns"), "heading": ("deg", "rad")}
        if k not in allowed or v not in allowed[k]:
            r.fail("units", f"{k} = {v!r}: expected t in {list(allowed['t'])} or heading in {list(allowed['heading'])}")
    pos = dict(lo=0.0, lo_open=True)
    h = HeadingSection(
        file=f,
        columns=cols,
        units=units,
        delimiter=_delimiter(r),
        gps_week=r.get("gps_week", int, None, lo=0, hi=5000),
        sigma=r.get("sigma_deg", float, 1.0, **pos) * DEG,
        rate_hz=r.get("rate_hz", float, 1.0, **pos),
    )
    r.done()
    return h


_TRUTH_COLUMNS = ("t", "week", "tow", "lat", "lon", "h", "ve", "vn", "vu", "vd", "roll", "pitch", "heading", "yaw")


def _evaluate(path, d, variables=None) -> EvaluateSection:
    r = _Reader(path, d, "evaluate", variables)
    truth = r.file("truth", required=False)
    fmt = r.get("truth_format", str, "kf-gins", choices=TRUTH_FORMATS)
    cols, units = r.get("truth_columns", dict, None), r.get("truth_units", dict, None)
    delim = r.data.get("truth_delimiter", ",")
    r.used.add("truth_delimiter")
    if truth is None:
        for k in ("truth_format", "truth_columns", "truth_units", "truth_delimiter"):
            if k in d:
                r.fail(k, "is only used with truth = FILE")
    if fmt == "csv" and truth is not None:
        if cols is None:
            r.fail(
                "truth_columns",
                "is required for truth_format = 'csv' (a table like {t = 0, lat = 1, lon = 2, h = 3, ...})",
            )
        for k, v in cols.items():
            if k not in _TRUTH_COLUMNS:
                r.fail("truth_columns", f"has unknown key {k!r}; known: {list(_TRUTH_COLUMNS)}")
            if isinstance(v, bool) or not isinstance(v, (int, str)) or (isinstance(v, int) and v < 0):
                r.fail("truth_columns", f"{k} must be a 0-based column index >= 0 or a header name, got {v!r}")
        for k, v in (units or {}).items():
            allowed = {"t": ("s", "ms", "us", "ns"), "angle": ("deg", "rad")}
            if k not in allowed or v not in allowed[k]:
                r.fail(
                    "truth_units",
                    f"{k} = {v!r}: expected t in {list(allowed['t'])} or angle in {list(allowed['angle'])}",
                )
    elif cols is not None or units is not None:
        r.fail(
            "truth_columns" if cols is not None else "truth_units",
            f"is only used with truth_format = 'csv', not {fmt!r}",
        )
    if not isinstance(delim, str) or not (delim == "whitespace" or len(delim) == 1):
        r.fail("truth_delimiter", f"must be one character or 'whitespace', got {delim!r}")
    outage_s = r.get("outage_s", float, 15.0, lo=0.0, lo_open=True)
    gap_s = r.get("gap_s", float, 45.0, lo=0.0, lo_open=True)
    outages = r.get("outages", bool, True)
    lo, hi = INS_CONFIG_RANGES["evaluate.shifts"]
    shifts = r.get("shifts", int, 1, lo=lo, hi=hi)
    period = outage_s + gap_s
    shift_s = r.get("shift_s", float, period / shifts, lo=0.0, lo_open=True)
    if "shift_s" in d and shifts == 1:
        r.fail("shift_s", "is only used with shifts > 1 (the number of shifted outage schedules)")
    if shifts > 1 and not outages:
        r.fail("shifts", "> 1 shifts the outage schedule, but outages = false withholds no GNSS")
    if shifts > 1 and (shifts - 1) * shift_s >= period - 1e-9:
        r.fail(
            "shift_s",
            f"= {shift_s:g} s: the last of the {shifts} shifts would start {(shifts - 1) * shift_s:g} s late, a whole "
            f"outage period (outage_s + gap_s = {period:g} s) or more, repeating an earlier shift's windows: "
            f"give shift_s < {period / (shifts - 1):g} s, or leave it out ({period / shifts:g} s: the shifts tile "
            "one period)",
        )
    e = EvaluateSection(
        outage_s=outage_s,
        first_s=r.get("first_s", float, 40.0, lo=0.0),
        gap_s=gap_s,
        end_margin_s=r.get("end_margin_s", float, 30.0, lo=0.0),
        outages=outages,
        truth=truth,
        truth_format=fmt,
        truth_columns=cols,
        truth_units=units,
        truth_delimiter=None if delim == "whitespace" else delim,
        shifts=shifts,
        shift_s=shift_s,
    )
    if not e.outages and truth is None:
        r.fail("outages", "= false leaves nothing to evaluate: give truth = FILE, or drop [evaluate]")
    r.done()
    return e


def _tune(path, d) -> TuneSection:
    r = _Reader(path, d, "tune")
    r.used.add("params")
    ps = d.get("params", ["arw", "vrw"])
    if not isinstance(ps, list) or not ps or not all(p in TUNABLE for p in ps) or len(set(ps)) != len(ps):
        r.fail("params", f"must be a non-empty list of distinct names from {list(TUNABLE)}, got {ps!r}")
    cal = d.get("calibrate", "auto")
    r.used.add("calibrate")
    if cal != "auto" and not isinstance(cal, bool):
        r.fail("calibrate", f"must be 'auto', true or false, got {cal!r}")
    t = TuneSection(
        params=tuple(ps),
        steps=r.get("steps", int, 25, lo=1, hi=10_000),
        mode=r.get("mode", str, "reverse", choices=("reverse", "forward")),
        loss=r.get("loss", str, "innovations", choices=("innovations", "outages")),
        calibrate=cal,
        calibrate_steps=r.get("calibrate_steps", int, 12, lo=1, hi=10_000),
    )
    r.done()
    return t


def find_ins_config(spec) -> pathlib.Path:
    """The config file of ``spec``: a path, or the name of a shipped config (``walk_0827``)."""
    p = pathlib.Path(spec)
    if p.suffix == ".toml" or p.exists():
        if not p.is_file():
            raise ConfigError(f"{p}: no such config file")
        return p
    shipped = INS_CONFIG_DIR / f"{spec}.toml"
    if shipped.is_file():
        return shipped
    names = sorted(q.stem for q in INS_CONFIG_DIR.glob("*.toml"))
    raise ConfigError(f"{spec}: no such config file, and not a shipped config (shipped: {', '.join(names)})")


def load_ins_config(spec, *, variables=None) -> InsConfig:
    """Read and check a ``jaxnav ins`` TOML (a path or a shipped name), converting it to SI.

    Every key is checked before any file is read (type, range, allowed values, unknown keys named);
    file paths are relative to the config file, and ``${VAR}`` in a path is replaced from
    ``variables`` or the environment. The keys, their units and frames: the INS guide
    (``docs/guide/ins.md``, "Your own IMU + GNSS logs"); vehicle frame forward-right-down, body frame
    right-forward-up (:func:`jaxnav.ins.sensor_to_body`).

    Args:
      spec: a path, or the name of a shipped config.
      variables: optional mapping for ``${NAME}`` in paths, used before the environment.

    Raises:
      ConfigError (a ValueError): naming the file and the key: unknown section or key, wrong
        type, a value out of range, conflicting keys, an unset ``${VAR}`` in a path.
    """
    path = find_ins_config(spec)
    d = load_toml(path)
    doc = ConfigTable(d, source=path, error=ConfigError)
    doc.expect(_SECTIONS)
    for sec in ("imu", "gnss"):
        if sec not in d:
            raise ConfigError(f"{path}: missing section [{sec}]")
    run = _Reader(path, d.get("run", {}), "run")
    name = run.get("name", str, path.stem)
    platform = run.get("platform", str, "handheld", choices=("car", "handheld", "foot", "rover"))
    run.done()
    imu = _imu(path, d["imu"], variables)
    gnss = _gnss(path, d["gnss"], variables)
    tune = _tune(path, d.get("tune", {}))
    if "vel_sigma_scale" in tune.params and not gnss.use_velocity:
        raise ConfigError(
            f"{path}: tune.params: vel_sigma_scale needs gnss.use_velocity = true (it scales the GNSS velocity sigmas)"
        )
    return InsConfig(
        path=path,
        name=name,
        imu=imu,
        gnss=gnss,
        noise=_noise(path, d.get("noise", {"grade": "consumer"})),
        alignment=_alignment(path, d.get("alignment", {})),
        constraints=_constraints(path, d.get("constraints", {}), platform),
        evaluate=_evaluate(path, d["evaluate"], variables) if "evaluate" in d else None,
        tune=tune,
        raw=d,
        odometer=_odometer(path, d["odometer"], imu, variables) if "odometer" in d else None,
        heading=_heading(path, d["heading"], variables) if "heading" in d else None,
    )


def _lever(r: _Reader, key):
    """A lever arm ``key`` (3 numbers, m), each within +-100 m."""
    v = r.get(key, "vec3", np.zeros(3))
    if np.max(np.abs(v)) > 100.0:
        r.fail(key, f"= {v.tolist()} m: a lever arm beyond 100 m is not plausible")
    return v
