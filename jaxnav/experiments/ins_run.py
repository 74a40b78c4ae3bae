"""``jaxnav ins CONFIG``: post-process a real IMU + GNSS recording from a config file alone.

Pipeline (host-side glue around the pure, jitted library functions):

1. read the IMU and GNSS files (:func:`jaxnav.io.read_ins_inputs`; formats of :mod:`jaxnav.io`), apply the
   mounting (:func:`jaxnav.ins.sensor_to_body`) and the IMU-GNSS time offset (given, or
   :func:`jaxnav.ins.search_time_offset` through :func:`recording_time_offset`);
2. align (:func:`jaxnav.ins.coarse_alignment`), build the GNSS measurements with the lever arm
   (:func:`jaxnav.ins.gnss_solution_measurements`), the pseudo-measurements (:func:`build_aids`) and the
   filter's noise (:func:`filter_params`, calibrated by :func:`calibrate_noise`);
3. run the loosely coupled filter (:func:`jaxnav.ins.loosely_coupled`) and the RTS smoother
   (:func:`jaxnav.ins.smooth`);
4. optionally withhold GNSS on simulated outages and score forward and smoothed solutions
   against the withheld RTK-fixed epochs (:func:`jaxnav.ins.outage_windows`, :func:`jaxnav.ins.score_run`);
5. optionally tune the noise densities by maximum likelihood (:func:`tune_noise`): the GNSS innovations
   over the whole run, or the fixes withheld on training windows (:func:`jaxnav.ins.withheld_fix_loss`).

Outputs are written by :mod:`jaxnav.experiments.ins_output`.
"""

from __future__ import annotations

import time
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxnav.geodesy import curvilinear_to_enu
from jaxnav.ins import (
    GATED_SHARE_WARN,
    Alignment,
    ImuNoise,
    LCGate,
    LCNoise,
    LCParams,
    LCResult,
    LCSave,
    NavState,
    NoCommonEpochError,
    OutageScores,
    PVMeasurements,
    SensorBiases,
    check_tunable,
    coarse_alignment,
    error_model_for,
    gnss_checked_standstill,
    gnss_solution_measurements,
    gnss_speed_test,
    in_windows,
    interpolate_on_samples,
    lc_params,
    loosely_coupled,
    nearest_samples,
    nhc,
    noise_preset,
    odometer,
    offset_search_epochs,
    outage_windows,
    scale_gnss_sigmas,
    score_run,
    search_time_offset,
    sensor_to_body,
    smooth,
    solution_errors,
    standstill_summary,
    training_windows,
    withheld_fix_loss,
    zaru,
    zupt,
)
from jaxnav.ins import calibration_params as ins_calibration_params
from jaxnav.ins import heading as heading_aid
from jaxnav.ins.calibration import TUNABLE
from jaxnav.ins.timing import MIN_SEARCH_EPOCHS
from jaxnav.io import (
    INS_NOISE_KEYS,
    ConfigError,
    ImuLog,
    InsConfig,
    PosSolution,
    imu_increments,
    read_ins_heading,
    read_ins_inputs,
    read_ins_odometer,
)
from jaxnav.tune import LCNoiseFit, calibrate_lc_noise, fit_lc_noise


def _evaluated(cfg: InsConfig):
    """The ``[evaluate]`` section when it withholds GNSS on outages, else None."""
    return cfg.evaluate if cfg.evaluate is not None and cfg.evaluate.outages else None


def _outages(cfg: InsConfig, t0: float, t1: float) -> np.ndarray:
    """(K, 2) s: the ``[evaluate]`` outage windows in the IMU span [t0, t1] s (:func:`jaxnav.ins.outage_windows`)."""
    ev = _evaluated(cfg)
    if ev is None:
        return np.zeros((0, 2))
    return outage_windows(
        t0, t1, first_s=ev.first_s, outage_s=ev.outage_s, gap_s=ev.gap_s, end_margin_s=ev.end_margin_s
    )


def heading_on_imu(cfg: InsConfig, t_imu):
    """The ``[heading]`` file at the IMU samples: (heading (N,) rad, sigma (N,) rad), NaN where no reading.

    Each reading goes to the IMU sample nearest its time (GNSS time scale, :func:`jaxnav.ins.nearest_samples`);
    readings outside the IMU span or farther than one sample interval from every sample are dropped.
    """
    t, head, sigma = read_ins_heading(cfg)
    t_imu = np.asarray(t_imu, float)
    hd, sg = np.full(t_imu.size, np.nan), np.full(t_imu.size, np.nan)
    j, ok = nearest_samples(t, t_imu)
    hd[j[ok]] = head[ok]
    if sigma is not None:
        sg[j[ok]] = sigma[ok]
    return hd, sg


