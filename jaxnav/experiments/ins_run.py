"""``jaxnav ins CONFIG``: post-process a real IMU + GNSS recording from a config file alone.

Pipeline (host-side glue around the pure, jitted library functions):

1. read the IMU and GNSS files (:func:`read_inputs`; formats of :mod:`jaxnav.io`), apply the
   mounting (:func:`jaxnav.experiments.ins_config.sensor_to_body`) and the IMU-GNSS time offset;
2. align (:func:`jaxnav.ins.coarse_alignment`), build the GNSS measurements with the lever arm
   (:func:`gnss_measurements`) and the filter's noise (:func:`filter_params`);
3. run the loosely coupled filter (:func:`jaxnav.ins.loosely_coupled`) and the RTS smoother
   (:func:`jaxnav.ins.smooth`);
4. optionally withhold GNSS on simulated outages and score forward and smoothed solutions
   against the withheld RTK-fixed epochs (:func:`jaxnav.ins.outage_windows`, :func:`jaxnav.ins.score_outages`);
5. optionally tune the noise densities by maximum likelihood (:func:`tune_noise`): gradient of
   the GNSS innovation negative log-likelihood over the whole run.

Outputs are written by :mod:`jaxnav.experiments.ins_output`.
"""

from __future__ import annotations

import math
import time
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxnav.experiments.ins_config import ConfigError, InsConfig
from jaxnav.geodesy import curvilinear_to_enu, enu_to_curvilinear
from jaxnav.ins import (
    ImuNoise,
    LCGate,
    LCParams,
    LCSave,
    OutageScores,
    SensorBiases,
    attitude_sigmas,
    clock_drift,
    coarse_alignment,
    error_model_for,
    estimate_time_offset,
    gnss_checked_standstill,
    gnss_speed_test,
    horizontal_fix_nll,
    horizontal_sigma,
    in_windows,
    interpolate_on_samples,
    lc_params,
    likelihood_time_offset,
    loosely_coupled,
    nearest_samples,
    nhc,
    noise_preset,
    odometer,
    offset_search_epochs,
    outage_windows,
    position_cov_enu,
    score_outages,
    sensor_to_body,
    smooth,
    standstill_intervals,
    training_windows,
    trajectory_errors,
    zaru,
    zupt,
)
from jaxnav.ins import gnss_measurements as ins_gnss_measurements
from jaxnav.ins import heading as heading_aid
from jaxnav.ins.attitude import quat_to_dcm
from jaxnav.ins.timing import MIN_SEARCH_EPOCHS
from jaxnav.io import (
    imu_increments,
    read_csv_gnss,
    read_csv_imu,
    read_csv_series,
    read_kfgins_gnss,
    read_kfgins_imu,
    read_kfgins_odometer,
    read_pos,
    read_rtklib_imu,
)


def read_inputs(cfg: InsConfig):
    """(:class:`jaxnav.io.ImuLog`, :class:`jaxnav.io.PosSolution`) of the config's files (SI, sensor axes).

    Raises:
      jaxnav.io.ReaderError: naming file and line of anything unreadable.
      FileNotFoundError: a missing file (named).
    """
    imu_c, g = cfg.imu, cfg.gnss
    truth = cfg.evaluate.truth if cfg.evaluate is not None else None
    odo = cfg.odometer.file if cfg.odometer is not None else None
    hdg = cfg.heading.file if cfg.heading is not None else None
    for p, key in (
        (imu_c.file, "imu.file"),
        (g.file, "gnss.file"),
        (imu_c.tag, "imu.tag"),
        (truth, "evaluate.truth"),
        (odo, "odometer.file"),
        (hdg, "heading.file"),
    ):
        if p is not None and not p.is_file():
            what = "a folder, not a file" if p.is_dir() else "no such file"
            raise FileNotFoundError(f"{p}: {what} ({cfg.path}: {key})")
    if imu_c.format == "rtklib-csv":
        imu = read_rtklib_imu(imu_c.file, imu_c.tag)
    elif imu_c.format == "kf-gins":
        odo_col = cfg.odometer is not None and cfg.odometer.source == "imu"
        imu = read_kfgins_imu(imu_c.file, gps_week=imu_c.gps_week, n_columns=8 if odo_col else None)
    else:
        imu = _csv(cfg, "imu", lambda: read_csv_imu(imu_c.file, imu_c.columns, imu_c.units, delimiter=imu_c.delimiter))
    if g.format == "rtklib-pos":
        pos = read_pos(g.file)
    elif g.format == "kf-gins":
        pos = read_kfgins_gnss(g.file, gps_week=g.gps_week)
    else:
        pos = _csv(
            cfg, "gnss", lambda: read_csv_gnss(g.file, g.columns, g.units, delimiter=g.delimiter, sigma_m=g.sigma_m)
        )
    return imu, pos


def _csv(cfg, section, read):
    """A csv reader's ValueError about the column map or units (not a ReaderError) names the config keys."""
    from jaxnav.io import ReaderError

    try:
        return read()
    except ReaderError:
        raise
    except ValueError as exc:
        raise ValueError(f"{cfg.path}: {section}.columns / {section}.units: {exc}") from None


def read_odometer(cfg: InsConfig):
    """(t (R,) s on the IMU file's clock, speed (R,) m/s) of the ``[odometer]`` source (NaN: no reading)."""
    o = cfg.odometer
    if o.source == "imu":
        return read_kfgins_odometer(cfg.imu.file, gps_week=cfg.imu.gps_week)
    d = _csv(cfg, "odometer", lambda: read_csv_series(o.file, o.columns, o.units, kind="speed", delimiter=o.delimiter))
    t = d["t"] if o.gps_week is None else d["t"] + o.gps_week * 604800.0
    return t, d["speed"]


def heading_on_imu(cfg: InsConfig, t_imu):
    """The ``[heading]`` CSV at the IMU samples: (heading (N,) rad, sigma (N,) rad), NaN where no reading.

    Each reading goes to the IMU sample nearest its time (GNSS time scale, :func:`jaxnav.ins.nearest_samples`);
    readings outside the IMU span or farther than one sample interval from every sample are dropped.
    """
    h = cfg.heading
    d = _csv(cfg, "heading", lambda: read_csv_series(h.file, h.columns, h.units, kind="heading", delimiter=h.delimiter))
    t = d["t"] if h.gps_week is None else d["t"] + h.gps_week * 604800.0
    t_imu = np.asarray(t_imu, float)
    hd, sg = np.full(t_imu.size, np.nan), np.full(t_imu.size, np.nan)
    j, ok = nearest_samples(t, t_imu)
    hd[j[ok]] = d["heading"][ok]
    if d["sigma"] is not None:
        sg[j[ok]] = d["sigma"][ok]
    return hd, sg


