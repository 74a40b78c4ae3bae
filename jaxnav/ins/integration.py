"""Loosely coupled INS/GNSS integration with feedback correction (S0 experiment; S3 stop updates).

One nested ``lax.scan``: the outer scan runs over measurement epochs, the inner one over the
IMU samples between them. Each epoch is four pure steps:

* propagate (:func:`_propagate_samples`, or :func:`_propagate_blocks` with ``nav_every > 1``):
  the strapdown step (:func:`jaxnav.ins.mech_step`) integrates bias-corrected increments while
  the integrals of what the error-state system matrix depends on (position, velocity, specific
  force and C_bn) are accumulated;
* discretise (:func:`_discretise`): F from their time averages, the interval's transition and
  process noise by a Taylor series or Van Loan's matrix exponential;
* measure (:func:`_measure`): the INS extrapolated to the epoch time, the antenna's position and
  velocity, z, H and R; then **the filter family's own** :func:`jaxnav.filters.filter_step`
  performs the prediction and the update, so every prior-inflation rule (constant, attenuated
  S_k, fading lambda_k) and noise estimator plugs in unchanged;
* feedback (:func:`_feedback`): the estimate is fed back (attitude, velocity, position reset;
  sensor-error estimates accumulated and applied to the IMU) and the error state restarts at zero.

The error-state model (18 or 15 states) is an :class:`jaxnav.ins.ErrorModel` chosen once per run.

With ``nav_every > 1`` the inner loop is replaced by the two-speed mechanization of
:func:`jaxnav.ins.mechanize` (array operations over the epoch's samples, one navigation-frame
update per ``nav_every`` samples, F's averages from the blocks): ~3x faster per run.

Measurements are position and velocity in local ENU metres with an antenna lever arm; the same
structure carries GNSS fixes and pseudo-measurements (ZUPT: velocity 0; known position; known
height: only the up component), selected per component by a mask. Epochs are matched to the
IMU by time, not index: an epoch between two IMU samples is compared with the INS state
extrapolated from the last sample to the epoch time.
"""

from __future__ import annotations

from functools import partial
from typing import Any, NamedTuple, Optional

import jax
import jax.numpy as jnp
import numpy as np

from jaxnav import _status
from jaxnav.filters import (
    FilterParams,
    FilterState,
    KalmanResult,
    LinearGaussian,
    NoEstimator,
    NoInflation,
    StepInput,
    filter_step,
    init_state,
    rts_smoother,
)
from jaxnav.geodesy import WGS84, Ellipsoid, check_float64, curvilinear_to_enu, enu_to_curvilinear
from jaxnav.ins.attitude import quat_mul, quat_normalize, quat_rotate, quat_to_dcm, rv_to_quat, skew
from jaxnav.ins.earth import earth_params, position_rate
from jaxnav.ins.error_model import ErrorModel, discretize_taylor, discretize_van_loan, error_model_for
from jaxnav.ins.mechanization import (
    ImuSample,
    MechParams,
    MechState,
    NavState,
    _body_blocks,
    _imu_flags,
    _scan_blocks,
    _two_speed_start,
    _TwoSpeed,
    mech_step,
)


#: per-epoch outputs that :func:`loosely_coupled` can save
LC_OUTPUTS = ("nav", "biases", "covs", "pred_covs", "Phi", "corrections", "innovations", "innov_covs",
              "nis", "factors", "noise", "valid")


class PVMeasurements(NamedTuple):
    """Position/velocity measurements at M epochs (GNSS fixes or stop pseudo-measurements).

    Attributes:
      t: (M,) epoch times, s (same time scale as the IMU), strictly increasing.
      pos: (M, 3) [lat rad, lon rad, h m] of the antenna (or the known point).
      vel: (M, 3) ENU velocity, m/s (zeros for a ZUPT).
      R: (M, 6, 6) covariance of [pos E, N, U (m), vel E, N, U (m/s)].
      mask: (M, 6) bool, which components are used (NaN components are masked automatically).
      lever: (M, 3) antenna lever arm in the body frame, m (zeros for pseudo-measurements at the IMU).
    """

    t: Any
    pos: Any
    vel: Any
    R: Any
    mask: Any
    lever: Any