def run_noise(cfg: InsConfig) -> LCNoise:
    """The run's :class:`LCNoise` from ``[noise]``: values given there, else the grade's :func:`jaxnav.ins.noise_preset`
    (without a grade: zeros, a 300 s gyro and a 3600 s accelerometer correlation time). The accelerometer's
    correlation time defaults to the gyro's when only that is given."""
    n = cfg.noise
    imu = noise_preset(n.grade) if n.grade else ImuNoise(gyro_arw=0.0, accel_vrw=0.0, gyro_bias_tau=300.0)
    given = {f: getattr(n, k) for k, f, _, _ in INS_NOISE_KEYS.values() if getattr(n, k) is not None}
    if n.bias_correlation_time is not None:
        given.setdefault("accel_bias_tau", n.bias_correlation_time)
    return LCNoise(
        imu=imu._replace(**given),
        init_att=np.asarray(n.init_attitude, float),
        init_vel=n.init_velocity,
        init_pos=n.init_position,
    )


def run_error_model(cfg: InsConfig):
    """The run's :class:`jaxnav.ins.ErrorModel`: ``noise.states``, plus the odometer scale-factor state when
    ``[odometer] estimate_scale`` (:meth:`jaxnav.ins.ErrorModel.with_odometer_scale`)."""
    model = error_model_for(cfg.noise.states)
    o = cfg.odometer
    return model.with_odometer_scale() if o is not None and o.estimate_scale else model


def filter_params(noise: LCNoise, pos0, model, *, odo_scale_sigma=0.0) -> LCParams:
    """:func:`jaxnav.ins.lc_params` of ``model`` from :class:`LCNoise` at ``pos0`` (3,) rad, rad, m; the roll/pitch
    sigma serves phi_E and phi_N, the heading sigma phi_U; ``odo_scale_sigma``: initial 1-sigma of the odometer
    scale-factor state (models with it), dimensionless."""
    att = jnp.asarray(noise.init_att)
    imu = noise.imu
    if model.idx.eps_r is not None:  # a Markov drift state with zero sigma would have no variance at all
        imu = imu._replace(gyro_bias_instability=jnp.maximum(imu.gyro_bias_instability, 1e-12))
    return lc_params(
        model,
        imu,
        jnp.asarray(pos0, float),
        att=jnp.stack([att[0], att[0], att[1]]),
        vel=noise.init_vel,
        pos_enu=noise.init_pos,
        odo_scale=odo_scale_sigma,
    )


class Prepared(NamedTuple):
    """Everything a run needs, made once from the config (host side).

    Attributes:
      cfg: the config.  imu, pos: the files read (IMU time shifted by ``time_offset`` s).
      C_bs: (3, 3) sensor to body (RFU).  lever_rfu: (3,) GNSS antenna minus IMU, body frame, m.
      time_offset_info: how the offset was found (results.json).
      t, dth, dv, dt: the IMU increments (N,), (N, 3) rad, (N, 3) m/s, (N,) s.
      alignment: the initial state.  outages: (K, 2) s simulated outage windows.
      meas: the GNSS measurements the filter gets (withheld epochs masked).  keep: (M,) index of the
        GNSS solution's epochs among ``pos``.  withheld: (M,) bool epochs withheld by ``[evaluate]``.
      densities: the noise of the run.
      standstill: (N,) bool per IMU sample, or None (no detection).
      aids: pseudo-measurements (:mod:`jaxnav.ins` aids: ZUPT, ZARU, NHC, odometer, heading).
      standstill_info: the detector report (:func:`detect_stops`), its series under "_series".
      odometer_speed: (N,) m/s wheel speed per IMU sample (NaN: none), or None (no ``[odometer]``).
      heading: (heading (N,) rad, sigma (N,) rad) per IMU sample (NaN: none), or None (no ``[heading]``).
    """

    cfg: InsConfig
    imu: ImuLog
    pos: PosSolution
    C_bs: np.ndarray
    lever_rfu: np.ndarray
    time_offset: float
    time_offset_info: dict
    t: np.ndarray
    dth: np.ndarray
    dv: np.ndarray
    dt: np.ndarray
    alignment: Alignment
    outages: np.ndarray
    meas: PVMeasurements
    keep: np.ndarray
    withheld: np.ndarray
    densities: LCNoise
    standstill: np.ndarray | None = None
    aids: tuple = ()
    standstill_info: dict = {}
    odometer_speed: np.ndarray | None = None
    heading: tuple[np.ndarray, np.ndarray] | None = None