def gnss_measurements(
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
    """The solution's epochs inside the IMU span as :func:`jaxnav.ins.gnss_measurements`, masked inside the outages.

    Epochs inside an outage keep an all-False mask, so the filter reports its free-inertial
    prediction there (and the smoother its estimate). Covariances: the solution's ENU position
    and velocity covariances with the standard deviations floored at ``pos_sigma_floor`` (m) and
    ``vel_sigma_floor`` (m/s); a missing velocity covariance counts as 1 (m/s)^2.

    Args:
      pos_sol: :class:`jaxnav.io.PosSolution`.  t_imu: (N,) IMU times, s.  outages: (K, 2) windows, s.
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
            f"(GNSS [{gt[0]:.3f}, {gt[-1]:.3f}] s): check the time systems and imu.time_offset_s"
        )
    t = gt[keep]
    pos = np.stack([np.asarray(pos_sol.lat)[keep], np.asarray(pos_sol.lon)[keep], np.asarray(pos_sol.h)[keep]], -1)
    withheld = np.zeros(keep.size, bool)
    for a, b in np.asarray(outages, float).reshape(-1, 2):
        withheld |= (t >= a) & (t < b)
    use = np.isin(np.asarray(pos_sol.q)[keep], np.asarray(qualities)) & ~withheld
    meas = ins_gnss_measurements(
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


class RunNoise(NamedTuple):
    """The noise of a run: the IMU's and the initial sigmas (SI; array leaves, so ``--tune`` differentiates them).

    Attributes:
      imu: :class:`jaxnav.ins.ImuNoise`; which of its densities enter the filter depends on
        ``noise.states`` (:meth:`jaxnav.ins.ErrorModel.Qc`).
      init_att: (2,) rad (roll/pitch, heading).  init_vel: m/s.  init_pos: m.
      pos_sigma_scale: factor on the GNSS position sigmas.  vel_sigma_scale: factor on the GNSS velocity sigmas.
    """

    imu: ImuNoise
    init_att: Any
    init_vel: Any
    init_pos: Any
    pos_sigma_scale: Any = 1.0
    vel_sigma_scale: Any = 1.0


#: ``[noise]`` keys (SI) -> :class:`jaxnav.ins.ImuNoise` fields
NOISE_KEYS = {
    "arw": "gyro_arw",
    "vrw": "accel_vrw",
    "gyro_bias_instability": "gyro_bias_instability",
    "bias_correlation_time": "gyro_bias_tau",
    "accel_bias_instability": "accel_bias_instability",
    "bias_correlation_time_accel": "accel_bias_tau",
    "gyro_bias_rw": "gyro_bias_rw",
    "accel_bias_rw": "accel_bias_rw",
    "init_gyro_bias": "gyro_bias_initial",
    "init_accel_bias": "accel_bias_initial",
    "init_gyro_scale": "gyro_sf",
    "init_accel_scale": "accel_sf",
}


def run_noise(cfg: InsConfig) -> RunNoise:
    """The run's :class:`RunNoise` from ``[noise]``: values given there, else the grade's :func:`jaxnav.ins.noise_preset`
    (without a grade: zeros, a 300 s gyro and a 3600 s accelerometer correlation time). The accelerometer's
    correlation time defaults to the gyro's when only that is given."""
    n = cfg.noise
    imu = noise_preset(n.grade) if n.grade else ImuNoise(gyro_arw=0.0, accel_vrw=0.0, gyro_bias_tau=300.0)
    given = {f: getattr(n, k) for k, f in NOISE_KEYS.items() if getattr(n, k, None) is not None}
    if n.bias_correlation_time is not None:
        given.setdefault("accel_bias_tau", n.bias_correlation_time)
    return RunNoise(
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


def filter_params(noise: RunNoise, pos0, model, *, odo_scale_sigma=0.0) -> LCParams:
    """:func:`jaxnav.ins.lc_params` of ``model`` from :class:`RunNoise` at ``pos0`` (3,) rad, rad, m; the roll/pitch
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
    """Everything a run needs, made once from the config (host side)."""

    cfg: Any
    imu: Any
    pos: Any
    C_bs: Any
    lever_rfu: Any
    time_offset: float
    time_offset_info: dict
    t: Any
    dth: Any
    dv: Any
    dt: Any
    alignment: Any
    outages: Any
    meas: Any
    keep: Any
    withheld: Any
    densities: RunNoise
    standstill: Any = None  # (N,) bool per IMU sample, or None (no detection)
    aids: tuple = ()  # pseudo-measurements (jaxnav.ins aids: ZUPT, ZARU, NHC, odometer)
    standstill_info: dict = {}  # detector report (detect_stops), with its series under "_series"
    odometer_speed: Any = None  # (N,) m/s wheel speed per IMU sample (NaN: none), or None (no [odometer])
    heading: Any = None  # (heading (N,) rad, sigma (N,) rad) per IMU sample (NaN: none), or None (no [heading])


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
    sc, sc_imu = r.scores, r.imu_only_scores
    info = {
        "kind": "SHOE GLRT",
        "platform": c.platform,
        "window_samples": r.window,
        "min_s": r.min_s,
        "threshold": r.threshold,
        "threshold_source": "config" if r.threshold_source == "given" else r.threshold_source,
        "quiet_samples": r.quiet_samples,
        "sigma_a_m_s2": c.detector_sigma_a,
        "sigma_w_rad_s": c.detector_sigma_w,
        "gnss_check": meas is not None,
        "gnss_k": c.zupt_gnss_k,
        "vetoed_samples": int(np.count_nonzero(r.vetoed)),
        "vetoed_intervals": int(standstill_intervals(t, r.vetoed).shape[0]),
        "vetoed_s": float(np.count_nonzero(r.vetoed) / rate),
        "unconfirmed_samples": int(np.count_nonzero(r.unconfirmed)),
        "unconfirmed_intervals": int(standstill_intervals(t, r.unconfirmed).shape[0]),
        "gnss_static_samples": int(np.count_nonzero(r.static)),
        "gnss_moving_samples": int(np.count_nonzero(r.moving)),
        "scored_samples": int(np.count_nonzero(r.covered)),
        "precision": sc.precision,
        "recall": sc.recall,
        "tp": sc.tp,
        "fp": sc.fp,
        "fn": sc.fn,
        "tn": sc.tn,
        "imu_only_precision": sc_imu.precision,
        "imu_only_recall": sc_imu.recall,
    }
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
        imu, pos = read_inputs(cfg)
    C_bs = sensor_to_body(cfg.imu.mounting)
    lever_rfu = sensor_to_body(np.eye(3)) @ np.asarray(cfg.gnss.lever_arm_frd, float)
    off_info: dict = {"source": "config"}
    off = cfg.imu.time_offset_s
    if off == "estimate":
        off, off_info = recording_time_offset(cfg, imu, pos, C_bs, lever_rfu, progress=progress)
    imu = imu._replace(t=np.asarray(imu.t, float) + float(off))
    t, dth, dv, dt = imu_increments(imu, C_bs)
    ev = cfg.evaluate if cfg.evaluate is not None and cfg.evaluate.outages else None
    if (
        ev is not None
        and len(
            outage_windows(
                t[0], t[-1], first_s=ev.first_s, outage_s=ev.outage_s, gap_s=ev.gap_s, end_margin_s=ev.end_margin_s
            )
        )
        == 0
    ):
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
    )
    # the alignment starts at the first GNSS fix, i.e. at the antenna: move it to the IMU
    C_bn = np.asarray(quat_to_dcm(np.asarray(align.nav0.q_bn)))
    p0 = np.asarray(align.nav0.pos, float)
    p_imu = p0 - np.asarray(enu_to_curvilinear(p0, C_bn @ lever_rfu))
    align = align._replace(nav0=align.nav0._replace(pos=p_imu))
    ev = cfg.evaluate if cfg.evaluate is not None and cfg.evaluate.outages else None
    outages = (
        np.zeros((0, 2))
        if ev is None
        else outage_windows(
            t[0], t[-1], first_s=ev.first_s, outage_s=ev.outage_s, gap_s=ev.gap_s, end_margin_s=ev.end_margin_s
        )
    )
    meas, keep, withheld = gnss_measurements(
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
        t_odo, sp = read_odometer(cfg)
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


def run_filter(prep: Prepared, d: RunNoise | None = None, *, meas=None, save=_SAVE):
    """The loosely coupled filter on a prepared recording; returns :class:`jaxnav.ins.LCResult`."""
    d = prep.densities if d is None else d
    o = prep.cfg.odometer
    model = run_error_model(prep.cfg)
    params = filter_params(
        d, prep.alignment.nav0.pos, model, odo_scale_sigma=o.init_scale_sigma if model.idx.s_odo is not None else 0.0
    )
    m = prep.meas if meas is None else meas
    # R -> D R D, D = diag(pos_sigma_scale x 3, vel_sigma_scale x 3): the sigmas scaled, correlations kept
    s = jnp.concatenate([jnp.broadcast_to(d.pos_sigma_scale, (3,)), jnp.broadcast_to(d.vel_sigma_scale, (3,))])
    m = m._replace(R=jnp.asarray(m.R) * (s[:, None] * s[None, :]))
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


def antenna_enu(nav, t_nav, t, lever, pos0):
    """(M, 3) antenna ENU (m, around ``pos0`` (3,)) of per-epoch nav states extrapolated to times ``t`` (M,)."""
    pos = np.asarray(nav.pos)
    enu = np.asarray(curvilinear_to_enu(pos0, pos - pos0))
    C = np.asarray(quat_to_dcm(np.asarray(nav.q_bn)))
    v = np.asarray(nav.v_n)
    return enu + (np.asarray(t) - np.asarray(t_nav))[:, None] * v + np.einsum("mij,mj->mi", C, lever)


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
    result: Any
    smoothed_nav: Any
    smoothed_biases: Any
    smoothed_covs: Any
    enu_ref: Any
    enu_fwd: Any
    enu_sm: Any
    fixed: Any
    scores: OutageScores | None
    runtime_s: float
    densities: RunNoise
    gnss_epochs: Any = None


def run_ins(prep: Prepared, d: RunNoise | None = None) -> InsRun:
    """Forward filter + RTS smoother on a prepared recording, scored on its outages if it has any."""
    d = prep.densities if d is None else d
    t0 = time.perf_counter()
    res = run_filter(prep, d)
    model = run_error_model(prep.cfg)
    sm_nav, sm_b, sm_P = smooth(res, error_model=model)
    jax.block_until_ready(sm_nav.pos)
    runtime = time.perf_counter() - t0
    meas = prep.meas
    # the filter's epochs are the GNSS epochs merged with the pseudo-measurement (ZUPT/NHC) epochs
    g = np.nonzero(np.asarray(res.epochs.gnss_row) >= 0)[0]
    ep = jax.tree_util.tree_map(lambda a: np.asarray(a)[g], res.epochs)
    sm_nav_g = jax.tree_util.tree_map(lambda a: np.asarray(a)[g], sm_nav)
    sm_P_g = np.asarray(sm_P)[g]
    pos0 = np.array([float(x) for x in prep.alignment.nav0.pos])
    lev = np.asarray(meas.lever)
    enu_f = antenna_enu(ep.nav, ep.t_nav, meas.t, lev, pos0)
    enu_s = antenna_enu(sm_nav_g, ep.t_nav, meas.t, lev, pos0)
    enu_ref = np.asarray(curvilinear_to_enu(pos0, np.asarray(meas.pos) - pos0))
    fixed = np.asarray(prep.pos.q)[prep.keep] == 1
    nonfinite = int(sum(np.count_nonzero(~np.isfinite(np.asarray(a))) for a in (*ep.nav, *sm_nav)))
    scores = None
    if prep.outages.shape[0]:
        e_f = np.hypot(*(enu_f - enu_ref)[:, :2].T)
        e_s = np.hypot(*(enu_s - enu_ref)[:, :2].T)
        scores = score_outages(
            np.asarray(meas.t),
            e_f,
            e_s,
            fixed,
            prep.withheld,
            prep.outages,
            runtime_s=runtime,
            n_nonfinite=nonfinite,
            sig_f=horizontal_sigma(ep.covs, ep.nav.pos, model.idx),
            sig_s=horizontal_sigma(sm_P_g, sm_nav_g.pos, model.idx),
        )
    return InsRun(
        prep=prep,
        result=res,
        smoothed_nav=sm_nav,
        smoothed_biases=sm_b,
        smoothed_covs=sm_P,
        enu_ref=enu_ref,
        enu_fwd=enu_f,
        enu_sm=enu_s,
        fixed=fixed,
        scores=scores,
        runtime_s=runtime,
        densities=d,
        gnss_epochs=g,
    )


def tuned_run(prep: Prepared, rep) -> InsRun:
    """:func:`run_ins` with the densities and lever arm of a ``--tune`` :class:`TuneReport`."""
    tuned_prep = prep._replace(
        lever_rfu=rep.lever_rfu,
        meas=prep.meas._replace(lever=np.broadcast_to(rep.lever_rfu, np.shape(prep.meas.lever)).copy()),
    )
    return run_ins(tuned_prep, rep.densities)


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
      prep: :class:`Prepared` (its time offset and standstill detection fitted without the withheld epochs).
      calibration: :func:`calibrate_noise`'s report.  run: the final :class:`InsRun` (after ``--tune`` if tuned).
      tune: the :class:`TuneReport`, or None.
    """

    prep: Prepared
    calibration: dict
    run: InsRun
    tune: Any = None


def fit_and_run(cfg: InsConfig, *, imu, pos, calibrate=None, tune: bool = False, progress=None) -> FittedRun:
    """The whole fitted pipeline of one outage schedule: :func:`prepare` (time offset and standstill
    detection on the GNSS epochs outside the config's outages), :func:`calibrate_noise`, :func:`run_ins`,
    and with ``tune`` :func:`tune_noise` and its rerun; nothing fitted sees the withheld epochs.

    Args:
      cfg: the config (e.g. :func:`shifted_config`).  imu, pos: the recording as read (:func:`read_inputs`;
        the IMU times before the time offset).  calibrate: "auto" | True | False (None: ``[tune] calibrate``).
      progress: callable for one line of text, or None.
    """
    prep = prepare(cfg, imu=imu, pos=pos, progress=progress)
    dens, cal = calibrate_noise(prep, calibrate, progress=progress)
    prep = prep._replace(densities=dens)
    run = run_ins(prep)
    rep = None
    if tune:
        t = cfg.tune
        rep = tune_noise(prep, t.params, max_evals=t.steps, mode=t.mode, loss_kind=t.loss)
        run = tuned_run(prep, rep)
    return FittedRun(prep=prep, calibration=cal, run=run, tune=rep)


def _search_epochs(cfg: InsConfig, pos, t_imu, span: float):
    """The GNSS solution restricted to the epochs every trial offset in [-span, span] s can use, and counts
    (:func:`jaxnav.ins.offset_search_epochs`; with ``[evaluate]`` its outages are left out).

    Raises:
      ValueError: fewer than :data:`jaxnav.ins.timing.MIN_SEARCH_EPOCHS` epochs remain (names
        ``imu.time_offset_search_s``).
    """
    gt = np.asarray(pos.t, float)
    t0, t1 = float(t_imu[0]), float(t_imu[-1])
    ev = cfg.evaluate if cfg.evaluate is not None and cfg.evaluate.outages else None
    windows = (
        None
        if ev is None
        else outage_windows(
            t0, t1, first_s=ev.first_s, outage_s=ev.outage_s, gap_s=ev.gap_s, end_margin_s=ev.end_margin_s
        )
    )
    sel = offset_search_epochs(gt, t_imu, span, windows)
    use, n = sel["use"], sel["n_used"]
    if n < MIN_SEARCH_EPOCHS:
        raise ValueError(
            f"time offset search: only {n} GNSS epoch(s) lie inside the IMU span "
            f"[{t0:.3f}, {t1:.3f}] s at every trial offset within +-{span} s (GNSS "
            f"[{gt[0]:.3f}, {gt[-1]:.3f}] s; at least {MIN_SEARCH_EPOCHS} needed): check the time "
            "systems, or reduce imu.time_offset_search_s"
        )
    M = gt.size
    sub = pos._replace(
        **{
            f: np.asarray(v)[use]
            for f, v in zip(pos._fields, pos)
            if isinstance(v, (np.ndarray, jnp.ndarray)) and np.ndim(v) >= 1 and np.shape(v)[0] == M
        }
    )
    return sub, {
        "n_epochs_used": n,
        "n_epochs_dropped_at_span_edges": sel["n_dropped_at_span_edges"],
        "n_epochs_withheld_by_evaluate": sel["n_withheld"],
        "fitted_on": (
            "GNSS epochs inside the IMU span at every trial offset"
            + (", outside the [evaluate] outages (widened by the search span)" if ev else "")
        ),
    }


def recording_time_offset(cfg: InsConfig, imu, pos, C_bs, lever_rfu, *, progress=print):
    """IMU-GNSS time offset (s, added to IMU times) of a recording by the filter's innovation likelihood.

    First guess: :func:`jaxnav.ins.estimate_time_offset` (yaw rate against GNSS course rate; it assumes the
    body points along the velocity, which a handheld device does not). Search:
    :func:`jaxnav.ins.likelihood_time_offset` over +-``imu.time_offset_search_s`` with this recording's
    filter (no outages, gate or pseudo-measurements) on the epochs of :func:`_search_epochs`; clock drift:
    :func:`jaxnav.ins.clock_drift` at the best offset, with a warning when significant.

    Returns:
      (offset s, info dict with the grid, its log-likelihoods, the estimate's sigma, the epoch counts
      and the method).
    """
    t, dth, dv, dt = imu_increments(imu, C_bs)
    span = cfg.imu.time_offset_search_s
    pos, common = _search_epochs(cfg, pos, t, span)
    llh = np.stack([np.asarray(pos.lat), np.asarray(pos.lon), np.asarray(pos.h)], -1)
    v = np.asarray(pos.v_enu, float)
    info = {"source": "estimate", **common}
    try:
        est = estimate_time_offset(
            t,
            dth / dt[:, None],
            np.asarray(pos.t, float),
            v if np.all(np.isfinite(v)) else None,
            llh=llh,
            f_b=dv / dt[:, None],
            max_offset_s=max(1.0, span + 0.5),
        )
        guess = float(est.offset_s)
        info.update(
            first_guess="yaw rate vs GNSS course rate cross-correlation",
            first_guess_s=guess,
            first_guess_sigma_s=float(est.sigma_s),
            first_guess_corr=float(est.corr),
            first_guess_epochs=int(est.n_epochs),
        )
        if not est.corr > 0.5:
            raise ValueError(f"weak correlation {est.corr:.2f}")
    except ValueError as exc:  # too few turns or epochs: search around zero
        guess = 0.0
        info.update(first_guess=f"0 (cross-correlation not usable: {exc})")
    # likelihoods comparable between offsets: the same GNSS epochs, no gate, no pseudo-measurements
    no_eval = cfg._replace(
        evaluate=None,
        imu=cfg.imu._replace(time_offset_s=0.0),
        gnss=cfg.gnss._replace(gate_probability=None),
        constraints=cfg.constraints._replace(zupt=False, nhc=False),
        odometer=None,
        heading=None,
    )
    cache = {}
    tg = np.asarray(pos.t, float)
    t_ref, T = 0.5 * (tg[0] + tg[-1]), float(tg[-1] - tg[0])

    def loglik(off, change=0.0):
        """Log-likelihood with IMU times t + off + change (t - t_ref) / T (a linear clock error)."""
        key = (round(float(off), 6), round(float(change), 6))
        if key not in cache:
            ti = np.asarray(imu.t, float)
            p = prepare(no_eval, imu=imu._replace(t=ti + key[0] + key[1] * (ti - t_ref) / T), pos=pos, progress=None)
            cache[key] = float(run_filter(p, save=("nav",)).loglik)
        return cache[key]

    res = likelihood_time_offset(loglik, span, guess=guess, progress=progress)
    best = res.offset_s
    drift = clock_drift(loglik, best, tg, span, widen_hint="widen imu.time_offset_search_s")
    grid = np.array(sorted(k[0] for k in cache if k[1] == 0.0))
    info.update(
        method="innovation log-likelihood: 50 ms grid over +-time_offset_search_s, 10 ms grid around its "
        "best, parabolic refinement",
        grid_s=grid,
        loglik=np.array([cache[(g, 0.0)] for g in grid]),
        offset_s=best,
        sigma_s=res.sigma_s,
        sigma_method="curvature of the log-likelihood parabola through the best three fine-grid points "
        "(treats the innovations as independent: optimistic when GNSS errors are correlated "
        "in time)",
        at_search_edge=res.at_edge,
        drift=drift,
    )
    if res.at_edge and progress:
        progress(
            f"warning: the time offset {best:+.3f} s is at the edge of the search (+-{span} s): widen "
            "imu.time_offset_search_s"
        )
    if drift.get("significant") and progress:
        progress(f"warning: {drift['warning']}")
    return best, info


#: ``[tune] params`` name -> (ImuNoise or RunNoise field, or "lever_arm"; bijector)
_TUNE_MAP = {
    "arw": ("gyro_arw", "log"),
    "vrw": ("accel_vrw", "log"),
    "gyro_bias_instability": ("gyro_bias_instability", "log"),
    "pos_sigma_scale": ("pos_sigma_scale", "log"),
    "vel_sigma_scale": ("vel_sigma_scale", "log"),
    "lever_arm": ("lever_arm", "real"),
}


class TuneReport(NamedTuple):
    """``--tune`` result: parameters before/after (SI), innovation log-likelihood before/after, evaluations, time.

    ``fitted_on``: which GNSS epochs the loss used; ``n_epochs``: how many (with ``[evaluate]`` never
    the withheld ones).
    """

    before: dict
    after: dict
    loglik_before: float
    loglik_after: float
    n_evals: int
    wall_time_s: float
    densities: RunNoise
    lever_rfu: Any
    fitted_on: str = ""
    n_epochs: int = 0


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
) -> TuneReport:
    """Maximum-likelihood tuning of noise densities (and the lever arm) by gradient through the whole filter.

    ``loss_kind``:

    * "innovations": the negative GNSS innovation log-likelihood of the forward filter over the
      whole run (every GNSS epoch the filter sees; the ``[evaluate]`` outages stay withheld) — the
      classic ML criterion; at a GNSS rate of several Hz it weighs predictions over fractions of a second.
    * "outages": the negative predictive log-likelihood of the GNSS fixes withheld on
      :func:`run_training_windows` (disjoint from the evaluation windows): horizontal antenna position
      predicted by the forward filter against each withheld fixed-quality fix, with the filter's
      predicted position variance plus the fix's own — the criterion for bridging outages.

    Minimised by L-BFGS (:func:`jaxnav.tune.minimize_lbfgs`) with reverse- or forward-mode
    gradients through the complete filter; densities are tuned on a log scale.

    Args:
      prep: :class:`Prepared` (its evaluation outages stay withheld).  names: parameters
        from ``_TUNE_MAP``.  max_evals: loss evaluations at most.  mode: "reverse" or "forward".
    """
    from jaxnav.tune import Space, minimize_lbfgs

    unknown = [n for n in names if n not in _TUNE_MAP]
    if unknown:
        raise ValueError(f"cannot tune {unknown}; tunable: {sorted(_TUNE_MAP)}")
    if "gyro_bias_instability" in names and prep.cfg.noise.states not in (18, 21):
        raise ValueError("gyro_bias_instability is a parameter of the 18- and 21-state models (noise.states)")
    if "vel_sigma_scale" in names and not prep.cfg.gnss.use_velocity:
        raise ValueError("vel_sigma_scale scales the GNSS velocity sigmas: it needs gnss.use_velocity = true")
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
    all_gnss = prep.meas._replace(mask=base_mask)
    n_fit = int(scored.sum()) if scored is not None else int(base_mask[:, :3].any(-1).sum())
    fitted_on = (
        "GNSS epochs the filter sees"
        + (", outside the [evaluate] outages" if prep.withheld.any() else "")
        + (": fixes withheld on the training windows" if scored is not None else ": their innovations")
    )
    d0 = prep.densities
    lever0 = jnp.asarray(prep.lever_rfu, float)
    p0 = {}
    for n in names:
        field, _ = _TUNE_MAP[n]
        p0[n] = (
            lever0
            if field == "lever_arm"
            else jnp.asarray(getattr(d0.imu if field in ImuNoise._fields else d0, field), float)
        )
    space = Space({n: _TUNE_MAP[n][1] for n in names})
    pos0 = jnp.asarray(np.asarray(prep.alignment.nav0.pos, float))
    ref = jnp.asarray(np.asarray(prep.meas.pos, float))
    R_h = jnp.asarray(np.asarray(prep.meas.R, float)[:, :2, :2])
    idx = run_error_model(prep.cfg).idx

    def unpack(p):
        fields = {_TUNE_MAP[n][0]: p[n] for n in names if _TUNE_MAP[n][0] != "lever_arm"}
        d = d0._replace(
            imu=d0.imu._replace(**{f: v for f, v in fields.items() if f in ImuNoise._fields}),
            **{f: v for f, v in fields.items() if f not in ImuNoise._fields},
        )
        lev = p.get("lever_arm", lever0)
        return d, lev

    def loss(p):
        d, lev = unpack(p)
        m = all_gnss._replace(lever=jnp.broadcast_to(lev, all_gnss.lever.shape))
        if loss_kind == "innovations":
            return -run_filter(prep, d, meas=m, save=("nav",)).loglik
        res = run_filter(prep, d, meas=m, save=("nav", "covs"))
        g = np.nonzero(np.asarray(res.epochs.gnss_row) >= 0)[0]
        nav = jax.tree_util.tree_map(lambda a: a[g], res.epochs.nav)
        nll = horizontal_fix_nll(
            nav,
            res.epochs.covs[g],
            res.epochs.t_nav[g],
            jnp.asarray(np.asarray(prep.meas.t)),
            ref,
            R_h * d.pos_sigma_scale**2,
            lev,
            pos0,
            idx,
        )
        return jnp.sum(jnp.where(jnp.asarray(scored), nll, 0.0))

    t0 = time.perf_counter()
    res = minimize_lbfgs(loss, p0, space, max_evals=max_evals, mode=mode)
    ll0 = -float(np.asarray(res.losses)[0])  # the first evaluation is at the start values
    d1, lev1 = unpack(res.params)
    ll1 = -float(res.loss)
    si = {n: np.asarray(v).tolist() for n, v in p0.items()}
    so = {n: np.asarray(v).tolist() for n, v in res.params.items()}
    return TuneReport(
        before=si,
        after=so,
        loglik_before=ll0,
        loglik_after=ll1,
        n_evals=int(res.n_evals),
        wall_time_s=time.perf_counter() - t0,
        densities=d1,
        lever_rfu=np.asarray(lev1),
        fitted_on=fitted_on,
        n_epochs=n_fit,
    )


#: band of the mean GNSS position (and velocity) NIS per degree of freedom inside which the noise counts as consistent
#: (a factor 1.25 either way in innovation variance; docs/guide/ins.md "Noise self-calibration")
NIS_BAND = (0.8, 1.25)
#: largest share of GNSS epochs whose NIS exceeds the gate's chi-square quantile for consistent noise
NIS_GATE_SHARE_MAX = 0.01
#: fewest GNSS position epochs the filter must see for a noise calibration
MIN_CALIBRATION_EPOCHS = 50
#: gated share of the GNSS epochs above which a run warns
GATED_SHARE_WARN = 0.05


def _block_nis(nu, S, use):
    """nu' S^-1 nu over the components ``use`` (K, m) bool of (K, m) innovations with (K, m, m) covariances;
    the others are left out (their rows and columns replaced by the identity, their innovations by 0)."""
    u = use[..., :, None] & use[..., None, :]
    eye = np.broadcast_to(np.eye(S.shape[-1]), S.shape)
    Sm = np.where(u, S, eye)
    L = np.linalg.cholesky(Sm)
    w = np.linalg.solve(L, np.where(use, nu, 0.0)[..., None])[..., 0]
    return np.sum(w * w, -1)


def gnss_nis(res, mask) -> dict:
    """NIS of the GNSS innovations per GNSS epoch: position, velocity and the whole epoch (the gate's statistic).

    Args:
      res: :class:`jaxnav.ins.LCResult` saved with "innovations", "innov_covs" (rows 0-2 of each epoch's
        stacked measurement are the GNSS position components, m, rows 3-5 the velocity, m/s).
      mask: (M, 6) bool GNSS mask (PVMeasurements).
    Returns:
      dict of (M,) arrays: ``pos`` (3 dof; NaN unless the three position components were used), ``vel``
      (3 dof; NaN unless the three velocity components were used), ``epoch`` (nu' S^-1 nu over every GNSS
      component used at the epoch, as :class:`jaxnav.ins.LCGate` computes it; NaN where none) and ``dof``
      (its number of components, 0 where none).
    """
    ep = res.epochs
    row = np.asarray(ep.gnss_row)
    g = np.nonzero(row >= 0)[0]
    nu = np.asarray(ep.innovations, float)[g, :6]
    S = np.asarray(ep.innov_covs, float)[g, :6, :6]
    M = np.asarray(mask).shape[0]
    used = np.asarray(mask, bool)[row[g], :6] & np.isfinite(nu)
    out = {k: np.full(M, np.nan) for k in ("pos", "vel", "epoch")}
    out["dof"] = np.zeros(M, int)
    for key, sl in (("pos", slice(0, 3)), ("vel", slice(3, 6))):
        ok = used[:, sl].all(-1)
        if ok.any():
            out[key][row[g][ok]] = _block_nis(nu[ok][:, sl], S[ok][:, sl, sl], used[ok][:, sl])
    k = used.sum(-1)
    ok = k > 0
    if ok.any():
        out["epoch"][row[g][ok]] = _block_nis(nu[ok], S[ok], used[ok])
        out["dof"][row[g][ok]] = k[ok]
    return out


def position_nis(res, mask) -> np.ndarray:
    """NIS of the GNSS position innovations per GNSS epoch: nu' S^-1 nu with the 3x3 position block.

    Args:
      res: :class:`jaxnav.ins.LCResult` saved with "innovations", "innov_covs" (rows 0-2 of each epoch's
        stacked measurement are the GNSS position components, m).  mask: (M, 6) bool GNSS mask (PVMeasurements).
    Returns:
      (M,) NIS (3 degrees of freedom), NaN at the epochs whose three position components were not all used.
    """
    return gnss_nis(res, mask)["pos"]


def nis_check(prep: Prepared, d: RunNoise | None = None) -> dict:
    """Mean GNSS NIS per degree of freedom (position, velocity) of the filter WITHOUT the chi-square gate,
    and the share of epochs the gate would reject.

    Only the GNSS epochs the filter sees (the ``[evaluate]`` outages stay withheld). Expected 1 for a
    consistent filter; consistent here: the mean position NIS per dof inside :data:`NIS_BAND`, the mean
    velocity NIS per dof too (where the run uses GNSS velocity), and at most :data:`NIS_GATE_SHARE_MAX`
    of the epochs beyond the gate's quantile — the whole epoch's NIS (every GNSS component used) against
    the chi-square quantile for its number of components, as the gate judges it, and the position and
    velocity NIS each against the 3-dof quantile (docs/guide/ins.md,
    "Noise self-calibration": thousands of time-correlated epochs make the chi-square band of the mean
    far too narrow to use, and GNSS noise dominating the innovations makes a wide band blind).

    Returns:
      dict: ``nis_per_dof`` (mean position NIS / 3), ``nis_median_per_dof`` (median position NIS / 2.366,
      the chi-square(3) median; robust to outliers), ``n_epochs`` (epochs with a position NIS),
      ``nis_vel_per_dof``, ``nis_vel_median_per_dof``, ``n_vel_epochs`` (the same for the velocity; NaN
      and 0 without GNSS velocity), ``share_above_gate`` (epoch NIS above the chi-square quantile of
      ``gnss.gate_probability``, or 0.9999 without a gate, for its number of components; over the epochs
      with any GNSS component), ``share_pos_above_gate`` / ``share_vel_above_gate`` (the position /
      velocity NIS above the chi-square(3) quantile; 0 without GNSS velocity), ``consistent`` (bool:
      both means in the band, all three shares at most :data:`NIS_GATE_SHARE_MAX`), ``loglik``.
    """
    from jaxnav.ins.integration import chi2_quantile

    g = prep.cfg.gnss
    # an open gate (probability 1: nothing rejected) where the run has a gate: the final run's compiled program
    ungated = prep._replace(
        cfg=prep.cfg._replace(gnss=g._replace(gate_probability=None if g.gate_probability is None else 1.0))
    )
    res = run_filter(ungated, d)
    nis = gnss_nis(res, prep.meas.mask)
    p, v, e, k = nis["pos"], nis["vel"], nis["epoch"], nis["dof"]
    ok, okv, oke = np.isfinite(p), np.isfinite(v), np.isfinite(e)
    n, nv = int(ok.sum()), int(okv.sum())
    prob = g.gate_probability if g.gate_probability is not None else 0.9999
    thr = np.array([np.inf] + [chi2_quantile(prob, j) for j in range(1, 7)])
    mean = float(np.mean(p[ok]) / 3.0) if n else float("nan")
    mean_v = float(np.mean(v[okv]) / 3.0) if nv else float("nan")
    share = float(np.mean(e[oke] > thr[k[oke]])) if oke.any() else float("nan")
    # each 3-dof block against its own quantile too: a block's outliers can hide in the 6-dof epoch NIS
    share_p = float(np.mean(p[ok] > thr[3])) if n else float("nan")
    share_v = float(np.mean(v[okv] > thr[3])) if nv else 0.0
    lo, hi = NIS_BAND
    return {
        "nis_per_dof": mean,
        "nis_median_per_dof": float(np.median(p[ok]) / 2.366) if n else float("nan"),
        "n_epochs": n,
        "nis_vel_per_dof": mean_v,
        "nis_vel_median_per_dof": float(np.median(v[okv]) / 2.366) if nv else float("nan"),
        "n_vel_epochs": nv,
        "share_above_gate": share,
        "share_pos_above_gate": share_p,
        "share_vel_above_gate": share_v,
        "consistent": bool(
            n
            and lo <= mean <= hi
            and (nv == 0 or lo <= mean_v <= hi)
            and max(share, share_p, share_v) <= NIS_GATE_SHARE_MAX
        ),
        "loglik": float(res.loglik),
    }


def _nis_report(check: dict, when: str) -> dict:
    """The NIS figures of a :func:`nis_check` as calibration-report keys tagged ``when`` ("before", "after")."""
    return {
        f"nis_{when}_per_dof": check["nis_per_dof"],
        f"nis_median_{when}_per_dof": check["nis_median_per_dof"],
        f"nis_vel_{when}_per_dof": check["nis_vel_per_dof"],
        f"nis_vel_median_{when}_per_dof": check["nis_vel_median_per_dof"],
        f"share_above_gate_{when}": check["share_above_gate"],
        f"share_pos_above_gate_{when}": check["share_pos_above_gate"],
        f"share_vel_above_gate_{when}": check["share_vel_above_gate"],
    }


def calibration_params(cfg: InsConfig) -> tuple:
    """The densities the default calibration fits: ARW, VRW and the GNSS position sigma factor, the GNSS
    velocity sigma factor where the run uses GNSS velocity (``gnss.use_velocity``), and the gyro bias
    instability where the model has a state for it (``noise.states`` 18 or 21)."""
    vel = ("vel_sigma_scale",) if cfg.gnss.use_velocity else ()
    extra = ("gyro_bias_instability",) if cfg.noise.states in (18, 21) else ()
    return ("arw", "vrw", "pos_sigma_scale", *vel, *extra)


def _display(name: str, v) -> float:
    """A tuned parameter in the unit of its config key (deg/sqrt(h), m/s/sqrt(h), deg/h, 1)."""
    from jaxnav.units import DEG_PER_HOUR, DEG_PER_SQRT_HOUR, HOUR

    scale = {
        "arw": 1.0 / DEG_PER_SQRT_HOUR,
        "vrw": math.sqrt(HOUR),
        "gyro_bias_instability": 1.0 / DEG_PER_HOUR,
        "pos_sigma_scale": 1.0,
        "vel_sigma_scale": 1.0,
    }[name]
    return float(v) * scale


#: unit of each calibrated parameter in :func:`calibrate_noise`'s report (the config key's unit)
DISPLAY_UNITS = {
    "arw": "deg/sqrt(h)",
    "vrw": "m/s/sqrt(h)",
    "gyro_bias_instability": "deg/h",
    "pos_sigma_scale": "1",
    "vel_sigma_scale": "1",
}


def _nis_words(chk: dict) -> tuple:
    """(what the check measured, what fails) of a :func:`nis_check` result, as short phrases."""
    lo, hi = NIS_BAND
    said, bad = [], []
    for what, key in (("position", "nis_per_dof"), ("velocity", "nis_vel_per_dof")):
        x = chk[key]
        if what == "velocity" and not chk["n_vel_epochs"]:
            continue
        inside = lo <= x <= hi
        said.append(f"GNSS {what} NIS per dof {x:.2f} {'inside' if inside else 'outside'} {lo:g}-{hi:g}")
        if not inside:
            bad.append(f"the GNSS {what} NIS per dof is {x:.2f}, outside {lo:g}-{hi:g}")
    for what, key in (("", "share_above_gate"), (" by the position NIS", "share_pos_above_gate")) + (
        ((" by the velocity NIS", "share_vel_above_gate"),) if chk["n_vel_epochs"] else ()
    ):
        sh = chk[key]
        if sh > NIS_GATE_SHARE_MAX:
            said.append(f"{100 * sh:.1f} % of the epochs beyond the gate{what}")
            bad.append(
                f"{100 * sh:.1f} % of the GNSS epochs are beyond the gate{what} (at most "
                f"{100 * NIS_GATE_SHARE_MAX:g} % for consistent noise)"
            )
    return ", ".join(said), bad


def calibrate_noise(prep: Prepared, mode=None, *, progress=None) -> tuple:
    """Self-calibration of the noise densities: NIS check of the configured noise, ML fit where it fails.

    1. The filter runs with the configured noise WITHOUT the chi-square gate; the mean NIS per degree of
       freedom of its GNSS position and velocity innovations (:func:`nis_check`, the epochs the filter
       sees) is compared with :data:`NIS_BAND`, the share of epochs beyond the gate's quantile with
       :data:`NIS_GATE_SHARE_MAX`.
    2. ``mode`` "auto": inside the band the configured noise is kept (one extra forward run). Outside it
       (or ``mode`` True), :func:`tune_noise` with the innovations loss fits :func:`calibration_params`
       (L-BFGS, forward-mode gradients, ``[tune] calibrate_steps`` evaluations) on the same epochs, ungated: the ``[evaluate]``
       outages stay withheld. False: nothing runs.
    3. Fewer than :data:`MIN_CALIBRATION_EPOCHS` GNSS position epochs: the configured noise is kept and
       the measured NIS reported with a warning.

    Args:
      prep: :class:`Prepared`.  mode: "auto" | True | False (default ``[tune] calibrate``).
      progress: callable for one line of text (stages and warnings), or None.
    Returns:
      (:class:`RunNoise` to run with, report dict for ``results.json`` ``calibration``: mode, ran, reason,
      NIS per dof before (and after), parameters before/after in SI and display units, the epochs fitted
      on and their number, evaluations, wall time, warning).
    """
    say = progress or (lambda *_: None)
    cfg = prep.cfg
    mode = cfg.tune.calibrate if mode is None else mode
    t0 = time.perf_counter()
    rep: dict = {
        "mode": mode,
        "ran": False,
        "nis_band_per_dof": list(NIS_BAND),
        "nis_gate_share_max": NIS_GATE_SHARE_MAX,
    }
    if mode is False:
        rep["reason"] = "calibrate = false: the configured noise is used as given"
        return prep.densities, rep
    before = nis_check(prep)
    n = before["n_epochs"]
    rep.update(
        _nis_report(before, "before"),
        n_nis_epochs=n,
        n_nis_vel_epochs=before["n_vel_epochs"],
        min_epochs=MIN_CALIBRATION_EPOCHS,
    )
    where = "GNSS position epochs the filter sees" + (
        ", outside the [evaluate] outages" if np.asarray(prep.withheld).any() else ""
    )
    if n < MIN_CALIBRATION_EPOCHS:
        rep["reason"] = (
            f"too few GNSS epochs to calibrate ({n} < {MIN_CALIBRATION_EPOCHS}): the configured noise is kept"
        )
        rep["warning"] = (
            f"only {n} GNSS position epochs, too few to check or calibrate the noise: GNSS position NIS per dof "
            f"{before['nis_per_dof']:.2f} (consistent: {NIS_BAND[0]:g}-{NIS_BAND[1]:g}); the configured noise is "
            "used, its uncertainties unchecked"
        )
        say(f"warning: {rep['warning']}")
        rep["wall_time_s"] = time.perf_counter() - t0
        return prep.densities, rep
    why = _nis_words(before)[0]
    if mode == "auto" and before["consistent"]:
        rep["reason"] = f"{why}: the configured noise is consistent and kept"
        rep["wall_time_s"] = time.perf_counter() - t0
        return prep.densities, rep
    names = calibration_params(cfg)
    rep["reason"] = f"calibrate = true; {why}" if mode is True else why
    say(
        f"calibrating {', '.join(names)} ({rep['reason']}): innovation likelihood on {n} {where}, ungated, "
        f"L-BFGS {cfg.tune.calibrate_steps} evaluations"
    )
    ungated = prep._replace(cfg=cfg._replace(gnss=cfg.gnss._replace(gate_probability=None)))
    # forward mode: 3-4 parameters cost 3-4 tangents, cheaper than reverse mode's tape (about 2x per evaluation)
    tr = tune_noise(ungated, names, max_evals=cfg.tune.calibrate_steps, mode="forward", loss_kind="innovations")
    after = nis_check(prep, tr.densities)
    rep.update(
        ran=True,
        params=list(names),
        loss="innovations (GNSS innovation log-likelihood of the forward filter, no gate)",
        before_si={k: float(v) for k, v in tr.before.items()},
        after_si={k: float(v) for k, v in tr.after.items()},
        before_display={k: _display(k, v) for k, v in tr.before.items()},
        after_display={k: _display(k, v) for k, v in tr.after.items()},
        display_units={k: DISPLAY_UNITS[k] for k in names},
        loglik_before=tr.loglik_before,
        loglik_after=tr.loglik_after,
        **_nis_report(after, "after"),
        fitted_on=where,
        n_epochs=tr.n_epochs,
        n_evals=tr.n_evals,
    )
    if not after["consistent"]:
        bits = _nis_words(after)[1]
        rep["warning"] = (
            f"after calibration {' and '.join(bits)}: the uncertainties may still be wrong (errors the "
            "error model has no state for?)"
        )
        say(f"warning: {rep['warning']}")
    rep["wall_time_s"] = time.perf_counter() - t0
    return tr.densities, rep


def _mask_without_outages(prep: Prepared):
    """The measurement mask with the simulated outages put back (qualities and velocity rules kept)."""
    ok = np.asarray(prep.meas.mask).copy()
    w = np.asarray(prep.withheld)
    if w.any():
        full = gnss_measurements(
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


# ----------------------------------------------------------------------------- reference trajectory
def read_truth(cfg: InsConfig):
    """The ``[evaluate] truth`` file as :class:`jaxnav.io.TruthTrajectory`, or None without one.

    Raises:
      FileNotFoundError: a missing file (named with the key).  jaxnav.io.ReaderError: FILE:LINE.
      ValueError: a column map the reader refuses (naming the config keys).
    """
    from jaxnav.io import ReaderError, read_csv_truth, read_kfgins_truth

    ev = cfg.evaluate
    if ev is None or ev.truth is None:
        return None
    if not ev.truth.is_file():
        what = "a folder, not a file" if ev.truth.is_dir() else "no such file"
        raise FileNotFoundError(f"{ev.truth}: {what} ({cfg.path}: evaluate.truth)")
    if ev.truth_format == "kf-gins":
        return read_kfgins_truth(ev.truth)
    try:
        return read_csv_truth(ev.truth, ev.truth_columns, ev.truth_units, delimiter=ev.truth_delimiter)
    except ReaderError:
        raise
    except ValueError as exc:
        raise ValueError(f"{cfg.path}: evaluate.truth_columns / evaluate.truth_units: {exc}") from None


def truth_errors(run: InsRun, truth, which: str):
    """:class:`jaxnav.ins.TrajectoryErrors` of the forward or smoothed IMU solution against the reference.

    The solution's epochs are the filter's (GNSS and pseudo-measurement epochs); a reference in GPST
    since 1980 is put on seconds of week when the solution is (an IMU file without ``gps_week``).
    """
    from jaxnav.ins.attitude import quat_to_euler

    ep = run.result.epochs
    nav, P = (run.smoothed_nav, run.smoothed_covs) if which == "smoothed" else (ep.nav, ep.covs)
    t = np.asarray(ep.t_nav, float)
    t, first = np.unique(t, return_index=True)
    pos = np.asarray(nav.pos, float)[first]
    v = np.asarray(nav.v_n, float)[first]
    P = np.asarray(P, float)[first]
    e = np.asarray(quat_to_euler(np.asarray(nav.q_bn)), float)[first]  # [pitch, roll, yaw], body RFU in ENU
    heading = np.mod(-e[:, 2], 2 * math.pi)
    rpy = np.stack([e[:, 1], e[:, 0], heading], -1)
    tt = np.asarray(truth.t, float)
    week = 604800.0
    if t[0] < 2 * week <= tt[0]:
        tt = tt - math.floor(tt[0] / week) * week
    if tt[-1] < t[0] or tt[0] > t[-1]:
        raise ConfigError(
            f"{run.prep.cfg.path}: evaluate.truth: {truth.path} spans [{tt[0]:.3f}, {tt[-1]:.3f}] s, "
            f"the solution [{t[0]:.3f}, {t[-1]:.3f}] s: no common epoch (another time scale? the "
            "reference must be in GPST like the GNSS solution)"
        )
    idx = run_error_model(run.prep.cfg).idx
    sd = np.sqrt(np.clip(np.diagonal(P, axis1=-2, axis2=-1), 0.0, None))
    return trajectory_errors(
        t,
        pos,
        v,
        rpy,
        tt,
        truth.pos,
        truth.v_enu,
        truth.rpy,
        cov_pos_enu=position_cov_enu(P, pos, idx),
        sig_vel=sd[:, idx.dv],
        sig_att=attitude_sigmas(P, heading, idx),
        windows=run.prep.outages,
    )