class LCParams(NamedTuple):
    """Tunable array parameters of the integration filter (all leaves reach ``vmap``/``grad``).

    Attributes:
      P0: (n, n) initial error covariance (n = 18 or 15, order of :data:`jaxnav.ins.IDX18`).
      Qc: (p, p) continuous noise density (9 x 9 from :func:`jaxnav.ins.error_model_Qc`, 6 x 6
        from :func:`jaxnav.ins.error_model_Qc15`).
      tau_markov: scalar or (3,) gyro Markov correlation time, s (unused for 15 states).
      R_scale: scalar multiplying every measurement covariance (assumed-noise mismatch studies).
    """

    P0: Any
    Qc: Any
    tau_markov: Any = 300.0
    R_scale: Any = 1.0


class SensorBiases(NamedTuple):
    """Accumulated sensor-error corrections applied to the raw IMU (body frame).

    Attributes:
      gyro: (3,) gyro random constant, rad/s.  markov: (3,) gyro Markov drift (decays with tau), rad/s.
      accel: (3,) accelerometer random constant, m/s^2.
    """

    gyro: Any
    markov: Any
    accel: Any


class LCEpochs(NamedTuple):
    """Per-epoch outputs (leading axis M; fields not saved are None).

    Attributes:
      t: (M,) epoch times.  t_nav: (M,) time of the IMU sample the state refers to.
      nav: :class:`NavState` after feedback, at t_nav.  biases: :class:`SensorBiases` after feedback.
      covs: (M, n, n) error covariance after the update.  pred_covs: (M, n, n) prior (after inflation).
      Phi: (M, n, n) transition from the previous epoch.  corrections: (M, n) estimate fed back.
      innovations, innov_covs, nis, factors, noise, valid: as :class:`jaxnav.filters.KalmanResult`.
    """

    t: Any = None
    t_nav: Any = None
    nav: Any = None
    biases: Any = None
    covs: Any = None
    pred_covs: Any = None
    Phi: Any = None
    corrections: Any = None
    innovations: Any = None
    innov_covs: Any = None
    nis: Any = None
    factors: Any = None
    noise: Any = None
    valid: Any = None


class LCResult(NamedTuple):
    """Result of :func:`loosely_coupled`.

    Attributes:
      epochs: :class:`LCEpochs`.  final_nav: :class:`NavState` at the last IMU sample used.
      final_biases: :class:`SensorBiases`.  loglik: innovation log-likelihood.
      n_nonfinite: NaN/inf measurement components masked.  n_skipped: epochs without any update.
      status: int32 flags.  imu_nav: per-sample :class:`NavState` every ``save_imu_every`` samples, or None.
    """

    epochs: LCEpochs
    final_nav: Any
    final_biases: Any
    loglik: Any
    n_nonfinite: Any
    n_skipped: Any
    status: Any
    imu_nav: Any = None


class Segments(NamedTuple):
    """Host-computed map of IMU samples to measurement epochs (static shapes for the nested scan)."""

    idx: Any  # (M, K) int IMU sample indices per epoch interval (padded)
    use: Any  # (M, K) bool, real samples
    t_last: Any  # (M,) end time of the last IMU sample before each epoch
    K: int


def segment_imu(t_imu, t_meas, dt_imu) -> Segments:
    """Assign IMU samples to measurement epochs by time (host side, numpy).

    Sample i covers (t_imu[i] - dt_imu[i], t_imu[i]]; epoch j receives the samples whose end time
    is in (t_meas[j-1], t_meas[j]] (the first epoch also everything before it).

    Raises:
      ValueError: if times are not increasing or the IMU and measurement spans do not overlap.
    """
    t_imu = np.asarray(t_imu, dtype=float)
    t_meas = np.asarray(t_meas, dtype=float)
    if t_imu.ndim != 1 or t_meas.ndim != 1:
        raise ValueError(f"IMU times {t_imu.shape} and measurement times {t_meas.shape} must be 1-D")
    if np.any(np.diff(t_imu) <= 0):
        raise ValueError(f"IMU times are not strictly increasing (index {int(np.argmax(np.diff(t_imu) <= 0)) + 1})")
    if np.any(np.diff(t_meas) <= 0):
        raise ValueError(f"measurement times are not strictly increasing (index {int(np.argmax(np.diff(t_meas) <= 0)) + 1})")
    t_start = t_imu[0] - np.broadcast_to(np.asarray(dt_imu, float), t_imu.shape)[0]
    if t_meas[0] <= t_start or t_meas[-1] > t_imu[-1] + 1e-9 or t_meas[0] > t_imu[-1]:
        raise ValueError(
            f"measurement epochs [{t_meas[0]:.6f}, {t_meas[-1]:.6f}] s are not inside the IMU span "
            f"({t_start:.6f}, {t_imu[-1]:.6f}] s; trim the measurements to the IMU data")
    ends = np.searchsorted(t_imu, t_meas + 1e-9, side="right")  # samples with t_imu <= t_meas
    starts = np.concatenate([[0], ends[:-1]])
    counts = ends - starts
    if np.any(counts == 0):
        j = int(np.argmax(counts == 0))
        raise ValueError(f"no IMU sample between measurement epochs {j - 1} and {j} (t = {t_meas[j]:.6f} s)")
    K = int(counts.max())
    idx = starts[:, None] + np.arange(K)[None, :]
    use = idx < ends[:, None]
    idx = np.minimum(idx, len(t_imu) - 1)
    return Segments(idx=idx, use=use, t_last=t_imu[ends - 1], K=K)


