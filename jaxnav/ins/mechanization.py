"""Strapdown mechanization in the ENU frame, forward and reverse (S3 class 2 steps 1-11, class 3).

One pure step integrates one IMU sample (angular increment dtheta, velocity increment dv over
dt) with one-previous-sample (two-sample) coning and sculling corrections, a velocity update
with Coriolis and gravity at the mid-interval, a trapezoidal position update and a quaternion
attitude update; :func:`mechanize` scans it over the samples. :func:`mechanize_backward` runs
the same step backwards in time exactly as S3 class 3 prescribes.
"""

from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from jaxnav import _status
from jaxnav.geodesy import WGS84, Ellipsoid, check_float64
from jaxnav.ins.attitude import (
    cross_c,
    quat_mul,
    quat_mul_c,
    quat_normalize,
    quat_rotate,
    quat_rotate_c,
    rv_to_quat,
    rv_to_quat_series_c,
)
from jaxnav.ins.earth import earth_params, gravity_minus_coriolis, position_rate


class NavState(NamedTuple):
    """Navigation state.

    Attributes:
      q_bn: (4,) attitude quaternion body -> nav (scalar first).
      v_n: (3,) ENU velocity, m/s.
      pos: (3,) [latitude rad, longitude rad, ellipsoidal height m].
    """

    q_bn: ArrayLike
    v_n: ArrayLike
    pos: ArrayLike


class MechState(NamedTuple):
    """Scan carry: the navigation state plus what the two-sample algorithms remember."""

    nav: NavState
    dtheta_prev: jax.Array  # (3,) previous angular increment, rad
    dv_prev: jax.Array  # (3,) previous velocity increment, m/s
    a_prev: jax.Array  # (3,) previous mean nav acceleration, m/s^2 (mid-interval extrapolation)
    status: jax.Array  # int32 flags


class ImuSample(NamedTuple):
    """One IMU sample: increments over the interval ending at the sample time."""

    dtheta: jax.Array  # (3,) angular increment in b, rad
    dv: jax.Array  # (3,) velocity increment (integrated specific force) in b, m/s
    dt: jax.Array  # scalar interval, s


class MechParams(NamedTuple):
    """Array parameters of the step (static choices are arguments of :func:`mech_step`)."""

    earth_rate_sign: ArrayLike = 1.0  # -1 for reverse navigation (S3 class 3)


def _coning_sculling(dth, dv, dth_prev, dv_prev, coning: bool):
    """Body-frame rotation vector and velocity increment of one sample (S3 class 2 steps 2-4).

    phi = dtheta + 1/12 dtheta_prev x dtheta (two-sample coning);
    dv_b = dv + 1/2 dtheta x dv + 1/12 (dtheta_prev x dv + dv_prev x dtheta) (rotation + sculling).
    All arguments are (x, y, z) component tuples of same-shape arrays (rad, m/s); returns (phi, dv_b).
    """
    rot = cross_c(dth, dv)
    if not coning:
        return tuple(dth), tuple(dv[i] + 0.5 * rot[i] for i in range(3))
    con, s1, s2 = cross_c(dth_prev, dth), cross_c(dth_prev, dv), cross_c(dv_prev, dth)
    phi = tuple(dth[i] + con[i] / 12.0 for i in range(3))
    dv_b = tuple(dv[i] + 0.5 * rot[i] + (s1[i] + s2[i]) / 12.0 for i in range(3))
    return phi, dv_b


class _Block(NamedTuple):
    """Body-frame part of one navigation-frame update over M samples (computed before the scan).

    dq: (4,) body rotation over the block, rv2q(phi_1) (x) ... (x) rv2q(phi_M).
    S: (4, 3) moments sum_j c_j^k u_j, k = 0..3, of the velocity increments u_j = B_{j-1} dv_b,j
       expressed in the body frame at the block start, c_j = mid-time of sample j from the block start;
       (1, 3) [dv_b] for a single sample (c = T/2).
    T: block duration, s.
    """

    dq: jax.Array
    S: jax.Array
    T: jax.Array


def _rot_sum(w, Y0, Y1, Y2):
    """sum_j R(-c_j w) y_j from the moments Y_k = sum_j c_j^k y_j, to second order in |w| c_j.

    R(-c w) y = y - c w x y + c^2/2 w x (w x y) + O(|w c|^3 |y|); |w| T <= 1e-4 rad (Earth plus
    transport rate over a 1 s block) leaves < 2e-13 of |y|.
    """
    return Y0 - jnp.cross(w, Y1) + 0.5 * jnp.cross(w, jnp.cross(w, Y2))


