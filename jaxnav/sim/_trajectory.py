"""Piecewise-analytic vehicle trajectories and their ideal (error-free) strapdown IMU output.

A trajectory is a start state plus a list of :class:`Segment`. Inside a segment the Euler-angle
rates, the along-track acceleration and a nav-frame "pulse" acceleration are constant, so the
attitude angles, the along-track speed and the pulse velocity are linear in time (closed form):

    [pitch, roll, yaw](t) = start + rate * (t - t_seg)        C_bn(t) = Rz(yaw) Rx(pitch) Ry(roll)
    speed(t) = speed_seg + a_track (t - t_seg)                v_pulse(t) = v_pulse_seg + a_pulse (t - t_seg)
    v_n(t) = speed(t) * C_bn(t) e_y + v_pulse(t)              (e_y = body forward axis)

The pulse velocity models the *sudden* east/north/up velocity changes of S0: a constant ENU
acceleration dV/duration that is not along the body axis (the vehicle side-slips / crabs while
it lasts; a later opposite step removes it). Position integrates d pos/dt = position_rate(pos,
v_n(t)) with classical RK4 (optionally several sub-steps per IMU interval).

The ideal IMU output is the inverse mechanization (ENU, right-forward-up body):

    w_ib^b = w_nb^b + C_bn^T w_in^n(pos, v_n)
    f^b    = C_bn^T [dv_n/dt + (2 w_ie^n + w_en^n) x v_n - g^n(lat, h)]

with w_nb^b in closed form from the Euler rates. The increments dtheta_k = int w_ib^b dt and
dv_k = int f^b dt over each IMU interval are body-frame integrals (what a real IMU outputs),
evaluated by 3-point Gauss-Legendre quadrature (degree 5 exact; the integrands are smooth inside
an interval because every segment boundary falls on a sample time). Positions at the quadrature
nodes are the cubic Hermite interpolant of the RK4 solution (positions and position rates at the
two ends of the interval; error O(dt^4) ~ 1e-14 m here).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxnav.geodesy import WGS84, Ellipsoid
from jaxnav.ins.attitude import euler_to_dcm, euler_to_quat
from jaxnav.ins.earth import earth_params, gravity_minus_coriolis, position_rate


class ScenarioError(ValueError):
    """A scenario/config value is invalid; the message names the field (dotted path)."""


# ------------------------------------------------------------------------------------------
# configuration

SEGMENT_KINDS = {
    # kind: change fields it may set (hold and label are allowed for every kind)
    "cruise": (),
    "rest": (),
    "accelerate": ("dspeed",),
    "turn": ("dheading",),
    "pitch": ("dpitch",),
    "climb": ("dpitch",),
    "roll": ("droll",),
    "velocity_step": ("dv_enu", "sensed"),
    "general": ("dspeed", "dheading", "dpitch", "droll", "dv_enu", "sensed"),
}


def _vec3(x, name, *, nonneg=False, positive=False):
    """Scalar or length-3 sequence -> tuple of 3 floats (validated)."""
    if isinstance(x, (bool, np.bool_)) or isinstance(x, str):
        raise ScenarioError(f"{name} must be a number or a list of 3 numbers, got {x!r}")
    if np.ndim(x) == 0:
        v = (float(x),) * 3
    else:
        arr = np.asarray(x, dtype=object).ravel()
        if arr.size != 3:
            raise ScenarioError(f"{name} must be a number or a list of 3 numbers, got {x!r}")
        try:
            v = tuple(float(a) for a in arr)
        except (TypeError, ValueError):
            raise ScenarioError(f"{name} must be a number or a list of 3 numbers, got {x!r}") from None
    if any(math.isnan(a) for a in v):
        raise ScenarioError(f"{name} contains NaN: {x!r}")
    if nonneg and any(a < 0 for a in v):
        raise ScenarioError(f"{name} must be >= 0, got {x!r}")
    if positive and any(not a > 0 for a in v):
        raise ScenarioError(f"{name} must be > 0, got {x!r}")
    return v


def _num(x, name, *, nonneg=False, positive=False, finite=True):
    if isinstance(x, (bool, np.bool_)) or not isinstance(x, (int, float, np.integer, np.floating)):
        raise ScenarioError(f"{name} must be a number, got {x!r}")
    v = float(x)
    if math.isnan(v) or (finite and math.isinf(v)):
        raise ScenarioError(f"{name} must be finite, got {x!r}")
    if nonneg and v < 0:
        raise ScenarioError(f"{name} must be >= 0, got {x!r}")
    if positive and not v > 0:
        raise ScenarioError(f"{name} must be > 0, got {x!r}")
    return v


@dataclass(frozen=True)
class Segment:
    """One trajectory segment (SI units; angles in rad).

    The change fields are spread uniformly over ``duration`` (constant rates), then the state
    is held for ``hold`` seconds. Durations are rounded to whole IMU intervals; the rates are
    computed from the rounded duration, so the total changes are exact.

    Attributes:
      kind: one of :data:`SEGMENT_KINDS` ("cruise", "rest", "accelerate", "turn", "pitch",
        "climb" (= "pitch", usually with a ``hold``), "roll", "velocity_step", "general").
      duration: s, time over which the change is applied.
      dspeed: m/s, along-track speed change (accelerate / decelerate).
      dheading: rad, heading change, clockwise from north positive (turn right).
      dpitch: rad, pitch change (nose up positive).  droll: rad, roll change (right wing down).
      dv_enu: (3,) m/s, sudden ENU velocity change applied as a constant nav-frame acceleration
        dv_enu / duration that is *not* along the body axis (the pulse velocity persists until an
        opposite step removes it).
      sensed: whether the IMU senses the pulse acceleration. ``False`` removes it from the
        *measured* accelerometer output (the ideal IMU stays exact): an explicit, configurable
        model mismatch — the INS then misses the velocity change that GNSS and truth contain.
      hold: s, time the reached state is held afterwards (a cruise appended to the segment).
      label: free text.
    """

    kind: str = "cruise"
    duration: float = 0.0
    dspeed: float = 0.0
    dheading: float = 0.0
    dpitch: float = 0.0
    droll: float = 0.0
    dv_enu: tuple = (0.0, 0.0, 0.0)
    sensed: bool = True
    hold: float = 0.0
    label: str = ""

    def __post_init__(self):
        if self.kind not in SEGMENT_KINDS:
            raise ScenarioError(f"segment kind must be one of {sorted(SEGMENT_KINDS)}, got {self.kind!r}")
        object.__setattr__(self, "duration", _num(self.duration, "segment.duration", nonneg=True))
        object.__setattr__(self, "hold", _num(self.hold, "segment.hold", nonneg=True))
        for f in ("dspeed", "dheading", "dpitch", "droll"):
            object.__setattr__(self, f, _num(getattr(self, f), f"segment.{f}"))
        object.__setattr__(self, "dv_enu", _vec3(self.dv_enu, "segment.dv_enu"))
        if not isinstance(self.sensed, (bool, np.bool_)):
            raise ScenarioError(f"segment.sensed must be true or false, got {self.sensed!r}")
        allowed = SEGMENT_KINDS[self.kind]
        for f in ("dspeed", "dheading", "dpitch", "droll"):
            if getattr(self, f) != 0.0 and f not in allowed:
                raise ScenarioError(f"segment.{f} is not allowed for kind {self.kind!r} (allowed: {allowed})")
        if any(self.dv_enu) and "dv_enu" not in allowed:
            raise ScenarioError(f"segment.dv_enu is not allowed for kind {self.kind!r} (allowed: {allowed})")
        if not self.sensed and "sensed" not in allowed:
            raise ScenarioError(
                f"segment.sensed is only meaningful for 'velocity_step' and 'general' (kind {self.kind!r})"
            )


@dataclass(frozen=True)
class TrajectorySpec:
    """Start state and segments of a trajectory (SI; angles rad).

    Attributes:
      lat, lon: rad.  h: ellipsoidal height, m.
      heading: rad, clockwise from north (yaw = -heading).  pitch, roll: rad.
      speed: m/s along the body forward axis.
      segments: tuple of :class:`Segment`.
    """

    lat: float
    lon: float
    h: float
    heading: float = 0.0
    pitch: float = 0.0
    roll: float = 0.0
    speed: float = 0.0
    segments: tuple = ()

    def __post_init__(self):
        for f in ("lat", "lon", "h", "heading", "pitch", "roll"):
            object.__setattr__(self, f, _num(getattr(self, f), f"trajectory.{f}"))
        object.__setattr__(self, "speed", _num(self.speed, "trajectory.speed", nonneg=True))
        if abs(self.lat) >= math.radians(89.0):
            raise ScenarioError(f"trajectory.lat must be within +-89 deg, got {math.degrees(self.lat)} deg")
        segs = tuple(self.segments)
        for i, s in enumerate(segs):
            if not isinstance(s, Segment):
                raise ScenarioError(f"trajectory.segments[{i}] must be a Segment, got {type(s).__name__}")
        object.__setattr__(self, "segments", segs)


# ------------------------------------------------------------------------------------------
# host-side segment table

_MAX_PITCH = math.radians(85.0)


class SegmentTable(NamedTuple):
    """Primitive constant-rate pieces (host numpy), one row per piece.

    start/rate columns: [pitch, roll, yaw, speed, vpulse_E, vpulse_N, vpulse_U] (rad, m/s) and
    their time derivatives. k0/n: first interval index and number of intervals. sensed: bool.
    source: index of the config segment (-1 for the fill-up cruise).
    """

    k0: np.ndarray
    n: np.ndarray
    start: np.ndarray
    rate: np.ndarray
    sensed: np.ndarray
    source: np.ndarray
    n_total: int


def _n_intervals(T, dt, name):
    n = int(round(T / dt))
    if T > 0 and n == 0:
        raise ScenarioError(f"{name} = {T} s is shorter than half an IMU interval ({dt} s)")
    return n


def segment_table(spec: TrajectorySpec, dt: float, duration: float | None = None) -> SegmentTable:
    """Expand the segments into constant-rate pieces on the IMU sample grid (host side).

    Raises :class:`ScenarioError` (naming the segment) when a segment drives the speed negative,
    the pitch beyond +-85 deg, a "rest" segment starts while moving, or the segments last longer
    than ``duration``. Shorter segment lists are filled up with a cruise to ``duration``.
    """
    state = np.array([spec.pitch, spec.roll, -spec.heading, spec.speed, 0.0, 0.0, 0.0])
    rows = []
    k = 0

    def add(n, delta, sensed, src):
        nonlocal state, k
        if n == 0:
            return
        rate = np.asarray(delta, float) / (n * dt)
        rows.append((k, n, state.copy(), rate, sensed, src))
        state = state + np.asarray(delta, float)
        k += n

    for i, s in enumerate(spec.segments):
        name = f"segments[{i}] ({s.kind}{', ' + s.label if s.label else ''})"
        if s.kind == "rest" and (abs(state[3]) > 1e-9 or np.any(np.abs(state[4:]) > 1e-9)):
            raise ScenarioError(
                f"{name}: 'rest' needs the vehicle stopped, but speed is {state[3]} m/s "
                f"and pulse velocity {state[4:]} m/s"
            )
        n = _n_intervals(s.duration, dt, f"{name}.duration")
        delta = np.array([s.dpitch, s.droll, -s.dheading, s.dspeed, *s.dv_enu])
        if n == 0 and np.any(delta != 0):
            raise ScenarioError(f"{name}.duration is 0 but the segment changes the state")
        add(n, delta, bool(s.sensed), i)
        if state[3] < -1e-9:
            raise ScenarioError(f"{name}: speed becomes negative ({state[3]} m/s); reduce dspeed")
        if abs(state[0]) > _MAX_PITCH:
            raise ScenarioError(f"{name}: pitch reaches {math.degrees(state[0])} deg (limit +-85 deg)")
        add(_n_intervals(s.hold, dt, f"{name}.hold"), np.zeros(7), True, i)
    if duration is not None:
        N = _n_intervals(duration, dt, "duration")
        if k > N:
            raise ScenarioError(f"the segments last {k * dt} s, longer than duration = {duration} s")
        add(N - k, np.zeros(7), True, -1)
    if k == 0:
        raise ScenarioError("the trajectory is empty: give segments or a duration")
    cols = list(zip(*rows))
    return SegmentTable(
        k0=np.array(cols[0], np.int64),
        n=np.array(cols[1], np.int64),
        start=np.stack(cols[2]),
        rate=np.stack(cols[3]),
        sensed=np.array(cols[4], bool),
        source=np.array(cols[5], np.int64),
        n_total=k,
    )


# ------------------------------------------------------------------------------------------
# closed-form kinematics


class Kinematics(NamedTuple):
    """Closed-form kinematic quantities at given times (all (..., k))."""

    euler: jax.Array  # (..., 3) [pitch, roll, yaw], rad
    v_n: jax.Array  # (..., 3) ENU velocity, m/s
    a_n: jax.Array  # (..., 3) dv_n/dt, m/s^2
    w_nb_b: jax.Array  # (..., 3) body rate relative to n, in b, rad/s
    a_pulse: jax.Array  # (..., 3) nav-frame pulse acceleration, m/s^2


def kinematics(start, rate, tau) -> Kinematics:
    """Evaluate a constant-rate piece at local times ``tau`` (s since the piece's start).

    Args:
      start, rate: (..., 7) piece start values and rates (see :class:`SegmentTable`).
      tau: (...) local time, s.
    Notes:
      With C_bn = Rz(y) Rx(p) Ry(r), the body rate is
      w_nb^b = Ry(r)^T (Rx(p)^T [0, 0, y'] + [p', 0, 0]) + [0, r', 0]
             = [cr p' - sr cp y',  r' + sp y',  sr p' + cr cp y'],
      and the forward axis C_bn e_y = [-sy cp, cy cp, sp] does not depend on roll.
    """
    x = start + rate * tau[..., None]
    p, r, y, s = x[..., 0], x[..., 1], x[..., 2], x[..., 3]
    pd, rd, yd, acc = rate[..., 0], rate[..., 1], rate[..., 2], rate[..., 3]
    sp, cp, sr, cr, sy, cy = jnp.sin(p), jnp.cos(p), jnp.sin(r), jnp.cos(r), jnp.sin(y), jnp.cos(y)
    fwd = jnp.stack([-sy * cp, cy * cp, sp], -1)
    dfwd = jnp.stack([-cy * cp * yd + sy * sp * pd, -sy * cp * yd - cy * sp * pd, cp * pd], -1)
    a_pulse = rate[..., 4:7]
    v = s[..., None] * fwd + x[..., 4:7]
    a = acc[..., None] * fwd + s[..., None] * dfwd + a_pulse
    w = jnp.stack([cr * pd - sr * cp * yd, rd + sp * yd, sr * pd + cr * cp * yd], -1)
    return Kinematics(euler=x[..., :3], v_n=v, a_n=a, w_nb_b=w, a_pulse=a_pulse)


# ------------------------------------------------------------------------------------------
# trajectory + ideal IMU


class Trajectory(NamedTuple):
    """True trajectory at the IMU rate and the ideal IMU increments.

    Attributes:
      t: (N+1,) sample times, s (t[0] = 0).  dt: () IMU interval, s.
      euler: (N+1, 3) [pitch, roll, yaw], rad (yaw unwrapped; heading = -yaw).
      q_bn: (N+1, 4) body -> nav quaternion, scalar first.
      v_n: (N+1, 3) ENU velocity, m/s.  pos: (N+1, 3) [lat rad, lon rad, h m].
      a_n: (N+1, 3) dv_n/dt, m/s^2 (right limit at a segment start; left limit at the end).
      dtheta: (N, 3) ideal angular increments int w_ib^b dt over (t_k, t_k+1], rad.
      dv: (N, 3) ideal velocity increments int f^b dt, m/s.
      dv_unsensed: (N, 3) part of ``dv`` from pulse accelerations the IMU does not sense
        (segments with ``sensed=False``), m/s; ``None`` when every segment is sensed.
      segment: (N,) int32 index of the config segment each interval belongs to (-1: fill-up).
    """

    t: jax.Array
    dt: jax.Array
    euler: jax.Array
    q_bn: jax.Array
    v_n: jax.Array
    pos: jax.Array
    a_n: jax.Array
    dtheta: jax.Array
    dv: jax.Array
    dv_unsensed: jax.Array | None
    segment: jax.Array


_GL_C = (0.5 - math.sqrt(15.0) / 10.0, 0.5, 0.5 + math.sqrt(15.0) / 10.0)
_GL_W = (5.0 / 18.0, 8.0 / 18.0, 5.0 / 18.0)


def _build(start, rate, piece, local, pos0, dt, unsensed_mask, *, substeps, ellipsoid, with_unsensed):
    """Jitted core; see :func:`generate_trajectory`. piece/local: (N,) int arrays."""
    N = piece.shape[0]
    st, rt = start[piece], rate[piece]  # (N, 7)
    tau0 = local.astype(dt.dtype) * dt  # local time at the interval start
    # velocities for RK4: 2*substeps + 1 equally spaced points per interval
    m = substeps
    fr = jnp.arange(2 * m + 1, dtype=dt.dtype) / (2 * m)
    v_rk = kinematics(st[:, None, :], rt[:, None, :], tau0[:, None] + fr[None, :] * dt).v_n  # (N, 2m+1, 3)

    def step(p, vs):
        h = dt / m
        for j in range(m):
            v0, vm, v1 = vs[2 * j], vs[2 * j + 1], vs[2 * j + 2]
            k1 = position_rate(p, v0, ellipsoid)
            k2 = position_rate(p + 0.5 * h * k1, vm, ellipsoid)
            k3 = position_rate(p + 0.5 * h * k2, vm, ellipsoid)
            k4 = position_rate(p + h * k3, v1, ellipsoid)
            p = p + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        return p, p

    _, pos_next = jax.lax.scan(step, pos0, v_rk)
    pos = jnp.concatenate([pos0[None], pos_next], 0)  # (N+1, 3)

    # sample-time kinematics: interval k's piece at its start; the last sample at the end of the last interval
    idx = jnp.concatenate([jnp.arange(N), jnp.array([N - 1])])
    tau_s = jnp.concatenate([tau0, tau0[-1:] + dt])
    ks = kinematics(start[piece[idx]], rate[piece[idx]], tau_s)
    q_bn = euler_to_quat(ks.euler)
    prate = position_rate(pos, ks.v_n, ellipsoid)  # (N+1, 3)

    # Gauss-Legendre quadrature of w_ib^b and f^b, in chunks of intervals (bounded temporaries)
    c = jnp.asarray(_GL_C, dt.dtype)
    w = jnp.asarray(_GL_W, dt.dtype)
    s = c[:, None]
    h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
    h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2

    def increments(x):
        st_, rt_, t0_, p0, p1, m0, m1, mask = x
        kn = kinematics(st_[None, :], rt_[None, :], t0_ + c * dt)  # (3 nodes, .)
        # cubic Hermite position at the nodes from the RK4 solution
        pos_nodes = h00 * p0 + h10 * dt * m0 + h01 * p1 + h11 * dt * m1
        e = earth_params(pos_nodes, kn.v_n, ellipsoid)
        CT = jnp.swapaxes(euler_to_dcm(kn.euler), -1, -2)
        w_ib = kn.w_nb_b + jnp.sum(CT * e.w_in_n[:, None, :], -1)
        f_n = kn.a_n - gravity_minus_coriolis(e, kn.v_n)  # v_dot = f_n + g - (2 w_ie + w_en) x v
        f_b = jnp.sum(CT * f_n[:, None, :], -1)
        out = (dt * (w @ w_ib), dt * (w @ f_b))
        if with_unsensed:
            out = out + (dt * (w @ jnp.sum(CT * kn.a_pulse[:, None, :], -1)) * mask,)
        return out

    xs = (st, rt, tau0, pos[:-1], pos[1:], prate[:-1], prate[1:], unsensed_mask)
    res = jax.lax.map(increments, xs, batch_size=min(N, 8192))
    dtheta, dv = res[0], res[1]
    dv_uns = res[2] if with_unsensed else None
    return ks.euler, q_bn, ks.v_n, pos, ks.a_n, dtheta, dv, dv_uns


_build_jit = jax.jit(_build, static_argnames=("substeps", "ellipsoid", "with_unsensed"))
_BUILDS: dict = {}


def _compiled_build(args, statics):
    """The compiled :func:`_build` for these argument shapes and static options (cached).

    Called on concrete arrays, a compiled executable runs eagerly even inside an outer ``jit`` or
    ``vmap``, so the trajectory is a constant of the caller's program; tracing ``_build`` under
    ``jax.ensure_compile_time_eval`` instead would evaluate each of its constant expressions
    op by op, every one a compile of its own.
    """
    key = (tuple((a.shape, a.dtype.str) for a in args), statics)
    if key not in _BUILDS:
        substeps, ellipsoid, with_uns = statics
        _BUILDS[key] = _build_jit.lower(*args, substeps=substeps, ellipsoid=ellipsoid, with_unsensed=with_uns).compile()
    return _BUILDS[key]


def generate_trajectory(
    spec: TrajectorySpec,
    *,
    imu_rate_hz: float,
    duration: float | None = None,
    rk4_substeps: int = 1,
    ellipsoid: Ellipsoid = WGS84,
) -> Trajectory:
    """Build the true trajectory and the ideal IMU increments (jitted; no Python loop over time).

    Args:
      spec: :class:`TrajectorySpec`.
      imu_rate_hz: IMU sample rate, Hz (dt = 1 / rate).
      duration: total time, s; a shorter segment list is filled up with a cruise (None: the sum
        of the segments).
      rk4_substeps: RK4 steps per IMU interval for the position (1 is exact to float64 at 100 Hz).
      ellipsoid: Earth model.
    Returns:
      :class:`Trajectory` (float64; requires :func:`jaxnav.enable_x64`).
    """
    if not jax.config.read("jax_enable_x64"):
        raise ScenarioError("the trajectory simulator needs float64: call jaxnav.enable_x64() first")
    rate_hz = _num(imu_rate_hz, "imu_rate_hz", positive=True)
    dt = 1.0 / rate_hz
    if int(rk4_substeps) < 1:
        raise ScenarioError(f"rk4_substeps must be >= 1, got {rk4_substeps!r}")
    tab = segment_table(spec, dt, duration)
    piece = np.repeat(np.arange(len(tab.n)), tab.n)
    local = np.arange(tab.n_total) - tab.k0[piece]
    unsensed = (~tab.sensed) & np.any(tab.rate[:, 4:7] != 0, axis=1)
    with_uns = bool(unsensed.any())
    mask = unsensed[piece].astype(np.float64)
    args = (
        np.asarray(tab.start, np.float64),
        np.asarray(tab.rate, np.float64),
        np.asarray(piece, np.int32),
        np.asarray(local, np.int32),
        np.asarray([spec.lat, spec.lon, spec.h], np.float64),
        np.asarray(dt, np.float64),
        np.asarray(mask, np.float64),
    )
    statics = (int(rk4_substeps), ellipsoid, with_uns)
    euler, q_bn, v_n, pos, a_n, dtheta, dv, dv_uns = _compiled_build(args, statics)(*args)
    with jax.ensure_compile_time_eval():
        t = jnp.arange(tab.n_total + 1, dtype=jnp.float64) * dt
        seg = jnp.asarray(tab.source[piece], jnp.int32)
    return Trajectory(
        t=t,
        dt=jnp.asarray(dt, jnp.float64),
        euler=euler,
        q_bn=q_bn,
        v_n=v_n,
        pos=pos,
        a_n=a_n,
        dtheta=dtheta,
        dv=dv,
        dv_unsensed=dv_uns,
        segment=seg,
    )
