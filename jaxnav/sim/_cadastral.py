"""Simulated cadastral survey (S3): a surveyor's cart walks between stops with a strapdown IMU.

The route is a sequence of legs: accelerate to walking speed, walk (optionally on a slope,
with a turn half-way), decelerate, stop at a point of one of the five S3 kinds. The trajectory
and the ideal IMU come from :func:`jaxnav.sim.generate_trajectory` (``rest`` segments are exact
stops), sensor errors from :func:`jaxnav.sim.corrupt_increments`; on top, isolated wild values
(spikes) are injected so that the S3 preprocessing has something to reject. Known points carry
a surveying error drawn per run with the stop list's sigmas.

Config file: ``jaxnav/sim/scenarios/cadastral.toml`` (edge units in the field names).
"""

from __future__ import annotations

import functools
import importlib.resources
import os
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxnav import units
from jaxnav._config import ConfigTable, load_toml, loads_toml
from jaxnav.ins.mechanization import NavState
from jaxnav.ins.noise import ImuNoise
from jaxnav.sim._imu import SensorLimits, simulator_noise
from jaxnav.sim._scenario import (
    _ACCEL,
    _GYRO,
    _INIT,
    InitialErrorConfig,
    ScenarioConfig,
    _imu_records,
    _read,
    make_trajectory,
    simulate,
)
from jaxnav.sim._trajectory import ScenarioError, Segment, TrajectorySpec, segment_table

_KINDS = ("known_coordinate", "known_position", "levelling", "zupt", "target")


@dataclass(frozen=True)
class Leg:
    """One leg of the survey: walk, then stop.

    Attributes:
      walk: s of motion (acceleration, walk, turn, deceleration included).
      turn: rad, heading change (clockwise positive) made half-way.
      slope: rad, pitch while walking (climb/descent); 0 for level ground.
      kind: stop kind (one of the five S3 kinds).  stop: s standing at the point.  name: point name.
    """

    walk: float
    kind: str
    stop: float
    turn: float = 0.0
    slope: float = 0.0
    name: str = ""


@dataclass(frozen=True)
class ImuGrade:
    """A sensor grade: its :class:`jaxnav.ins.ImuNoise`, :class:`SensorLimits`, initial alignment errors."""

    name: str
    noise: ImuNoise
    limits: SensorLimits = field(default_factory=SensorLimits)
    initial_errors: InitialErrorConfig = field(default_factory=InitialErrorConfig)

    def __post_init__(self):
        object.__setattr__(self, "noise", simulator_noise(self.noise))