class _NavFrame(NamedTuple):
    """Navigation-frame quantities of one update, frozen at the block's mid-time."""

    w_in: jax.Array  # (3,) w_ie + w_en, rad/s
    G: jax.Array  # (3,) g - (2 w_ie + w_en) x v_mid, m/s^2
    pos_mid: jax.Array  # (3,) extrapolated mid-block position (where the radii are taken)
    v_mid: jax.Array  # (3,) the velocity at which w_en and Coriolis are taken, m/s


def _nav_update(nav: NavState, a_prev, blk: _Block, earth_rate_sign, ellipsoid, hold_height, G_prev=None):
    """Navigation-frame update over one block (S3 class 2 steps 5-11), with w_in, g, Coriolis at mid-block.

    With Y_k = C_bn(q) S_k (block-start nav frame) and the nav frame turning at w_in:
    v' = v + sum_j R(-c_j w_in) y_j + G T;  pos' = pos + M_pv(mid) int v dt, with the trapezoid
    int v dt = T v + T sum_j R(-c_j w) y_j - sum_j c_j R(-c_j w) y_j + G T^2 / 2 (exact for the
    per-sample trapezoids); q' = rv2q(-w_in T) (x) q (x) dq. One sample (M = 1) is :func:`mech_step`.
    The velocity at which w_en and Coriolis are taken is v + T/2 a_prev (one sample, as
    :func:`mech_step`), or with ``G_prev`` (the previous block's G) the block's mean velocity
    predicted from its own increments, v + Y_0 - Y_1 / T + G_prev T / 2: exact for the terms
    linear in v, and free of the one-block lag of a_prev.
    Returns (nav', a' = (v' - v) / T, :class:`_NavFrame`).
    """
    T = blk.T
    Y = quat_rotate(nav.q_bn, blk.S)
    if G_prev is None:
        v_mid = nav.v_n + 0.5 * T * a_prev
    else:
        v_mid = nav.v_n + Y[0] - Y[1] / T + 0.5 * T * G_prev
        if hold_height:
            v_mid = v_mid.at[2].set(0.0)
    pos_mid = nav.pos + 0.5 * T * position_rate(nav.pos, v_mid, ellipsoid)
    e = earth_params(pos_mid, v_mid, ellipsoid, earth_rate_sign)
    G = gravity_minus_coriolis(e, v_mid)
    if blk.S.shape[0] == 1:  # one sample: c = T/2, and the trapezoid is T (v + v') / 2
        cw = 0.5 * T * e.w_in_n
        dv_rot = Y[0] - jnp.cross(cw, Y[0]) + 0.5 * jnp.cross(cw, jnp.cross(cw, Y[0]))
        trap = T * nav.v_n + 0.5 * T * dv_rot + 0.5 * T * T * G
    else:
        dv_rot = _rot_sum(e.w_in_n, Y[0], Y[1], Y[2])
        trap = T * (nav.v_n + dv_rot) - _rot_sum(e.w_in_n, Y[1], Y[2], Y[3]) + 0.5 * T * T * G
    v_new = nav.v_n + dv_rot + G * T
    if hold_height:
        v_new = v_new.at[2].set(0.0)
    pos_new = nav.pos + position_rate(pos_mid, trap, ellipsoid)
    if hold_height:
        pos_new = pos_new.at[2].set(nav.pos[2])
    q_new = quat_normalize(quat_mul(rv_to_quat(-T * e.w_in_n), quat_mul(nav.q_bn, blk.dq)))
    frame = _NavFrame(e.w_in_n, G, pos_mid, v_mid)
    return NavState(q_bn=q_new, v_n=v_new, pos=pos_new), (v_new - nav.v_n) / T, frame


