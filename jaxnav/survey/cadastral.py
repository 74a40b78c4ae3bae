"""S3 cadastral-survey IMU post-processing (Southeast University patent 11453409).

A surveyor carries a strapdown IMU and stops at points. The pipeline, per the patent:

1. preprocessing (:mod:`jaxnav.survey._preprocess`, :mod:`jaxnav.survey._ar`): wild values,
   zero-phase low-pass, statistics, AR(p) error model and its Kalman filter;
2. segmentation into stops (five kinds) and the three data classes (:mod:`jaxnav.survey._stops`);
3. class 1: forward Kalman filter with the static observation models (zero velocity at every
   stop, known E/N/U at known-coordinate points, known E/N at known-position points, known U at
   levelling points) + RTS fixed-interval smoothing -> gyro and accelerometer error estimates ->
   compensation of the raw data. This reuses :func:`jaxnav.ins.loosely_coupled` (stops are masked
   position/velocity pseudo-measurements) and :func:`jaxnav.ins.smooth`;
   class 2: pure strapdown between stops, restarted at every known-coordinate point;
   class 3: reverse navigation (:func:`jaxnav.ins.mech_step` with the Earth rate and angular
   increments negated, as :func:`jaxnav.ins.mechanize_backward`) from the next known-coordinate
   point back to the target, fused with the forward position.

Target-point stages reported (each is a position of the target point):

* ``forward``  (a): raw data, pure strapdown from the last known-coordinate point before the
  target (position reset to its known coordinates, velocity to zero, attitude carried on);
* ``preprocessed``: the same on preprocessed data (gain of step 1 alone);
* ``smoothed`` (b): preprocessed data compensated with the class-1 smoothed sensor errors, pure
  strapdown from the smoothed state at the last known-coordinate point;
* ``fused``    (c): (b) fused with the reverse navigation from the next known-coordinate point,
  inverse-variance weighted per E/N/U component with covariances propagated through the
  filter's own error model (:func:`propagate_covariances`);
* diagnostics: ``filtered`` (the causal class-1 filter at the target stop) and ``rts`` (the
  smoothed class-1 solution at the target stop).

Host-side planning (:func:`plan_survey`) turns a stop list into static index arrays; the
numerical work (:func:`process_survey`) is one jit-able, vmappable function of the IMU data.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from jaxnav.geodesy import curvilinear_to_enu, enu_to_curvilinear
from jaxnav.ins.error_model import IDX18
from jaxnav.ins.integration import LCParams, LCSave, PVMeasurements, SensorBiases, loosely_coupled, smooth
from jaxnav.ins.mechanization import ImuSample, MechParams, MechState, NavState, mech_step
from jaxnav.survey._preprocess import PreprocessParams, preprocess_imu
from jaxnav.survey._stops import (
    KNOWN_COORDINATE,
    KNOWN_POSITION,
    LEVELLING,
    STOP_KINDS,
    TARGET,
    StopList,
    classify,
    validate_stops,
)

#: target-position stages, in pipeline order
STAGES = ("forward", "preprocessed", "smoothed", "fused", "filtered", "rts")


class CadastralParams(NamedTuple):
    """Tunable arrays of the pipeline (vmap/grad-able leaves).

    Attributes:
      P0: (18, 18) initial error covariance of the class-1 filter (order of :data:`jaxnav.ins.IDX18`).
      Qc: (9, 9) continuous noise density (:meth:`jaxnav.ins.ErrorModel.Qc` of the 18-state model).
      tau_markov: scalar or (3,) gyro Markov correlation time, s.
      zupt_sigma: zero-velocity observation std, m/s.
      pre: :class:`jaxnav.survey.PreprocessParams`.
    """

    P0: jax.Array
    Qc: jax.Array
    tau_markov: jax.Array
    zupt_sigma: ArrayLike = 0.005
    pre: PreprocessParams = PreprocessParams()


class SurveyPlan(NamedTuple):
    """Static (host, numpy) layout of a survey: built once by :func:`plan_survey`.

    Attributes:
      stops: :class:`StopList`.  t_imu: (N,) sample end times, s.  dt: sample interval, s.
      t_meas: (M,) class-1 epochs (on sample times).  meas_stop: (M,) stop index per epoch (-1: moving).
      meas_mask: (M, 6) pseudo-measurement components used [pos E, N, U, vel E, N, U].
      sample_epoch: (N,) epoch whose smoothed sensor errors compensate each sample.
      targets: (T,) stop indices of the targets.  class3: (T,) the patent's class-3 flag.
      fwd_reset: (N,) int, forward strapdown: reset the state *before* sample i to row
        fwd_reset[i] of the known-point table (-1: none).  bwd_reset: (N,) likewise for the
        state *after* sample i in the reverse run.  known: (R,) stop index of each table row.
      known_epoch_f, known_epoch_b: (R,) epoch of the forward / backward reset of each row.
      arrival, departure: (T,) state index (0..N) at the target stop's first / last sample time.
      arr_epoch, dep_epoch: (T,) epochs used for the target's forward / backward covariance.
      has_next: (T,) bool, a known-coordinate point follows the target (reverse navigation possible).
      stop_epochs: (T, E) epochs inside each target stop (padded), stop_epoch_w: (T, E) weights.
      fwd_epoch_reset, bwd_epoch_reset: (M,) table row reset at each epoch in the covariance scans.
    """

    stops: StopList
    t_imu: jax.Array
    dt: float
    t_meas: jax.Array
    meas_stop: jax.Array
    meas_mask: jax.Array
    sample_epoch: jax.Array
    targets: jax.Array
    class3: jax.Array
    fwd_reset: jax.Array
    bwd_reset: jax.Array
    known: jax.Array
    known_epoch_f: jax.Array
    known_epoch_b: jax.Array
    arrival: jax.Array
    departure: jax.Array
    arr_epoch: jax.Array
    dep_epoch: jax.Array
    has_next: jax.Array
    stop_epochs: jax.Array
    stop_epoch_w: np.ndarray
    fwd_epoch_reset: jax.Array
    bwd_epoch_reset: jax.Array


def plan_survey(stops: StopList, t_imu, *, meas_rate_hz: float = 1.0, margin_s: float = 0.5) -> SurveyPlan:
    """Host-side layout of the S3 processing for a stop list and IMU sample times.

    Args:
      stops: :class:`StopList`.  t_imu: (N,) end times of uniformly spaced IMU samples, s.
      meas_rate_hz: rate of the class-1 epochs (snapped to whole samples).
      margin_s: stop edges excluded from the static observations, s (start/stop transients).
    Returns:
      :class:`SurveyPlan`.
    Raises:
      ValueError: stop list outside the data's span, overlapping stops, a target with no
        known-coordinate point before it, a stop too short to hold a class-1 epoch.
    """
    t = np.asarray(t_imu, float)
    if t.ndim != 1 or t.size < 2:
        raise ValueError(f"t_imu must be a 1-D array of at least 2 times, got shape {t.shape}")
    d = np.diff(t)
    dt = float(np.median(d))
    if np.any(np.abs(d - dt) > 1e-6 * max(dt, 1.0)):
        raise ValueError("the cadastral pipeline needs uniformly spaced IMU samples (resample first)")
    t_grid = np.concatenate([[t[0] - dt], t])  # state times s_0..s_N
    validate_stops(stops, t_grid[0], t_grid[-1])
    N = t.size
    K = len(stops.t_start)
    step = max(1, int(round(1.0 / (meas_rate_hz * dt))))
    t_meas = t[step - 1 :: step]
    M = t_meas.size
    eps = 1e-6 * dt
    in_stop = (t_meas[:, None] >= stops.t_start[None, :] + margin_s - eps) & (
        t_meas[:, None] <= stops.t_end[None, :] - margin_s + eps
    )
    meas_stop = np.where(in_stop.any(1), np.argmax(in_stop, 1), -1)
    for k in range(K):
        if not (meas_stop == k).any():
            raise ValueError(
                f"stop {stops.name[k]!r} [{stops.t_start[k]:.2f}, {stops.t_end[k]:.2f}] s is too short "
                f"for a class-1 epoch at {meas_rate_hz} Hz with {margin_s} s margins"
            )
    mask = np.zeros((M, 6), bool)
    mask[:, 3:] = meas_stop[:, None] >= 0
    # a known coordinate is one observation per stop (its error is common to the stop's epochs):
    # applied at the stop's middle epoch
    for k in range(K):
        ep = np.flatnonzero(meas_stop == k)
        mid = ep[len(ep) // 2]
        kind = stops.kind[k]
        if kind == KNOWN_COORDINATE:
            mask[mid, 0:3] = True
        elif kind == KNOWN_POSITION:
            mask[mid, 0:2] = True
        elif kind == LEVELLING:
            mask[mid, 2] = True
    sample_epoch = np.clip(np.searchsorted(t_meas, t - eps, side="left"), 0, M - 1)
    cls = classify(stops, t)
    known = np.flatnonzero(stops.kind == KNOWN_COORDINATE)
    kef = np.array([np.flatnonzero(meas_stop == k)[-1] for k in known])
    keb = np.array([np.flatnonzero(meas_stop == k)[0] for k in known])
    grid_idx = lambda tt: np.searchsorted(t_grid, tt - eps, side="left")
    fwd_reset = np.full(N, -1)
    bwd_reset = np.full(N, -1)
    for r, _k in enumerate(known):
        i = grid_idx(t_meas[kef[r]])  # state index of the forward reset
        if i < N:
            fwd_reset[i] = r
        j = grid_idx(t_meas[keb[r]])  # state index of the backward reset: state after sample j-1
        bwd_reset[j - 1] = r
    fwd_epoch_reset = np.full(M, -1)
    bwd_epoch_reset = np.full(M, -1)
    fwd_epoch_reset[kef] = np.arange(len(known))
    bwd_epoch_reset[keb] = np.arange(len(known))
    targets = np.flatnonzero(stops.kind == TARGET)
    arrival = np.array([grid_idx(stops.t_start[k]) for k in targets], int)
    departure = np.array([np.searchsorted(t_grid, stops.t_end[k] + eps, side="right") - 1 for k in targets], int)
    arr_epoch = np.clip(np.searchsorted(t_meas, t_grid[arrival] - eps, side="left"), 0, M - 1)
    dep_epoch = np.clip(np.searchsorted(t_meas, t_grid[departure] + eps, side="right") - 1, 0, M - 1)
    has_next = cls.next_known[targets] >= 0 if targets.size else np.zeros(0, bool)
    E = max([int((meas_stop == k).sum()) for k in targets] + [1])
    stop_epochs = np.zeros((targets.size, E), int)
    stop_w = np.zeros((targets.size, E))
    for i, k in enumerate(targets):
        ep = np.flatnonzero(meas_stop == k)
        stop_epochs[i, : ep.size] = ep
        stop_w[i, : ep.size] = 1.0 / ep.size
    return SurveyPlan(
        stops=stops,
        t_imu=t,
        dt=dt,
        t_meas=t_meas,
        meas_stop=meas_stop,
        meas_mask=mask,
        sample_epoch=sample_epoch,
        targets=targets,
        class3=cls.class3[targets],
        fwd_reset=fwd_reset,
        bwd_reset=bwd_reset,
        known=known,
        known_epoch_f=kef,
        known_epoch_b=keb,
        arrival=arrival,
        departure=departure,
        arr_epoch=arr_epoch,
        dep_epoch=dep_epoch,
        has_next=has_next,
        stop_epochs=stop_epochs,
        stop_epoch_w=stop_w,
        fwd_epoch_reset=fwd_epoch_reset,
        bwd_epoch_reset=bwd_epoch_reset,
    )


def stop_measurements(plan: SurveyPlan, known_pos, zupt_sigma, nav_pos0) -> PVMeasurements:
    """Class-1 static observation models as masked position/velocity pseudo-measurements.

    Every stop epoch observes zero velocity (std ``zupt_sigma``); the known coordinates of a
    known-coordinate (E, N, U), known-position (E, N) or levelling (U) stop are observed once.

    Args:
      plan: :class:`SurveyPlan`.  known_pos: (K, 3) [lat rad, lon rad, h m] of the stops (NaN where unknown).
      zupt_sigma: m/s.  nav_pos0: (3,) a finite position used where nothing is known (masked).
    Returns:
      :class:`jaxnav.ins.PVMeasurements` with M epochs.
    """
    M = plan.t_meas.size
    st = np.clip(plan.meas_stop, 0, None)
    kp = jnp.asarray(known_pos)[st]
    pos = jnp.where(jnp.isfinite(kp), kp, nav_pos0[None, :])
    sig = np.asarray(plan.stops.sigma)[st]
    zs = jnp.asarray(zupt_sigma, pos.dtype)
    var = jnp.concatenate([jnp.asarray(sig**2), jnp.broadcast_to(zs**2, (M, 3))], 1)
    R = jax.vmap(jnp.diag)(var)
    return PVMeasurements(
        t=plan.t_meas,
        pos=pos,
        vel=jnp.zeros((M, 3), pos.dtype),
        R=R,
        mask=jnp.asarray(plan.meas_mask),
        lever=jnp.zeros((M, 3), pos.dtype),
    )


def _strapdown_resets(nav_init: NavState, dtheta, dv, dt, reset, table: NavState, reset_attitude, sign):
    """Pure strapdown (S3 class 2) with state resets; reset[i] >= 0 replaces the state before sample i.

    ``reset_attitude`` (bool) and ``sign`` (Earth-rate sign) are array leaves, so several passes
    (forward raw, forward compensated, reverse) run as one vmapped scan.
    """

    def step(mech: MechState, x):
        dth, dvi, r = x
        row = jnp.clip(r, 0, None)
        tab = jax.tree_util.tree_map(lambda a: a[row], table)
        q = jnp.where(reset_attitude, tab.q_bn, mech.nav.q_bn)
        new_nav = NavState(q_bn=q, v_n=tab.v_n, pos=tab.pos)
        nav = jax.tree_util.tree_map(lambda a, b: jnp.where(r >= 0, a, b), new_nav, mech.nav)
        mech = mech._replace(nav=nav, a_prev=jnp.where(r >= 0, 0.0, mech.a_prev))
        mech, out = mech_step(mech, ImuSample(dth, dvi, dt), MechParams(earth_rate_sign=sign))
        return mech, out.pos

    z3 = jnp.zeros(3, dtheta.dtype)
    init = MechState(nav=nav_init, dtheta_prev=z3, dv_prev=z3, a_prev=z3, status=jnp.zeros((), jnp.int32))
    final, pos = jax.lax.scan(step, init, (dtheta, dv, jnp.asarray(reset)))
    return pos, final.status


def strapdown_with_resets(
    nav0: NavState, dtheta, dv, dt, reset, table: NavState, *, reset_attitude: bool = True, backward: bool = False
):
    """Pure strapdown restarted at known points, forward (S3 class 2) or reverse (S3 class 3).

    Forward: ``reset[i] = r >= 0`` replaces the state before sample i with row r of ``table``
    (attitude only if ``reset_attitude``). Backward: samples are read in reverse order with the
    angular increments and the Earth rate negated and the velocity negated (exactly
    :func:`jaxnav.ins.mechanize_backward`); ``reset[i] = r`` sets the state *after* sample i
    (forward sense of velocity in ``table``) before the reverse run integrates sample i.

    Args:
      nav0: starting :class:`NavState` (forward: before sample 0; backward: after the last sample,
        forward sense of velocity).
      dtheta, dv: (N, 3) increments, rad and m/s.  dt: scalar, s.
      reset: (N,) int (static layout, numpy).  table: :class:`NavState` with (R, ...) leaves.
    Returns:
      (positions (N, 3), status): forward row i is the state after sample i; backward row i is
      the state *before* sample i (at the sample's start).
    """
    if not backward:
        return _strapdown_resets(nav0, dtheta, dv, dt, reset, table, reset_attitude, 1.0)
    nav_b, dth_b, dv_b, reset_b, tab_b = _reverse_inputs(nav0, dtheta, dv, reset, table)
    pos, status = _strapdown_resets(nav_b, dth_b, dv_b, dt, reset_b, tab_b, reset_attitude, -1.0)
    return pos[::-1], status


def _reverse_inputs(nav_end, dtheta, dv, reset, table):
    """Inputs of the reverse run (S3 class 3): samples reversed, angular increments and velocities negated."""
    return (
        nav_end._replace(v_n=-nav_end.v_n),
        -dtheta[::-1],
        dv[::-1],
        np.asarray(reset)[::-1],
        table._replace(v_n=-table.v_n),
    )


def propagate_covariances(Phi, pred_covs, covs, P0, reset_f, reset_b, table_P):
    """Error covariance of pure strapdown restarted at known points, forward and backward.

    The class-1 filter's saved moments give the discrete process noise of each epoch interval,
    Qd_j = P_{j|j-1} - Phi_j P_{j-1} Phi_j^T (no inflation). Forward: P_j = Phi_j P_{j-1} Phi_j^T
    + Qd_j, reset to the smoothed covariance at known-point epochs. Backward (reverse
    navigation): P_{j-1} = Phi_j^{-1} (P_j + Qd_j) Phi_j^{-T}, reset likewise.

    Args:
      Phi, pred_covs, covs: (M, n, n) from :func:`jaxnav.ins.loosely_coupled`.  P0: (n, n).
      reset_f, reset_b: (M,) int rows of ``table_P`` (R, n, n) to reset to (-1: none).
    Returns:
      (forward (M, n, n), backward (M, n, n)) covariances.
    """
    prev = jnp.concatenate([P0[None], covs[:-1]], 0)
    Qd = pred_covs - jnp.einsum("mij,mjk,mlk->mil", Phi, prev, Phi)
    Qd = 0.5 * (Qd + jnp.swapaxes(Qd, 1, 2))

    def fwd(P, x):
        F, Q, r = x
        P = F @ P @ F.T + Q
        P = jnp.where(r >= 0, table_P[jnp.clip(r, 0, None)], P)
        return P, P

    _, Pf = jax.lax.scan(fwd, table_P[0], (Phi, Qd, jnp.asarray(reset_f)))

    # backward: Pb at epoch j from epoch j+1: Phi_{j+1}^{-1} (P_{j+1} + Qd_{j+1}) Phi_{j+1}^{-T}
    def bwd(P, x):
        F, Q, r = x  # F, Q of epoch j+1; r = reset at epoch j
        A = jnp.linalg.solve(F, P + Q)
        P = jnp.linalg.solve(F, A.T).T
        P = 0.5 * (P + P.T)
        P = jnp.where(r >= 0, table_P[jnp.clip(r, 0, None)], P)
        return P, P

    rb = jnp.asarray(reset_b)
    last = table_P[jnp.clip(rb[-1], 0, None)]
    _, Pb = jax.lax.scan(bwd, last, (Phi[1:], Qd[1:], rb[:-1]), reverse=True)
    Pb = jnp.concatenate([Pb, last[None]], 0)
    return Pf, Pb


def enu_difference(pos, ref):
    """[E, N, U] metres of geodetic ``pos`` relative to ``ref`` (small offsets; (..., 3))."""
    return curvilinear_to_enu(ref, pos - ref)


def _enu_var(P, pos):
    """E, N, U variances (m^2) of the position-error block of P (..., 18, 18) at pos (..., 3)."""
    i = IDX18.dpos.start
    # the metres per unit of [dlat, dlon, dh] in E, N, U order
    s = curvilinear_to_enu(pos, jnp.ones_like(pos))
    return jnp.stack([P[..., i + 1, i + 1] * s[..., 0] ** 2, P[..., i, i] * s[..., 1] ** 2, P[..., i + 2, i + 2]], -1)


class SurveyOutput(NamedTuple):
    """Output of :func:`process_survey` (T targets).

    Attributes:
      targets: dict stage -> (T, 3) target position [lat, lon, h] for each of :data:`STAGES`.
      sigma_forward, sigma_backward: (T, 3) propagated E/N/U std of the (b) forward and the reverse
        target positions, m.  weight_forward: (T, 3) fusion weight of the forward position.
      backward: (T, 3) reverse-navigation target positions.
      biases: smoothed :class:`jaxnav.ins.SensorBiases` per epoch (M, 3).
      nav_smoothed: smoothed :class:`NavState` per epoch.  nav_filtered: filtered :class:`NavState`.
      n_rejected: wild values replaced.  status: int32 flags (filter | mechanization).
      route: dict of (N, 3) positions (``forward``, ``smoothed``, ``backward``) or None.
    """

    targets: dict
    sigma_forward: jax.Array
    sigma_backward: jax.Array
    weight_forward: jax.Array
    backward: jax.Array
    biases: SensorBiases
    nav_smoothed: NavState
    nav_filtered: NavState
    n_rejected: jax.Array
    status: jax.Array
    route: dict | None = None


def process_survey(
    plan: SurveyPlan,
    nav0: NavState,
    dtheta,
    dv,
    known_pos,
    params: CadastralParams,
    *,
    preprocess: bool = True,
    lowpass: bool = True,
    return_route: bool = False,
) -> SurveyOutput:
    """The S3 post-processing of one survey (steps 1-3; see the module docstring).

    Jit- and vmap-able in (nav0, dtheta, dv, known_pos, params); ``plan`` is static (closed over).

    Args:
      plan: :class:`SurveyPlan`.  nav0: :class:`NavState` before the first sample (from alignment).
      dtheta, dv: (N, 3) raw increments, rad and m/s (body right-forward-up).
      known_pos: (K, 3) known [lat rad, lon rad, h m] per stop (NaN where not known).
      params: :class:`CadastralParams`.
      preprocess: static, run step 1 (wild values, low-pass) before classes 1-3.
      lowpass: static, include the zero-phase low-pass in step 1.
      return_route: static, also return the (N, 3) positions of the strapdown passes.
    Returns:
      :class:`SurveyOutput`.
    Raises:
      ValueError: shapes not matching the plan.
    """
    N = plan.t_imu.size
    K = len(plan.stops.t_start)
    if jnp.shape(dtheta) != (N, 3) or jnp.shape(dv) != (N, 3):
        raise ValueError(f"dtheta {jnp.shape(dtheta)} and dv {jnp.shape(dv)} must be ({N}, 3) to match the plan")
    if jnp.shape(known_pos) != (K, 3):
        raise ValueError(f"known_pos has shape {jnp.shape(known_pos)}; expected ({K}, 3) for {K} stops")
    dt = plan.dt
    dtype = jnp.asarray(dtheta).dtype
    known_pos = jnp.asarray(known_pos, dtype)
    kn = known_pos[plan.known]  # (R, 3) known-coordinate points
    R_ = plan.known.size
    z = jnp.zeros((R_, 3), dtype)

    def at_states(pos_after, idx, nav_start):
        # state index i (0..N): i = 0 is the start state, else the position after sample i - 1
        full = jnp.concatenate([nav_start[None], pos_after], 0)
        return full[np.asarray(idx)]

    if preprocess:
        pre = preprocess_imu(dtheta, dv, dt, params.pre, lowpass=lowpass)
        dth_p, dv_p, n_rej = pre.dtheta, pre.dv, pre.n_rejected
    else:
        dth_p, dv_p, n_rej = dtheta, dv, jnp.zeros((), jnp.int32)

    # class 1: forward filter with the static observations + RTS smoothing
    meas = stop_measurements(plan, known_pos, params.zupt_sigma, nav0.pos)
    lcp = LCParams(P0=params.P0, Qc=params.Qc, tau_markov=params.tau_markov)
    res = loosely_coupled(
        nav0,
        plan.t_imu,
        dth_p,
        dv_p,
        meas,
        lcp,
        dt_imu=dt,
        save=LCSave(("nav", "biases", "covs", "pred_covs", "Phi", "corrections")),
    )
    nav_s, bias_s, covs_s = smooth(res)
    # compensation of the raw (preprocessed) data with the smoothed sensor errors
    se = np.asarray(plan.sample_epoch)
    g_err = (bias_s.gyro + bias_s.markov)[se]
    a_err = bias_s.accel[se]
    dth_c = dth_p - g_err * dt
    dv_c = dv_p - a_err * dt
    # class 2: pure strapdown of the compensated data from the smoothed state at each known point
    ef = np.asarray(plan.known_epoch_f)
    eb = np.asarray(plan.known_epoch_b)
    tab_f = jax.tree_util.tree_map(lambda a: a[ef], nav_s)
    tab_b = jax.tree_util.tree_map(lambda a: a[eb], nav_s)
    # class 3: reverse navigation from the next known point
    nav_end = jax.tree_util.tree_map(lambda a: a[-1], nav_s)
    rev = _reverse_inputs(nav_end, dth_c, dv_c, plan.bwd_reset, tab_b)
    # the four strapdown passes as one vmapped scan: (a) raw and preprocessed data restarted at known
    # points (known position, zero velocity, attitude carried on), (b) compensated data restarted at
    # the smoothed states, (c) the reverse run
    tab_a = NavState(q_bn=tab_f.q_bn, v_n=z, pos=kn)
    stack = lambda *a: jax.tree_util.tree_map(lambda *x: jnp.stack(x), *a)
    fr = np.asarray(plan.fwd_reset)
    pos4, st4 = jax.vmap(_strapdown_resets, in_axes=(0, 0, 0, None, 0, 0, 0, 0))(
        stack(nav0, nav0, nav0, rev[0]),
        stack(dtheta, dth_p, dth_c, rev[1]),
        stack(dv, dv_p, dv_c, rev[2]),
        dt,
        jnp.asarray(np.stack([fr, fr, fr, rev[3]])),
        stack(tab_a, tab_a, tab_f, rev[4]),
        jnp.array([False, False, True, True]),
        jnp.array([1.0, 1.0, 1.0, -1.0], dtype),
    )
    pos_a, pos_p, pos_b, pos_r = pos4[0], pos4[1], pos4[2], pos4[3][::-1]

    # covariances of the forward / reverse strapdown, for the fusion
    ep = res.epochs
    table_P = covs_s[ef]
    table_Pb = covs_s[eb]
    Pf, _ = propagate_covariances(
        ep.Phi, ep.pred_covs, ep.covs, params.P0, plan.fwd_epoch_reset, np.full_like(plan.bwd_epoch_reset, -1), table_P
    )
    _, Pb = propagate_covariances(
        ep.Phi, ep.pred_covs, ep.covs, params.P0, np.full_like(plan.fwd_epoch_reset, -1), plan.bwd_epoch_reset, table_Pb
    )
    arr, dep = np.asarray(plan.arrival), np.asarray(plan.departure)
    fwd_a = at_states(pos_a, arr, nav0.pos)
    fwd_p = at_states(pos_p, arr, nav0.pos)
    fwd_b = at_states(pos_b, arr, nav0.pos)
    # backward rows are states before sample i, i.e. state index i; the end state N is the start
    bwd_full = jnp.concatenate([pos_r, nav_end.pos[None]], 0)
    bwd = bwd_full[dep]
    vf = _enu_var(Pf[np.asarray(plan.arr_epoch)], fwd_b)
    vb = _enu_var(Pb[np.asarray(plan.dep_epoch)], bwd)
    has_next = jnp.asarray(plan.has_next)[:, None]
    w = jnp.where(has_next, vb / (vf + vb), 1.0)
    d_b = enu_difference(bwd, fwd_b)
    fused_enu = (1.0 - w) * d_b
    fused = fwd_b + enu_to_curvilinear(fwd_b, fused_enu)
    sw = jnp.asarray(plan.stop_epoch_w)[..., None]
    sidx = np.asarray(plan.stop_epochs)
    filt = jnp.sum(ep.nav.pos[sidx] * sw, 1)
    rts = jnp.sum(nav_s.pos[sidx] * sw, 1)
    targets = dict(forward=fwd_a, preprocessed=fwd_p, smoothed=fwd_b, fused=fused, filtered=filt, rts=rts)
    route = dict(forward=pos_a, smoothed=pos_b, backward=pos_r) if return_route else None
    status = res.status | jnp.bitwise_or.reduce(st4)
    return SurveyOutput(
        targets=targets,
        sigma_forward=jnp.sqrt(vf),
        sigma_backward=jnp.sqrt(vb),
        weight_forward=w,
        backward=bwd,
        biases=bias_s,
        nav_smoothed=nav_s,
        nav_filtered=ep.nav,
        n_rejected=n_rej,
        status=status,
        route=route,
    )


def target_errors(out: SurveyOutput, truth_pos):
    """E/N/U errors of every stage's target positions, m: dict stage -> (T, 3)."""
    return {s: enu_difference(out.targets[s], truth_pos) for s in STAGES}


def summarize_errors(errors: dict) -> dict:
    """Summaries over seeds and targets: horizontal and vertical RMS, mean, median, 95th percentile.

    Args:
      errors: dict stage -> (S, T, 3) E/N/U errors, m.
    Returns:
      dict stage -> dict of floats; plus ``gain`` ratios of RMS horizontal/vertical vs stage (a).
    """
    out = {}
    for s, e in errors.items():
        e = np.asarray(e)
        hz = np.hypot(e[..., 0], e[..., 1]).ravel()
        vt = np.abs(e[..., 2]).ravel()
        out[s] = {
            "rms_h": float(np.sqrt(np.mean(hz**2))),
            "rms_v": float(np.sqrt(np.mean(vt**2))),
            "mean_h": float(hz.mean()),
            "mean_v": float(vt.mean()),
            "median_h": float(np.median(hz)),
            "median_v": float(np.median(vt)),
            "p95_h": float(np.percentile(hz, 95)),
            "p95_v": float(np.percentile(vt, 95)),
            "n": int(hz.size),
        }
    if "forward" in out:
        ref = out["forward"]
        for s in out:
            out[s]["ratio_h_vs_forward"] = out[s]["rms_h"] / ref["rms_h"]
            out[s]["ratio_v_vs_forward"] = out[s]["rms_v"] / ref["rms_v"]
    return out


__all__ = [
    "STAGES",
    "STOP_KINDS",
    "CadastralParams",
    "cadastral_params",
    "SurveyOutput",
    "SurveyPlan",
    "enu_difference",
    "plan_survey",
    "process_survey",
    "propagate_covariances",
    "stop_measurements",
    "strapdown_with_resets",
    "summarize_errors",
    "target_errors",
]


def cadastral_params(
    *,
    gyro_bias,
    gyro_markov,
    gyro_tau,
    gyro_arw,
    accel_bias,
    accel_vrw,
    attitude_sigma,
    velocity_sigma=0.01,
    position_sigma=0.005,
    zupt_sigma=0.005,
    pre: PreprocessParams = PreprocessParams(),
) -> CadastralParams:
    """Class-1 filter parameters from a sensor specification (SI; scalars or (3,)).

    P0 = diag(attitude^2, velocity^2, position^2 (as lat/lon/h at the filter's scale: metres are
    converted with a 6.4e6 m Earth radius), gyro bias^2, gyro Markov^2, accel bias^2);
    Qc of :data:`jaxnav.ins.ERROR_MODEL_18` (ARW, Markov driving noise, VRW; :meth:`jaxnav.ins.ErrorModel.Qc`).

    Args:
      gyro_bias, gyro_markov: rad/s.  gyro_tau: s.  gyro_arw: rad/sqrt(s).
      accel_bias: m/s^2.  accel_vrw: m/s/sqrt(s).  attitude_sigma: rad (E, N, U tilt/heading).
      velocity_sigma: m/s.  position_sigma: m.  zupt_sigma: m/s.  pre: preprocessing parameters.
    Returns:
      :class:`CadastralParams`.
    Notes:
      A Markov std of zero is floored at 1 % of the bias std (and 1e-10 rad/s) so the predicted
      covariances stay positive definite for the RTS smoother.
    """
    from jaxnav.ins import ERROR_MODEL_18, ImuNoise

    v3 = lambda x: jnp.broadcast_to(jnp.asarray(x, jnp.float64), (3,))
    gm = jnp.maximum(v3(gyro_markov), jnp.maximum(0.01 * v3(gyro_bias), 1e-10))
    r = 6.4e6
    P0 = jnp.diag(
        jnp.concatenate(
            [
                v3(attitude_sigma) ** 2,
                v3(velocity_sigma) ** 2,
                jnp.array([(position_sigma / r) ** 2, (position_sigma / r) ** 2, position_sigma**2]),
                jnp.maximum(v3(gyro_bias), 1e-10) ** 2,
                gm**2,
                jnp.maximum(v3(accel_bias), 1e-8) ** 2,
            ]
        )
    )
    Qc = ERROR_MODEL_18.Qc(
        ImuNoise(gyro_arw=v3(gyro_arw), accel_vrw=v3(accel_vrw), gyro_bias_instability=gm, gyro_bias_tau=v3(gyro_tau))
    )
    return CadastralParams(
        P0=P0, Qc=Qc, tau_markov=v3(gyro_tau), zupt_sigma=jnp.asarray(zupt_sigma, jnp.float64), pre=pre
    )
