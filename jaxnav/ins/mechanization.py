"""Strapdown mechanization in the ENU frame, forward and reverse (S3 class 2 steps 1-11, class 3).

One pure step integrates one IMU sample (angular increment dtheta, velocity increment dv over
dt) with one-previous-sample (two-sample) coning and sculling corrections, a velocity update
with Coriolis and gravity at the mid-interval, a trapezoidal position update and a quaternion
attitude update; :func:`mechanize` scans it over the samples. :func:`mechanize_backward` runs
the same step backwards in time exactly as S3 class 3 prescribes.
"""

from __future__ import annotations

from functools import partial
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxnav import _status
from jaxnav.geodesy import WGS84, Ellipsoid, check_float64
from jaxnav.ins.attitude import quat_mul, quat_normalize, quat_rotate, rv_to_quat
from jaxnav.ins.earth import earth_params, position_rate


class NavState(NamedTuple):
    """Navigation state.

    Attributes:
      q_bn: (4,) attitude quaternion body -> nav (scalar first).
      v_n: (3,) ENU velocity, m/s.
      pos: (3,) [latitude rad, longitude rad, ellipsoidal height m].
    """

    q_bn: Any
    v_n: Any
    pos: Any


class MechState(NamedTuple):
    """Scan carry: the navigation state plus what the two-sample algorithms remember."""

    nav: NavState
    dtheta_prev: Any  # (3,) previous angular increment, rad
    dv_prev: Any  # (3,) previous velocity increment, m/s
    a_prev: Any  # (3,) previous mean nav acceleration, m/s^2 (mid-interval extrapolation)
    status: Any  # int32 flags


class ImuSample(NamedTuple):
    """One IMU sample: increments over the interval ending at the sample time."""

    dtheta: Any  # (3,) angular increment in b, rad
    dv: Any  # (3,) velocity increment (integrated specific force) in b, m/s
    dt: Any  # scalar interval, s


class MechParams(NamedTuple):
    """Array parameters of the step (static choices are arguments of :func:`mech_step`)."""

    earth_rate_sign: Any = 1.0  # -1 for reverse navigation (S3 class 3)


def mech_step(state: MechState, imu: ImuSample, params: MechParams = MechParams(), *,
              ellipsoid: Ellipsoid = WGS84, coning: bool = True, hold_height: bool = False):
    """Integrate one IMU sample (S3 class 2 steps 1-11; two-sample coning/sculling).

    phi = dtheta + 1/12 dtheta_prev x dtheta (coning);
    dv_b = dv + 1/2 dtheta x dv + 1/12 (dtheta_prev x dv + dv_prev x dtheta) (rotation + sculling);
    with v, pos extrapolated to mid-interval and w_in^n, g^n evaluated there:
    v_k = v_{k-1} + rot(-w_in dt/2) C_bn dv_b + [g - (2 w_ie + w_en) x v] dt;
    pos_k = pos_{k-1} + M_pv(mid) (v_{k-1} + v_k)/2 dt;
    q_k = rv2q(-w_in dt) (x) q_{k-1} (x) rv2q(phi).

    Args:
      state: :class:`MechState`.  imu: :class:`ImuSample`.  params: :class:`MechParams`.
      ellipsoid: static Earth model.  coning: static, apply the coning/sculling corrections.
      hold_height: static; keep h fixed and V_U = 0 (perfect height aiding). The free vertical
        channel is unstable (time constant sqrt(R / 2g) ~ 9.5 min), so long unaided runs hold it.
    Returns:
      (new state, new :class:`NavState`).
    """
    nav = state.nav
    dth, dv, dt = imu.dtheta, imu.dv, imu.dt
    if coning:
        phi = dth + jnp.cross(state.dtheta_prev, dth) / 12.0
        dv_b = dv + 0.5 * jnp.cross(dth, dv) + (jnp.cross(state.dtheta_prev, dv) + jnp.cross(state.dv_prev, dth)) / 12.0
    else:
        phi, dv_b = dth, dv + 0.5 * jnp.cross(dth, dv)
    v_mid = nav.v_n + 0.5 * dt * state.a_prev
    pos_mid = nav.pos + 0.5 * dt * position_rate(nav.pos, v_mid, ellipsoid)
    e = earth_params(pos_mid, v_mid, ellipsoid, params.earth_rate_sign)
    dv_n = quat_rotate(rv_to_quat(-0.5 * dt * e.w_in_n), quat_rotate(nav.q_bn, dv_b))
    g_cor = e.g_n - jnp.cross(2.0 * e.w_ie_n + e.w_en_n, v_mid)
    v_new = nav.v_n + dv_n + g_cor * dt
    if hold_height:
        v_new = v_new.at[2].set(0.0)
    pos_new = nav.pos + dt * position_rate(pos_mid, 0.5 * (nav.v_n + v_new), ellipsoid)
    if hold_height:
        pos_new = pos_new.at[2].set(nav.pos[2])
    q_new = quat_normalize(quat_mul(rv_to_quat(-dt * e.w_in_n), quat_mul(nav.q_bn, rv_to_quat(phi))))
    new_nav = NavState(q_bn=q_new, v_n=v_new, pos=pos_new)
    bad_in = ~(jnp.all(jnp.isfinite(dth)) & jnp.all(jnp.isfinite(dv)))
    bad_dt = ~(jnp.isfinite(dt) & (dt > 0))
    flags = (jnp.where(bad_in, _status.NONFINITE_IMU, 0) | jnp.where(bad_dt, _status.BAD_IMU_TIME, 0)).astype(jnp.int32)
    new = MechState(nav=new_nav, dtheta_prev=dth, dv_prev=dv, a_prev=(v_new - nav.v_n) / dt,
                    status=state.status | flags)
    return new, new_nav