def _imu_flags(dth, dv, dt, series=False):
    """NONFINITE_IMU, BAD_IMU_TIME and, with ``series`` (the block paths), IMU_INCREMENT_TOO_LARGE.

    |dtheta| <= pi keeps the coning-corrected increment below pi + pi^2/12 < 2 pi, the range where
    :func:`rv_to_quat_series_c` is exact.
    """
    r2 = jnp.sum(dth * dth, axis=-1)
    bad_in = ~(jnp.all(jnp.isfinite(r2)) & jnp.all(jnp.isfinite(dv)))
    bad_dt = ~jnp.all(jnp.isfinite(dt) & (dt > 0))
    flags = jnp.where(bad_in, _status.NONFINITE_IMU, 0) | jnp.where(bad_dt, _status.BAD_IMU_TIME, 0)
    if series:
        flags = flags | jnp.where(jnp.any(r2 > np.pi**2), _status.IMU_INCREMENT_TOO_LARGE, 0)
    return flags.astype(jnp.int32)


def mech_step(
    state: MechState,
    imu: ImuSample,
    params: MechParams = MechParams(),
    *,
    ellipsoid: Ellipsoid = WGS84,
    coning: bool = True,
    hold_height: bool = False,
):
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
    dth, dv, dt = imu.dtheta, imu.dv, imu.dt
    phi, dv_b = _coning_sculling(
        jnp.unstack(dth), jnp.unstack(dv), jnp.unstack(state.dtheta_prev), jnp.unstack(state.dv_prev), coning
    )
    blk = _Block(dq=rv_to_quat(jnp.stack(phi)), S=jnp.stack(dv_b)[None], T=dt)
    new_nav, a_new, _ = _nav_update(state.nav, state.a_prev, blk, params.earth_rate_sign, ellipsoid, hold_height)
    new = MechState(
        nav=new_nav, dtheta_prev=dth, dv_prev=dv, a_prev=a_new, status=state.status | _imu_flags(dth, dv, dt)
    )
    return new, new_nav


class _Prefix(NamedTuple):
    """Per-sample prefixes inside each block, for states between navigation-frame updates."""

    B: jax.Array  # 4 x (nb, M) components: body rotation from the block start to the end of sample j
    S: jax.Array  # 4 x 3 x (nb, M): the moments of :class:`_Block` over samples 1..j
    tau: jax.Array  # (nb, M) time from the block start to the end of sample j


def _prefix_products(r):
    """B_j = r_1 (x) ... (x) r_j along axis 1 of (nb, M) quaternion components, in sample order.

    Sequential in j (the rounding of the per-sample recursion), vectorised over the blocks: a
    ``lax.scan`` over j (measured steadier than unrolling, whose fusions vary with M).
    """

    def step(b, rj):
        b = quat_mul_c(b, rj)
        return b, b

    first = tuple(a[:, 0] for a in r)
    _, rest = jax.lax.scan(step, first, tuple(a[:, 1:].T for a in r))
    return tuple(jnp.concatenate([f[:, None], x.T], axis=1) for f, x in zip(first, rest))


def _body_blocks(dtheta, dv, dt, dth_prev, dv_prev, M: int, coning: bool, prefix: bool):
    """Body-frame part of the mechanization for all blocks of M samples at once (no recursion in time).

    Args: dtheta, dv (N, 3) increments; dt (N,); dth_prev, dv_prev (3,) the sample before the
    first; N a multiple of M. Returns (:class:`_Block` with a leading (N/M,) axis, :class:`_Prefix` or None).
    """
    N = dtheta.shape[0]
    nb = N // M
    th, dvr = dtheta.T, dv.T  # components as contiguous rows
    pth = jnp.concatenate([dth_prev[:, None], th[:, :-1]], axis=1)
    pdv = jnp.concatenate([dv_prev[:, None], dvr[:, :-1]], axis=1)
    phi, dv_b = _coning_sculling(tuple(th), tuple(dvr), tuple(pth), tuple(pdv), coning)
    phi = tuple(a.reshape(nb, M) for a in phi)
    dv_b = tuple(a.reshape(nb, M) for a in dv_b)
    dt = dt.reshape(nb, M)
    B = _prefix_products(rv_to_quat_series_c(*phi))
    first = (jnp.ones((nb, 1), dt.dtype),) + (jnp.zeros((nb, 1), dt.dtype),) * 3
    B_prev = tuple(jnp.concatenate([f, b[:, :-1]], axis=1) for f, b in zip(first, B))
    u = quat_rotate_c(B_prev, dv_b)
    tau = jnp.cumsum(dt, axis=1)
    c = tau - 0.5 * dt
    ck = (None, c, c * c, c * c * c)
    mom = [[ui if k is None else k * ui for ui in u] for k in ck]  # [k][axis] (nb, M)
    blk = _Block(
        dq=jnp.stack([b[:, -1] for b in B], axis=-1),
        S=jnp.stack([jnp.stack([m.sum(axis=1) for m in row], axis=-1) for row in mom], axis=1),
        T=tau[:, -1],
    )
    if not prefix:
        return blk, None
    pre = _Prefix(B=B, S=tuple(tuple(jnp.cumsum(m, axis=1) for m in row) for row in mom), tau=tau)
    return blk, pre