def detect_stops(cfg: InsConfig, t, dth, dv, dt, static_s: float, meas=None):
    """Standstill per IMU sample by :func:`jaxnav.ins.gnss_checked_standstill` with the ``[constraints]``
    detector keys, checked by the GNSS epochs the filter sees (``meas.mask``: withheld fixes never
    decide a ZUPT) through :func:`jaxnav.ins.gnss_speed_test`.

    Args:
      t: (N,) s.  dth, dv: (N, 3) increments.  dt: (N,) s.  meas: PVMeasurements or None (no GNSS check).
    Returns:
      (standstill (N,) bool, info dict for results.json).
    """
    c = cfg.constraints
    rate = 1.0 / float(np.median(dt))
    tg = q = spd = sig = None
    if meas is not None:
        mk = np.asarray(meas.mask, bool)
        pos = np.asarray(meas.pos, float)
        enu = np.asarray(curvilinear_to_enu(pos[0], pos - pos[0]))
        q, spd, sig = gnss_speed_test(meas.t, enu, meas.vel, meas.R, mk[:, :3].all(1), mk[:, 3:].all(1))
        tg = np.asarray(meas.t, float)
    gap = 1.5 * float(np.median(np.diff(tg))) if tg is not None and tg.size > 1 else 1.0
    r = gnss_checked_standstill(
        t,
        dv / dt[:, None],
        dth / dt[:, None],
        sigma_a=c.detector_sigma_a,
        sigma_w=c.detector_sigma_w,
        platform=c.platform,
        static_s=static_s,
        window=c.detector_window,
        min_s=c.detector_min_s,
        threshold=c.detector_threshold,
        t_gnss=tg,
        q_gnss=q,
        k_moving=c.zupt_gnss_k,
        max_gap_s=gap,
        rate_hz=rate,
    )
    info = {
        "kind": "SHOE GLRT",
        "platform": c.platform,
        **standstill_summary(r, t, rate),
        "sigma_a_m_s2": c.detector_sigma_a,
        "sigma_w_rad_s": c.detector_sigma_w,
        "gnss_check": meas is not None,
        "gnss_k": c.zupt_gnss_k,
    }
    if info["threshold_source"] == "given":
        info["threshold_source"] = "config"
    info["_series"] = {
        "stat": r.stat,
        "raw": r.raw,
        "moving": r.moving,
        "unconfirmed": r.unconfirmed,
        "static": r.static,
        "t_gnss": tg,
        "speed": spd,
        "speed_sigma": sig,
    }
    return r.detected, info


def build_aids(cfg: InsConfig, standstill, odo_speed=None, hdg=None):
    """The ``[constraints]`` pseudo-measurements (:func:`jaxnav.ins.zupt`, ``zaru``, ``nhc``) and the
    ``[odometer]`` wheel speed (:func:`jaxnav.ins.odometer`, ``odo_speed`` (N,) m/s per IMU sample) and the
    ``[heading]`` input (:func:`jaxnav.ins.heading`, ``hdg`` = (heading, sigma) (N,) rad each) for a run."""
    c = cfg.constraints
    aids = []
    if standstill is not None and standstill.any():
        aids.append(zupt(standstill, sigma=c.zupt_sigma, rate_hz=c.zupt_rate_hz))
        if c.zaru:
            aids.append(zaru(standstill, density=c.zaru_density, rate_hz=c.zupt_rate_hz))
    if c.nhc:
        active = None if standstill is None else ~standstill
        aids.append(
            nhc(
                active,
                sigma=(c.nhc_sigma, c.nhc_sigma),
                lever_b=sensor_to_body(np.eye(3)) @ c.nhc_lever_frd,
                rate_hz=c.nhc_rate_hz,
            )
        )
    o = cfg.odometer
    if o is not None and odo_speed is not None:
        aids.append(
            odometer(odo_speed, sigma=o.sigma, lever_b=sensor_to_body(np.eye(3)) @ o.lever_arm_frd, rate_hz=o.rate_hz)
        )
    if cfg.heading is not None and hdg is not None:
        aids.append(heading_aid(hdg[0], sigma=hdg[1], default_sigma=cfg.heading.sigma, rate_hz=cfg.heading.rate_hz))
    return tuple(aids)


