"""INS/GNSS scenarios: a config tree (SI inside, edge units in TOML), the S0 scenario, and
:func:`simulate`, which turns a config and a PRNG key into truth, IMU and GNSS data.

The deterministic part (trajectory and ideal IMU) is computed once per config by
:func:`make_trajectory` (cached, computed eagerly even inside a trace); :func:`simulate` then only
draws the random parts, so ``jax.vmap(lambda k: simulate(cfg, k).imu.dv)(keys)`` batches just the
sensor errors.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib.resources
import json
import math
import os
from dataclasses import dataclass, field
from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxnav import units
from jaxnav._config import ConfigTable, load_toml, loads_toml
from jaxnav.geodesy import WGS84, enu_to_curvilinear
from jaxnav.ins.attitude import quat_mul, rv_to_quat
from jaxnav.ins.mechanization import NavState
from jaxnav.ins.noise import ImuNoise
from jaxnav.sim._gnss import GnssConfig, GnssData, gnss_epochs, simulate_gnss
from jaxnav.sim._imu import SensorLimits, corrupt_increments, simulator_noise
from jaxnav.sim._trajectory import (
    SEGMENT_KINDS,
    ScenarioError,
    Segment,
    Trajectory,
    TrajectorySpec,
    _vec3,
    generate_trajectory,
    segment_table,
)

PPM = 1e-6  # dimensionless per part-per-million (not in jaxnav.units)


@dataclass(frozen=True)
class InitialErrorConfig:
    """Initial INS errors (SI), per axis.

    Attributes:
      attitude: (3,) misalignment phi (E, N, U), rad: C_bn^ins = (I - [phi x]) C_bn^true.
      velocity: (3,) ENU velocity error, m/s.  position: (3,) ENU position error, m.
      mode: "random" draws each error from N(0, value^2) per run; "fixed" applies exactly
        +value on every axis.
    """

    attitude: tuple = (0.0, 0.0, 0.0)
    velocity: tuple = (0.0, 0.0, 0.0)
    position: tuple = (0.0, 0.0, 0.0)
    mode: str = "random"

    def __post_init__(self):
        for f in ("attitude", "velocity", "position"):
            object.__setattr__(self, f, _vec3(getattr(self, f), f"initial_errors.{f}", nonneg=True))
        if self.mode not in ("random", "fixed"):
            raise ScenarioError(f"initial_errors.mode must be 'random' or 'fixed', got {self.mode!r}")


@dataclass(frozen=True)
class ScenarioConfig:
    """A complete INS/GNSS simulation scenario (SI inside; hashable, usable as a static argument).

    Attributes:
      name, description: text.
      trajectory: :class:`TrajectorySpec` (start state and segments).
      duration: s (segments shorter than this are filled up with a cruise).
      imu_rate_hz: IMU rate, Hz.
      noise: :class:`jaxnav.ins.ImuNoise` of the gyro and accelerometer (SI; each term stored as a
        (3,) tuple; the bias and scale-factor random walks must be 0, the simulator draws none).
      limits: :class:`SensorLimits` (saturation and bandwidth, not modelled by the filters).
      gnss: :class:`GnssConfig`.
      initial_errors: :class:`InitialErrorConfig`.
      rk4_substeps: RK4 steps per IMU interval for the true position.
    """

    trajectory: TrajectorySpec
    duration: float
    imu_rate_hz: float = 100.0
    noise: ImuNoise = ImuNoise(0.0, 0.0)
    limits: SensorLimits = field(default_factory=SensorLimits)
    gnss: GnssConfig = field(default_factory=GnssConfig)
    initial_errors: InitialErrorConfig = field(default_factory=InitialErrorConfig)
    rk4_substeps: int = 1
    name: str = ""
    description: str = ""

    def __post_init__(self):
        object.__setattr__(self, "noise", simulator_noise(self.noise))

    @property
    def dt(self) -> float:
        """IMU interval, s."""
        return 1.0 / self.imu_rate_hz

    @property
    def origin(self) -> tuple:
        """(lat rad, lon rad, h m) of the local ENU frame: the start point."""
        return (self.trajectory.lat, self.trajectory.lon, self.trajectory.h)

    def validate(self) -> ScenarioConfig:
        """Check the host-side layout (segments fit, epochs on samples); return self."""
        tab = segment_table(self.trajectory, self.dt, self.duration)
        gnss_epochs(self.gnss, self.dt, tab.n_total)
        return self


# ------------------------------------------------------------------------------------------
# simulation


class ImuData(NamedTuple):
    """IMU increments over the N intervals (t_k, t_k+1].

    Attributes:
      dt: () s.  dtheta, dv: (N, 3) measured increments, rad and m/s (body frame).
      dtheta_ideal, dv_ideal: (N, 3) error-free increments (the same arrays as the truth's).
    """

    dt: jax.Array
    dtheta: jax.Array
    dv: jax.Array
    dtheta_ideal: jax.Array
    dv_ideal: jax.Array


class SensorErrors(NamedTuple):
    """The true sensor errors of one run (``None`` where the config term is zero).

    White noise is not stored (it is measured - ideal - the terms below, up to saturation).

    Attributes:
      gyro_bias: (3,) rad/s random constant (S0 eps_b).  gyro_markov: (N, 3) rad/s (S0 eps_r).
      gyro_scale: (3,) or None.  accel_bias: (3,) m/s^2 (S0 nabla).  accel_markov: (N, 3) or None.
      accel_scale: (3,) or None.
    """

    gyro_bias: jax.Array
    gyro_markov: jax.Array
    gyro_scale: jax.Array | None
    accel_bias: jax.Array
    accel_markov: jax.Array | None
    accel_scale: jax.Array | None


class InitialErrorDraw(NamedTuple):
    """Drawn initial INS errors: attitude phi (3,) rad (ENU), velocity (3,) m/s, position (3,) m ENU."""

    attitude: jax.Array
    velocity: jax.Array
    position: jax.Array


class SimResult(NamedTuple):
    """Output of :func:`simulate`.

    Attributes:
      truth: :class:`Trajectory` (deterministic, shared by every key).
      imu: :class:`ImuData`.  gnss: :class:`GnssData`.  errors: :class:`SensorErrors`.
      nav0: :class:`jaxnav.ins.NavState` to start the INS at t = 0 (truth plus initial errors).
      initial_errors: :class:`InitialErrorDraw`.
    Notes:
      Under ``vmap`` return only the fields you need: returning ``truth`` or the ideal increments
      from a vmapped function broadcasts them over the batch.
    """

    truth: Trajectory
    imu: ImuData
    gnss: GnssData
    errors: SensorErrors
    nav0: NavState
    initial_errors: InitialErrorDraw


@functools.lru_cache(maxsize=4)
def _cached_trajectory(spec, rate, duration, substeps):
    return generate_trajectory(spec, imu_rate_hz=rate, duration=duration, rk4_substeps=substeps)


def make_trajectory(config: ScenarioConfig) -> Trajectory:
    """Truth and ideal IMU of a scenario (deterministic; cached for the last 4 configs).

    Computed eagerly (a compiled program run on concrete arrays) even when called inside ``jit``/``vmap``,
    so the cache never holds tracers.
    """
    return _cached_trajectory(config.trajectory, config.imu_rate_hz, config.duration, config.rk4_substeps)


def cut_timeline(cfg: ScenarioConfig, duration: float) -> ScenarioConfig:
    """The scenario ``cfg`` cut to ``duration`` s: the trajectory segments (change + hold) that end by then.

    Raises:
      ValueError: if the first segment ends after ``duration``.
    """
    segs, t = [], 0.0
    for seg in cfg.trajectory.segments:
        if t + seg.duration + seg.hold > duration + 1e-9:
            break
        segs.append(seg)
        t += seg.duration + seg.hold
    if not segs:
        raise ValueError(f"duration {duration} s is shorter than the first trajectory segment")
    return dataclasses.replace(
        cfg, duration=float(duration), trajectory=dataclasses.replace(cfg.trajectory, segments=tuple(segs))
    )


def perturb_nav(nav: NavState, attitude, velocity, position_enu, ellipsoid=WGS84) -> NavState:
    """Apply ENU attitude (phi, rad), velocity (m/s) and position (m) errors to a navigation state.

    q_ins = rv2q(-phi) (x) q_true, i.e. C_bn^ins = (I - [phi x]) C_bn^true to first order.
    """
    if not hasattr(position_enu, "dtype"):  # a list or tuple of numbers takes the state's dtype
        position_enu = jnp.asarray(position_enu, jnp.result_type(nav.pos))
    dpos = enu_to_curvilinear(nav.pos, position_enu, ellipsoid)
    return NavState(q_bn=quat_mul(rv_to_quat(-attitude), nav.q_bn), v_n=nav.v_n + velocity, pos=nav.pos + dpos)


@functools.partial(jax.jit, static_argnames=("config",))
def _simulate_random(key, truth: Trajectory, config: ScenarioConfig):
    kg, ka, kn, ki = jax.random.split(key, 4)
    dt = truth.dt
    dth, gd = corrupt_increments(kg, truth.dtheta, dt, config.noise, "gyro", config.limits)
    dv, ad = corrupt_increments(ka, truth.dv, dt, config.noise, "accel", config.limits, unsensed=truth.dv_unsensed)
    epochs = gnss_epochs(config.gnss, config.dt, truth.dtheta.shape[0])
    gnss = simulate_gnss(kn, config.gnss, truth, epochs, jnp.asarray(config.origin))
    ie = config.initial_errors
    sig = [jnp.asarray(v, truth.pos.dtype) for v in (ie.attitude, ie.velocity, ie.position)]
    if ie.mode == "random":
        z = jax.random.normal(ki, (3, 3), truth.pos.dtype)
        draw = [s * zi for s, zi in zip(sig, z)]
    else:
        draw = sig
    init = InitialErrorDraw(*draw)
    nav_true = NavState(q_bn=truth.q_bn[0], v_n=truth.v_n[0], pos=truth.pos[0])
    nav0 = perturb_nav(nav_true, *draw)
    errors = SensorErrors(
        gyro_bias=gd.bias,
        gyro_markov=gd.markov,
        gyro_scale=gd.scale,
        accel_bias=ad.bias,
        accel_markov=ad.markov,
        accel_scale=ad.scale,
    )
    return dth, dv, gnss, errors, nav0, init


def simulate(config: ScenarioConfig, key, *, trajectory: Trajectory | None = None) -> SimResult:
    """Simulate one run of a scenario: sensor errors, GNSS fixes and initial INS errors.

    The key is split into four fixed sub-keys (gyro, accelerometer, GNSS, initial errors).

    Args:
      config: :class:`ScenarioConfig` (static; hashable).
      key: PRNG key.
      trajectory: the :func:`make_trajectory` output for ``config`` (computed and cached if None).
    Returns:
      :class:`SimResult`. Works under ``jit`` and ``vmap`` over keys; only key-dependent work is
      batched.
    Notes:
      Cost of the full S0 (200 000 samples) on a shared 2-core CPU: the trajectory once, ~0.3 s
      (plus ~1-3 s compile, ~0.7 GB peak RSS); one key ~0.05 s. 256 keys of ``.imu.dv`` under
      ``jax.jit(jax.vmap(...))``: ~8 s, 3.7 GB peak RSS of which 1.2 GB is the float64 output (jit
      drops the outputs you do not return). The same without ``jit`` (eager ``vmap``) computes every
      output for every key: ~30 s, 7.3 GB peak. For larger Monte Carlo batches use
      ``jax.lax.map(..., batch_size=...)`` over keys, or draw inside the consumer's own vmap.
    """
    if not isinstance(config, ScenarioConfig):
        raise TypeError(f"config must be a ScenarioConfig, got {type(config).__name__}")
    truth = make_trajectory(config) if trajectory is None else trajectory
    n = int(round(config.duration * config.imu_rate_hz))
    if truth.dtheta.shape != (n, 3):
        raise ValueError(
            f"trajectory has {truth.dtheta.shape[0]} IMU intervals but the config needs {n} "
            "(duration * imu_rate_hz): pass make_trajectory(config) for this config"
        )
    dth, dv, gnss, errors, nav0, init = _simulate_random(key, truth, config=config)
    imu = ImuData(dt=truth.dt, dtheta=dth, dv=dv, dtheta_ideal=truth.dtheta, dv_ideal=truth.dv)
    return SimResult(truth=truth, imu=imu, gnss=gnss, errors=errors, nav0=nav0, initial_errors=init)


# ------------------------------------------------------------------------------------------
# TOML <-> config (edge units)

# (toml key, attribute, factor to SI, kind)
_START = [
    ("lat_deg", "lat", units.DEG, "num"),
    ("lon_deg", "lon", units.DEG, "num"),
    ("height_m", "h", 1.0, "num"),
    ("heading_deg", "heading", units.DEG, "num"),
    ("pitch_deg", "pitch", units.DEG, "num"),
    ("roll_deg", "roll", units.DEG, "num"),
    ("speed_mps", "speed", 1.0, "num>=0"),
]
_TIME = [
    ("duration_s", "duration", 1.0, "num>0"),
    ("imu_rate_hz", "imu_rate_hz", 1.0, "num>0"),
    ("rk4_substeps", "rk4_substeps", 1, "int>=1"),
]
_SEGMENT = [
    ("kind", "kind", None, "str"),
    ("label", "label", None, "str"),
    ("duration_s", "duration", 1.0, "num>=0"),
    ("hold_s", "hold", 1.0, "num>=0"),
    ("dspeed_mps", "dspeed", 1.0, "num"),
    ("dheading_deg", "dheading", units.DEG, "num"),
    ("dpitch_deg", "dpitch", units.DEG, "num"),
    ("droll_deg", "droll", units.DEG, "num"),
    ("dv_enu_mps", "dv_enu", 1.0, "vec3"),
    ("sensed", "sensed", None, "bool"),
]
# the [gyro] and [accel] tables: fields of jaxnav.ins.ImuNoise and of SensorLimits
_GYRO = [
    ("bias_deg_per_h", "gyro_bias_initial", units.DEG_PER_HOUR, "vec3>=0"),
    ("markov_deg_per_h", "gyro_bias_instability", units.DEG_PER_HOUR, "vec3>=0"),
    ("markov_tau_s", "gyro_bias_tau", 1.0, "vec3>0"),
    ("arw_deg_per_sqrt_h", "gyro_arw", units.DEG_PER_SQRT_HOUR, "vec3>=0"),
    ("scale_factor_ppm", "gyro_sf", PPM, "vec3>=0"),
    ("saturation_deg_per_s", "gyro_saturation", units.DEG, "vec3>0"),
    ("bandwidth_hz", "gyro_bandwidth", 1.0, "vec3>0"),
]
_ACCEL = [
    ("bias_mg", "accel_bias_initial", units.MG, "vec3>=0"),
    ("markov_mg", "accel_bias_instability", units.MG, "vec3>=0"),
    ("markov_tau_s", "accel_bias_tau", 1.0, "vec3>0"),
    ("vrw_ug_per_sqrt_hz", "accel_vrw", units.UG, "vec3>=0"),
    ("scale_factor_ppm", "accel_sf", PPM, "vec3>=0"),
    ("saturation_g", "accel_saturation", units.G0, "vec3>0"),
    ("bandwidth_hz", "accel_bandwidth", 1.0, "vec3>0"),
]


def _imu_records(fields: dict):
    """(:class:`jaxnav.ins.ImuNoise`, :class:`SensorLimits`) from the read [gyro] and [accel] fields."""
    noise = {k: v for k, v in fields.items() if k in ImuNoise._fields}
    limits = {k: v for k, v in fields.items() if k not in ImuNoise._fields}
    return ImuNoise(**{"gyro_arw": 0.0, "accel_vrw": 0.0, **noise}), SensorLimits(**limits)


class _ImuFields:
    """Attribute view of a config's noise and limits, for writing the [gyro] and [accel] tables."""

    def __init__(self, noise: ImuNoise, limits: SensorLimits):
        self.__dict__.update(noise._asdict(), **limits.__dict__)


_GNSS = [
    ("rate_hz", "rate_hz", 1.0, "num>0"),
    ("first_epoch_s", "first_epoch", 1.0, "num>=0"),
    ("pos_sigma_m", "pos_sigma", 1.0, "vec3>=0"),
    ("vel_sigma_mps", "vel_sigma", 1.0, "vec3>=0"),
    ("outages_s", "outages", 1.0, "outages"),
    ("outlier_prob", "outlier_prob", 1.0, "prob"),
    ("outlier_pos_m", "outlier_pos", 1.0, "num>=0"),
    ("outlier_vel_mps", "outlier_vel", 1.0, "num>=0"),
]
_INIT = [
    ("attitude_arcsec", "attitude", units.ARCSEC, "vec3>=0"),
    ("velocity_mps", "velocity", 1.0, "vec3>=0"),
    ("position_m", "position", 1.0, "vec3>=0"),
    ("mode", "mode", None, "str"),
]
_TOP = [("name", "name", None, "str"), ("description", "description", None, "str")]
_SECTIONS = {"time": _TIME, "start": _START, "gyro": _GYRO, "accel": _ACCEL, "gnss": _GNSS, "initial_errors": _INIT}
_REQUIRED = {"time": ("duration_s", "imu_rate_hz"), "start": ("lat_deg", "lon_deg", "height_m")}
# which TOML change fields each segment kind accepts
_SEG_FIELD = {
    "dspeed": "dspeed_mps",
    "dheading": "dheading_deg",
    "dpitch": "dpitch_deg",
    "droll": "droll_deg",
    "dv_enu": "dv_enu_mps",
    "sensed": "sensed",
}


def _is_num(x):
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _convert(t: ConfigTable, key, factor, kind):
    """Field ``key`` of table ``t`` of the given kind, times ``factor`` (edge unit -> SI)."""
    if kind == "str":
        return t.get(key, str)
    if kind == "bool":
        return t.get(key, bool)
    if kind == "int>=1":
        return t.get(key, int, lo=1)
    x, path = t.data[key], t.key(key)
    if kind.startswith("vec3"):
        if not (_is_num(x) or (isinstance(x, list) and len(x) == 3 and all(_is_num(a) for a in x))):
            t.fail(key, f"must be a number or a list of 3 numbers, got {x!r}")
        v = _vec3(x, path, nonneg=kind == "vec3>=0", positive=kind == "vec3>0")
        return tuple(a * factor for a in v)
    if kind == "outages":
        if not isinstance(x, list):
            t.fail(key, f"must be a list of [start, end] pairs (s), got {x!r}")
        out = []
        for i, o in enumerate(x):
            if not (isinstance(o, list) and len(o) == 2 and all(_is_num(a) for a in o)):
                raise ScenarioError(f"{path}[{i}] must be a pair [start, end] in s, got {o!r}")
            if not o[1] > o[0]:
                raise ScenarioError(f"{path}[{i}] must have end > start, got {o!r}")
            out.append((float(o[0]), float(o[1])))
        return tuple(out)
    bounds = {"num>=0": dict(lo=0.0), "num>0": dict(lo=0.0, lo_open=True), "prob": dict(lo=0.0, hi=1.0)}
    return t.get(key, float, **bounds.get(kind, {})) * factor


def _read(t: ConfigTable, schema, required=()):
    """The fields of ``schema`` given in table ``t``, in SI; unknown fields and missing ``required`` ones refused."""
    t.expect(s[0] for s in schema)
    for k in required:
        if not t.has(k):
            t.fail(k, "is required")
    return {attr: _convert(t, k, fac, kind) for k, attr, fac, kind in schema if t.has(k)}


def scenario_from_dict(d: dict, *, validate: bool = True) -> ScenarioConfig:
    """Build a :class:`ScenarioConfig` from a TOML-shaped dict in edge units.

    Raises :class:`ScenarioError` (a ``ValueError``) naming the offending field, e.g.
    ``gyro.markov_tau_s = -3.0 must be > 0``, ``segments[3].dheading_deg is not allowed for kind 'accelerate'``.
    """
    doc = ConfigTable(d, error=ScenarioError)
    doc.expect([s[0] for s in _TOP] + list(_SECTIONS) + ["segments"])
    top = {attr: doc.get(k, str) for k, attr, _, _ in _TOP if doc.has(k)}
    for name in _REQUIRED:
        if not doc.has(name):
            raise ScenarioError(f"[{name}] section is required")
    sec = {
        name: _read(doc.table(name) or ConfigTable({}, name, error=ScenarioError), schema, _REQUIRED.get(name, ()))
        for name, schema in _SECTIONS.items()
    }
    segs = []
    for st in doc.tables("segments"):
        s = _read(st, _SEGMENT, ("kind", "duration_s"))
        kind = s["kind"]
        if kind not in SEGMENT_KINDS:
            st.fail("kind", f"must be one of {sorted(SEGMENT_KINDS)}, got {kind!r}")
        for attr, key in _SEG_FIELD.items():
            if st.has(key) and attr not in SEGMENT_KINDS[kind]:
                ok = [_SEG_FIELD[a] for a in SEGMENT_KINDS[kind]]
                st.fail(key, f"is not allowed for kind {kind!r} (allowed: {ok or 'none'})")
        segs.append(Segment(**s))
    spec = TrajectorySpec(segments=tuple(segs), **sec["start"])
    t = sec["time"]
    noise, limits = _imu_records({**sec["gyro"], **sec["accel"]})
    cfg = ScenarioConfig(
        trajectory=spec,
        duration=t["duration"],
        imu_rate_hz=t["imu_rate_hz"],
        rk4_substeps=t.get("rk4_substeps", 1),
        noise=noise,
        limits=limits,
        gnss=GnssConfig(**sec["gnss"]),
        initial_errors=InitialErrorConfig(**sec["initial_errors"]),
        **top,
    )
    return cfg.validate() if validate else cfg


def loads_scenario(text: str) -> ScenarioConfig:
    """Parse a scenario from TOML text (see ``jaxnav/sim/scenarios/s0.toml`` for the fields)."""
    try:
        d = loads_toml(text)
    except ValueError as e:
        raise ScenarioError(str(e)) from None
    return scenario_from_dict(d)


def load_scenario(path: str | os.PathLike) -> ScenarioConfig:
    """Read a scenario TOML file."""
    try:
        d = load_toml(path)
    except ValueError as e:
        raise ScenarioError(str(e)) from None
    try:
        return scenario_from_dict(d)
    except ScenarioError as e:
        raise ScenarioError(f"{os.fspath(path)}: {e}") from None


def _back(v, factor, kind):
    if v is None:
        return None
    if kind in ("str", "bool", "int>=1"):
        return v
    if kind.startswith("vec3"):
        out = [a / factor for a in v]
        return out[0] if out[0] == out[1] == out[2] else out
    if kind == "outages":
        return [list(o) for o in v]
    return v / factor


def _write(obj, schema, skip_default=None):
    out = {}
    for key, attr, fac, kind in schema:
        v = getattr(obj, attr)
        if v is None:
            continue
        if skip_default is not None and v == getattr(skip_default, attr):
            continue
        out[key] = _back(v, fac, kind)
    return out


def scenario_to_dict(cfg: ScenarioConfig) -> dict:
    """Inverse of :func:`scenario_from_dict` (edge units; None-valued options omitted)."""
    tr = cfg.trajectory
    d = _write(cfg, _TOP)
    d["time"] = {"duration_s": cfg.duration, "imu_rate_hz": cfg.imu_rate_hz, "rk4_substeps": cfg.rk4_substeps}
    d["start"] = _write(tr, _START)
    imu = _ImuFields(cfg.noise, cfg.limits)
    d["gyro"] = _write(imu, _GYRO)
    d["accel"] = _write(imu, _ACCEL)
    d["gnss"] = _write(cfg.gnss, _GNSS)
    d["initial_errors"] = _write(cfg.initial_errors, _INIT)
    segs = []
    for s in tr.segments:
        sd = {"kind": s.kind, "duration_s": s.duration}
        sd.update(_write(s, [e for e in _SEGMENT if e[0] not in ("kind", "duration_s")], skip_default=Segment()))
        segs.append(sd)
    d["segments"] = segs
    return d


def _toml_value(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(a) for a in v) + "]"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def dumps_scenario(cfg: ScenarioConfig) -> str:
    """Write a scenario as TOML text (round-trips through :func:`loads_scenario`)."""
    d = scenario_to_dict(cfg)
    lines = [f"{k} = {_toml_value(d[k])}" for k in ("name", "description") if k in d]
    for sec in ("time", "start", "gyro", "accel", "gnss", "initial_errors"):
        lines += ["", f"[{sec}]"] + [f"{k} = {_toml_value(v)}" for k, v in d[sec].items()]
    for sd in d["segments"]:
        lines += ["", "[[segments]]"] + [f"{k} = {_toml_value(v)}" for k, v in sd.items()]
    return "\n".join(lines) + "\n"


def s0_scenario() -> ScenarioConfig:
    """The S0 experiment (Tan, Wu, Kang 2019): see ``jaxnav/sim/scenarios/s0.toml`` for every choice."""
    return _s0_cached()


@functools.lru_cache(maxsize=1)
def _s0_cached():
    text = importlib.resources.files("jaxnav.sim").joinpath("scenarios/s0.toml").read_text(encoding="utf-8")
    return loads_scenario(text)