def _between(start: NavState, fr: _NavFrame, pre: _Prefix, dt, hold_height, ellipsoid):
    """States after every sample of every block, from the block-start states (the equations of :func:`_nav_update`).

    Vectorised over blocks and samples, in components. start, fr: (nb, ...) from the scan;
    pre: :class:`_Prefix` with (nb, M) components; dt (nb, M). Returns a NavState of (nb, M, ...).
    """
    col = lambda a: tuple(a[:, i, None] for i in range(a.shape[1]))  # (nb, k) -> k x (nb, 1)
    q, v0, p0, w, G = col(start.q_bn), col(start.v_n), col(start.pos), col(fr.w_in), col(fr.G)
    Y = [quat_rotate_c(q, S) for S in pre.S[:3]]
    wY1, wY2 = cross_c(w, Y[1]), cross_c(w, cross_c(w, Y[2]))
    tau = pre.tau
    v = [v0[i] + (Y[0][i] - wY1[i] + 0.5 * wY2[i]) + G[i] * tau for i in range(3)]
    if hold_height:
        v[2] = jnp.zeros_like(v[2])
    trap = [jnp.cumsum(0.5 * dt * (jnp.concatenate([v0[i], v[i][:, :-1]], axis=1) + v[i]), axis=1) for i in range(3)]
    k = col(position_rate(fr.pos_mid, jnp.ones_like(fr.pos_mid), ellipsoid))  # [1/(R_M+h), 1/((R_N+h) cos L), 1]
    pos = [p0[0] + trap[1] * k[0], p0[1] + trap[0] * k[1], p0[2] + (0.0 if hold_height else trap[2])]
    # rotation of the nav frame over tau: |w tau| < 1e-4, well inside the exact range of the series
    n = rv_to_quat_series_c(*(-tau * w[i] for i in range(3)))
    qj = quat_mul_c(n, quat_mul_c(q, pre.B))
    norm = jnp.sqrt(sum(a * a for a in qj))
    stack = lambda xs: jnp.stack([jnp.broadcast_to(x, tau.shape) for x in xs], axis=-1)
    return NavState(q_bn=stack([a / norm for a in qj]), v_n=stack(v), pos=stack(pos))


class _TwoSpeed(NamedTuple):
    """Carry of the navigation-frame recursion of the two-speed mechanization."""

    nav: NavState
    a_prev: jax.Array  # (3,) mean nav acceleration of the last block, m/s^2
    G: jax.Array  # (3,) the last block's g - (2 w_ie + w_en) x v, m/s^2 (predicts the next block's mean velocity)


def _two_speed_start(nav: NavState, a_prev, earth_rate_sign, ellipsoid) -> _TwoSpeed:
    """The carry before the first block: G taken at the start state."""
    e = earth_params(nav.pos, nav.v_n, ellipsoid, earth_rate_sign)
    return _TwoSpeed(nav, a_prev, gravity_minus_coriolis(e, nav.v_n))