def measurement_model(nav: NavState, w_ib_b, lever_b, n_states: int, ellipsoid: Ellipsoid = WGS84):
    """Predicted antenna position/velocity and H (6 x n) of the PV measurement.

    z = [D (pos_ins_ant - pos_meas) (ENU m), v_ins_ant - v_meas (ENU m/s)] with
    pos_ant = pos + C_bn l, v_ant = v + C_bn (w_nb^b x l). With the phi-angle convention
    (C_computed = (I - [phi x]) C_true): dz_pos = D dpos + [(C_bn l) x] phi,
    dz_vel = dV + [(C_bn (w x l)) x] phi.

    Returns:
      (pos_ant (3,), v_ant (3,), H (6, n)).
    """
    C = quat_to_dcm(nav.q_bn)
    e = earth_params(nav.pos, nav.v_n, ellipsoid)
    w_nb_b = w_ib_b - C.T @ e.w_in_n
    l_n = C @ lever_b
    lv_n = C @ jnp.cross(w_nb_b, lever_b)
    pos_ant = nav.pos + enu_to_curvilinear(nav.pos, l_n, ellipsoid)
    v_ant = nav.v_n + lv_n
    # D: rows E, N, U; columns dlat, dlon, dh. s: metres per rad of dlon (E), per rad of dlat (N), per m of dh
    s = curvilinear_to_enu(nav.pos, jnp.ones(3, nav.pos.dtype), ellipsoid)
    D = jnp.array([[0.0, s[0], 0.0], [s[1], 0.0, 0.0], [0.0, 0.0, 1.0]])
    H = jnp.zeros((6, n_states), nav.v_n.dtype)
    H = H.at[0:3, 0:3].set(skew(l_n)).at[0:3, 6:9].set(D)
    H = H.at[3:6, 0:3].set(skew(lv_n)).at[3:6, 3:6].set(jnp.eye(3, dtype=H.dtype))
    return pos_ant, v_ant, H


def _apply_correction(nav: NavState, biases: SensorBiases, x, idx):
    """Feed an error estimate back: q <- rv2q(phi) (x) q, v -= dV, pos -= dpos, biases += estimates."""
    q = quat_normalize(quat_mul(rv_to_quat(x[idx.phi]), nav.q_bn))
    nav = NavState(q_bn=q, v_n=nav.v_n - x[idx.dv], pos=nav.pos - x[idx.dpos])
    markov = biases.markov + (x[idx.eps_r] if idx.eps_r is not None else 0.0)
    biases = SensorBiases(gyro=biases.gyro + x[idx.eps_b], markov=markov, accel=biases.accel + x[idx.nabla])
    return nav, biases


class _Carry(NamedTuple):
    """Carry of the epoch scan."""

    mech: MechState
    biases: SensorBiases
    kf: FilterState
    G_prev: Any = None  # two-speed mechanization: the last block's gravity minus Coriolis (else None)


class _Sums(NamedTuple):
    """Integrals over one epoch interval of what F depends on; divided by the interval they build F.

    F is linear in f_n and C_bn and varies slowly with pos and v, so F at the time averages equals
    the average of F up to O(dt_epoch^2) in the slowly varying terms.
    """

    pos: Any  # (3,) sum pos dt
    v: Any  # (3,) sum v_n dt, m
    f: Any  # (3,) sum C_bn dv = integral of f_n dt, m/s
    C: Any  # (3, 3) sum C_bn dt, s