def prepare(cfg: InsConfig, *, imu=None, pos=None, progress=print) -> Prepared:
    """Read, mount, time-shift and align; build the measurements with the ``[evaluate]`` outages."""
    if imu is None or pos is None:
        imu, pos = read_ins_inputs(cfg)
    C_bs = sensor_to_body(cfg.imu.mounting)
    lever_rfu = sensor_to_body(np.eye(3)) @ np.asarray(cfg.gnss.lever_arm_frd, float)
    off_info: dict = {"source": "config"}
    off = cfg.imu.time_offset_s
    if off == "estimate":
        off, off_info = recording_time_offset(cfg, imu, pos, C_bs, lever_rfu, progress=progress)
    imu = imu._replace(t=np.asarray(imu.t, float) + float(off))
    t, dth, dv, dt = imu_increments(imu, C_bs)
    outages = _outages(cfg, t[0], t[-1])
    ev = _evaluated(cfg)
    if ev is not None and len(outages) == 0:
        raise ConfigError(
            f"{cfg.path}: evaluate.first_s = {ev.first_s:g} + outage_s = {ev.outage_s:g} + "
            f"end_margin_s = {ev.end_margin_s:g} s leave no outage window in the {t[-1] - t[0]:.1f} s "
            "IMU span, so nothing would be withheld: lower them, or drop [evaluate]"
        )
    a = cfg.alignment
    dens = run_noise(cfg)
    att = None if a.attitude is None else np.array([a.attitude[1], a.attitude[0], -a.attitude[2]])
    align = coarse_alignment(
        t,
        dv / dt[:, None],
        dth / dt[:, None],
        pos,
        static_s=a.static_s,
        min_speed=a.min_speed,
        course_s=a.course_s,
        heading=a.heading,
        attitude=att,
        gyro_arw=float(dens.imu.gyro_arw),
        gyro_bias_sigma=float(dens.imu.gyro_bias_instability),
        lever_rfu=lever_rfu,
    )
    meas, keep, withheld = gnss_solution_measurements(
        pos,
        t,
        outages,
        lever_rfu=lever_rfu,
        pos_sigma_floor=cfg.gnss.pos_sigma_floor,
        vel_sigma_floor=cfg.gnss.vel_sigma_floor,
        use_velocity=cfg.gnss.use_velocity,
        qualities=(1,) if cfg.gnss.fixed_only else (1, 2, 3, 4, 5, 6),
    )
    standstill, stop_info = (
        detect_stops(cfg, t, dth, dv, dt, a.static_s, meas) if cfg.constraints.zupt == "auto" else (None, {})
    )
    odo = None
    if cfg.odometer is not None:
        t_odo, sp = read_ins_odometer(cfg)
        odo = interpolate_on_samples(t_odo + float(off), sp, t)  # the odometer shares the IMU's clock
        if not np.isfinite(odo).any():
            raise ConfigError(
                f"{cfg.path}: odometer: no reading falls inside the IMU span [{t[0]:.3f}, {t[-1]:.3f}] s "
                f"(readings [{t_odo[0]:.3f}, {t_odo[-1]:.3f}] s before the time offset): check the "
                "odometer's time scale (odometer.gps_week)"
            )
    hdg = None
    if cfg.heading is not None:
        hdg = heading_on_imu(cfg, t)
        if not np.isfinite(hdg[0]).any():
            raise ConfigError(
                f"{cfg.path}: heading: no reading falls inside the IMU span [{t[0]:.3f}, {t[-1]:.3f}] s: "
                "check its time scale (heading.gps_week)"
            )
    return Prepared(
        cfg=cfg,
        imu=imu,
        pos=pos,
        C_bs=C_bs,
        lever_rfu=lever_rfu,
        time_offset=float(off),
        time_offset_info=off_info,
        t=t,
        dth=dth,
        dv=dv,
        dt=dt,
        alignment=align,
        outages=outages,
        meas=meas,
        keep=keep,
        withheld=withheld,
        densities=dens,
        standstill=standstill,
        aids=build_aids(cfg, standstill, odo, hdg),
        standstill_info=stop_info,
        odometer_speed=odo,
        heading=hdg,
    )


_SAVE = ("nav", "biases", "covs", "pred_covs", "Phi", "corrections", "innovations", "innov_covs", "nis", "valid")


def run_filter(prep: Prepared, d: LCNoise | None = None, *, meas=None, save=_SAVE):
    """The loosely coupled filter on a prepared recording; returns :class:`jaxnav.ins.LCResult`."""
    d = prep.densities if d is None else d
    o = prep.cfg.odometer
    model = run_error_model(prep.cfg)
    params = filter_params(
        d, prep.alignment.nav0.pos, model, odo_scale_sigma=o.init_scale_sigma if model.idx.s_odo is not None else 0.0
    )
    m = scale_gnss_sigmas(prep.meas if meas is None else meas, d.pos_sigma_scale, d.vel_sigma_scale)
    g = prep.cfg.gnss
    gate = None if g.gate_probability is None else LCGate(g.gate_probability, g.gate_max_run)
    z3 = np.zeros(3)
    b0 = SensorBiases(gyro=np.asarray(prep.alignment.gyro_bias), markov=z3, accel=z3)
    return loosely_coupled(
        prep.alignment.nav0,
        prep.t,
        prep.dth,
        prep.dv,
        m,
        params,
        dt_imu=prep.dt,
        biases0=b0,
        error_model=model,
        save=LCSave(tuple(save)),
        aids=prep.aids,
        gate=gate,
    )