def _scan_blocks(
    carry: _TwoSpeed,
    blk: _Block,
    earth_rate_sign,
    ellipsoid,
    hold_height,
    *,
    emit=None,
    acc=None,
    accumulate=None,
    xs=None,
    skip_empty=False,
):
    """The two-speed block driver: one :func:`_nav_update` per block of samples, a ``lax.scan``.

    Used by :func:`mechanize` (``nav_every``) and by :func:`jaxnav.ins.loosely_coupled`
    (``nav_every``, between two fixes). The blocks' body-frame parts come from :func:`_body_blocks`.

    Args:
      carry: :class:`_TwoSpeed` at the start of the first block.  blk: :class:`_Block` with a leading (nb,) axis.
      emit: optional (start nav, new nav, :class:`_NavFrame`) -> per-block output.
      acc, accumulate, xs: an optional running sum over the blocks, acc <- accumulate(acc, start nav,
        :class:`_NavFrame`, T, x), with per-block inputs xs (leading axis nb).
      skip_empty: static; blocks of zero duration (padding) leave the carry and acc as they are.
    Returns:
      (carry after the last block, acc, stacked outputs of ``emit`` or None).
    """

    def step(c, bx):
        (two, a), (b, x) = c, bx
        if skip_empty:
            ok = b.T > 0
            b = b._replace(T=jnp.where(ok, b.T, 1.0))
        nav, a_new, fr = _nav_update(two.nav, two.a_prev, b, earth_rate_sign, ellipsoid, hold_height, two.G)
        new = (_TwoSpeed(nav, a_new, fr.G), a if accumulate is None else accumulate(a, two.nav, fr, b.T, x))
        if skip_empty:
            new = jax.tree_util.tree_map(lambda n_, o_: jnp.where(ok, n_, o_), new, c)
        return new, (None if emit is None else emit(two.nav, nav, fr))

    (carry, acc), out = jax.lax.scan(step, (carry, acc), (blk, xs))
    return carry, acc, out


class MechResult(NamedTuple):
    """Output of :func:`mechanize`.

    Attributes:
      nav: :class:`NavState` with a leading axis (one row per saved sample, see ``save_every``).
      final: the :class:`MechState` after the last sample (carry it on to continue).
      status: int32 flags (NONFINITE_IMU, BAD_IMU_TIME, IMU_INCREMENT_TOO_LARGE); see :func:`jaxnav.raise_for_status`.
    """

    nav: NavState
    final: MechState
    status: jax.Array


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
            raise ValueError(
                f"{name} has a NaN/inf IMU sample at index {int(np.argmax(bad))} "
                "(mechanization cannot skip samples; fill or cut the gap)"
            )
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
            raise ValueError(
                f"IMU time is not increasing at index {i + 1}: t[{i}] = {t[i]!r}, t[{i + 1}] = {t[i + 1]!r}"
            )
        med = np.median(d) if d.size else 0.0
        if d.size and (d > 1.5 * med).any():
            i = int(np.argmax(d > 1.5 * med))
            raise ValueError(f"IMU time has a gap of {d[i]:.6g} s after index {i} (median interval {med:.6g} s)")


@partial(jax.jit, static_argnames=("ellipsoid", "save_every", "coning", "kind", "hold_height", "nav_every"))
def _mechanize(
    nav0, dtheta, dv, dt, earth_rate_sign, a0, ellipsoid, save_every, coning, kind, hold_height, nav_every=1
):
    N = dtheta.shape[0]
    dt = jnp.broadcast_to(jnp.asarray(dt, nav0.v_n.dtype), (N,))
    if kind == "rates":
        dtheta, dv = dtheta * dt[:, None], dv * dt[:, None]
    z3 = jnp.zeros(3, nav0.v_n.dtype)
    init = MechState(
        nav=nav0, dtheta_prev=z3, dv_prev=z3, a_prev=z3 if a0 is None else a0, status=jnp.zeros((), jnp.int32)
    )
    params = MechParams(earth_rate_sign=earth_rate_sign)
    if nav_every > 1:
        return _mechanize_blocks(init, dtheta, dv, dt, params, ellipsoid, save_every, coning, hold_height, nav_every)
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