class MechResult(NamedTuple):
    """Output of :func:`mechanize`.

    Attributes:
      nav: :class:`NavState` with a leading axis (one row per saved sample, see ``save_every``).
      final: the :class:`MechState` after the last sample (carry it on to continue).
      status: int32 flags (NONFINITE_IMU, BAD_IMU_TIME); see :func:`jaxnav.raise_for_status`.
    """

    nav: NavState
    final: MechState
    status: Any


def _concrete(*xs):
    return not any(isinstance(x, jax.core.Tracer) for x in xs)


def check_imu(dtheta, dv, dt, t=None):
    """Host-side validation of IMU samples; raise ValueError naming the first bad sample.

    Checks shapes ((N, 3), (N, 3), scalar or (N,)), finite values, positive intervals, and —
    when times ``t`` (N,) are given — strictly increasing times without gaps (an interval more
    than 1.5x the median): the mechanization cannot skip samples silently.
    """
    dtheta, dv = np.asarray(dtheta), np.asarray(dv)
    if dtheta.ndim != 2 or dtheta.shape[1] != 3 or dv.shape != dtheta.shape:
        raise ValueError(f"dtheta has shape {dtheta.shape} and dv {dv.shape}; expected (N, 3) each")
    N = dtheta.shape[0]
    dt = np.asarray(dt, dtype=float)
    if dt.shape not in ((), (N,)):
        raise ValueError(f"dt has shape {dt.shape}; expected () or ({N},)")
    for name, a in (("dtheta", dtheta), ("dv", dv)):
        bad = ~np.isfinite(a).all(axis=1)
        if bad.any():
            raise ValueError(f"{name} has a NaN/inf IMU sample at index {int(np.argmax(bad))} "
                             "(mechanization cannot skip samples; fill or cut the gap)")
    dts = np.broadcast_to(dt, (N,))
    if not (np.isfinite(dts).all() and (dts > 0).all()):
        raise ValueError(f"dt must be finite and > 0; bad at index {int(np.argmax(~(np.isfinite(dts) & (dts > 0))))}")
    if t is not None:
        t = np.asarray(t, dtype=float)
        if t.shape != (N,):
            raise ValueError(f"t has shape {t.shape}; expected ({N},)")
        d = np.diff(t)
        if (d <= 0).any():
            i = int(np.argmax(d <= 0))
            raise ValueError(f"IMU time is not increasing at index {i + 1}: t[{i}] = {t[i]!r}, t[{i + 1}] = {t[i + 1]!r}")
        med = np.median(d) if d.size else 0.0
        if d.size and (d > 1.5 * med).any():
            i = int(np.argmax(d > 1.5 * med))
            raise ValueError(f"IMU time has a gap of {d[i]:.6g} s after index {i} (median interval {med:.6g} s)")