class InsRun(NamedTuple):
    """One processed recording.

    Attributes:
      prep: :class:`Prepared`.  result: the forward :class:`jaxnav.ins.LCResult`.
      smoothed_nav, smoothed_biases, smoothed_covs: RTS solution at the epochs ((M, ...), (M, n, n)).
      enu_ref, enu_fwd, enu_sm: (M, 3) antenna ENU of GNSS, forward and smoothed solutions around the
        start, m.  fixed: (M,) bool fixed-quality epochs.  scores: :class:`OutageScores` or None.
      runtime_s: filter + smoother wall time (incl. compilation), s.  densities: those used.
      gnss_epochs: (M,) index of the GNSS epochs among the filter's epochs (the others are
        pseudo-measurement epochs: ZUPT, NHC).
    """

    prep: Prepared
    result: LCResult
    smoothed_nav: NavState
    smoothed_biases: SensorBiases
    smoothed_covs: jax.Array
    enu_ref: np.ndarray
    enu_fwd: np.ndarray
    enu_sm: np.ndarray
    fixed: np.ndarray
    scores: OutageScores | None
    runtime_s: float
    densities: LCNoise
    gnss_epochs: np.ndarray | None = None


def run_ins(prep: Prepared, d: LCNoise | None = None) -> InsRun:
    """Forward filter + RTS smoother on a prepared recording, scored on its outages if it has any."""
    d = prep.densities if d is None else d
    t0 = time.perf_counter()
    res = run_filter(prep, d)
    model = run_error_model(prep.cfg)
    sm_nav, sm_b, sm_P = smooth(res, error_model=model)
    jax.block_until_ready(sm_nav.pos)
    runtime = time.perf_counter() - t0
    fixed = np.asarray(prep.pos.q)[prep.keep] == 1
    pos0 = np.array([float(x) for x in prep.alignment.nav0.pos])
    tr, scores = score_run(
        res, sm_nav, sm_P, prep.meas, fixed, prep.withheld, prep.outages, model.idx, pos0, runtime_s=runtime
    )
    return InsRun(
        prep=prep,
        result=res,
        smoothed_nav=sm_nav,
        smoothed_biases=sm_b,
        smoothed_covs=sm_P,
        enu_ref=tr.enu_ref,
        enu_fwd=tr.enu_fwd,
        enu_sm=tr.enu_sm,
        fixed=fixed,
        scores=scores,
        runtime_s=runtime,
        densities=d,
        gnss_epochs=tr.gnss_epochs,
    )


def tuned_run(prep: Prepared, rep) -> InsRun:
    """:func:`run_ins` with the noise and lever arm of a ``--tune`` :class:`jaxnav.tune.LCNoiseFit`."""
    tuned_prep = prep._replace(
        lever_rfu=rep.lever,
        meas=prep.meas._replace(lever=np.broadcast_to(rep.lever, np.shape(prep.meas.lever)).copy()),
    )
    return run_ins(tuned_prep, rep.noise)


def shifted_config(cfg: InsConfig, k: int) -> InsConfig:
    """The config of shift ``k`` of the ``[evaluate] shifts`` protocol: the outage schedule starting
    ``k shift_s`` later (``first_s + k shift_s``; :func:`jaxnav.ins.shifted_outage_windows`), as a single
    schedule (``shifts = 1``), so that :func:`prepare` withholds GNSS on shift k's windows and every fit
    (time offset, standstill check, noise calibration, ``--tune``) leaves them out."""
    ev = cfg.evaluate
    return cfg._replace(evaluate=ev._replace(first_s=ev.first_s + k * ev.shift_s, shifts=1))


class FittedRun(NamedTuple):
    """One withheld-GNSS run with everything fitted on the GNSS epochs it sees (:func:`fit_and_run`).

    Attributes:
      prep: :class:`Prepared` (its time offset and standstill detection fitted without the withheld
        epochs; its noise the calibrated one).  calibration: :func:`calibrate_noise`'s report (with
        ``gate_warning`` where the gate rejected more than :data:`jaxnav.ins.GATED_SHARE_WARN` of the
        GNSS epochs).  run: the final :class:`InsRun` (after ``--tune`` if tuned).
      tune: the ``--tune`` :class:`jaxnav.tune.LCNoiseFit`, or None.  untuned: the run before ``--tune``
        (``run`` itself without it).  gated_share: GNSS epochs gated / used by ``untuned``.
    """

    prep: Prepared
    calibration: dict
    run: InsRun
    tune: LCNoiseFit | None = None
    untuned: InsRun | None = None
    gated_share: float = 0.0