def _mechanize_blocks(init: MechState, dtheta, dv, dt, params, ellipsoid, save_every, coning, hold_height, M):
    """Two-speed mechanization: body-frame terms for every sample at once, one nav-frame update per M samples.

    The body-frame recursions (coning/sculling, the attitude increments inside a block, the
    velocity increments in the block-start body frame) need no navigation state, so they are
    computed for all samples with array operations; only the M-times slower navigation-frame
    recursion (:func:`_nav_update`) is a ``lax.scan``. States between updates come from the same
    equations (:func:`_between`). A tail of N mod M samples is one shorter block.
    """
    N = dtheta.shape[0]
    M = min(M, N)
    nb, r = divmod(N, M)
    at_ends = save_every % M == 0  # then N % M == 0 too (N % save_every == 0 is checked)
    sign = params.earth_rate_sign
    status = init.status | _imu_flags(dtheta, dv, dt, series=True)
    blk, pre = _body_blocks(
        dtheta[: nb * M], dv[: nb * M], dt[: nb * M], init.dtheta_prev, init.dv_prev, M, coning, prefix=not at_ends
    )

    run = partial(_scan_blocks, earth_rate_sign=sign, ellipsoid=ellipsoid, hold_height=hold_height)
    carry = _two_speed_start(init.nav, init.a_prev, sign, ellipsoid)
    if at_ends and save_every > M:
        k = save_every // M
        blk = jax.tree_util.tree_map(lambda a: a.reshape((nb // k, k) + a.shape[1:]), blk)

        def chunk(c, b):
            c, _, _ = run(c, b)
            return c, c.nav

        end, navs = jax.lax.scan(chunk, carry, blk)
    elif at_ends:
        end, _, navs = run(carry, blk, emit=lambda start, new, fr: new)
    else:
        end, _, (starts, frames) = run(carry, blk, emit=lambda start, new, fr: (start, fr))
        navs = _between(starts, frames, pre, dt[: nb * M].reshape(nb, M), hold_height, ellipsoid)
        navs = jax.tree_util.tree_map(lambda a: a.reshape((nb * M,) + a.shape[2:]), navs)
        if r:
            n = nb * M
            tb, tp = _body_blocks(dtheta[n:], dv[n:], dt[n:], dtheta[n - 1], dv[n - 1], r, coning, True)
            end, _, (start, fr) = run(end, tb, emit=lambda start, new, fr: (start, fr))
            tail = _between(start, fr, tp, dt[n:][None], hold_height, ellipsoid)
            tail = jax.tree_util.tree_map(lambda a: a[0], tail)
            navs = jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a, b]), navs, tail)
        navs = jax.tree_util.tree_map(lambda a: a[save_every - 1 :: save_every], navs)
    final = MechState(nav=end.nav, dtheta_prev=dtheta[-1], dv_prev=dv[-1], a_prev=end.a_prev, status=status)
    return MechResult(nav=navs, final=final, status=status)


def _prepare(nav0, dtheta, dv, dt, t, save_every, validate, nav_every=1):
    dtheta, dv = jnp.asarray(dtheta), jnp.asarray(dv)
    if dtheta.ndim != 2 or dtheta.shape[-1] != 3 or dv.shape != dtheta.shape:
        raise ValueError(f"dtheta has shape {dtheta.shape} and dv {dv.shape}; expected (N, 3) each")
    N = dtheta.shape[0]
    if jnp.shape(dt) not in ((), (N,)):
        raise ValueError(f"dt has shape {jnp.shape(dt)}; expected () or ({N},)")
    for name, a, shp in (("q_bn", nav0.q_bn, (4,)), ("v_n", nav0.v_n, (3,)), ("pos", nav0.pos, (3,))):
        if jnp.shape(a) != shp:
            raise ValueError(f"nav0.{name} has shape {jnp.shape(a)}; expected {shp}")
    if not isinstance(nav_every, (int, np.integer)) or nav_every < 1:
        raise ValueError(f"nav_every={nav_every!r} must be an integer >= 1")
    if save_every < 1 or N % save_every:
        raise ValueError(f"save_every={save_every} must divide the number of samples N={N}")
    check_float64(nav0.pos, what="nav0.pos (absolute latitude/longitude/height)")
    if validate and _concrete(dtheta, dv, dt, t):
        check_imu(dtheta, dv, dt, t)