@partial(jax.jit, static_argnames=("ellipsoid", "save_every", "coning", "kind", "hold_height"))
def _mechanize(nav0, dtheta, dv, dt, earth_rate_sign, a0, ellipsoid, save_every, coning, kind, hold_height):
    N = dtheta.shape[0]
    dt = jnp.broadcast_to(jnp.asarray(dt, nav0.v_n.dtype), (N,))
    if kind == "rates":
        dtheta, dv = dtheta * dt[:, None], dv * dt[:, None]
    z3 = jnp.zeros(3, nav0.v_n.dtype)
    init = MechState(nav=nav0, dtheta_prev=z3, dv_prev=z3, a_prev=z3 if a0 is None else a0,
                     status=jnp.zeros((), jnp.int32))
    params = MechParams(earth_rate_sign=earth_rate_sign)
    xs = ImuSample(dtheta=dtheta, dv=dv, dt=dt)
    step = partial(mech_step, params=params, ellipsoid=ellipsoid, coning=coning, hold_height=hold_height)
    if save_every == 1:
        final, navs = jax.lax.scan(step, init, xs)
    else:
        xs = jax.tree_util.tree_map(lambda a: a.reshape((N // save_every, save_every) + a.shape[1:]), xs)

        def chunk(c, x):
            c, _ = jax.lax.scan(step, c, x)
            return c, c.nav

        final, navs = jax.lax.scan(chunk, init, xs)
    return MechResult(nav=navs, final=final, status=final.status)


def _prepare(nav0, dtheta, dv, dt, t, save_every, validate):
    dtheta, dv = jnp.asarray(dtheta), jnp.asarray(dv)
    if dtheta.ndim != 2 or dtheta.shape[-1] != 3 or dv.shape != dtheta.shape:
        raise ValueError(f"dtheta has shape {dtheta.shape} and dv {dv.shape}; expected (N, 3) each")
    N = dtheta.shape[0]
    if jnp.shape(dt) not in ((), (N,)):
        raise ValueError(f"dt has shape {jnp.shape(dt)}; expected () or ({N},)")
    for name, a, shp in (("q_bn", nav0.q_bn, (4,)), ("v_n", nav0.v_n, (3,)), ("pos", nav0.pos, (3,))):
        if jnp.shape(a) != shp:
            raise ValueError(f"nav0.{name} has shape {jnp.shape(a)}; expected {shp}")
    if save_every < 1 or N % save_every:
        raise ValueError(f"save_every={save_every} must divide the number of samples N={N}")
    check_float64(nav0.pos, what="nav0.pos (absolute latitude/longitude/height)")
    if validate and _concrete(dtheta, dv, dt, t):
        check_imu(dtheta, dv, dt, t)


def mechanize(nav0: NavState, dtheta, dv, dt, *, t=None, kind: str = "increments", a0=None,
              ellipsoid: Ellipsoid = WGS84, save_every: int = 1, coning: bool = True,
              hold_height: bool = False, validate: bool = True) -> MechResult:
    """Forward strapdown mechanization over N IMU samples (S3 class 2), a ``lax.scan`` of :func:`mech_step`.

    Args:
      nav0: :class:`NavState` at the time of the first sample's start.
      dtheta: (N, 3) angular increments in b, rad (or angular rates, rad/s, with kind="rates").
      dv: (N, 3) velocity increments in b, m/s (or specific force, m/s^2, with kind="rates").
      dt: scalar or (N,) sample intervals, s.
      t: optional (N,) sample times, s, checked for increasing order and gaps.
      kind: static, "increments" or "rates" (rates are multiplied by dt: rectangular integration).
      a0: optional (3,) nav acceleration at the start (for the first mid-interval extrapolation).
      ellipsoid: static Earth model.  save_every: static, keep every k-th state (memory).
      coning: static, two-sample coning/sculling corrections.
      hold_height: static, hold h and V_U = 0 (see :func:`mech_step`).
      validate: check concrete inputs on the host (NaN samples, non-increasing time, gaps).
    Returns:
      :class:`MechResult`; ``nav`` holds the state after each saved sample (times t_1..t_N).
    Raises:
      ValueError: wrong shapes (at trace time), float32 position, or bad concrete samples.
    """
    if kind not in ("increments", "rates"):
        raise ValueError(f"kind must be 'increments' or 'rates', got {kind!r}")
    _prepare(nav0, dtheta, dv, dt, t, save_every, validate)
    return _mechanize(nav0, jnp.asarray(dtheta), jnp.asarray(dv), dt, 1.0, a0, ellipsoid, save_every, coning,
                      kind, hold_height)


def mechanize_backward(nav_end: NavState, dtheta, dv, dt, *, t=None, kind: str = "increments", a0=None,
                       ellipsoid: Ellipsoid = WGS84, save_every: int = 1, coning: bool = True,
                       hold_height: bool = False, validate: bool = True) -> MechResult:
    """Reverse (backward) navigation exactly as S3 class 3.

    Starts from the forward solution's end state with the velocity negated, reads the samples in
    reverse order with the angular increments and the Earth rate negated (velocity increments
    unchanged), and mechanizes forward in that reversed time. In reversed time this is the exact
    time reversal of the navigation equations.

    Args:
      nav_end: :class:`NavState` at the end of the last sample (forward sense of velocity).
      dtheta, dv, dt, t, kind, ellipsoid, save_every, coning, hold_height, validate: as :func:`mechanize`,
        given in forward time order.
      a0: optional (3,) forward-time nav acceleration at the end.
    Returns:
      :class:`MechResult` whose ``nav`` is put back in forward time order with the forward sense
      of velocity: row i is the state at the *start* of sample i (times t_0..t_{N-1}; with
      ``save_every = k``, rows are t_0, t_k, ...). ``final.nav`` is the state at t_0 with the
      velocity still negated (the raw carry of the reversed run).
    """
    if kind not in ("increments", "rates"):
        raise ValueError(f"kind must be 'increments' or 'rates', got {kind!r}")
    _prepare(nav_end, dtheta, dv, dt, t, save_every, validate)
    dth = -jnp.asarray(dtheta)[::-1]
    dvr = jnp.asarray(dv)[::-1]
    dtr = dt if jnp.ndim(dt) == 0 else jnp.asarray(dt)[::-1]
    nav0 = nav_end._replace(v_n=-jnp.asarray(nav_end.v_n))
    res = _mechanize(nav0, dth, dvr, dtr, -1.0, None if a0 is None else jnp.asarray(a0),
                     ellipsoid, save_every, coning, kind, hold_height)
    navs = NavState(q_bn=res.nav.q_bn[::-1], v_n=-res.nav.v_n[::-1], pos=res.nav.pos[::-1])
    return MechResult(nav=navs, final=res.final, status=res.status)