def fit_and_run(cfg: InsConfig, *, imu, pos, prep=None, calibrate=None, tune: bool = False, progress=None) -> FittedRun:
    """The whole fitted pipeline of one outage schedule: :func:`prepare` (time offset and standstill
    detection on the GNSS epochs outside the config's outages), :func:`calibrate_noise`, :func:`run_ins`
    (and the gated-share check), and with ``tune`` :func:`tune_noise` and its rerun; nothing fitted sees
    the withheld epochs.

    Args:
      cfg: the config (e.g. :func:`shifted_config`).  imu, pos: the recording as read (:func:`jaxnav.io.read_ins_inputs`;
        the IMU times before the time offset).  prep: its :class:`Prepared` if already made (None: made here).
      calibrate: "auto" | True | False (None: ``[tune] calibrate``).  tune: run ``--tune``.
      progress: callable for one line of text, or None.
    """
    say = progress or (lambda *_: None)
    prep = prepare(cfg, imu=imu, pos=pos, progress=progress) if prep is None else prep
    mode = cfg.tune.calibrate if calibrate is None else calibrate
    if mode is not False:
        say(
            f"checking the noise: GNSS position and velocity NIS of the configured noise without the gate "
            f"(calibrate = {mode})"
        )
    dens, cal = calibrate_noise(prep, mode, progress=progress)
    prep = prep._replace(densities=dens)
    say(
        f"IMU {prep.t.size} samples over {prep.t[-1] - prep.t[0]:.1f} s, GNSS {prep.meas.t.size} epochs; "
        f"running the filter and the smoother"
    )
    run = untuned = run_ins(prep)
    n_used = int(np.count_nonzero(np.asarray(prep.meas.mask)[:, :3].any(-1)))
    n_gated = int(run.result.n_gated) if run.result.n_gated is not None else 0
    gated_share = n_gated / n_used if n_used else 0.0
    if gated_share > GATED_SHARE_WARN:
        cal["gate_warning"] = (
            f"the chi-square gate rejected {n_gated} of {n_used} GNSS epochs ({100 * gated_share:.1f} %, above "
            f"{100 * GATED_SHARE_WARN:.0f} %): the noise does not explain the GNSS data"
        )
        say(f"warning: {cal['gate_warning']}")
    rep = None
    if tune:
        t = cfg.tune
        say(f"tuning {', '.join(t.params)} by the {t.loss} likelihood (L-BFGS, {t.steps} evaluations)")
        rep = tune_noise(prep, t.params, max_evals=t.steps, mode=t.mode, loss_kind=t.loss)
        run = tuned_run(prep, rep)
    return FittedRun(prep=prep, calibration=cal, run=run, tune=rep, untuned=untuned, gated_share=gated_share)


def _search_epochs(cfg: InsConfig, pos, t_imu, span: float):
    """The GNSS solution restricted to the epochs every trial offset in [-span, span] s can use, and counts
    (:func:`jaxnav.ins.offset_search_epochs`; with ``[evaluate]`` its outages are left out).

    Raises:
      ValueError: fewer than :data:`jaxnav.ins.timing.MIN_SEARCH_EPOCHS` epochs remain (names
        ``imu.time_offset_search_s``).
    """
    gt = np.asarray(pos.t, float)
    t0, t1 = float(t_imu[0]), float(t_imu[-1])
    sel = offset_search_epochs(gt, t_imu, span, _outages(cfg, t0, t1))
    n = sel["n_used"]
    if n < MIN_SEARCH_EPOCHS:
        raise ValueError(
            f"time offset search: only {n} GNSS epoch(s) lie inside the IMU span "
            f"[{t0:.3f}, {t1:.3f}] s at every trial offset within +-{span} s (GNSS "
            f"[{gt[0]:.3f}, {gt[-1]:.3f}] s; at least {MIN_SEARCH_EPOCHS} needed): check the time "
            "systems, or reduce imu.time_offset_search_s"
        )
    return pos.take(sel["use"]), {
        "n_epochs_used": n,
        "n_epochs_dropped_at_span_edges": sel["n_dropped_at_span_edges"],
        "n_epochs_withheld_by_evaluate": sel["n_withheld"],
        "fitted_on": (
            "GNSS epochs inside the IMU span at every trial offset"
            + (", outside the [evaluate] outages (widened by the search span)" if _evaluated(cfg) else "")
        ),
    }