@dataclass(frozen=True)
class CadastralScenario:
    """A simulated cadastral survey (SI; hashable, a static argument).

    Attributes:
      lat, lon, h, heading: start point (rad, m) and initial heading (rad, clockwise from north).
      speed: walking speed, m/s.  accel_time, turn_time, pitch_time: s per manoeuvre.
      first_stop: s at the first (known-coordinate) point, where the survey starts; first_name.
      legs: tuple of :class:`Leg`.  imu_rate_hz: Hz.  grade: :class:`ImuGrade`.
      wild_prob: probability of a wild value per sample and axis; wild_gyro rad/s, wild_accel m/s^2
        magnitudes (random sign).
      sigma_known: (3,) E/N/U std of known-coordinate points, m; sigma_position: horizontal std of
        known-position points, m; sigma_levelling: height std of levelling points, m.
      gait_hz, gait_pitch: the cart's pitching while it moves (frequency, Hz; peak-to-peak, rad), made
        of constant-rate trajectory pieces so that truth and IMU agree. Without it a cart at constant
        velocity is, for an IMU, indistinguishable from a stop.
    """

    lat: float
    lon: float
    h: float
    heading: float
    legs: tuple
    grade: ImuGrade
    speed: float = 1.2
    accel_time: float = 2.0
    turn_time: float = 4.0
    pitch_time: float = 1.0
    first_stop: float = 40.0
    first_name: str = "K0"
    imu_rate_hz: float = 100.0
    wild_prob: float = 0.0
    wild_gyro: float = 0.0
    wild_accel: float = 0.0
    sigma_known: tuple = (0.005, 0.005, 0.005)
    sigma_position: float = 0.02
    sigma_levelling: float = 0.005
    gait_hz: float = 0.0
    gait_pitch: float = 0.0

    def __post_init__(self):
        if self.first_stop <= 0 or not self.legs:
            raise ScenarioError("a cadastral survey needs first_stop > 0 and at least one leg")
        for i, leg in enumerate(self.legs):
            if leg.kind not in _KINDS:
                raise ScenarioError(f"legs[{i}].stop_kind must be one of {_KINDS}, got {leg.kind!r}")
            need = (
                2 * self.accel_time
                + (self.turn_time if leg.turn else 0.0)
                + (2 * self.pitch_time if leg.slope else 0.0)
            )
            if leg.walk < need + 1.0:
                raise ScenarioError(f"legs[{i}].walk_s = {leg.walk} s is too short for its manoeuvres ({need} s + 1 s)")
            if leg.stop <= 0:
                raise ScenarioError(f"legs[{i}].stop_s must be > 0")

    @property
    def dt(self) -> float:
        return 1.0 / self.imu_rate_hz

    def _gait(self, duration, dspeed=0.0):
        """A moving piece with the gait: pitch oscillating +-gait_pitch/2 at gait_hz (constant-rate
        sub-pieces, so truth and IMU stay consistent); the speed change is spread over it."""
        dur = round(duration * self.imu_rate_hz) / self.imu_rate_hz
        if not (self.gait_hz > 0 and self.gait_pitch > 0) or dur < 1.0 / self.gait_hz:
            kind = "accelerate" if dspeed else "cruise"
            return [Segment(kind=kind, duration=dur, dspeed=dspeed)]
        half = round(0.5 / self.gait_hz * self.imu_rate_hz) / self.imu_rate_hz
        q = round(half / 2 * self.imu_rate_hz) / self.imu_rate_hz
        n = int((dur - 2 * q) // half)
        n -= n % 2
        rest = round((dur - 2 * q - n * half) * self.imu_rate_hz) / self.imu_rate_hz
        parts = [(q, 0.5)] + [(half, -1.0 if i % 2 == 0 else 1.0) for i in range(n)] + [(q, -0.5)]
        total = sum(p[0] for p in parts)
        segs = [
            Segment(kind="general", duration=d, dpitch=sgn * self.gait_pitch, dspeed=dspeed * d / total)
            for d, sgn in parts
        ]
        if rest > 0:
            segs.append(Segment(kind="cruise", duration=rest))
        return segs

    def _segments(self):
        segs = [Segment(kind="rest", duration=self.first_stop, label=self.first_name)]
        for leg in self.legs:
            cruise = (
                leg.walk
                - 2 * self.accel_time
                - (self.turn_time if leg.turn else 0.0)
                - (2 * self.pitch_time if leg.slope else 0.0)
            )
            c1 = round(cruise / 2 * self.imu_rate_hz) / self.imu_rate_hz
            segs += self._gait(self.accel_time, self.speed)
            if leg.slope:
                segs.append(Segment(kind="pitch", duration=self.pitch_time, dpitch=leg.slope))
            segs += self._gait(c1)
            if leg.turn:
                segs.append(Segment(kind="turn", duration=self.turn_time, dheading=leg.turn))
            segs += self._gait(round((cruise - c1) * self.imu_rate_hz) / self.imu_rate_hz)
            if leg.slope:
                segs.append(Segment(kind="pitch", duration=self.pitch_time, dpitch=-leg.slope))
            segs += self._gait(self.accel_time, -self.speed)
            segs.append(Segment(kind="rest", duration=leg.stop, label=leg.name))
        return tuple(segs)

    @property
    def duration(self) -> float:
        return self.first_stop + sum(leg.walk + leg.stop for leg in self.legs)

    def scenario_config(self) -> ScenarioConfig:
        """The equivalent :class:`jaxnav.sim.ScenarioConfig` (trajectory + IMU; GNSS unused)."""
        spec = TrajectorySpec(lat=self.lat, lon=self.lon, h=self.h, heading=self.heading, segments=self._segments())
        return ScenarioConfig(
            trajectory=spec,
            duration=self.duration,
            imu_rate_hz=self.imu_rate_hz,
            noise=self.grade.noise,
            limits=self.grade.limits,
            initial_errors=self.grade.initial_errors,
            name="cadastral",
            description=f"S3 cadastral survey, {self.grade.name} IMU",
        )


class SurveyTruth(NamedTuple):
    """Host-side truth of a survey.

    Attributes:
      stops: :class:`jaxnav.survey.StopList` with the *true* stop coordinates (exact).
      t_imu: (N,) sample end times, s.  pos: (N+1, 3) true positions at the state times.
      stop_pos: (K, 3) true [lat, lon, h] of each stop.  targets: (T,) stop indices of targets.
    """

    stops: Any
    t_imu: jax.Array
    pos: jax.Array
    stop_pos: jax.Array
    targets: jax.Array


def survey_truth(scn: CadastralScenario) -> SurveyTruth:
    """Stops (spans, kinds, true coordinates) and the true trajectory of a scenario (host side)."""
    from jaxnav.survey._stops import make_stop_list

    cfg = scn.scenario_config()
    tr = make_trajectory(cfg)
    t = np.asarray(tr.t)
    dt = scn.dt
    spans, kinds, names = [], [], []
    t0 = 0.0
    spans.append((0.0, scn.first_stop))
    kinds.append("known_coordinate")
    names.append(scn.first_name)
    t0 = scn.first_stop
    for i, leg in enumerate(scn.legs):
        a = t0 + leg.walk
        spans.append((a, a + leg.stop))
        kinds.append(leg.kind)
        names.append(leg.name or f"P{i + 1}")
        t0 = a + leg.stop
    spans = np.round(np.array(spans) / dt) * dt
    pos = np.asarray(tr.pos)
    idx = np.round(spans[:, 0] / dt).astype(int)
    stop_pos = pos[idx]
    sig = []
    for k in kinds:
        if k == "known_coordinate":
            sig.append(scn.sigma_known)
        elif k == "known_position":
            sig.append((scn.sigma_position, scn.sigma_position, 1.0))
        elif k == "levelling":
            sig.append((1.0, 1.0, scn.sigma_levelling))
        else:
            sig.append((1.0, 1.0, 1.0))
    known_pos = stop_pos.copy()
    code = np.array([_KINDS.index(k) for k in kinds])
    known_pos[code == 1, 2] = np.nan
    known_pos[code == 2, :2] = np.nan
    known_pos[code >= 3] = np.nan
    stops = make_stop_list(spans[:, 0], spans[:, 1], code, known_pos, np.array(sig, float), names)
    return SurveyTruth(stops=stops, t_imu=t[1:], pos=pos, stop_pos=stop_pos, targets=np.flatnonzero(code == 4))


class CadastralRun(NamedTuple):
    """One simulated survey (what a vmapped Monte Carlo needs).

    Attributes:
      dtheta, dv: (N, 3) measured increments (sensor errors and wild values), rad, m/s.
      nav0: :class:`jaxnav.ins.NavState` at t = 0 with the grade's initial alignment errors.
      known_pos: (K, 3) surveyed coordinates of the stops (true + surveying error; NaN unknown).
      n_wild: number of wild values injected.
      gyro_bias, accel_bias: (3,) the run's sensor random constants (rad/s, m/s^2).
    """

    dtheta: jax.Array
    dv: jax.Array
    nav0: NavState
    known_pos: jax.Array
    n_wild: jax.Array
    gyro_bias: jax.Array
    accel_bias: jax.Array


def simulate_cadastral(scn: CadastralScenario, key, truth: SurveyTruth | None = None) -> CadastralRun:
    """Draw one run of a cadastral survey (jit/vmap over keys).

    Args:
      scn: :class:`CadastralScenario` (static).  key: PRNG key (split: sensors, wild values,
        known-point errors).  truth: :func:`survey_truth` output (computed if None).
    Returns:
      :class:`CadastralRun`.
    """
    truth = survey_truth(scn) if truth is None else truth
    cfg = scn.scenario_config()
    k_sim, k_wild, k_known = jax.random.split(key, 3)
    run = simulate(cfg, k_sim)
    dth, dv = run.imu.dtheta, run.imu.dv
    N = dth.shape[0]
    kw = jax.random.split(k_wild, 4)
    dtype = dth.dtype

    def spikes(k1, k2, mag):
        hit = jax.random.bernoulli(k1, scn.wild_prob, (N, 3))
        sgn = jnp.where(jax.random.bernoulli(k2, 0.5, (N, 3)), 1.0, -1.0)
        return jnp.where(hit, sgn * mag * scn.dt, 0.0).astype(dtype), jnp.sum(hit)

    sg, ng = spikes(kw[0], kw[1], scn.wild_gyro)
    sa, na = spikes(kw[2], kw[3], scn.wild_accel)
    kp = jnp.asarray(truth.stops.pos)
    sig = jnp.asarray(truth.stops.sigma)
    e = sig * jax.random.normal(k_known, sig.shape, dtype)
    from jaxnav.geodesy import enu_to_curvilinear

    d = enu_to_curvilinear(jnp.asarray(truth.stop_pos), e)
    return CadastralRun(
        dtheta=dth + sg,
        dv=dv + sa,
        nav0=run.nav0,
        known_pos=kp + d,
        n_wild=ng + na,
        gyro_bias=run.errors.gyro_bias,
        accel_bias=run.errors.accel_bias,
    )


# ------------------------------------------------------------------------------------------
# TOML

_SURVEY = [
    ("lat_deg", units.DEG),
    ("lon_deg", units.DEG),
    ("height_m", 1.0),
    ("heading_deg", units.DEG),
    ("speed_mps", 1.0),
    ("accel_s", 1.0),
    ("turn_s", 1.0),
    ("pitch_s", 1.0),
    ("first_stop_s", 1.0),
    ("imu_rate_hz", 1.0),
    ("gait_hz", 1.0),
    ("gait_pitch_deg", units.DEG),
]
_SURVEY_ATTR = {
    "lat_deg": "lat",
    "lon_deg": "lon",
    "height_m": "h",
    "heading_deg": "heading",
    "speed_mps": "speed",
    "accel_s": "accel_time",
    "turn_s": "turn_time",
    "pitch_s": "pitch_time",
    "first_stop_s": "first_stop",
    "imu_rate_hz": "imu_rate_hz",
    "gait_hz": "gait_hz",
    "gait_pitch_deg": "gait_pitch",
}
_LEG = {
    "walk_s": ("walk", 1.0),
    "turn_deg": ("turn", units.DEG),
    "slope_deg": ("slope", units.DEG),
    "stop_kind": ("kind", None),
    "stop_s": ("stop", 1.0),
    "name": ("name", None),
}
_WILD = {"prob": ("wild_prob", 1.0), "gyro_deg_per_s": ("wild_gyro", units.DEG), "accel_g": ("wild_accel", units.G0)}
_KNOWN = {
    "known_coordinate_sigma_m": ("sigma_known", 1.0),
    "known_position_sigma_m": ("sigma_position", 1.0),
    "levelling_sigma_m": ("sigma_levelling", 1.0),
}


#: plausible range [lo, hi] of every numeric key of a cadastral TOML, in the key's (config) unit
#: ("imu.gyro.*" holds for every grade); a value outside is refused naming the key (docs/api/survey.md)
RANGES = {
    "survey.lat_deg": (-90.0, 90.0),
    "survey.lon_deg": (-180.0, 360.0),
    "survey.height_m": (-500.0, 9000.0),
    "survey.heading_deg": (-360.0, 360.0),
    "survey.speed_mps": (0.05, 10.0),
    "survey.accel_s": (0.05, 60.0),
    "survey.turn_s": (0.05, 600.0),
    "survey.pitch_s": (0.05, 60.0),
    "survey.first_stop_s": (1.0, 3600.0),
    "survey.imu_rate_hz": (10.0, 10000.0),
    "survey.gait_hz": (0.0, 10.0),
    "survey.gait_pitch_deg": (0.0, 30.0),
    "legs.walk_s": (0.1, 36000.0),
    "legs.turn_deg": (-360.0, 360.0),
    "legs.slope_deg": (-45.0, 45.0),
    "legs.stop_s": (0.5, 3600.0),
    "wild.prob": (0.0, 0.1),
    "wild.gyro_deg_per_s": (0.0, 1e4),
    "wild.accel_g": (0.0, 100.0),
    "known_points.known_coordinate_sigma_m": (1e-5, 100.0),
    "known_points.known_position_sigma_m": (1e-5, 100.0),
    "known_points.levelling_sigma_m": (1e-5, 100.0),
    "imu.gyro.bias_deg_per_h": (0.0, 1e5),
    "imu.gyro.markov_deg_per_h": (0.0, 1e5),
    "imu.gyro.markov_tau_s": (0.1, 1e7),
    "imu.gyro.arw_deg_per_sqrt_h": (0.0, 30.0),
    "imu.gyro.scale_factor_ppm": (0.0, 1e5),
    "imu.gyro.saturation_deg_per_s": (1.0, 1e5),
    "imu.gyro.bandwidth_hz": (0.1, 1e4),
    "imu.accel.bias_mg": (0.0, 1000.0),
    "imu.accel.markov_mg": (0.0, 1000.0),
    "imu.accel.markov_tau_s": (0.1, 1e7),
    "imu.accel.vrw_ug_per_sqrt_hz": (0.0, 1e5),
    "imu.accel.scale_factor_ppm": (0.0, 1e5),
    "imu.accel.saturation_g": (0.5, 1000.0),
    "imu.accel.bandwidth_hz": (0.1, 1e4),
    "imu.initial_errors.attitude_arcsec": (0.0, 3.6e5),
    "imu.initial_errors.velocity_mps": (0.0, 100.0),
    "imu.initial_errors.position_m": (0.0, 1e4),
    "pipeline.meas_rate_hz": (0.01, 1000.0),
    "pipeline.margin_s": (0.0, 60.0),
    "pipeline.zupt_sigma_mps": (1e-5, 10.0),
    "pipeline.outlier_k": (1.0, 100.0),
    "pipeline.lowpass_hz": (0.1, 1e4),
    "pipeline.velocity_sigma0_mps": (1e-5, 100.0),
    "pipeline.position_sigma0_m": (1e-5, 1e4),
}


def _plausible(t: ConfigTable, key, generic: str):
    """``key`` of table ``t`` (a number or a list of numbers, config units) inside ``RANGES[generic]``."""
    if generic in RANGES:
        t.check_plausible(key, t.data[key], RANGES[generic])


def _check_ranges(doc: ConfigTable):
    """Every numeric key of a cadastral TOML inside :data:`RANGES` (before any conversion)."""
    for sec in ("survey", "wild", "known_points", "pipeline"):
        t = doc.table(sec) or ConfigTable({}, sec, error=ScenarioError)
        if sec == "pipeline":
            t.expect(q.split(".", 1)[1] for q in RANGES if q.startswith("pipeline."))
        for k in t.data:
            _plausible(t, k, f"{sec}.{k}")
    for leg in doc.tables("legs"):
        for k in leg.data:
            _plausible(leg, k, f"legs.{k}")
    imu = doc.table("imu")
    for g in imu.data if imu is not None else ():
        gt = imu.table(g)
        for sec in gt.data:
            t = gt.table(sec)
            for k in t.data:
                _plausible(t, k, f"imu.{sec}.{k}")


def _number(t: ConfigTable, key, factor=1.0):
    """A finite number ``key`` of ``t``, or each of a list of them, times ``factor``."""
    v = t.data[key]
    t.used.add(key)
    if isinstance(v, list):
        t.get(key, "numbers")
        return tuple(float(a) * factor for a in v)
    return t.get(key, float) * factor


def cadastral_from_dict(d: dict) -> tuple[dict, dict]:
    """Build the scenarios (one per IMU grade) and the pipeline settings from a TOML dict.

    Returns:
      (dict grade name -> :class:`CadastralScenario`, dict of [pipeline] settings (edge units)).
    Raises:
      ScenarioError: naming the offending field.
    """
    doc = ConfigTable(d, error=ScenarioError)
    doc.expect(("name", "description", "survey", "legs", "imu", "wild", "known_points", "pipeline"))
    sv = doc.table("survey", required=True)
    _check_ranges(doc)
    kw = {}
    sv.expect([*_SURVEY_ATTR, "first_name"])
    for k in sv.data:
        if k == "first_name":
            kw["first_name"] = str(sv.data[k])
        else:
            kw[_SURVEY_ATTR[k]] = sv.get(k, float) * dict(_SURVEY)[k]
    for req in ("lat", "lon", "h"):
        if req not in kw:
            sv.fail([k for k, a in _SURVEY_ATTR.items() if a == req][0], "is required")
    kw.setdefault("heading", 0.0)
    legs = []
    for lt in doc.tables("legs"):
        lt.expect(_LEG)
        lk = {}
        for k in lt.data:
            attr, fac = _LEG[k]
            lk[attr] = str(lt.data[k]) if fac is None else lt.get(k, float) * fac
        for req in ("walk", "kind", "stop"):
            if req not in lk:
                lt.fail([k for k, a in _LEG.items() if a[0] == req][0], "is required")
        legs.append(Leg(**lk))
    kw["legs"] = tuple(legs)
    for sec, table in (("wild", _WILD), ("known_points", _KNOWN)):
        t = doc.table(sec) or ConfigTable({}, sec, error=ScenarioError)
        t.expect(table)
        for k in t.data:
            attr, fac = table[k]
            if attr == "sigma_known":
                v = _number(t, k)
                kw[attr] = v if isinstance(v, tuple) else (v,) * 3
            else:
                kw[attr] = t.get(k, float) * fac
    imu = doc.table("imu")
    if imu is None or not imu.data:
        raise ScenarioError("[imu.<grade>] sections are required (e.g. [imu.tactical.gyro])")
    out = {}
    for gname in imu.data:
        gt = imu.table(gname)
        gt.expect(("gyro", "accel", "initial_errors"))
        g = _read(gt.table("gyro") or ConfigTable({}, f"imu.{gname}.gyro", error=ScenarioError), _GYRO)
        a = _read(gt.table("accel") or ConfigTable({}, f"imu.{gname}.accel", error=ScenarioError), _ACCEL)
        ie = _read(
            gt.table("initial_errors") or ConfigTable({}, f"imu.{gname}.initial_errors", error=ScenarioError), _INIT
        )
        noise, limits = _imu_records({**g, **a})
        grade = ImuGrade(name=gname, noise=noise, limits=limits, initial_errors=InitialErrorConfig(**ie))
        out[gname] = CadastralScenario(grade=grade, **kw)
    for scn in list(out.values())[:1]:  # the route is the grades' common one: expand it once, here, so that a
        c = scn.scenario_config()  # route the IMU rate cannot sample is refused with the file, not mid-run
        try:
            segment_table(c.trajectory, 1.0 / c.imu_rate_hz, c.duration)
        except ScenarioError as e:
            raise ScenarioError(
                f"survey and legs: the route they describe is not valid at imu_rate_hz = "
                f"{c.imu_rate_hz:g}: {e} (lengthen accel_s, turn_s or pitch_s, or raise "
                f"imu_rate_hz)"
            ) from None
    return out, dict(d.get("pipeline", {}))


def load_cadastral(path: str | os.PathLike | None = None) -> tuple[dict, dict]:
    """Read a cadastral TOML (default: the shipped ``scenarios/cadastral.toml``); see :func:`cadastral_from_dict`."""
    try:
        if path is None:
            src = "cadastral.toml"
            d = loads_toml(
                importlib.resources.files("jaxnav.sim")
                .joinpath("scenarios/cadastral.toml")
                .read_text(encoding="utf-8"),
                source=src,
            )
        else:
            src = os.fspath(path)
            d = load_toml(path)
    except ValueError as e:
        raise ScenarioError(str(e)) from None
    try:
        return cadastral_from_dict(d)
    except ScenarioError as e:
        raise ScenarioError(f"{src}: {e}") from None


def short_survey(scn: CadastralScenario, n_legs: int = 4) -> CadastralScenario:
    """The first ``n_legs`` legs of a scenario, with the last stop turned into a known-coordinate point.

    Raises:
      ValueError: ``n_legs`` < 1, or the shortened survey would have no target point left to
        score (naming the smallest ``n_legs`` that keeps one).
    """
    import dataclasses

    if n_legs < 1:
        raise ValueError(f"n_legs must be >= 1, got {n_legs}")
    kinds = [leg.kind for leg in scn.legs]
    if "target" not in kinds[: n_legs - 1]:
        first = next((i for i, k in enumerate(kinds[:-1]) if k == "target"), None)
        need = "no number of legs keeps one" if first is None else f"use at least {first + 2} legs"
        raise ValueError(
            f"the first {n_legs} leg(s) end at no target point once the last stop becomes a known "
            f"point, so there is nothing to score; {need} (the survey has {len(kinds)})"
        )
    legs = list(scn.legs[:n_legs])
    legs[-1] = dataclasses.replace(legs[-1], kind="known_coordinate")
    return dataclasses.replace(scn, legs=tuple(legs))


@functools.lru_cache(maxsize=1)
def cadastral_scenarios():
    """The shipped scenarios (dict grade -> :class:`CadastralScenario`) and pipeline settings."""
    return load_cadastral(None)


class CalibrationRecord(NamedTuple):
    """A static IMU error record (the ideal output is constant, so only the errors vary).

    Attributes:
      gyro, accel: (N, 3) measured rate (rad/s) and specific-force (m/s^2) errors, wild values included.
      gyro_coloured, accel_coloured: (N, 3) bias + Gauss-Markov part (no white noise, no wild values).
      n_wild: wild values injected.
    """

    gyro: jax.Array
    accel: jax.Array
    gyro_coloured: jax.Array
    accel_coloured: jax.Array
    n_wild: jax.Array


@functools.partial(jax.jit, static_argnames=("scn", "n"))
def calibration_record(scn: CadastralScenario, key, n: int) -> CalibrationRecord:
    """Simulate n samples of the grade's sensor errors at rest (for S3 step-1 identification).

    Uses :func:`jaxnav.sim.draw_sensor_errors` on a zero ideal signal, plus the scenario's wild values.
    """
    from jaxnav.sim._imu import apply_sensor_errors, draw_sensor_errors

    dt = scn.dt
    kg, ka, kw = jax.random.split(key, 3)
    z = jnp.zeros((n, 3))
    out = []
    for k, sensor in ((kg, "gyro"), (ka, "accel")):
        d = draw_sensor_errors(k, scn.grade.noise, sensor, n, dt)
        meas = apply_sensor_errors(z, dt, d, sensor, scn.grade.limits) / dt
        col = d.bias + (d.markov if d.markov is not None else 0.0)
        out.append((meas, jnp.broadcast_to(col, (n, 3))))
    k1, k2, k3, k4 = jax.random.split(kw, 4)
    hit_g = jax.random.bernoulli(k1, scn.wild_prob, (n, 3))
    hit_a = jax.random.bernoulli(k3, scn.wild_prob, (n, 3))
    sg = jnp.where(jax.random.bernoulli(k2, 0.5, (n, 3)), 1.0, -1.0)
    sa = jnp.where(jax.random.bernoulli(k4, 0.5, (n, 3)), 1.0, -1.0)
    return CalibrationRecord(
        gyro=out[0][0] + jnp.where(hit_g, sg * scn.wild_gyro, 0.0),
        accel=out[1][0] + jnp.where(hit_a, sa * scn.wild_accel, 0.0),
        gyro_coloured=out[0][1],
        accel_coloured=out[1][1],
        n_wild=jnp.sum(hit_g) + jnp.sum(hit_a),
    )