def mechanize(
    nav0: NavState,
    dtheta,
    dv,
    dt,
    *,
    t=None,
    kind: str = "increments",
    a0=None,
    ellipsoid: Ellipsoid = WGS84,
    save_every: int = 1,
    coning: bool = True,
    hold_height: bool = False,
    validate: bool = True,
    nav_every: int = 1,
) -> MechResult:
    """Forward strapdown mechanization over N IMU samples (S3 class 2), a ``lax.scan`` of :func:`mech_step`.

    Args:
      nav0: :class:`NavState` at the time of the first sample's start.
      dtheta: (N, 3) angular increments in b, rad (or angular rates, rad/s, with kind="rates").
      dv: (N, 3) velocity increments in b, m/s (or specific force, m/s^2, with kind="rates").
      dt: scalar or (N,) sample intervals, s.
      t: optional (N,) sample times, s, checked for increasing order and gaps.
      kind: static, "increments" or "rates" (rates are multiplied by dt: rectangular integration).
      a0: optional (3,) nav acceleration at the start (for the first mid-interval extrapolation;
        with ``nav_every > 1`` each block predicts its mean velocity from its own increments
        and a0 is not needed).
      ellipsoid: static Earth model.  save_every: static, keep every k-th state (memory).
      coning: static, two-sample coning/sculling corrections.
      hold_height: static, hold h and V_U = 0 (see :func:`mech_step`).
      validate: check concrete inputs on the host (NaN samples, non-increasing time, gaps).
      nav_every: static, two-speed mechanization (S3 class 2 with the navigation-frame steps
        at a lower rate): Earth rate, transport rate, gravity and Coriolis are evaluated once
        per ``nav_every`` samples at the block's mid-time, while attitude and velocity increments
        stay exact per sample. The body-frame work then runs as array operations over all
        samples and only N / nav_every steps are sequential (several times faster, see
        ``benchmarks/bench_ins.py``). 1 (default) is the per-sample :func:`mech_step` scan.
        Measured on the full S0 trajectory (2000 s, 100 Hz): the error against the true
        trajectory grows from 0.134 m (1) to 0.141 m (10) and 0.165 m (20); it grows with
        (nav_every dt)^2. States between updates use the same frozen terms.
    Returns:
      :class:`MechResult`; ``nav`` holds the state after each saved sample (times t_1..t_N).
    Raises:
      ValueError: wrong shapes (at trace time), float32 position, or bad concrete samples.
    """
    if kind not in ("increments", "rates"):
        raise ValueError(f"kind must be 'increments' or 'rates', got {kind!r}")
    _prepare(nav0, dtheta, dv, dt, t, save_every, validate, nav_every)
    return _mechanize(
        nav0,
        jnp.asarray(dtheta),
        jnp.asarray(dv),
        dt,
        1.0,
        a0,
        ellipsoid,
        save_every,
        coning,
        kind,
        hold_height,
        int(nav_every),
    )


def mechanize_backward(
    nav_end: NavState,
    dtheta,
    dv,
    dt,
    *,
    t=None,
    kind: str = "increments",
    a0=None,
    ellipsoid: Ellipsoid = WGS84,
    save_every: int = 1,
    coning: bool = True,
    hold_height: bool = False,
    validate: bool = True,
    nav_every: int = 1,
) -> MechResult:
    """Reverse (backward) navigation exactly as S3 class 3.

    Starts from the forward solution's end state with the velocity negated, reads the samples in
    reverse order with the angular increments and the Earth rate negated (velocity increments
    unchanged), and mechanizes forward in that reversed time. In reversed time this is the exact
    time reversal of the navigation equations.

    Args:
      nav_end: :class:`NavState` at the end of the last sample (forward sense of velocity).
      dtheta, dv, dt, t, kind, ellipsoid, save_every, coning, hold_height, validate, nav_every: as
        :func:`mechanize`, given in forward time order.
      a0: optional (3,) forward-time nav acceleration at the end.
    Returns:
      :class:`MechResult` whose ``nav`` is put back in forward time order with the forward sense
      of velocity: row i is the state at the *start* of sample i (times t_0..t_{N-1}; with
      ``save_every = k``, rows are t_0, t_k, ...). ``final.nav`` is the state at t_0 with the
      velocity still negated (the raw carry of the reversed run).
    """
    if kind not in ("increments", "rates"):
        raise ValueError(f"kind must be 'increments' or 'rates', got {kind!r}")
    _prepare(nav_end, dtheta, dv, dt, t, save_every, validate, nav_every)
    dth = -jnp.asarray(dtheta)[::-1]
    dvr = jnp.asarray(dv)[::-1]
    dtr = dt if jnp.ndim(dt) == 0 else jnp.asarray(dt)[::-1]
    nav0 = nav_end._replace(v_n=-jnp.asarray(nav_end.v_n))
    res = _mechanize(
        nav0,
        dth,
        dvr,
        dtr,
        -1.0,
        None if a0 is None else jnp.asarray(a0),
        ellipsoid,
        save_every,
        coning,
        kind,
        hold_height,
        int(nav_every),
    )
    navs = NavState(q_bn=res.nav.q_bn[::-1], v_n=-res.nav.v_n[::-1], pos=res.nav.pos[::-1])
    return MechResult(nav=navs, final=res.final, status=res.status)