def recording_time_offset(cfg: InsConfig, imu, pos, C_bs, lever_rfu, *, progress=print):
    """IMU-GNSS time offset (s, added to IMU times) of a recording: :func:`jaxnav.ins.search_time_offset`
    over +-``imu.time_offset_search_s`` with this recording's filter (no outages, gate or pseudo-measurements,
    so that the likelihoods of the trials compare) on the epochs of :func:`_search_epochs`.

    Returns:
      (offset s, info dict: the epoch counts and the search's report).
    """
    t, dth, dv, dt = imu_increments(imu, C_bs)
    span = cfg.imu.time_offset_search_s
    pos, common = _search_epochs(cfg, pos, t, span)
    no_eval = cfg._replace(
        evaluate=None,
        imu=cfg.imu._replace(time_offset_s=0.0),
        gnss=cfg.gnss._replace(gate_probability=None),
        constraints=cfg.constraints._replace(zupt=False, nhc=False),
        odometer=None,
        heading=None,
    )
    tg, ti = np.asarray(pos.t, float), np.asarray(imu.t, float)
    t_ref, T = 0.5 * (tg[0] + tg[-1]), float(tg[-1] - tg[0])

    def loglik(off, change):
        p = prepare(no_eval, imu=imu._replace(t=ti + off + change * (ti - t_ref) / T), pos=pos, progress=None)
        return float(run_filter(p, save=("nav",)).loglik)

    llh = np.stack([np.asarray(pos.lat), np.asarray(pos.lon), np.asarray(pos.h)], -1)
    info = search_time_offset(
        loglik,
        span,
        t,
        dth / dt[:, None],
        dv / dt[:, None],
        tg,
        llh,
        pos.v_enu,
        progress=progress,
        widen_hint="widen imu.time_offset_search_s",
    )
    return info["offset_s"], {"source": "estimate", **common, **info}


def run_training_windows(prep: Prepared) -> np.ndarray:
    """(K, 2) GNSS outages for ``--tune`` with ``loss = "outages"``: :func:`jaxnav.ins.training_windows`
    between the ``[evaluate]`` windows, or without them the default protocol's windows
    (:func:`jaxnav.ins.outage_windows`)."""
    ev = prep.cfg.evaluate
    t0, t1 = float(prep.t[0]), float(prep.t[-1])
    if ev is None or not ev.outages:
        return outage_windows(t0, t1)
    return training_windows(prep.outages, t1, ev.outage_s)


def tune_noise(
    prep: Prepared, names, *, max_evals: int = 25, mode: str = "reverse", loss_kind: str = "innovations"
) -> LCNoiseFit:
    """``--tune``: :func:`jaxnav.tune.fit_lc_noise` of ``names`` on the GNSS epochs the filter sees.

    ``loss_kind``:

    * "innovations": the negative GNSS innovation log-likelihood of the forward filter over the
      whole run (every GNSS epoch the filter sees; the ``[evaluate]`` outages stay withheld) — the
      classic ML criterion; at a GNSS rate of several Hz it weighs predictions over fractions of a second.
    * "outages": :func:`jaxnav.ins.horizontal_fix_nll` of the GNSS fixes withheld on
      :func:`run_training_windows` (disjoint from the evaluation windows): horizontal antenna position
      predicted by the forward filter against each withheld fixed-quality fix, with the filter's
      predicted position variance plus the fix's own — the criterion for bridging outages.

    Args:
      prep: :class:`Prepared` (its evaluation outages stay withheld).  names: parameters of
        :data:`jaxnav.ins.calibration.TUNABLE`.  max_evals: loss evaluations at most.  mode: "reverse" or "forward".
    """
    check_tunable(names, n_states=prep.cfg.noise.states, use_velocity=prep.cfg.gnss.use_velocity)
    if loss_kind not in ("innovations", "outages"):
        raise ValueError(f"loss must be 'innovations' or 'outages', got {loss_kind!r}")
    # only the epochs the filter may see: the [evaluate] outages stay withheld, scored once after tuning
    base_mask = np.asarray(prep.meas.mask).copy()
    scored = None
    if loss_kind == "outages":
        tw = run_training_windows(prep)
        inside = in_windows(prep.meas.t, tw)
        fixed = np.asarray(prep.pos.q)[prep.keep] == 1
        scored = inside & fixed & base_mask[:, :3].any(-1)
        if scored.sum() < 5:
            raise ValueError(
                f"--tune loss 'outages': only {int(scored.sum())} fixed GNSS epochs inside the training "
                f"windows {tw.tolist()}; use loss = 'innovations'"
            )
        base_mask = base_mask & ~inside[:, None]
    seen = prep.meas._replace(mask=base_mask)
    pos0 = jnp.asarray(np.asarray(prep.alignment.nav0.pos, float))
    idx = run_error_model(prep.cfg).idx

    def loss(d, lev):
        m = seen._replace(lever=jnp.broadcast_to(lev, seen.lever.shape))
        if loss_kind == "innovations":
            return -run_filter(prep, d, meas=m, save=("nav",)).loglik
        res = run_filter(prep, d, meas=m, save=("nav", "covs"))
        return withheld_fix_loss(res, prep.meas, scored, lev, pos0, idx, R_scale=d.pos_sigma_scale**2)

    return fit_lc_noise(
        loss,
        prep.densities,
        names,
        lever=jnp.asarray(prep.lever_rfu, float),
        max_evals=max_evals,
        mode=mode,
        fitted_on="GNSS epochs the filter sees"
        + (", outside the [evaluate] outages" if prep.withheld.any() else "")
        + (": fixes withheld on the training windows" if scored is not None else ": their innovations"),
        n_epochs=int(scored.sum()) if scored is not None else int(base_mask[:, :3].any(-1).sum()),
    )