class _Propagated(NamedTuple):
    """The INS at the last IMU sample of an epoch interval, and what the filter needs from the interval."""

    mech: MechState
    biases: SensorBiases  # the Markov drift decayed over the interval
    sums: _Sums
    T: Any  # time covered by the interval's samples, s
    w_last: Any  # (3,) angular rate of the last sample, rad/s (lever-arm velocity)
    G: Any  # two-speed: the last block's gravity minus Coriolis (else None)


def _where_tree(c, a, b):
    return jax.tree_util.tree_map(lambda x, y: jnp.where(c, x, y), a, b)


def _zero_sums(dtype):
    z3 = jnp.zeros(3, dtype)
    return _Sums(z3, z3, z3, jnp.zeros((3, 3), dtype))


def _propagate_samples(mech: MechState, biases: SensorBiases, rows, tau, ellipsoid, hold_height, save_imu_every):
    """The IMU samples of one epoch interval, one :func:`mech_step` each, with the sensor-error correction.

    Args:
      rows: (raw dtheta (K, 3) rad, raw dv (K, 3) m/s, dt (K,) s, use (K,) bool); unused samples
        (padding) leave everything as it is.
    Returns:
      (:class:`_Propagated`, NavState every ``save_imu_every``-th sample or None).
    """
    dtype = mech.nav.v_n.dtype
    mparams = MechParams(earth_rate_sign=1.0)

    def step(c, x):
        (mech, biases, sums, T, w_last), (dth_raw, dv_raw, dt, use) = c, x
        dth = dth_raw - (biases.gyro + biases.markov) * dt
        dvc = dv_raw - biases.accel * dt
        new_mech, nav = mech_step(mech, ImuSample(dth, dvc, dt), mparams, ellipsoid=ellipsoid,
                                  hold_height=hold_height)
        C = quat_to_dcm(nav.q_bn)
        sums = _Sums(sums.pos + nav.pos * dt, sums.v + nav.v_n * dt, sums.f + C @ dvc, sums.C + C * dt)
        new = (new_mech, biases._replace(markov=biases.markov * jnp.exp(-dt / tau)), sums, T + dt, dth / dt)
        return _where_tree(use, new, c), (nav if save_imu_every else None)

    init = (mech, biases, _zero_sums(dtype), jnp.zeros((), dtype), jnp.zeros(3, dtype))
    (mech, biases, sums, T, w_last), navs = jax.lax.scan(step, init, rows)
    if save_imu_every:
        navs = jax.tree_util.tree_map(lambda a: a[save_imu_every - 1::save_imu_every], navs)
    return _Propagated(mech, biases, sums, T, w_last, None), navs


