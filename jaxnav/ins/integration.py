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

The error-state model (15, 18 or 21 states) is an :class:`jaxnav.ins.ErrorModel` chosen once per run.

With ``nav_every > 1`` the inner loop is replaced by the two-speed mechanization of
:func:`jaxnav.ins.mechanize` (array operations over the epoch's samples, one navigation-frame
update per ``nav_every`` samples, F's averages from the blocks): ~3x faster per run.

Measurements are position and velocity in local ENU metres with an antenna lever arm; the same
structure carries GNSS fixes and pseudo-measurements (ZUPT: velocity 0; known position; known
height: only the up component), selected per component by a mask. Epochs are matched to the
IMU by time, not index: an epoch between two IMU samples is compared with the INS state
extrapolated from the last sample to the epoch time.

Further measurements come through the general interface of :mod:`jaxnav.ins.measurements`
(``aids=``: ZUPT, ZARU, non-holonomic constraint, odometer, heading, or a user's model): the
filter's epochs are then the GNSS epochs merged with the IMU samples where an aid applies, and
each epoch stacks the rows of every model into one masked update. GNSS epochs can be gated by
their normalised innovation squared against a chi-square quantile (``gate=``, :class:`LCGate`).
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import partial
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from jaxnav import _status
from jaxnav._numerics import masked_measurement, safe_cholesky, whiten
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
from jaxnav.geodesy import WGS84, Ellipsoid, check_float64
from jaxnav.ins.attitude import quat_mul, quat_normalize, quat_rotate, quat_to_dcm, rv_to_quat
from jaxnav.ins.error_model import ERROR_MODEL_18, ErrorModel, discretize_taylor, discretize_van_loan
from jaxnav.ins.measurements import GNSS_PV, Aid, GnssData, MeasContext, MeasRows
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
from jaxnav.ins.noise import ImuNoise

#: per-epoch outputs that :func:`loosely_coupled` can save
LC_OUTPUTS = (
    "nav",
    "biases",
    "covs",
    "pred_covs",
    "Phi",
    "corrections",
    "innovations",
    "innov_covs",
    "nis",
    "factors",
    "noise",
    "valid",
    "gated",
    "gnss_nis",
)


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

    t: ArrayLike
    pos: ArrayLike
    vel: ArrayLike
    R: ArrayLike
    mask: ArrayLike
    lever: ArrayLike


class LCParams(NamedTuple):
    """Tunable array parameters of the integration filter (all leaves reach ``vmap``/``grad``).

    :func:`lc_params` builds them from an :class:`jaxnav.ins.ErrorModel` and an :class:`jaxnav.ins.ImuNoise`.

    Attributes:
      P0: (n, n) initial error covariance (order of the model's names; :meth:`jaxnav.ins.ErrorModel.P0`).
      Qc: (p, p) continuous noise density of the model's noise inputs (:meth:`jaxnav.ins.ErrorModel.Qc`).
      tau_markov: scalar or (3,) gyro Markov correlation time, s (unused for 15 states); for models
        with Gauss-Markov biases (21 states, ``ERROR_MODEL_15GM``) scalar or (6,) correlation times
        [gyro bias (3), accelerometer bias (3)], s, ``inf`` for a random walk.
      R_scale: scalar multiplying every measurement covariance (assumed-noise mismatch studies).
    """

    P0: ArrayLike
    Qc: ArrayLike
    tau_markov: ArrayLike = 300.0
    R_scale: ArrayLike = 1.0


def _floor_sigmas(c, floor):
    """Covariances (..., 3, 3) with standard deviations raised to ``floor`` (correlations kept)."""
    d = jnp.sqrt(jnp.clip(jnp.diagonal(c, axis1=-2, axis2=-1), 0, None))
    s = jnp.maximum(d, floor) / jnp.where(d > 0, d, 1.0)
    c = c * s[..., :, None] * s[..., None, :]
    return jnp.where(jnp.eye(3, dtype=bool), jnp.maximum(c, floor**2), c)


def gnss_measurements(
    t,
    pos,
    vel,
    pos_cov,
    vel_cov,
    *,
    use=None,
    use_vel=None,
    lever=(0.0, 0.0, 0.0),
    pos_sigma_floor=0.0,
    vel_sigma_floor=0.0,
) -> PVMeasurements:
    """:class:`PVMeasurements` of M GNSS fixes: R = blockdiag(position covariance, velocity covariance).

    The standard deviations are floored at ``pos_sigma_floor`` / ``vel_sigma_floor`` with the
    correlations kept; a NaN velocity covariance counts as 1 (m/s)^2 and a NaN velocity is not used.

    Args:
      t: (M,) epoch times, s (concrete: they shape the filter's scan).
      pos: (M, 3) antenna [lat rad, lon rad, h m].  vel: (M, 3) ENU velocity, m/s.
      pos_cov: (M, 3, 3) or (3, 3) ENU position covariance, m^2.  vel_cov: (M, 3, 3) or (3, 3), (m/s)^2.
      use: (M,) bool, epochs whose position (and velocity) are used; None: all.
      use_vel: (M,) bool, epochs whose velocity is used; None: as ``use``.
      lever: (3,) or (M, 3) antenna minus IMU in the body frame (right, forward, up), m.
      pos_sigma_floor: m.  vel_sigma_floor: m/s.
    Returns:
      :class:`PVMeasurements`.
    Raises:
      ValueError: shapes that do not match M.
    """
    M = np.shape(t)[0]
    pos, vel, lever = jnp.asarray(pos, jnp.float64), jnp.asarray(vel, jnp.float64), jnp.asarray(lever, jnp.float64)
    pc = jnp.broadcast_to(jnp.asarray(pos_cov, jnp.float64), (M, 3, 3)) if jnp.shape(pos_cov)[-2:] == (3, 3) else None
    vc = jnp.broadcast_to(jnp.asarray(vel_cov, jnp.float64), (M, 3, 3)) if jnp.shape(vel_cov)[-2:] == (3, 3) else None
    if pos.shape != (M, 3) or vel.shape != (M, 3) or pc is None or vc is None or lever.shape not in ((3,), (M, 3)):
        raise ValueError(
            f"gnss_measurements(): pos {pos.shape}, vel {vel.shape}, pos_cov {jnp.shape(pos_cov)}, vel_cov "
            f"{jnp.shape(vel_cov)}, lever {lever.shape} do not fit {M} epochs: (M, 3), (M, 3), (M, 3, 3) or "
            f"(3, 3), the same, (3,) or (M, 3)"
        )
    use = jnp.ones(M, bool) if use is None else jnp.asarray(use, bool)
    use_vel = use if use_vel is None else jnp.asarray(use_vel, bool)
    R = jnp.zeros((M, 6, 6))
    R = R.at[:, :3, :3].set(_floor_sigmas(pc, pos_sigma_floor))
    R = R.at[:, 3:, 3:].set(_floor_sigmas(jnp.where(jnp.isfinite(vc), vc, 1.0), vel_sigma_floor))
    fin = jnp.isfinite(vel)
    mask = jnp.concatenate([jnp.broadcast_to(use[:, None], (M, 3)), use_vel[:, None] & fin], axis=1)
    return PVMeasurements(
        t=t, pos=pos, vel=jnp.where(fin, vel, 0.0), R=R, mask=mask, lever=jnp.broadcast_to(lever, (M, 3))
    )


def gnss_solution_measurements(
    pos_sol,
    t_imu,
    outages=(),
    *,
    lever_rfu=(0.0, 0.0, 0.0),
    pos_sigma_floor: float = 0.02,
    vel_sigma_floor: float = 0.05,
    use_velocity: bool = True,
    qualities=(1, 2),
):
    """A GNSS solution's epochs inside the IMU span as :func:`gnss_measurements`, masked inside the outages.

    Epochs inside an outage keep an all-False mask, so the filter reports its free-inertial
    prediction there (and the smoother its estimate). Covariances: the solution's ENU position
    and velocity covariances with the standard deviations floored at ``pos_sigma_floor`` (m) and
    ``vel_sigma_floor`` (m/s); a missing velocity covariance counts as 1 (m/s)^2.

    Args:
      pos_sol: a solution record with fields t (s), lat, lon (rad), h (m), q (quality), v_enu (m/s),
        cov_enu, vcov_enu (m^2, (m/s)^2), e.g. :class:`jaxnav.io.PosSolution`.  t_imu: (N,) IMU times, s.  outages: (K, 2) windows, s.
      lever_rfu: (3,) antenna minus IMU in jaxnav's right-forward-up body frame, m.
      qualities: solution qualities (``.pos`` Q: 1 fix, 2 float, ...) used.
    Returns:
      (:class:`jaxnav.ins.PVMeasurements`, index (M,) of the kept solution epochs, withheld (M,) bool).
    """
    t_imu = np.asarray(t_imu, float)
    gt = np.asarray(pos_sol.t, float)
    # an epoch needs an IMU sample ending at or before it (one inside the first sample's interval has none)
    keep = np.nonzero((gt >= t_imu[0] - 1e-9) & (gt <= t_imu[-1]))[0]
    if keep.size < 2:
        raise ValueError(
            f"only {keep.size} GNSS epoch(s) fall inside the IMU span [{t_imu[0]:.3f}, {t_imu[-1]:.3f}] s "
            f"(GNSS [{gt[0]:.3f}, {gt[-1]:.3f}] s): check the time systems and the IMU time offset"
        )
    t = gt[keep]
    pos = np.stack([np.asarray(pos_sol.lat)[keep], np.asarray(pos_sol.lon)[keep], np.asarray(pos_sol.h)[keep]], -1)
    withheld = np.zeros(keep.size, bool)
    for a, b in np.asarray(outages, float).reshape(-1, 2):
        withheld |= (t >= a) & (t < b)
    use = np.isin(np.asarray(pos_sol.q)[keep], np.asarray(qualities)) & ~withheld
    meas = gnss_measurements(
        t,
        pos,
        np.asarray(pos_sol.v_enu, float)[keep],
        np.asarray(pos_sol.cov_enu)[keep],
        np.asarray(pos_sol.vcov_enu, float)[keep],
        use=use,
        use_vel=use if use_velocity else np.zeros_like(use),
        lever=lever_rfu,
        pos_sigma_floor=pos_sigma_floor,
        vel_sigma_floor=vel_sigma_floor,
    )
    return meas, keep, withheld


def lc_params(model: ErrorModel, noise: ImuNoise, pos0, *, att, vel, pos_enu, odo_scale=0.0, R_scale=1.0) -> LCParams:
    """:class:`LCParams` of an error model from the IMU's noise and the initial navigation sigmas.

    P0 (:meth:`ErrorModel.P0`): the navigation sigmas given here; gyro and accelerometer biases from
    the turn-on sigmas of ``noise``, the gyro Markov drift (18 states) from its bias instability,
    the scale factors from its scale-factor sigmas. Qc and the correlation times from ``noise``
    (:meth:`ErrorModel.Qc`, :meth:`ErrorModel.tau`).

    Args:
      model: :class:`ErrorModel`.  noise: :class:`jaxnav.ins.ImuNoise` (SI).
      pos0: (3,) [lat rad, lon rad, h m] where the ENU position sigmas are converted.
      att: attitude sigma (E, N, U), rad, scalar or (3,).  vel: ENU velocity sigma, m/s.
      pos_enu: ENU position sigma, m.  odo_scale: odometer scale-factor sigma (models with the
        state), dimensionless.  R_scale: factor on every measurement covariance.
    Returns:
      :class:`LCParams`; array leaves, so ``vmap``/``grad`` reach the noise and sigmas.
    """
    P0 = model.P0(
        pos0,
        att=att,
        vel=vel,
        pos_enu=pos_enu,
        gyro_bias=noise.gyro_bias_initial,
        accel_bias=noise.accel_bias_initial,
        gyro_markov=noise.gyro_bias_instability,
        gyro_scale=noise.gyro_sf,
        accel_scale=noise.accel_sf,
        odo_scale=odo_scale,
    )
    return LCParams(P0=P0, Qc=model.Qc(noise), tau_markov=model.tau(noise), R_scale=R_scale)


class SensorBiases(NamedTuple):
    """Accumulated sensor-error corrections applied to the raw IMU (body frame).

    Attributes:
      gyro: (3,) gyro bias, rad/s.  markov: (3,) gyro Markov drift (decays with tau), rad/s.
      accel: (3,) accelerometer bias, m/s^2.
      gyro_scale, accel_scale: (3,) scale-factor errors (dimensionless), or None for models without
        them. The raw increments are corrected as (raw - bias dt) / (1 + scale).
      odo_scale: (1,) odometer scale-factor error k (reading = (1 + k) speed, dimensionless), or None
        for models without the state (:meth:`jaxnav.ins.ErrorModel.with_odometer_scale`).
    """

    gyro: ArrayLike
    markov: ArrayLike
    accel: ArrayLike
    gyro_scale: ArrayLike | None = None
    accel_scale: ArrayLike | None = None
    odo_scale: ArrayLike | None = None


class LCEpochs(NamedTuple):
    """Per-epoch outputs (leading axis M; fields not saved are None).

    Attributes:
      t: (M,) epoch times.  t_nav: (M,) time of the IMU sample the state refers to.
      nav: :class:`NavState` after feedback, at t_nav.  biases: :class:`SensorBiases` after feedback.
      covs: (M, n, n) error covariance after the update.  pred_covs: (M, n, n) prior (after inflation).
      Phi: (M, n, n) transition from the previous epoch.  corrections: (M, n) estimate fed back.
      innovations, innov_covs, nis, factors, noise, valid: as :class:`jaxnav.filters.KalmanResult`.
      gated: (M,) bool, the epoch's GNSS components were rejected by the chi-square gate.
      gnss_nis: (M,) NIS of the epoch's valid GNSS components against the prior (0 where none;
        computed only with gating on, else None).
      gnss_row: (M,) int, the row of the run's :class:`PVMeasurements` at each epoch (-1: an epoch of
        pseudo-measurements only); always filled.
    """

    t: jax.Array | None = None
    t_nav: jax.Array | None = None
    nav: NavState | None = None
    biases: SensorBiases | None = None
    covs: jax.Array | None = None
    pred_covs: jax.Array | None = None
    Phi: jax.Array | None = None
    corrections: jax.Array | None = None
    innovations: jax.Array | None = None
    innov_covs: jax.Array | None = None
    nis: jax.Array | None = None
    factors: jax.Array | None = None
    noise: Any = None
    valid: jax.Array | None = None
    gated: jax.Array | None = None
    gnss_nis: jax.Array | None = None
    gnss_row: jax.Array | None = None


class LCResult(NamedTuple):
    """Result of :func:`loosely_coupled`.

    Attributes:
      epochs: :class:`LCEpochs`.  final_nav: :class:`NavState` at the last IMU sample used.
      final_biases: :class:`SensorBiases`.  loglik: innovation log-likelihood.
      n_nonfinite: NaN/inf measurement components masked.  n_skipped: epochs without any update.
      status: int32 flags.  imu_nav: per-sample :class:`NavState` every ``LCSave.imu_every`` samples, or None.
      n_gated: int32, GNSS epochs rejected by the chi-square gate (0 without gating).
    """

    epochs: LCEpochs
    final_nav: NavState
    final_biases: SensorBiases
    loglik: jax.Array
    n_nonfinite: jax.Array
    n_skipped: jax.Array
    status: jax.Array
    imu_nav: NavState | None = None
    n_gated: jax.Array | None = None


class Segments(NamedTuple):
    """Host-computed map of IMU samples to measurement epochs (static shapes for the nested scan)."""

    idx: np.ndarray  # (M, K) int IMU sample indices per epoch interval (padded)
    use: np.ndarray  # (M, K) bool, real samples
    t_last: np.ndarray  # (M,) end time of the last IMU sample before each epoch
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
        raise ValueError(
            f"measurement times are not strictly increasing (index {int(np.argmax(np.diff(t_meas) <= 0)) + 1})"
        )
    t_start = t_imu[0] - np.broadcast_to(np.asarray(dt_imu, float), t_imu.shape)[0]
    if t_meas[0] <= t_start or t_meas[-1] > t_imu[-1] + 1e-9 or t_meas[0] > t_imu[-1]:
        raise ValueError(
            f"measurement epochs [{t_meas[0]:.6f}, {t_meas[-1]:.6f}] s are not inside the IMU span "
            f"({t_start:.6f}, {t_imu[-1]:.6f}] s; trim the measurements to the IMU data"
        )
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


def _apply_correction(nav: NavState, biases: SensorBiases, x, idx):
    """Feed an error estimate back: q <- rv2q(phi) (x) q, v -= dV, pos -= dpos, sensor errors += estimates."""
    q = quat_normalize(quat_mul(rv_to_quat(x[idx.phi]), nav.q_bn))
    nav = NavState(q_bn=q, v_n=nav.v_n - x[idx.dv], pos=nav.pos - x[idx.dpos])
    markov = biases.markov + (x[idx.eps_r] if idx.eps_r is not None else 0.0)
    biases = biases._replace(gyro=biases.gyro + x[idx.eps_b], markov=markov, accel=biases.accel + x[idx.nabla])
    if idx.s_g is not None:
        biases = biases._replace(gyro_scale=biases.gyro_scale + x[idx.s_g], accel_scale=biases.accel_scale + x[idx.s_a])
    if idx.s_odo is not None:
        biases = biases._replace(odo_scale=biases.odo_scale + x[idx.s_odo])
    return nav, biases


class LCGate(NamedTuple):
    """Chi-square gate of the GNSS epochs (:func:`loosely_coupled`'s ``gate``).

    A GNSS epoch whose NIS (valid components, against the un-inflated prior) exceeds the chi-square
    quantile of ``prob`` for its number of valid components is rejected: its GNSS components are
    masked, the epoch's aids kept, it is counted in ``n_gated`` and flagged GNSS_GATED.

    Attributes:
      prob: probability in (0, 1); 1.0: an open gate that rejects nothing (the same compiled program as
        a gated run, for an ungated run that shares its compilation).
      max_run: after this many consecutive rejected GNSS epochs the next one is accepted whatever its
        NIS (re-acquisition: a gate alone locks a filter out for good once it has drifted, e.g. after
        a poor initial heading or a long outage); int >= 1.
    """

    prob: float
    max_run: int = 10


class LCDiscretization(NamedTuple):
    """How each epoch interval's Phi and Qd are computed (:func:`loosely_coupled`'s ``discretization``).

    Attributes:
      method: "taylor": :func:`~jaxnav.ins.discretize_taylor` with ``order`` terms, flagging
        DISCRETIZATION_INACCURATE in ``status`` if the series had not converged; "van_loan": the
        matrix exponential of :func:`~jaxnav.ins.discretize_van_loan`. For S0 (1 s epochs) both agree
        to ~1e-15; the series is 2.4x faster per run and 3x faster under ``jax.jvp``.
      order: number of series terms.
    """

    method: str = "taylor"
    order: int = 8


class LCPropagation(NamedTuple):
    """How the IMU samples between epochs are integrated (:func:`loosely_coupled`'s ``propagation``).

    Attributes:
      nav_every: > 1 mechanizes the samples between fixes by the two-speed algorithm of
        :func:`jaxnav.ins.mechanize` (navigation-frame terms once per ``nav_every`` samples, the
        body-frame work as array operations; F's time averages from the blocks): ~3x faster per run.
        1: the per-sample :func:`jaxnav.ins.mech_step` loop.
      hold_height: as :func:`jaxnav.ins.mechanize`.
      remat: wrap each epoch in ``jax.checkpoint`` so that reverse-mode gradients store one carry per
        epoch instead of every IMU sample's intermediates (the forward result is identical).
      max_epoch_samples: the scan pads every epoch interval to the longest one, so one long gap
        (a GNSS outage taken out of ``meas``, IMU data long before the first fix) would multiply
        the work of the whole run. Intervals with more samples than this are split by
        prediction-only epochs (no measurement; ``result.epochs.gnss_row`` -1) of at most this
        many samples. None (default): automatic, the 90th percentile of the samples per interval,
        applied only where the longest interval exceeds twice that; 0: never split. Not with
        ``LCSave.imu_every`` (its per-sample layout follows the intervals).
    """

    nav_every: int = 1
    hold_height: bool = False
    remat: bool = False
    max_epoch_samples: int | None = None


class LCSave(NamedTuple):
    """What :func:`loosely_coupled` returns besides the final state (its ``save``).

    Attributes:
      epochs: per-epoch outputs, a subset of :data:`LC_OUTPUTS` (fields of :class:`LCEpochs`).
      imu_every: if > 0 also the navigation state every k-th IMU sample (``LCResult.imu_nav``); needs
        ``nav_every = 1`` and k dividing the samples per epoch interval.
    """

    epochs: tuple = (
        "nav",
        "biases",
        "covs",
        "pred_covs",
        "Phi",
        "corrections",
        "innovations",
        "nis",
        "factors",
        "valid",
    )
    imu_every: int = 0


class _Carry(NamedTuple):
    """Carry of the epoch scan."""

    mech: MechState
    biases: SensorBiases
    kf: FilterState
    G_prev: jax.Array | None = None  # two-speed mechanization: the last block's gravity minus Coriolis (else None)
    n_gated: jax.Array | None = None  # int32 count of gated GNSS epochs
    gate_run: jax.Array | None = None  # int32 consecutive gated GNSS epochs (re-acquisition after gate_max_run)


class _Sums(NamedTuple):
    """Integrals over one epoch interval of what F depends on; divided by the interval they build F.

    F is linear in f_n and C_bn and varies slowly with pos and v, so F at the time averages equals
    the average of F up to O(dt_epoch^2) in the slowly varying terms.
    """

    pos: jax.Array  # (3,) sum pos dt
    v: jax.Array  # (3,) sum v_n dt, m
    f: jax.Array  # (3,) sum C_bn dv = integral of f_n dt, m/s
    C: jax.Array  # (3, 3) sum C_bn dt, s
    Cw: jax.Array | None = None  # (3, 3) sum C_bn diag(dtheta) = integral of C_bn diag(w_ib_b) dt (scale-factor models)
    Cf: jax.Array | None = None  # (3, 3) sum C_bn diag(dv) = integral of C_bn diag(f_b) dt (scale-factor models)


class _Propagated(NamedTuple):
    """The INS at the last IMU sample of an epoch interval, and what the filter needs from the interval."""

    mech: MechState
    biases: SensorBiases  # the Markov drift decayed over the interval
    sums: _Sums
    T: jax.Array  # time covered by the interval's samples, s
    w_last: jax.Array  # (3,) angular rate of the last sample, rad/s (lever-arm velocity)
    G: jax.Array | None  # two-speed: the last block's gravity minus Coriolis (else None)


def _where_tree(c, a, b):
    return jax.tree_util.tree_map(lambda x, y: jnp.where(c, x, y), a, b)


def _zero_sums(dtype, scale=False):
    z3, z33 = jnp.zeros(3, dtype), jnp.zeros((3, 3), dtype)
    return _Sums(z3, z3, z3, z33, z33 if scale else None, z33 if scale else None)


def _correct(dth_raw, dv_raw, dt, biases: SensorBiases, markov):
    """Sensor-error correction of raw increments: (raw - bias dt) / (1 + scale) (scale only if present)."""
    dth = dth_raw - (biases.gyro + markov) * dt
    dvc = dv_raw - biases.accel * dt
    if biases.gyro_scale is not None:
        dth = dth / (1.0 + biases.gyro_scale)
        dvc = dvc / (1.0 + biases.accel_scale)
    return dth, dvc


def _decay_gm(biases: SensorBiases, T, tau_b):
    """Gauss-Markov biases: the applied estimates decay like the mean of the process, exp(-T / tau)."""
    if tau_b is None:
        return biases
    return biases._replace(gyro=biases.gyro * jnp.exp(-T / tau_b[:3]), accel=biases.accel * jnp.exp(-T / tau_b[3:]))


def _propagate_samples(mech: MechState, biases: SensorBiases, rows, tau, ellipsoid, hold_height, imu_every, tau_b=None):
    """The IMU samples of one epoch interval, one :func:`mech_step` each, with the sensor-error correction.

    Args:
      rows: (raw dtheta (K, 3) rad, raw dv (K, 3) m/s, dt (K,) s, use (K,) bool); unused samples
        (padding) leave everything as it is.
      tau: (3,) Markov drift correlation times, s.  tau_b: (6,) Gauss-Markov bias correlation times
        (models with ``bias_gm``), else None.
    Returns:
      (:class:`_Propagated`, NavState every ``imu_every``-th sample or None).
    """
    dtype = mech.nav.v_n.dtype
    mparams = MechParams(earth_rate_sign=1.0)

    scale = biases.gyro_scale is not None

    def step(c, x):
        (mech, biases, sums, T, _), (dth_raw, dv_raw, dt, use) = c, x
        dth, dvc = _correct(dth_raw, dv_raw, dt, biases, biases.markov)
        new_mech, nav = mech_step(mech, ImuSample(dth, dvc, dt), mparams, ellipsoid=ellipsoid, hold_height=hold_height)
        C = quat_to_dcm(nav.q_bn)
        sums = _Sums(
            sums.pos + nav.pos * dt,
            sums.v + nav.v_n * dt,
            sums.f + C @ dvc,
            sums.C + C * dt,
            sums.Cw + C * dth[None, :] if scale else None,
            sums.Cf + C * dvc[None, :] if scale else None,
        )
        new = (new_mech, biases._replace(markov=biases.markov * jnp.exp(-dt / tau)), sums, T + dt, dth / dt)
        return _where_tree(use, new, c), (nav if imu_every else None)

    init = (mech, biases, _zero_sums(dtype, scale), jnp.zeros((), dtype), jnp.zeros(3, dtype))
    (mech, biases, sums, T, w_last), navs = jax.lax.scan(step, init, rows)
    if imu_every:
        navs = jax.tree_util.tree_map(lambda a: a[imu_every - 1 :: imu_every], navs)
    return _Propagated(mech, _decay_gm(biases, T, tau_b), sums, T, w_last, None), navs


def _propagate_blocks(
    mech: MechState, biases: SensorBiases, G_prev, rows, tau, M: int, ellipsoid, hold_height, tau_b=None
):
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
    dth, dvc = _correct(dth_raw, dv_raw, dtu[:, None], biases, biases.markov * decay_before)
    dth = jnp.where(use[:, None], dth, 0.0)
    dvc = jnp.where(use[:, None], dvc, 0.0)
    scale = biases.gyro_scale is not None
    nb = -(-K // M)
    padn = nb * M - K
    pad = lambda a: jnp.concatenate([a, jnp.zeros((padn,) + a.shape[1:], dtype)]) if padn else a
    blk, pre = _body_blocks(pad(dth), pad(dvc), pad(dtu), mech.dtheta_prev, mech.dv_prev, M, True, prefix=True)
    Bq = jnp.stack(pre.B, axis=-1)  # (nb, M, 4) body rotation to the end of each sample
    f_b = jnp.sum(quat_rotate(Bq, pad(dvc).reshape(nb, M, 3)), axis=1)  # (nb, 3)
    Cq = quat_to_dcm(Bq)  # (nb, M, 3, 3)
    C_b = jnp.sum(Cq * pad(dtu).reshape(nb, M)[..., None, None], axis=1)  # (nb, 3, 3)
    if scale:  # block sums of C diag(dtheta), C diag(dv) in the block's start frame
        Cw_b = jnp.sum(Cq * pad(dth).reshape(nb, M, 1, 3), axis=1)
        Cf_b = jnp.sum(Cq * pad(dvc).reshape(nb, M, 1, 3), axis=1)
        xs = (f_b, C_b, Cw_b, Cf_b)
    else:
        xs = (f_b, C_b)

    def add(sums, start, fr, T, x):
        C0 = quat_to_dcm(start.q_bn)
        Cw = sums.Cw + C0 @ x[2] if scale else None
        Cf = sums.Cf + C0 @ x[3] if scale else None
        return _Sums(sums.pos + fr.pos_mid * T, sums.v + fr.v_mid * T, sums.f + C0 @ x[0], sums.C + C0 @ x[1], Cw, Cf)

    two, sums, _ = _scan_blocks(
        _TwoSpeed(mech.nav, mech.a_prev, G_prev),
        blk,
        1.0,
        ellipsoid,
        hold_height,
        acc=_zero_sums(dtype, scale),
        accumulate=add,
        xs=xs,
        skip_empty=True,
    )
    last = jnp.maximum(jnp.sum(use) - 1, 0)
    flags = _imu_flags(dth, dvc, jnp.where(use, dt, 1.0), series=True)
    new_mech = MechState(
        nav=two.nav, dtheta_prev=dth[last], dv_prev=dvc[last], a_prev=two.a_prev, status=mech.status | flags
    )
    T = jnp.sum(dtu)
    new_biases = _decay_gm(biases._replace(markov=biases.markov * jnp.exp(-T / tau)), T, tau_b)
    return _Propagated(new_mech, new_biases, sums, T, dth[last] / dt[last], two.G)


def _discretise(model: ErrorModel, p: _Propagated, tau, Qc, ellipsoid, how: LCDiscretization):
    """Phi and Qd of one epoch interval (S0 eqs. (1), (8)) from F at the interval's time averages.

    Returns:
      (Phi (n, n), Qd (n, n), int32 flag: DISCRETIZATION_INACCURATE if the Taylor series had not converged).
    """
    Tsafe = jnp.maximum(p.T, 1e-300)
    s = p.sums
    avg = lambda a: None if a is None else a / Tsafe
    F = model.F(avg(s.pos), avg(s.v), avg(s.f), avg(s.C), tau, ellipsoid=ellipsoid, Cw=avg(s.Cw), Cf=avg(s.Cf))
    G = model.G(quat_to_dcm(p.mech.nav.q_bn))
    if how.method == "van_loan":
        Phi, Qd = discretize_van_loan(F, G, Qc, p.T)
        return Phi, Qd, jnp.zeros((), jnp.int32)
    Phi, Qd, err = discretize_taylor(F, G, Qc, p.T, order=how.order)
    return Phi, Qd, jnp.where(err > 1e-10, _status.DISCRETIZATION_INACCURATE, 0).astype(jnp.int32)


def _measure(ctx: MeasContext, m: PVMeasurements, R_scale, n: int, ellipsoid) -> MeasRows:
    """z (6,), H (6, n), R (6, 6), mask (6,) of one epoch's PV measurement (m: its row of :class:`PVMeasurements`)
    through :data:`jaxnav.ins.measurements.GNSS_PV`.

    The INS state is extrapolated from its last IMU sample by ctx.dtx = t_epoch - t_sample (s).
    """
    return GNSS_PV.fn(ctx, GnssData(m.pos, m.vel, m.R, m.mask, m.lever), R_scale, None, n, ellipsoid)


def _mean_rate(rows, still, biases: SensorBiases):
    """Mean corrected angular rate (3,) over the interval's samples flagged ``still`` (K,), and their time (s)."""
    dth_raw, _, dt, use = rows
    w = still & use
    T = jnp.sum(jnp.where(w, dt, 0.0))
    sdth = jnp.sum(jnp.where(w[:, None], dth_raw, 0.0), axis=0)
    w_raw = sdth / jnp.maximum(T, 1e-300)
    wm = w_raw - (biases.gyro + biases.markov)
    if biases.gyro_scale is not None:
        wm = wm / (1.0 + biases.gyro_scale)
    return jnp.where(T > 0, wm, 0.0), T


def _gate(rows: MeasRows, Phi, Qd, P, gate_run, thresholds, max_run: int):
    """Chi-square gate of one epoch's GNSS rows against the prior of the feedback filter (x = 0).

    S = (H Phi) P (H Phi)^T + H Qd H^T + R over the valid components; NIS = z^T S^-1 z is compared
    with ``thresholds[dof]`` (dof = number of valid components, thresholds[0] unused). After
    ``max_run`` consecutive rejected GNSS epochs the next one is accepted whatever its NIS, so a
    filter that drifted away (bad start, long outage) is pulled back instead of rejecting every
    later fix.

    Args:
      rows: the epoch's GNSS :class:`MeasRows` (6 rows).  Phi, Qd, P: (n, n).
      gate_run: int32, consecutive rejected GNSS epochs before this one.
      thresholds: (7,) chi-square quantiles by dof.  max_run: static int.
    Returns:
      (rows with the rejected components masked, gated bool, nis scalar (0 where no valid
      component), gate_run after this epoch).
    """
    valid = rows.mask & jnp.isfinite(rows.z)
    HPhi = rows.H @ Phi
    S = HPhi @ P @ HPhi.T + rows.H @ Qd @ rows.H.T + rows.R
    _, Sm = masked_measurement(rows.H, 0.5 * (S + S.T), valid)
    L, ok = safe_cholesky(Sm)
    w = whiten(L, jnp.where(valid, rows.z, 0.0))
    nis = jnp.sum(w * w)
    dof = jnp.sum(valid)
    gated = (dof > 0) & ok & (nis > thresholds[dof]) & (gate_run < max_run)
    gate_run = jnp.where(gated, gate_run + 1, jnp.where(jnp.any(valid), 0, gate_run))
    rows = rows._replace(mask=rows.mask & ~(gated & jnp.isfinite(rows.z)))
    return rows, gated, jnp.where(dof > 0, nis, 0.0), gate_run


def _stack(parts):
    """One measurement from several :class:`MeasRows`: rows concatenated, R block-diagonal."""
    if len(parts) == 1:
        return parts[0]
    return MeasRows(
        z=jnp.concatenate([r.z for r in parts]),
        H=jnp.concatenate([r.H for r in parts]),
        R=jax.scipy.linalg.block_diag(*[r.R for r in parts]),
        mask=jnp.concatenate([r.mask for r in parts]),
    )


def _feedback(p: _Propagated, kf: FilterState, idx, flag) -> _Carry:
    """Feed the estimate kf.x back to the INS and the sensor errors; the error state restarts at zero."""
    nav, biases = _apply_correction(p.mech.nav, p.biases, kf.x, idx)
    kf = kf._replace(x=jnp.zeros_like(kf.x), status=kf.status | flag)
    return _Carry(mech=p.mech._replace(nav=nav), biases=biases, kf=kf, G_prev=p.G)


_STEP_OUTPUTS = ("means", "covs", "pred_covs", "innovations", "innov_covs", "nis", "factors", "noise", "valid")


class _AidEpochs(NamedTuple):
    """Per-epoch inputs of the aids (leading axis M'): data (tuple of pytrees or None), active (M', A) bool,
    still (M', K) bool rows of the mean-rate aid or None."""

    data: Any
    active: jax.Array
    still: jax.Array | None


class _CoreInputs(NamedTuple):
    """The arrays of one run, on the filter's epochs (M epochs, K IMU samples per interval at most)."""

    nav0: NavState
    biases0: SensorBiases
    rows: tuple  # (dtheta (M, K, 3), dv (M, K, 3), dt (M, K), use (M, K) bool): raw IMU samples per interval
    t_last: jax.Array  # (M,) end time of the last IMU sample before each epoch
    meas: PVMeasurements
    aid_epochs: _AidEpochs | None
    aid_params: tuple
    gate_thresholds: jax.Array | None  # (7,) chi-square quantiles by dof, or None without gating


class _CoreOptions(NamedTuple):
    """The static options of one run (a ``jax.jit`` static argument)."""

    model: ErrorModel
    save: LCSave
    propagation: LCPropagation
    discretization: LCDiscretization
    gate_max_run: int
    aid_models: tuple
    ellipsoid: Ellipsoid
    check_finite: bool


def _propagate(carry: _Carry, rows, tau, tau_b, opts: _CoreOptions):
    """The epoch interval's IMU samples: per sample, or by blocks with ``nav_every > 1``."""
    pr = opts.propagation
    if pr.nav_every > 1:
        return _propagate_blocks(
            carry.mech, carry.biases, carry.G_prev, rows, tau, pr.nav_every, opts.ellipsoid, pr.hold_height, tau_b
        ), None
    return _propagate_samples(
        carry.mech, carry.biases, rows, tau, opts.ellipsoid, pr.hold_height, opts.save.imu_every, tau_b
    )


@partial(jax.jit, static_argnames=("opts",))
def _lc_core(inputs: _CoreInputs, params: LCParams, inflation, estimator, opts: _CoreOptions) -> LCResult:
    """The epoch scan of :func:`loosely_coupled`: propagate, discretise, measure (gate), filter step, feed back."""
    model, save = opts.model, opts.save
    dtype = inputs.nav0.v_n.dtype
    tau_all = jnp.broadcast_to(jnp.asarray(params.tau_markov, dtype), (model.tau_size,))
    tau = jnp.full(3, jnp.inf, dtype) if model.bias_gm else tau_all  # the Markov drift's (none with GM biases)
    tau_b = tau_all if model.bias_gm else None
    Qc, R_scale = jnp.asarray(params.Qc, dtype), jnp.asarray(params.R_scale, dtype)
    fparams = FilterParams(
        model=LinearGaussian(None, None, None, None, None),
        inflation=NoInflation() if inflation is None else inflation,
        estimator=NoEstimator() if estimator is None else estimator,
    )
    gate = inputs.gate_thresholds is not None
    z0, z3 = jnp.zeros((), dtype), jnp.zeros(3, dtype)

    def epoch(carry: _Carry, inp):
        rows, t_meas, t_nav, m, ae = inp
        p, navs = _propagate(carry, rows, tau, tau_b, opts)
        Phi, Qd, flag = _discretise(model, p, tau_all, Qc, opts.ellipsoid, opts.discretization)
        w_mean, T_mean = (z3, z0) if ae is None or ae.still is None else _mean_rate(rows, ae.still, carry.biases)
        ctx = MeasContext(
            nav=p.mech.nav, w_ib_b=p.w_last, w_mean_b=w_mean, T_mean=T_mean, dtx=t_meas - t_nav, biases=p.biases
        )
        gnss = _measure(ctx, m, R_scale, model.n, opts.ellipsoid)
        gated, gnss_nis, gate_run = jnp.zeros((), bool), z0, carry.gate_run
        if gate:
            gnss, gated, gnss_nis, gate_run = _gate(
                gnss, Phi, Qd, carry.kf.P, carry.gate_run, inputs.gate_thresholds, opts.gate_max_run
            )
            flag = flag | jnp.where(gated, _status.GNSS_GATED, 0).astype(jnp.int32)
        parts = [gnss]
        for i, am in enumerate(opts.aid_models):
            r = am.fn(ctx, ae.data[i], inputs.aid_params[i], model.idx, model.n, opts.ellipsoid)
            parts.append(r._replace(mask=r.mask & ae.active[i]))
        z, H, R, mask = _stack(parts)
        # x is zero after every feedback; the literal zero lets XLA drop the products F x and H x
        kf_prior = carry.kf._replace(x=jnp.zeros(model.n, dtype))
        kf, info = filter_step(
            kf_prior,
            StepInput(z=z, mask=mask, F=Phi, H=H, Q=Qd, R=R),
            fparams,
            save=_STEP_OUTPUTS,
            check_finite=opts.check_finite,
        )
        new = _feedback(p, kf, model.idx, flag)._replace(
            n_gated=carry.n_gated + gated.astype(jnp.int32), gate_run=gate_run
        )
        allv = dict(
            nav=new.mech.nav,
            biases=new.biases,
            covs=kf.P,
            pred_covs=info.pred_covs,
            Phi=Phi,
            corrections=kf.x,
            innovations=info.innovations,
            innov_covs=info.innov_covs,
            nis=info.nis,
            factors=info.factors,
            noise=info.noise,
            valid=info.valid,
            gated=gated,
            gnss_nis=gnss_nis if gate else None,
        )
        return new, (LCEpochs(t=t_meas, t_nav=t_nav, **{k: allv[k] for k in save.epochs}), navs)

    mech0 = MechState(nav=inputs.nav0, dtheta_prev=z3, dv_prev=z3, a_prev=z3, status=jnp.zeros((), jnp.int32))
    m_total = 6 + sum(am.size for am in opts.aid_models)
    kf0 = init_state(jnp.zeros(model.n, dtype), params.P0, m_total, inflation=inflation, estimator=estimator)
    G0 = _two_speed_start(inputs.nav0, z3, 1.0, opts.ellipsoid).G if opts.propagation.nav_every > 1 else None
    if opts.propagation.remat:
        # reverse mode keeps only the per-epoch carries and recomputes each epoch's IMU samples
        # on the way back: tape memory O(epochs) instead of O(IMU samples)
        epoch = jax.checkpoint(epoch)
    carry0 = _Carry(mech0, inputs.biases0, kf0, G0, jnp.zeros((), jnp.int32), jnp.zeros((), jnp.int32))
    xs = (inputs.rows, inputs.meas.t, inputs.t_last, inputs.meas, inputs.aid_epochs)
    final, (ep, navs) = jax.lax.scan(epoch, carry0, xs)
    return LCResult(
        epochs=ep,
        final_nav=final.mech.nav,
        final_biases=final.biases,
        loglik=final.kf.loglik,
        n_nonfinite=final.kf.n_nonfinite,
        n_skipped=final.kf.n_skipped,
        status=final.kf.status | final.mech.status,
        imu_nav=navs if save.imu_every else None,
        n_gated=final.n_gated,
    )


def chi2_quantile(prob: float, dof: int) -> float:
    """Quantile of the chi-square distribution with integer ``dof`` (host side, float64 bisection).

    CDF by the closed forms for integer degrees of freedom (Abramowitz & Stegun 26.4.4-26.4.5):
    even k = 2m: 1 - exp(-x/2) sum_{i<m} (x/2)^i / i!;  odd k = 2m + 1:
    erf(sqrt(x/2)) - sqrt(2/pi) exp(-x/2) sum_{i=1..m} x^(i - 1/2) / (1 3 5 ... (2i - 1)).

    Raises:
      ValueError: prob outside (0, 1) or dof < 1.
    """
    import math

    if not (0.0 < prob < 1.0):
        raise ValueError(f"gate probability must be in (0, 1), got {prob!r}")
    if int(dof) != dof or dof < 1:
        raise ValueError(f"dof must be a positive integer, got {dof!r}")
    k = int(dof)

    def cdf(x):
        if x <= 0:
            return 0.0
        if k % 2 == 0:
            term, tot = 1.0, 1.0
            for i in range(1, k // 2):
                term *= (x / 2) / i
                tot += term
            return 1.0 - math.exp(-x / 2) * tot
        tot, term = 0.0, 0.0
        for i in range(1, (k - 1) // 2 + 1):
            term = math.sqrt(x) if i == 1 else term * x / (2 * i - 1)
            tot += term
        return math.erf(math.sqrt(x / 2)) - math.sqrt(2 / math.pi) * math.exp(-x / 2) * tot

    lo, hi = 0.0, 1.0
    while cdf(hi) < prob:
        hi *= 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if cdf(mid) < prob else (lo, mid)
    return 0.5 * (lo + hi)


def _split_samples(t_imu, t_epochs, max_samples):
    """Host side: (N,) bool, the IMU samples after which a prediction-only epoch splits a long interval, or None.

    Epoch interval j holds the samples ending in (t_epochs[j-1], t_epochs[j]] (see :func:`segment_imu`);
    one of c > cap samples is cut after every cap-th sample, into ceil(c / cap) pieces of at most cap.
    ``max_samples``: cap (``LCPropagation.max_epoch_samples``); None: the 90th percentile of the
    interval lengths, only when the longest exceeds twice that; 0: no split.
    """
    if max_samples == 0:
        return None
    ends = np.searchsorted(t_imu, np.asarray(t_epochs, float) + 1e-9, side="right")
    starts = np.concatenate([[0], ends[:-1]])
    counts = ends - starts
    if max_samples is None:
        cap = max(int(np.ceil(np.percentile(counts, 90))), 1)
        if counts.max() <= 2 * cap:
            return None
    else:
        cap = int(max_samples)
    long = np.nonzero(counts > cap)[0]
    if not long.size:
        return None
    n_cuts = (counts[long] - 1) // cap
    first = np.repeat(starts[long], n_cuts)
    m = np.arange(n_cuts.sum()) - np.repeat(np.cumsum(n_cuts) - n_cuts, n_cuts) + 1  # 1..n_cuts per interval
    split = np.zeros(len(t_imu), bool)
    split[first + m * cap - 1] = True
    return split


def _merge_epochs(t_imu, meas: PVMeasurements, active):
    """Host side: the filter's epochs = GNSS epochs merged with the IMU samples where an aid applies.

    Args:
      t_imu: (N,) IMU times.  meas: the GNSS :class:`PVMeasurements` (times concrete).
      active: (A, N) bool, thinned aid masks.
    Returns:
      (merged :class:`PVMeasurements` (M',...), gnss_row (M',) int (-1: no GNSS), sample (M',) int: the last
      IMU sample at or before each epoch).
    """
    t_g = np.asarray(meas.t, float)
    L = np.searchsorted(t_imu, t_g + 1e-9, side="right") - 1
    aid_k = np.nonzero(np.any(active, axis=0))[0]
    aid_k = aid_k[~np.isin(aid_k, L)]
    t_all = np.concatenate([t_g, t_imu[aid_k]])
    row = np.concatenate([np.arange(t_g.size), np.full(aid_k.size, -1)])
    order = np.argsort(t_all, kind="stable")
    t_all, row = t_all[order], row[order]
    sample = np.searchsorted(t_imu, t_all + 1e-9, side="right") - 1
    # rows without GNSS take a neighbouring fix's values with an all-False mask
    fill = np.maximum.accumulate(np.where(row >= 0, row, -1))
    fill = np.where(fill < 0, 0, fill)
    src = np.where(row >= 0, row, fill)
    has = jnp.asarray(row >= 0)
    take = lambda a: jnp.asarray(a)[src]
    merged = PVMeasurements(
        t=t_all,
        pos=take(meas.pos),
        vel=jnp.where(has[:, None], take(meas.vel), 0.0),
        R=take(meas.R),
        mask=take(meas.mask) & has[:, None],
        lever=jnp.where(has[:, None], take(meas.lever), 0.0),
    )
    return merged, row, sample


def _check_options(model, gate, save: LCSave, propagation: LCPropagation, discretization: LCDiscretization):
    """ValueError for options of the wrong type or out of range."""
    for name, v, cls in (
        ("error_model", model, ErrorModel),
        ("save", save, LCSave),
        ("propagation", propagation, LCPropagation),
        ("discretization", discretization, LCDiscretization),
    ):
        if not isinstance(v, cls):
            raise ValueError(f"{name} must be an {cls.__name__}, got {type(v).__name__}")
    if gate is not None and not isinstance(gate, LCGate):
        raise ValueError(f"gate must be an LCGate or None, got {type(gate).__name__}")
    if discretization.method not in ("taylor", "van_loan"):
        raise ValueError(f"discretization must be 'taylor' or 'van_loan', got {discretization.method!r}")
    unknown = [s for s in save.epochs if s not in LC_OUTPUTS]
    if unknown:
        raise ValueError(f"unknown outputs {unknown}; choose from {LC_OUTPUTS}")
    if "gnss_nis" in save.epochs and gate is None:
        raise ValueError("the output 'gnss_nis' needs a gate (it is the gate's statistic)")
    if gate is not None and (not isinstance(gate.max_run, (int, np.integer)) or gate.max_run < 1):
        raise ValueError(f"gate max_run={gate.max_run!r} must be an integer >= 1")
    if not isinstance(propagation.nav_every, (int, np.integer)) or propagation.nav_every < 1:
        raise ValueError(f"nav_every={propagation.nav_every!r} must be an integer >= 1")
    mx = propagation.max_epoch_samples
    if mx is not None and (not isinstance(mx, (int, np.integer)) or isinstance(mx, bool) or mx < 0):
        raise ValueError(f"max_epoch_samples={mx!r} must be None or an integer >= 0")
    if propagation.nav_every > 1 and save.imu_every:
        raise ValueError("save imu_every needs the per-sample loop: use nav_every=1")


def _check_shapes(model: ErrorModel, N: int, dtheta, dv, meas: PVMeasurements, params: LCParams):
    """ValueError naming the shapes when the IMU, measurement or parameter arrays do not fit."""
    if jnp.shape(dtheta) != (N, 3) or jnp.shape(dv) != (N, 3):
        raise ValueError(f"dtheta {jnp.shape(dtheta)} and dv {jnp.shape(dv)} must be ({N}, 3) to match t_imu")
    M = np.shape(meas.t)[0]
    for name, shp in (("pos", (M, 3)), ("vel", (M, 3)), ("R", (M, 6, 6)), ("mask", (M, 6)), ("lever", (M, 3))):
        if jnp.shape(getattr(meas, name)) != shp:
            raise ValueError(f"meas.{name} has shape {jnp.shape(getattr(meas, name))}; expected {shp}")
    n, p = model.n, model.p
    if jnp.shape(params.P0) != (n, n) or jnp.shape(params.Qc) != (p, p):
        raise ValueError(
            f"params.P0 {jnp.shape(params.P0)} / Qc {jnp.shape(params.Qc)} must be "
            f"({n}, {n}) / ({p}, {p}) for the {n}-state model"
        )
    if jnp.ndim(params.tau_markov) > 0 and jnp.shape(params.tau_markov) not in ((3,), (model.tau_size,)):
        raise ValueError(
            f"params.tau_markov has shape {jnp.shape(params.tau_markov)}; expected () or "
            f"({model.tau_size},) for the {n}-state model"
        )
    if jnp.ndim(params.tau_markov) > 0 and jnp.shape(params.tau_markov)[0] != model.tau_size:
        raise ValueError(
            f"params.tau_markov has shape {jnp.shape(params.tau_markov)}; the model with Gauss-Markov "
            f"biases needs ({model.tau_size},) = [gyro bias taus (3), accelerometer bias taus (3)]"
        )


def _thin_aids(aids, N: int, dt_imu):
    """Host side: each aid's ``active`` mask (N,) as given and thinned to its ``rate_hz``; index of the mean-rate aid."""
    dtm = float(np.median(np.broadcast_to(np.asarray(dt_imu, float), (N,))))
    raw, thinned = [], []
    for i, a in enumerate(aids):
        if not isinstance(a, Aid):
            raise ValueError(f"aids must be Aid records (jaxnav.ins.measurements), got {type(a).__name__}")
        act = np.ones(N, bool) if a.active is None else np.asarray(a.active)
        if act.shape != (N,) or act.dtype != bool:
            raise ValueError(
                f"aids[{i}] ({a.model.name}): active must be a ({N},) bool array, got {act.dtype} {act.shape}"
            )
        raw.append(act)
        if a.rate_hz is not None:
            k = max(1, int(round(1.0 / (a.rate_hz * dtm))))
            act = act & ((np.arange(N) + 1) % k == 0)
        thinned.append(act)
    mean_aids = [i for i, a in enumerate(aids) if a.model.needs_mean_rate]
    if len(mean_aids) > 1:
        raise ValueError("at most one aid may use the interval's mean angular rate (ZARU)")
    return raw, thinned, (mean_aids[0] if mean_aids else None)


def _aid_epochs(aids, N: int, raw, thinned, mean_aid, sample, seg: Segments) -> _AidEpochs:
    """The aids' data, active flags and mean-rate rows on the filter's epochs (``sample``: their IMU sample)."""
    for i, a in enumerate(aids):
        for leaf in jax.tree_util.tree_leaves(a.data):
            if jnp.shape(leaf)[:1] != (N,):
                raise ValueError(
                    f"aids[{i}] ({a.model.name}): data leaves must have {N} rows (one per "
                    f"IMU sample), got {jnp.shape(leaf)}"
                )
    data = tuple(
        None if a.data is None else jax.tree_util.tree_map(lambda x: jnp.asarray(x)[sample], a.data) for a in aids
    )
    active = jnp.asarray(np.stack([t[sample] for t in thinned], axis=-1))
    still = None if mean_aid is None else jnp.asarray(raw[mean_aid][seg.idx] & seg.use)
    return _AidEpochs(data=data, active=active, still=still)


def _initial_biases(model: ErrorModel, biases0: SensorBiases | None, dtype) -> SensorBiases:
    """``biases0`` (default zeros) with exactly the optional fields the model has (zeros where not given)."""
    z3 = jnp.zeros(3, dtype)
    b = SensorBiases(z3, z3, z3) if biases0 is None else biases0
    if model.scale_factors:
        b = b._replace(
            gyro_scale=z3 if b.gyro_scale is None else b.gyro_scale,
            accel_scale=z3 if b.accel_scale is None else b.accel_scale,
        )
    else:
        b = b._replace(gyro_scale=None, accel_scale=None)
    if model.idx.s_odo is None:
        return b._replace(odo_scale=None)
    return b._replace(
        odo_scale=jnp.zeros(1, dtype) if b.odo_scale is None else jnp.reshape(jnp.asarray(b.odo_scale, dtype), (1,))
    )


def loosely_coupled(
    nav0: NavState,
    t_imu,
    dtheta,
    dv,
    meas: PVMeasurements,
    params: LCParams,
    *,
    dt_imu=None,
    biases0: SensorBiases | None = None,
    error_model: ErrorModel = ERROR_MODEL_18,
    aids: Sequence[Aid] = (),
    gate: LCGate | None = None,
    inflation=None,
    estimator=None,
    save: LCSave = LCSave(),
    propagation: LCPropagation = LCPropagation(),
    discretization: LCDiscretization = LCDiscretization(),
    ellipsoid: Ellipsoid = WGS84,
    check_finite: bool = True,
    max_sigma: float = 1e3,
) -> LCResult:
    """Loosely coupled INS/GNSS filter with feedback correction (S0 experiment, eqs. (4)-(19)).

    Args:
      nav0: initial :class:`NavState` at ``t_imu[0] - dt_imu[0]``.
      t_imu: (N,) end time of each IMU sample, s (concrete: it shapes the nested scan).
      dtheta: (N, 3) angular increments, rad.  dv: (N, 3) velocity increments, m/s (body frame).
      meas: :class:`PVMeasurements` (times concrete); components with a standard deviation above
        ``max_sigma`` (m or m/s) or NaN are masked and counted.
      params: :class:`LCParams` (array leaves: P0, Qc, tau, R scale).
      dt_imu: scalar or (N,) sample intervals (default: from ``t_imu``, the first copied).
      biases0: initial :class:`SensorBiases` (default zeros; scale factors default to zeros for
        models that have them).
      error_model: static :class:`jaxnav.ins.ErrorModel` (default S0's 18 states;
        :func:`jaxnav.ins.error_model_for` gives one by its number of states).
      aids: :class:`jaxnav.ins.measurements.Aid` s (ZUPT, ZARU, NHC, odometer, heading, or one's
        own :class:`~jaxnav.ins.measurements.MeasurementModel`); their ``active`` masks are
        concrete (they set the epochs), their data and parameters may be traced. The filter's
        epochs become the GNSS epochs merged with the IMU samples where an aid applies (after
        thinning to its ``rate_hz``); ``result.epochs.gnss_row`` maps them back to ``meas``.
        An aid active at the sample of a GNSS epoch is applied in that epoch's update.
      gate: static :class:`LCGate`, or None (default): no gating.
      inflation, estimator: plug-ins of :mod:`jaxnav.filters` (classic when None).
      save: static :class:`LCSave`.  propagation: static :class:`LCPropagation`.
      discretization: static :class:`LCDiscretization`.
      ellipsoid: static Earth model.  check_finite: static, as :func:`jaxnav.filters.kalman_filter`.
    Returns:
      :class:`LCResult`.
    Raises:
      ValueError: shapes, non-increasing times, IMU/measurement spans that do not overlap, aid
        masks of the wrong length, more than one mean-rate (ZARU) aid, options out of range.
    """
    model = error_model
    _check_options(model, gate, save, propagation, discretization)
    N = np.shape(t_imu)[0]
    _check_shapes(model, N, dtheta, dv, meas, params)
    check_float64(nav0.pos, meas.pos, what="absolute positions")
    if isinstance(t_imu, jax.core.Tracer) or isinstance(meas.t, jax.core.Tracer):
        raise ValueError(
            "t_imu and meas.t must be concrete arrays (they set the scan's shapes); close over "
            "them instead of passing them through jit/vmap"
        )
    t_imu = np.asarray(t_imu, dtype=float)
    if dt_imu is None:
        d = np.diff(t_imu)
        dt_imu = np.concatenate([d[:1], d])
    sig = jnp.sqrt(jnp.diagonal(meas.R, axis1=1, axis2=2))
    meas = meas._replace(mask=jnp.asarray(meas.mask, bool) & (sig <= max_sigma), t=np.asarray(meas.t, float))
    aids = tuple(aids)
    raw, thinned, mean_aid = _thin_aids(aids, N, dt_imu) if aids else ([], [], None)
    gnss_meas, gnss_row, aid_epochs, n_split = meas, np.arange(np.shape(meas.t)[0]), None, 0
    if aids:
        meas, gnss_row, sample = _merge_epochs(t_imu, gnss_meas, np.stack(thinned))
    split = None if save.imu_every else _split_samples(t_imu, meas.t, propagation.max_epoch_samples)
    if split is not None:
        meas, gnss_row, sample = _merge_epochs(t_imu, gnss_meas, np.stack(thinned + [split]))
        n_split = int(np.count_nonzero((gnss_row < 0) & ~np.any([t[sample] for t in thinned], axis=0)))
    seg = segment_imu(t_imu, meas.t, dt_imu)
    if aids:
        aid_epochs = _aid_epochs(aids, N, raw, thinned, mean_aid, sample, seg)
    if save.imu_every and seg.K % save.imu_every:
        raise ValueError(f"save imu_every={save.imu_every} must divide the samples per epoch interval ({seg.K})")
    thresholds = None
    if gate is not None:
        open_ = float(gate.prob) == 1.0  # a gate that rejects nothing: the gated run's program, no epoch gated
        thresholds = jnp.asarray(
            [np.inf] + [np.inf if open_ else chi2_quantile(float(gate.prob), k) for k in range(1, 7)]
        )
    dtype = jnp.asarray(nav0.v_n).dtype
    dt_all = jnp.broadcast_to(jnp.asarray(dt_imu, dtype), (N,))
    # the IMU samples of every epoch interval, (M, K, ...); padded samples get dt = 1 and are skipped by ``use``
    rows = (jnp.asarray(dtheta)[seg.idx], jnp.asarray(dv)[seg.idx], jnp.where(seg.use, dt_all[seg.idx], 1.0), seg.use)
    inputs = _CoreInputs(
        nav0=nav0,
        biases0=_initial_biases(model, biases0, dtype),
        rows=rows,
        t_last=seg.t_last,
        meas=meas._replace(t=jnp.asarray(meas.t, jnp.float64)),
        aid_epochs=aid_epochs,
        aid_params=tuple(a.params for a in aids),
        gate_thresholds=thresholds,
    )
    opts = _CoreOptions(
        model=model,
        save=save._replace(epochs=tuple(save.epochs), imu_every=int(save.imu_every)),
        propagation=propagation,
        discretization=discretization,
        gate_max_run=10 if gate is None else int(gate.max_run),
        aid_models=tuple(a.model for a in aids),
        ellipsoid=ellipsoid,
        check_finite=check_finite,
    )
    res = _lc_core(inputs, params, inflation, estimator, opts)
    # the prediction-only epochs that split long intervals are not skipped updates
    return res._replace(epochs=res.epochs._replace(gnss_row=gnss_row), n_skipped=res.n_skipped - n_split)


def smooth(result: LCResult, *, error_model: ErrorModel = ERROR_MODEL_18) -> tuple[NavState, SensorBiases, Any]:
    """RTS smoothing of a feedback filter over its saved epoch moments, applied to the navigation solution.

    Take each epoch's post-feedback state as the reference. There the filtered error mean is
    0, and the prior mean is -x_{j+1} (the prediction, 0 relative to the pre-update state, seen
    from the post-feedback state that the correction x_{j+1} moved). The RTS recursion
    (:func:`jaxnav.filters.rts_smoother` on the saved P, priors and Phi) therefore gives
    dx^s_j = C_j (dx^s_{j+1} + x_{j+1}), C_j = P_j Phi_{j+1}^T P_{j+1|j}^{-1}, dx^s_M = 0; it is
    fed back to the epoch's state like a filter correction.

    Args:
      result: :class:`LCResult` saved with "nav", "biases", "covs", "pred_covs", "Phi", "corrections".
      error_model: the run's :class:`ErrorModel` (as given to :func:`loosely_coupled`).
    Returns:
      (smoothed :class:`NavState` (M, ...), smoothed :class:`SensorBiases`, smoothed covariances (M, n, n)).
    """
    ep = result.epochs
    for name in ("nav", "biases", "covs", "pred_covs", "Phi", "corrections"):
        if getattr(ep, name) is None:
            raise ValueError(f"smooth() needs the per-epoch output '{name}' (add it to save=)")
    M, n = ep.covs.shape[:2]
    model = error_model
    if n != model.n:
        raise ValueError(f"the result has {n} states; the error model has {model.n}: pass the run's error_model")
    zeros = jnp.zeros((M, n), ep.covs.dtype)
    filt = KalmanResult(means=zeros, covs=ep.covs, pred_means=-ep.corrections, pred_covs=ep.pred_covs)
    sm = rts_smoother(LinearGaussian(F=ep.Phi, H=None, Q=None, R=None), filt)
    idx = model.idx
    nav, biases = jax.vmap(lambda nv, b, x: _apply_correction(nv, b, x, idx))(ep.nav, ep.biases, sm.means)
    return nav, biases, sm.covs