def calibration_params(cfg: InsConfig) -> tuple:
    """:func:`jaxnav.ins.calibration_params` of the run's error model and GNSS velocity use."""
    return ins_calibration_params(cfg.noise.states, cfg.gnss.use_velocity)


def _config_unit(name: str) -> tuple:
    """(unit, SI value of one unit) of a calibrated parameter (:data:`jaxnav.ins.calibration.TUNABLE`) as the
    config gives it (:data:`jaxnav.io.INS_NOISE_KEYS`); a sigma factor is dimensionless."""
    field = TUNABLE[name][0]
    return next(((unit, si) for _, f, si, unit in INS_NOISE_KEYS.values() if f == field), ("1", 1.0))


def calibrate_noise(prep: Prepared, mode=None, *, progress=None) -> tuple:
    """The run's noise self-calibration: :func:`jaxnav.tune.calibrate_lc_noise` of :func:`calibration_params`
    on the GNSS epochs the filter sees (the ``[evaluate]`` outages stay withheld), ``[tune] calibrate_steps``
    evaluations.

    Args:
      prep: :class:`Prepared`.  mode: "auto" | True | False (default ``[tune] calibrate``).
      progress: callable for one line of text (stages and warnings), or None.
    Returns:
      (:class:`jaxnav.ins.LCNoise` to run with, the report for ``results.json`` ``calibration``, with the
      parameters also in their config units: ``before_display``, ``after_display``, ``display_units``).
    """
    cfg = prep.cfg
    g = cfg.gnss

    def run(d, gate_probability, save):
        p = prep._replace(cfg=cfg._replace(gnss=g._replace(gate_probability=gate_probability)))
        return run_filter(p, d) if save is None else run_filter(p, d, save=save)

    noise, rep = calibrate_lc_noise(
        run,
        prep.densities,
        np.asarray(prep.meas.mask),
        calibration_params(cfg),
        mode=cfg.tune.calibrate if mode is None else mode,
        max_evals=cfg.tune.calibrate_steps,
        gate_probability=g.gate_probability,
        fitted_on="GNSS position epochs the filter sees"
        + (", outside the [evaluate] outages" if np.asarray(prep.withheld).any() else ""),
        progress=progress,
    )
    if rep["ran"]:
        for when in ("before", "after"):
            rep[f"{when}_display"] = {k: float(v) / _config_unit(k)[1] for k, v in rep[f"{when}_si"].items()}
        rep["display_units"] = {k: _config_unit(k)[0] for k in rep["params"]}
    return noise, rep


def _mask_without_outages(prep: Prepared):
    """The measurement mask with the simulated outages put back (qualities and velocity rules kept)."""
    ok = np.asarray(prep.meas.mask).copy()
    w = np.asarray(prep.withheld)
    if w.any():
        full = gnss_solution_measurements(
            prep.pos,
            prep.t,
            (),
            lever_rfu=prep.lever_rfu,
            pos_sigma_floor=prep.cfg.gnss.pos_sigma_floor,
            vel_sigma_floor=prep.cfg.gnss.vel_sigma_floor,
            use_velocity=prep.cfg.gnss.use_velocity,
            qualities=(1,) if prep.cfg.gnss.fixed_only else (1, 2, 3, 4, 5, 6),
        )[0]
        ok = np.asarray(full.mask)
    return ok


def truth_errors(run: InsRun, truth, which: str):
    """:class:`jaxnav.ins.TrajectoryErrors` of the forward or smoothed IMU solution against the reference
    (:func:`jaxnav.ins.solution_errors` at the filter's epochs, outages from ``[evaluate]``)."""
    ep = run.result.epochs
    nav, P = (run.smoothed_nav, run.smoothed_covs) if which == "smoothed" else (ep.nav, ep.covs)
    try:
        return solution_errors(ep.t_nav, nav, P, truth, run_error_model(run.prep.cfg).idx, windows=run.prep.outages)
    except NoCommonEpochError as exc:
        raise ConfigError(f"{run.prep.cfg.path}: evaluate.truth: {truth.path}: {exc}") from None