def _propagate_blocks(mech: MechState, biases: SensorBiases, G_prev, rows, tau, M: int, ellipsoid, hold_height):
    """The IMU samples of one epoch interval by the two-speed mechanization (:func:`jaxnav.ins.mechanize`'s
    ``nav_every``), with the sensor-error correction and F's sums.

    Bias-corrected increments, coning/sculling and the in-block attitude increments are array
    operations over the epoch's K samples; one navigation-frame update per M samples is the block
    driver :func:`jaxnav.ins.mechanization._scan_blocks`. The Markov drift decays sample by
    sample exactly as in the per-sample loop. The sums of pos and v use each block's mid-point
    position and mean velocity, those of f_n and C_bn the block's body-frame sums rotated by its
    start attitude (the nav frame turns < 1e-5 rad in a block).

    Args:
      rows: as :func:`_propagate_samples` (padded samples at the end).  M: static block length.
    Returns:
      :class:`_Propagated`.
    """
    dth_raw, dv_raw, dt, use = rows
    dtype = dt.dtype
    K = dt.shape[0]
    dtu = jnp.where(use, dt, 0.0)
    decay_before = jnp.exp(-(jnp.cumsum(dtu) - dtu)[:, None] / tau)  # Markov factor at each sample
    dth = jnp.where(use[:, None], dth_raw - (biases.gyro + biases.markov * decay_before) * dtu[:, None], 0.0)
    dvc = jnp.where(use[:, None], dv_raw - biases.accel * dtu[:, None], 0.0)
    nb = -(-K // M)
    padn = nb * M - K
    pad = lambda a: jnp.concatenate([a, jnp.zeros((padn,) + a.shape[1:], dtype)]) if padn else a  # noqa: E731
    blk, pre = _body_blocks(pad(dth), pad(dvc), pad(dtu), mech.dtheta_prev, mech.dv_prev, M, True, prefix=True)
    Bq = jnp.stack(pre.B, axis=-1)  # (nb, M, 4) body rotation to the end of each sample
    f_b = jnp.sum(quat_rotate(Bq, pad(dvc).reshape(nb, M, 3)), axis=1)  # (nb, 3)
    C_b = jnp.sum(quat_to_dcm(Bq) * pad(dtu).reshape(nb, M)[..., None, None], axis=1)  # (nb, 3, 3)

    def add(sums, start, fr, T, x):
        fb, Cb = x
        C0 = quat_to_dcm(start.q_bn)
        return _Sums(sums.pos + fr.pos_mid * T, sums.v + fr.v_mid * T, sums.f + C0 @ fb, sums.C + C0 @ Cb)

    two, sums, _ = _scan_blocks(_TwoSpeed(mech.nav, mech.a_prev, G_prev), blk, 1.0, ellipsoid, hold_height,
                                acc=_zero_sums(dtype), accumulate=add, xs=(f_b, C_b), skip_empty=True)
    last = jnp.maximum(jnp.sum(use) - 1, 0)
    flags = _imu_flags(dth, dvc, jnp.where(use, dt, 1.0), series=True)
    new_mech = MechState(nav=two.nav, dtheta_prev=dth[last], dv_prev=dvc[last], a_prev=two.a_prev,
                         status=mech.status | flags)
    T = jnp.sum(dtu)
    new_biases = biases._replace(markov=biases.markov * jnp.exp(-T / tau))
    return _Propagated(new_mech, new_biases, sums, T, dth[last] / dt[last], two.G)


def _discretise(model: ErrorModel, p: _Propagated, tau, Qc, ellipsoid, method, order):
    """Phi and Qd of one epoch interval (S0 eqs. (1), (8)) from F at the interval's time averages.

    Returns:
      (Phi (n, n), Qd (n, n), int32 flag: DISCRETIZATION_INACCURATE if the Taylor series had not converged).
    """
    Tsafe = jnp.maximum(p.T, 1e-300)
    F = model.F(*(a / Tsafe for a in p.sums), tau, ellipsoid=ellipsoid)
    G = model.G(quat_to_dcm(p.mech.nav.q_bn))
    if method == "van_loan":
        Phi, Qd = discretize_van_loan(F, G, Qc, p.T)
        return Phi, Qd, jnp.zeros((), jnp.int32)
    Phi, Qd, err = discretize_taylor(F, G, Qc, p.T, order=order)
    return Phi, Qd, jnp.where(err > 1e-10, _status.DISCRETIZATION_INACCURATE, 0).astype(jnp.int32)


def _measure(nav: NavState, w_last, dtx, m: PVMeasurements, R_scale, n: int, ellipsoid):
    """z (6,), H (6, n), R (6, 6) of one epoch's PV measurement (m: its row of :class:`PVMeasurements`).

    The INS state is extrapolated from its last IMU sample by dtx = t_epoch - t_sample (s).
    """
    nav_x = nav._replace(pos=nav.pos + dtx * position_rate(nav.pos, nav.v_n, ellipsoid))
    pos_ant, v_ant, H = measurement_model(nav_x, w_last, m.lever, n, ellipsoid)
    z = jnp.concatenate([curvilinear_to_enu(nav_x.pos, pos_ant - m.pos, ellipsoid), v_ant - m.vel])
    return z, H, R_scale * m.R


def _feedback(p: _Propagated, kf: FilterState, idx, flag) -> _Carry:
    """Feed the estimate kf.x back to the INS and the sensor errors; the error state restarts at zero."""
    nav, biases = _apply_correction(p.mech.nav, p.biases, kf.x, idx)
    kf = kf._replace(x=jnp.zeros_like(kf.x), status=kf.status | flag)
    return _Carry(mech=p.mech._replace(nav=nav), biases=biases, kf=kf, G_prev=p.G)


_STEP_OUTPUTS = ("means", "covs", "pred_covs", "innovations", "innov_covs", "nis", "factors", "noise", "valid")


@partial(jax.jit, static_argnames=("n_states", "save", "ellipsoid", "hold_height", "check_finite",
                                   "save_imu_every", "remat", "discretization", "taylor_order", "nav_every"))
def _lc_core(nav0, biases0, dtheta, dv, dt_imu, t_imu, seg_idx, seg_use, t_last, meas, params, inflation,
             estimator, n_states, save, ellipsoid, hold_height, check_finite, save_imu_every, remat=False,
             discretization="taylor", taylor_order=8, nav_every=1):
    dtype = nav0.v_n.dtype
    model = error_model_for(n_states)
    tau = jnp.broadcast_to(jnp.asarray(params.tau_markov, dtype), (3,))
    Qc, R_scale = jnp.asarray(params.Qc, dtype), jnp.asarray(params.R_scale, dtype)
    fparams = FilterParams(model=LinearGaussian(None, None, None, None, None),
                           inflation=NoInflation() if inflation is None else inflation,
                           estimator=NoEstimator() if estimator is None else estimator)

    def outer(carry: _Carry, inp):
        rows, t_meas, t_nav, m = inp
        if nav_every > 1:
            p = _propagate_blocks(carry.mech, carry.biases, carry.G_prev, rows, tau, nav_every, ellipsoid, hold_height)
            navs = None
        else:
            p, navs = _propagate_samples(carry.mech, carry.biases, rows, tau, ellipsoid, hold_height, save_imu_every)
        Phi, Qd, flag = _discretise(model, p, tau, Qc, ellipsoid, discretization, taylor_order)
        z, H, R = _measure(p.mech.nav, p.w_last, t_meas - t_nav, m, R_scale, model.n, ellipsoid)
        # x is zero after every feedback; the literal zero lets XLA drop the products F x and H x
        kf_prior = carry.kf._replace(x=jnp.zeros(model.n, dtype))
        kf, info = filter_step(kf_prior, StepInput(z=z, mask=m.mask, F=Phi, H=H, Q=Qd, R=R), fparams,
                               save=_STEP_OUTPUTS, check_finite=check_finite)
        new = _feedback(p, kf, model.idx, flag)
        allv = dict(nav=new.mech.nav, biases=new.biases, covs=kf.P, pred_covs=info.pred_covs, Phi=Phi,
                    corrections=kf.x, innovations=info.innovations, innov_covs=info.innov_covs, nis=info.nis,
                    factors=info.factors, noise=info.noise, valid=info.valid)
        return new, (LCEpochs(t=t_meas, t_nav=t_nav, **{k: allv[k] for k in save}), navs)

    z3 = jnp.zeros(3, dtype)
    mech0 = MechState(nav=nav0, dtheta_prev=z3, dv_prev=z3, a_prev=z3, status=jnp.zeros((), jnp.int32))
    kf0 = init_state(jnp.zeros(model.n, dtype), params.P0, 6, inflation=inflation, estimator=estimator)
    G0 = _two_speed_start(nav0, z3, 1.0, ellipsoid).G if nav_every > 1 else None
    if remat:
        # reverse mode keeps only the per-epoch carries and recomputes each epoch's IMU samples
        # on the way back: tape memory O(epochs) instead of O(IMU samples)
        outer = jax.checkpoint(outer)
    # gather the IMU samples of every epoch interval once: (M, K, 3), padded samples get dt = 1
    # and are skipped by the ``use`` mask (no dynamic indexing inside the scan)
    dt_all = jnp.broadcast_to(jnp.asarray(dt_imu, dtype), (dtheta.shape[0],))
    rows = (dtheta[seg_idx], dv[seg_idx], jnp.where(seg_use, dt_all[seg_idx], 1.0), seg_use)
    final, (ep, navs) = jax.lax.scan(outer, _Carry(mech0, biases0, kf0, G0), (rows, meas.t, t_last, meas))
    return LCResult(epochs=ep, final_nav=final.mech.nav, final_biases=final.biases, loglik=final.kf.loglik,
                    n_nonfinite=final.kf.n_nonfinite, n_skipped=final.kf.n_skipped,
                    status=final.kf.status | final.mech.status, imu_nav=navs if save_imu_every else None)


def loosely_coupled(nav0: NavState, t_imu, dtheta, dv, meas: PVMeasurements, params: LCParams, *,
                    dt_imu=None, biases0: Optional[SensorBiases] = None, n_states: int = 18, inflation=None,
                    estimator=None, save=("nav", "biases", "covs", "pred_covs", "Phi", "corrections",
                                          "innovations", "nis", "factors", "valid"),
                    ellipsoid: Ellipsoid = WGS84, hold_height: bool = False, check_finite: bool = True,
                    max_sigma: float = 1e3, save_imu_every: int = 0, remat: bool = False,
                    discretization: str = "taylor", taylor_order: int = 8, nav_every: int = 1) -> LCResult:
    """Loosely coupled INS/GNSS filter with feedback correction (S0 experiment, eqs. (4)-(19)).

    Args:
      nav0: initial :class:`NavState` at ``t_imu[0] - dt_imu[0]``.
      t_imu: (N,) end time of each IMU sample, s (concrete: it shapes the nested scan).
      dtheta: (N, 3) angular increments, rad.  dv: (N, 3) velocity increments, m/s (body frame).
      meas: :class:`PVMeasurements` (times concrete); components with a standard deviation above
        ``max_sigma`` (m or m/s) or NaN are masked and counted.
      params: :class:`LCParams` (array leaves: P0, Qc, tau, R scale).
      dt_imu: scalar or (N,) sample intervals (default: from ``t_imu``, the first copied).
      biases0: initial :class:`SensorBiases` (default zeros).
      n_states: static 18 (S0) or 15 (no Markov drift).
      inflation, estimator: plug-ins of :mod:`jaxnav.filters` (classic when None).
      save: static per-epoch outputs (subset of ``LC_OUTPUTS``).
      ellipsoid, hold_height: static, as :func:`jaxnav.ins.mechanize`.
      check_finite: static, as :func:`jaxnav.filters.kalman_filter`.
      save_imu_every: static; if > 0 also return the navigation state every k-th IMU sample.
      remat: static; wrap each GNSS epoch in ``jax.checkpoint`` so that reverse-mode gradients
        (``jax.grad`` w.r.t. b, rho, noise scales) store one carry per epoch instead of every
        IMU sample's intermediates (the forward result is identical).
      discretization: static; "taylor" (default): Phi and Qd per epoch by
        :func:`~jaxnav.ins.discretize_taylor` with ``taylor_order`` terms, flagging
        DISCRETIZATION_INACCURATE in ``status`` if the series had not converged; "van_loan": the
        matrix exponential of :func:`~jaxnav.ins.discretize_van_loan`. For S0 (1 s epochs) both
        agree to ~1e-15; the series is 2.4x faster per run and 3x faster under ``jax.jvp``.
      taylor_order: static number of series terms (default 8).
      nav_every: static; > 1 mechanizes the samples between fixes by the two-speed algorithm of
        :func:`jaxnav.ins.mechanize` (navigation-frame terms once per ``nav_every`` samples,
        the body-frame work as array operations), and takes the time averages that F needs from
        the blocks (mid-block position, mean velocity, block sums of f_n and C_bn). 1 (default):
        the per-sample :func:`jaxnav.ins.mech_step` loop. Not combined with ``save_imu_every``.
    Returns:
      :class:`LCResult`.
    Raises:
      ValueError: shapes, non-increasing times, IMU/measurement spans that do not overlap.
    """
    model = error_model_for(n_states)  # raises ValueError for other sizes
    if discretization not in ("taylor", "van_loan"):
        raise ValueError(f"discretization must be 'taylor' or 'van_loan', got {discretization!r}")
    unknown = [s for s in save if s not in LC_OUTPUTS]
    if unknown:
        raise ValueError(f"unknown outputs {unknown}; choose from {LC_OUTPUTS}")
    N = np.shape(t_imu)[0]
    if jnp.shape(dtheta) != (N, 3) or jnp.shape(dv) != (N, 3):
        raise ValueError(f"dtheta {jnp.shape(dtheta)} and dv {jnp.shape(dv)} must be ({N}, 3) to match t_imu")
    M = np.shape(meas.t)[0]
    for name, shp in (("pos", (M, 3)), ("vel", (M, 3)), ("R", (M, 6, 6)), ("mask", (M, 6)), ("lever", (M, 3))):
        if jnp.shape(getattr(meas, name)) != shp:
            raise ValueError(f"meas.{name} has shape {jnp.shape(getattr(meas, name))}; expected {shp}")
    n, p = model.n, model.p
    if jnp.shape(params.P0) != (n, n) or jnp.shape(params.Qc) != (p, p):
        raise ValueError(f"params.P0 {jnp.shape(params.P0)} / Qc {jnp.shape(params.Qc)} must be "
                         f"({n}, {n}) / ({p}, {p}) for n_states={n_states}")
    check_float64(nav0.pos, meas.pos, what="absolute positions")
    if isinstance(t_imu, jax.core.Tracer) or isinstance(meas.t, jax.core.Tracer):
        raise ValueError("t_imu and meas.t must be concrete arrays (they set the scan's shapes); close over "
                         "them instead of passing them through jit/vmap")
    t_imu = np.asarray(t_imu, dtype=float)
    if dt_imu is None:
        d = np.diff(t_imu)
        dt_imu = np.concatenate([d[:1], d])
    seg = segment_imu(t_imu, np.asarray(meas.t, float), dt_imu)
    sig = jnp.sqrt(jnp.diagonal(meas.R, axis1=1, axis2=2))
    mask = jnp.asarray(meas.mask, bool) & (sig <= max_sigma)
    meas = meas._replace(mask=mask, t=jnp.asarray(meas.t, jnp.float64))
    z3 = jnp.zeros(3, jnp.asarray(nav0.v_n).dtype)
    biases0 = SensorBiases(z3, z3, z3) if biases0 is None else biases0
    if not isinstance(nav_every, (int, np.integer)) or nav_every < 1:
        raise ValueError(f"nav_every={nav_every!r} must be an integer >= 1")
    if nav_every > 1 and save_imu_every:
        raise ValueError("save_imu_every needs the per-sample loop: use nav_every=1")
    if save_imu_every and seg.K % save_imu_every:
        raise ValueError(f"save_imu_every={save_imu_every} must divide the samples per epoch interval ({seg.K})")
    return _lc_core(nav0, biases0, jnp.asarray(dtheta), jnp.asarray(dv), dt_imu, t_imu, seg.idx, seg.use,
                    seg.t_last, meas, params, inflation, estimator, n_states, tuple(save), ellipsoid,
                    hold_height, check_finite, int(save_imu_every), bool(remat), discretization, int(taylor_order),
                    int(nav_every))


def smooth(result: LCResult, *, n_states: int = 18) -> tuple[NavState, SensorBiases, Any]:
    """RTS smoothing of a feedback filter over its saved epoch moments, applied to the navigation solution.

    Take each epoch's post-feedback state as the reference. There the filtered error mean is
    0, and the prior mean is -x_{j+1} (the prediction, 0 relative to the pre-update state, seen
    from the post-feedback state that the correction x_{j+1} moved). The RTS recursion
    (:func:`jaxnav.filters.rts_smoother` on the saved P, priors and Phi) therefore gives
    dx^s_j = C_j (dx^s_{j+1} + x_{j+1}), C_j = P_j Phi_{j+1}^T P_{j+1|j}^{-1}, dx^s_M = 0; it is
    fed back to the epoch's state like a filter correction.

    Args:
      result: :class:`LCResult` saved with "nav", "biases", "covs", "pred_covs", "Phi", "corrections".
    Returns:
      (smoothed :class:`NavState` (M, ...), smoothed :class:`SensorBiases`, smoothed covariances (M, n, n)).
    """
    ep = result.epochs
    for name in ("nav", "biases", "covs", "pred_covs", "Phi", "corrections"):
        if getattr(ep, name) is None:
            raise ValueError(f"smooth() needs the per-epoch output '{name}' (add it to save=)")
    M, n = ep.covs.shape[:2]
    if n != n_states:
        raise ValueError(f"the result has {n} states; pass n_states={n}")
    zeros = jnp.zeros((M, n), ep.covs.dtype)
    filt = KalmanResult(means=zeros, covs=ep.covs, pred_means=-ep.corrections, pred_covs=ep.pred_covs)
    sm = rts_smoother(LinearGaussian(F=ep.Phi, H=None, Q=None, R=None), filt)
    idx = error_model_for(n).idx
    nav, biases = jax.vmap(lambda nv, b, x: _apply_correction(nv, b, x, idx))(ep.nav, ep.biases, sm.means)
    return nav, biases, sm.covs
