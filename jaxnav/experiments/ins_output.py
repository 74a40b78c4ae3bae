"""Files written by ``jaxnav ins``: trajectory CSV, RTKLIB-style ``.pos``, GeoJSON, KML, results.json.

All times GPST (seconds since 1980-01-06 and calendar); positions WGS-84 geodetic (the GNSS
solution's datum), ellipsoidal heights; attitude of the vehicle frame (forward-right-down):
roll, pitch, heading (clockwise from north), deg. Sigmas are the solution's own 1-sigma.
"""

from __future__ import annotations

import math
import pathlib
import time

import jax
import numpy as np

from jaxnav.experiments.ins_run import InsRun, run_error_model
from jaxnav.ins import outage_statistics
from jaxnav.io import (
    NavSolution,
    Track,
    nav_solution,
    noise_in_config_units,
    write_geojson,
    write_kml,
    write_pos,
    write_trajectory_csv,
)


def _solution(run: InsRun, which: str) -> NavSolution:
    """The forward or smoothed solution at the filter epochs (:func:`jaxnav.io.nav_solution`), with the GNSS
    epochs it used and their quality."""
    ep = run.result.epochs
    nav, P = (run.smoothed_nav, run.smoothed_covs) if which == "smoothed" else (ep.nav, ep.covs)
    row = np.asarray(ep.gnss_row)
    mask = np.asarray(run.prep.meas.mask)[:, :3].any(-1)
    used = np.where(row >= 0, mask[np.maximum(row, 0)], False)
    q = np.where(used, np.asarray(run.prep.pos.q)[run.prep.keep][np.maximum(row, 0)], 0)
    return nav_solution(ep.t_nav, nav, P, run_error_model(run.prep.cfg).idx, gnss_used=used, quality=q)


def _tracks(run: InsRun) -> list:
    """:class:`jaxnav.io.Track` lines: smoothed and forward solutions, the smoothed one inside each outage."""
    sm = np.asarray(run.smoothed_nav.pos)
    tracks = [
        Track("RTS smoothed", sm, color=KML_ORANGE, width=2, clamp_to_ground=True),
        Track("forward filter", np.asarray(run.result.epochs.nav.pos), color=KML_BLUE, width=2, clamp_to_ground=True),
    ]
    t = np.asarray(run.result.epochs.t)
    for k, (a, b) in enumerate(run.prep.outages):
        w = (t >= a) & (t < b)
        if w.sum() >= 2:
            tracks.append(
                Track(
                    f"simulated outage {k + 1}",
                    sm[w],
                    {"gpst_start_s": float(a), "gpst_end_s": float(b)},
                    color=KML_RED,
                    width=4,
                )
            )
    return tracks


#: KML line colours (aabbggrr)
KML_ORANGE, KML_BLUE, KML_RED = "ff00a5ff", "ffff0000", "ff0000ff"


def write_outputs(run: InsRun, out) -> list:
    """The solution files of a run into ``out``: trajectory CSVs (smoothed, forward), ``.pos``, GeoJSON, KML."""
    out = pathlib.Path(out)
    cfg = run.prep.cfg
    sm, fw = _solution(run, "smoothed"), _solution(run, "forward")
    tracks = _tracks(run)
    return [
        str(write_trajectory_csv(out / "trajectory.csv", sm, title=f"jaxnav ins: smoothed solution of {cfg.name}")),
        str(
            write_trajectory_csv(
                out / "trajectory_forward.csv", fw, title=f"jaxnav ins: forward solution of {cfg.name}"
            )
        ),
        str(
            write_pos(
                out / f"{cfg.name}_ins.pos",
                sm,
                comments=[("program", "jaxnav ins (smoothed INS/GNSS solution)"), ("config", str(cfg.path))],
            )
        ),
        str(write_geojson(out / "track.geojson", tracks)),
        str(write_kml(out / "track.kml", tracks, name=f"jaxnav ins: {cfg.name}")),
    ]


def write_figures(run: InsRun, out, *, fmt: str = "png") -> list:
    """The figures of a run into ``out``: track + outage errors, differences to GNSS, attitude, biases, and
    the time offset likelihood where it was estimated."""
    from jaxnav.plot import plot_ins_attitude, plot_ins_biases, plot_ins_differences, plot_outage_track

    out = pathlib.Path(out)
    name = run.prep.cfg.name
    paths = []
    if run.scores is not None:
        paths.append(
            plot_outage_track(
                run.scores, run.enu_ref, run.enu_fwd, run.enu_sm, out / f"track_outages.{fmt}", title=name
            )
        )
    g = run.gnss_epochs
    ep = jax.tree_util.tree_map(lambda a: np.asarray(a)[g], run.result.epochs)
    t = np.asarray(run.prep.meas.t)
    f = jax.tree_util.tree_map(lambda a: np.asarray(a)[g], _solution(run, "forward"))
    s = jax.tree_util.tree_map(lambda a: np.asarray(a)[g], _solution(run, "smoothed"))
    from jaxnav.experiments.ins_run import _mask_without_outages

    m = _mask_without_outages(run.prep)  # the GNSS epochs usable, withheld ones included
    d_pos = np.where(m[:, :3], run.enu_fwd - run.enu_ref, np.nan)
    v_ref = np.asarray(run.prep.pos.v_enu, float)[run.prep.keep]
    d_vel = np.where(m[:, 3:], np.asarray(ep.nav.v_n) - v_ref, np.nan)
    paths.append(
        plot_ins_differences(
            t,
            d_pos,
            f.sig_pos_enu,
            d_vel,
            f.sig_vel,
            run.prep.outages,
            out / f"differences_to_gnss.{fmt}",
            title=f"{name}: forward filter minus GNSS (antenna position, velocity) with the filter's "
            "+-3 sigma; GNSS withheld in the grey windows",
        )
    )
    paths.append(
        plot_ins_attitude(
            t,
            np.degrees(f.rpy),
            np.degrees(s.rpy),
            np.degrees(s.sig_att),
            run.prep.outages,
            out / f"attitude.{fmt}",
            title=f"{name}: attitude of the vehicle frame",
        )
    )
    from jaxnav.ins import error_model_for
    from jaxnav.units import DEG_PER_HOUR, MG

    n = run.prep.cfg.noise.states
    idx = error_model_for(n).idx
    fb, sb = ep.biases, jax.tree_util.tree_map(lambda a: np.asarray(a)[g], run.smoothed_biases)
    sd = np.sqrt(np.clip(np.diagonal(np.asarray(ep.covs), axis1=-2, axis2=-1), 0.0, None))
    gyro_f = (np.asarray(fb.gyro) + np.asarray(fb.markov)) / DEG_PER_HOUR
    gyro_s = (np.asarray(sb.gyro) + np.asarray(sb.markov)) / DEG_PER_HOUR
    paths.append(
        plot_ins_biases(
            t,
            gyro_f,
            sd[:, idx.eps_b] / DEG_PER_HOUR,
            np.asarray(fb.accel) / MG,
            sd[:, idx.nabla] / MG,
            run.prep.outages,
            out / f"biases.{fmt}",
            title=f"{name}: estimated sensor biases ({n}-state model)",
            gyro_sm=gyro_s,
            accel_sm=np.asarray(sb.accel) / MG,
        )
    )
    ser = run.prep.standstill_info.get("_series")
    if ser is not None:
        from jaxnav.plot import plot_standstill

        info = run.prep.standstill_info
        paths.append(
            plot_standstill(
                run.prep.t,
                ser["stat"],
                info["threshold"],
                run.prep.standstill,
                ser["raw"] & ser["moving"],
                ser["t_gnss"],
                ser["speed"],
                ser["speed_sigma"],
                run.prep.outages,
                out / f"standstill.{fmt}",
                title=f"{name}: standstill detector ({info['platform']} preset) and GNSS check",
                unconfirmed=ser["unconfirmed"],
            )
        )
    off = run.prep.time_offset_info
    if "grid_s" in off:
        from jaxnav.plot import plot_time_offset_likelihood

        paths.append(
            plot_time_offset_likelihood(
                off["grid_s"],
                off["loglik"],
                off["offset_s"],
                off["sigma_s"],
                out / f"time_offset.{fmt}",
                title=f"{name}: IMU-GNSS time offset by the innovation likelihood ({off['n_epochs_used']} GNSS epochs)",
            )
        )
    return [str(p) for p in paths]


def _edge_units(d):
    """A statistics dict with every ``*_rad`` key turned into ``*_deg`` (the report's unit for angles)."""
    from jaxnav.units import rad_to_deg

    if isinstance(d, dict):
        return {
            (k[:-4] + "_deg" if k.endswith("_rad") else k): (rad_to_deg(v) if k.endswith("_rad") else _edge_units(v))
            for k, v in d.items()
        }
    return d


def _truth_evaluation(run: InsRun, truth, evaluation, *, tuned: bool):
    """Forward and smoothed solutions against the reference: (errors per solution, the ``evaluation``
    dict with a ``truth`` block added; keys with unit suffixes, angles in deg)."""
    from jaxnav.experiments.ins_run import truth_errors
    from jaxnav.ins import error_statistics

    ev = run.prep.cfg.evaluate
    errs = {w: truth_errors(run, truth, w) for w in ("forward", "smoothed")}
    block = {
        "file": str(ev.truth),
        "format": ev.truth_format,
        "n_records": int(np.asarray(truth.t).size),
        "solution": "after --tune" if tuned else "as configured",
        "point": "IMU (not the antenna)",
        "errors": "solution minus reference; position in local ENU at the reference, m; heading wrapped to "
        "+-180 deg; outages = the [evaluate] windows (GNSS withheld); NEES of the 3-D position "
        "(expected 3); shares within 3 sigma (expected 0.9973 per component)",
    }
    for w, e in errs.items():
        block[w] = _edge_units(error_statistics(e, n_windows=int(np.asarray(run.prep.outages).shape[0])))
    out = dict(evaluation or {})
    out["truth"] = block
    return errs, out


def _densities_dict(d) -> dict:
    """The run's noise (:class:`jaxnav.ins.LCNoise`) for results.json, in the config's units."""
    keys = (
        "arw_deg_per_sqrt_h",
        "vrw_m_per_s_per_sqrt_h",
        "gyro_bias_instability_deg_per_h",
        "bias_correlation_time_s",
    )
    return {
        **noise_in_config_units(d.imu, keys + ("init_gyro_bias_deg_per_s", "init_accel_bias_mg")),
        "pos_sigma_scale": float(d.pos_sigma_scale),
        "vel_sigma_scale": float(d.vel_sigma_scale),
    }


def _constraints(prep, run) -> dict:
    """What the pseudo-measurements did: standstill detection, ZUPT/ZARU/NHC epochs."""
    from jaxnav.ins import standstill_intervals

    c = prep.cfg.constraints
    d = {
        "zupt": c.zupt,
        "zaru": c.zaru,
        "nhc": c.nhc,
        "n_filter_epochs": int(np.asarray(run.result.epochs.t).size),
        "n_gnss_epochs": int(prep.meas.t.size),
    }
    if prep.standstill is not None:
        iv = np.asarray(standstill_intervals(prep.t, prep.standstill)).reshape(-1, 2)
        d.update(
            standstill_samples=int(np.count_nonzero(prep.standstill)),
            standstill_intervals=int(iv.shape[0]),
            standstill_s=float(np.sum(iv[:, 1] - iv[:, 0])) if iv.size else 0.0,
            standstill_intervals_gpst_s=iv.tolist(),
            detector={k: v for k, v in prep.standstill_info.items() if not k.startswith("_")},
        )
    return d


def _odometer(prep, run) -> dict | None:
    """The wheel-speed input and its estimated scale factor (1 + k: reading = (1 + k) speed) with 1-sigma:
    forward filter at the last epoch, RTS smoother (a random constant: the same at every epoch)."""
    o = prep.cfg.odometer
    if o is None:
        return None
    from jaxnav.experiments.ins_run import run_error_model

    sp = np.asarray(prep.odometer_speed, float)
    d = {
        "source": o.source if o.source == "imu" else str(o.file),
        "sigma_m_s": o.sigma,
        "rate_hz": o.rate_hz,
        "lever_arm_frd_m": np.asarray(o.lever_arm_frd, float).tolist(),
        "imu_samples_with_reading": int(np.count_nonzero(np.isfinite(sp))),
        "imu_samples": int(sp.size),
        "scale_factor_estimated": bool(o.estimate_scale),
    }
    idx = run_error_model(prep.cfg).idx.s_odo
    if idx is not None:
        k_f = float(np.asarray(run.result.final_biases.odo_scale).reshape(-1)[0])
        P = np.asarray(run.result.epochs.covs)[-1]
        k_s = float(np.asarray(run.smoothed_biases.odo_scale)[0].reshape(-1)[0])
        Ps = np.asarray(run.smoothed_covs)[0]
        d.update(
            scale_factor=1.0 + k_f,
            scale_factor_sigma=float(np.sqrt(max(P[idx, idx][0, 0], 0.0))),
            scale_factor_smoothed=1.0 + k_s,
            scale_factor_smoothed_sigma=float(np.sqrt(max(Ps[idx, idx][0, 0], 0.0))),
            scale_factor_initial_sigma=o.init_scale_sigma,
            scale_factor_model="reading = scale_factor x forward speed of the wheel point; a random constant",
        )
    return d


def process(cfg, out, *, tune: bool = False, calibrate=None, command: str = "", progress=print) -> dict:
    """The whole ``jaxnav ins`` job: calibrate the noise where needed, run (and with ``tune`` tune, then rerun),
    write every output into ``out``.

    ``calibrate``: "auto" | True | False, overriding ``[tune] calibrate`` (None: the config's;
    :func:`jaxnav.experiments.ins_run.calibrate_noise`). ``--tune`` starts from the noise the calibration
    leaves. ``progress``: a callable taking one line of text for the stages ("reading ...", "tuning ..."), or None.

    Returns:
      the ``results.json`` dict (also written), with "provenance" (:func:`jaxnav.io.provenance`: version,
      commit, date, config file and contents; ``command`` where given) and "files" (everything
      written, paths relative to ``out``).
    """
    from jaxnav import INFO_FLAGS, status_messages
    from jaxnav.experiments.ins_run import fit_and_run, prepare
    from jaxnav.io import provenance, write_json

    out = pathlib.Path(out)
    say = progress or (lambda *_: None)
    say(f"reading {cfg.imu.file.name} and {cfg.gnss.file.name}")
    from jaxnav.io import read_ins_inputs, read_ins_truth

    truth = read_ins_truth(cfg)  # before the filter: a bad reference file fails fast
    imu, pos = read_ins_inputs(cfg)
    prep = prepare(cfg, imu=imu, pos=pos, progress=progress)
    check_shifts(cfg, prep.t)  # before any fit: a shift without an outage window fails fast
    mode = cfg.tune.calibrate if calibrate is None else calibrate
    fr = fit_and_run(cfg, imu=imu, pos=pos, prep=prep, calibrate=mode, tune=tune, progress=progress)
    prep, cal, run = fr.prep, fr.calibration, fr.untuned
    n_used = int(np.count_nonzero(np.asarray(prep.meas.mask)[:, :3].any(-1)))
    n_gated = int(run.result.n_gated) if run.result.n_gated is not None else 0
    prov = provenance(config_file=cfg.path, config=cfg.raw)
    if command:
        prov["command"] = command
    results = {
        "provenance": prov,
        "mounting": {
            "source": cfg.imu.mounting_source,
            "C_vehicle_sensor": np.asarray(cfg.imu.mounting).tolist(),
            "C_body_rfu_sensor": np.asarray(prep.C_bs).tolist(),
        },
        "time_offset_s": prep.time_offset,
        "time_offset": prep.time_offset_info,
        "alignment": {
            "roll_deg": math.degrees(float(prep.alignment.att0[1])),
            "pitch_deg": math.degrees(float(prep.alignment.att0[0])),
            "heading_deg": (-math.degrees(float(prep.alignment.att0[2]))) % 360.0,
            "heading_method": "GNSS course carried back by the gyro",
            "static_window_end_gpst_s": prep.alignment.t_static,
            "gyro_bias_deg_per_s": np.degrees(np.asarray(prep.alignment.gyro_bias)).tolist(),
        },
        "n_states": cfg.noise.states,
        "noise": _densities_dict(run.densities),
        "imu": {
            "file": str(cfg.imu.file),
            "n_samples": int(prep.t.size),
            "n_skipped_lines": int(getattr(prep.imu, "n_skipped_lines", 0)),
            "gpst_start_s": float(prep.t[0]),
            "gpst_end_s": float(prep.t[-1]),
        },
        "gnss": {
            "file": str(cfg.gnss.file),
            "n_epochs_in_imu_span": int(prep.meas.t.size),
            "n_epochs_used": n_used,
            "n_withheld": int(np.count_nonzero(prep.withheld)),
            "n_gated": n_gated,
            "gated_share": fr.gated_share,
        },
        "calibration": cal,
        "constraints": _constraints(prep, run),
        "odometer": _odometer(prep, run),
        "heading": None
        if prep.heading is None
        else {
            "file": str(cfg.heading.file),
            "rate_hz": cfg.heading.rate_hz,
            "default_sigma_deg": math.degrees(cfg.heading.sigma),
            "imu_samples_with_reading": int(np.count_nonzero(np.isfinite(prep.heading[0]))),
        },
        "status": int(run.result.status),
        "status_flags": status_messages(run.result.status),
        "status_ok": int(run.result.status) & ~INFO_FLAGS == 0,
        "n_nonfinite": int(run.result.n_nonfinite),
        "n_gated_gnss_epochs": int(run.result.n_gated) if run.result.n_gated is not None else 0,
        "n_skipped_updates": int(run.result.n_skipped),
        "loglik": float(run.result.loglik),
        "runtime_s": run.runtime_s,
        "evaluation": None if run.scores is None else outage_statistics(run.scores),
    }
    if tune:
        rep, run_t = fr.tune, fr.run
        results["tune"] = {
            "params": list(cfg.tune.params),
            "loss": cfg.tune.loss,
            "before_si": rep.before,
            "after_si": rep.after,
            "loglik_before": rep.loglik_before,
            "loglik_after": rep.loglik_after,
            "n_evals": rep.n_evals,
            "wall_time_s": rep.wall_time_s,
            "fitted_on": rep.fitted_on,
            "n_epochs": rep.n_epochs,
            "noise_after": _densities_dict(rep.noise),
            "evaluation_before": results["evaluation"],
            "evaluation_after": None if run_t.scores is None else outage_statistics(run_t.scores),
            "n_gated_gnss_epochs_after": int(run_t.result.n_gated) if run_t.result.n_gated is not None else 0,
            "started_from": "the calibrated noise" if cal.get("ran") else "the configured noise",
        }
        run = run_t
        results["odometer"] = _odometer(prep, run)
    results["tuning"] = _tuning(prep, results)
    errs = None
    if truth is not None:
        say(f"scoring against the reference trajectory {cfg.evaluate.truth.name}")
        errs, results["evaluation"] = _truth_evaluation(run, truth, results.get("evaluation"), tuned=tune)
    shifted = None
    if cfg.evaluate is not None and cfg.evaluate.shifts > 1:
        shifted = shifted_outages(cfg, imu, pos, run, cal, truth, calibrate=mode, tune=tune, progress=progress)
        results["evaluation"]["shifted_outages"] = shifted["results"]
        results["tuning"]["shifted_outages"] = (
            f"each of the {cfg.evaluate.shifts} shifts is its own run: what is fitted (time offset, standstill "
            "check, noise calibration, --tune) is fitted again per shift on the GNSS epochs that shift sees, never "
            "on its withheld ones"
        )
    files = write_outputs(run, out)
    files += write_figures(run, out)
    if shifted is not None:
        files.append(str(plot_shifted(shifted, out / "shifted_outages.png", name=cfg.name)))
    if errs is not None:
        from jaxnav.plot import plot_truth_errors

        files.append(
            str(
                plot_truth_errors(
                    errs["forward"],
                    errs["smoothed"],
                    run.prep.outages,
                    out / "truth_errors.png",
                    title=f"{cfg.name}: IMU solution minus the reference trajectory "
                    f"({cfg.evaluate.truth.name}), +-3 sigma; GNSS withheld in the grey windows",
                )
            )
        )
    results["files"] = sorted(pathlib.Path(f).relative_to(out).as_posix() for f in files) + ["results.json"]
    write_json(out / "results.json", results)
    return results


def check_shifts(cfg, t) -> None:
    """Every shifted outage schedule of ``[evaluate] shifts`` has a window in the IMU span ``t`` (N,) s,
    else :class:`jaxnav.io.ConfigError` naming the keys."""
    from jaxnav.ins import shifted_outage_windows
    from jaxnav.io import ConfigError

    ev = cfg.evaluate
    if ev is None or ev.shifts <= 1:
        return
    t0, t1 = float(t[0]), float(t[-1])
    wins = shifted_outage_windows(
        t0,
        t1,
        shifts=ev.shifts,
        shift_s=ev.shift_s,
        first_s=ev.first_s,
        outage_s=ev.outage_s,
        gap_s=ev.gap_s,
        end_margin_s=ev.end_margin_s,
    )
    for k, w in enumerate(wins):
        if not len(w):
            raise ConfigError(
                f"{cfg.path}: evaluate.shifts = {ev.shifts} with shift_s = {ev.shift_s:g} s: shift {k} (first outage "
                f"{ev.first_s + k * ev.shift_s:g} s after the start, {ev.outage_s:g} s long, end_margin_s = "
                f"{ev.end_margin_s:g} s) has no outage window in the {t1 - t0:.1f} s IMU span: give fewer shifts, a "
                "smaller shift_s or end_margin_s"
            )


def shifted_outages(cfg, imu, pos, run0, cal0, truth, *, calibrate, tune: bool, progress=None) -> dict:
    """The ``[evaluate] shifts`` protocol: the outage schedule shifted by ``k shift_s`` (k = 1 .. shifts - 1),
    each shift its own run with every fit redone on the GNSS epochs it sees
    (:func:`jaxnav.experiments.ins_run.fit_and_run` of :func:`jaxnav.experiments.ins_run.shifted_config`);
    shift 0 is the main run ``run0`` (calibration report ``cal0``).

    Scores per outage of every shift: the largest drift of the forward and smoothed solutions, against
    the reference trajectory ``truth`` (3-D and horizontal, :func:`jaxnav.ins.outage_drift_maxima`) or,
    without one, against the withheld fixed GNSS epochs (horizontal, the runs'
    :class:`jaxnav.ins.OutageScores`); pooled over all shifts by :func:`jaxnav.ins.pooled_outage_drifts`.

    Returns:
      dict: ``results`` (the ``evaluation.shifted_outages`` block of results.json, per-outage rows included)
      and ``three_d`` (bool: scored against a reference trajectory, so with 3-D drifts), as
      :func:`plot_shifted` takes it.
    """
    from jaxnav.experiments.ins_run import fit_and_run, shifted_config, truth_errors
    from jaxnav.ins import outage_drift_maxima, pooled_outage_drifts

    ev = cfg.evaluate
    say = progress or (lambda *_: None)
    t_start = time.perf_counter()
    fitted = [
        name
        for name, on in (
            ("time offset", cfg.imu.time_offset_s == "estimate"),
            ("standstill check", cfg.constraints.zupt == "auto"),
            ("noise check and calibration", calibrate is not False),
            ("--tune", tune),
        )
        if on
    ]
    refit = f"{', '.join(fitted)} fitted on the epochs it sees" if fitted else "nothing fitted"
    runs = [(run0, cal0)]
    for k in range(1, ev.shifts):
        say(f"shift {k} of {ev.shifts - 1}: GNSS withheld on the outages {k * ev.shift_s:g} s later; {refit}")
        fr = fit_and_run(
            shifted_config(cfg, k),
            imu=imu,
            pos=pos,
            calibrate=calibrate,
            tune=tune,
            progress=lambda m, k=k: say(f"shift {k}: {m}"),
        )
        runs.append((fr.run, fr.calibration))
    per_shift, per_outage = [], []
    mx = {w: {"h": [], "3d": []} for w in ("forward", "smoothed")}
    for k, (run, cal) in enumerate(runs):
        prep = run.prep
        W = int(prep.outages.shape[0])
        if truth is not None:
            got = {w: outage_drift_maxima(truth_errors(run, truth, w), W) for w in ("forward", "smoothed")}
            for w, (m3, mh, _) in got.items():
                mx[w]["3d"].append(m3)
                mx[w]["h"].append(mh)
            n_scored = got["forward"][2]
        else:
            sc = run.scores
            mx["forward"]["h"].append(np.asarray(sc.fwd_max, float))
            mx["smoothed"]["h"].append(np.asarray(sc.sm_max, float))
            n_scored = np.asarray(sc.n_ref, int)
        for j, (a, b) in enumerate(prep.outages):
            row = {
                "shift": k,
                "window": j + 1,
                "gpst_start_s": float(a),
                "gpst_end_s": float(b),
                "start_since_imu_start_s": float(a - prep.t[0]),
                "n_scored_epochs": int(n_scored[j]),
                "forward_max_h_m": float(mx["forward"]["h"][k][j]),
                "smoothed_max_h_m": float(mx["smoothed"]["h"][k][j]),
            }
            if truth is not None:
                row["forward_max_3d_m"] = float(mx["forward"]["3d"][k][j])
                row["smoothed_max_3d_m"] = float(mx["smoothed"]["3d"][k][j])
            if not n_scored[j]:
                row["null_reason"] = "no scored epoch in the window" + ("" if truth is not None else " (no fixed GNSS)")
            per_outage.append(row)
        per_shift.append(
            {
                "shift": k,
                "refitted": fitted,
                "delay_s": k * ev.shift_s,
                "first_s": ev.first_s + k * ev.shift_s,
                "n_windows": W,
                "n_scored_windows": int(np.count_nonzero(n_scored)),
                "n_withheld_gnss_epochs": int(np.count_nonzero(prep.withheld)),
                "time_offset_s": prep.time_offset,
                "time_offset_source": prep.time_offset_info.get("source", "config"),
                "noise_calibrated": bool(cal.get("ran")),
                "noise": _densities_dict(run.densities),
                "gnss_epochs_fitted_on": int(np.count_nonzero(np.asarray(prep.meas.mask)[:, :3].any(-1))),
                "runtime_s": run.runtime_s,
            }
        )
        if cal.get("warning"):
            per_shift[-1]["calibration_warning"] = cal["warning"]
    three = truth is not None
    pooled = {w: pooled_outage_drifts(mx[w]["h"], mx[w]["3d"] if three else None) for w in mx}
    res = {
        "shifts": ev.shifts,
        "shift_s": ev.shift_s,
        "period_s": ev.outage_s + ev.gap_s,
        "reference": (
            f"the reference trajectory {ev.truth.name} (IMU point; 3-D and horizontal drift)"
            if three
            else "the withheld fixed-quality GNSS positions (antenna; horizontal drift)"
        ),
        "solution": "after --tune (refitted per shift)" if tune else "as configured (calibrated per shift)",
        "fitted": "per shift, on the GNSS epochs that shift's filter sees (its own outages withheld)",
        "n_outages": pooled["forward"]["n_outages"],
        "n_windows": sum(s["n_windows"] for s in per_shift),
        "forward": pooled["forward"],
        "smoothed": pooled["smoothed"],
        "per_shift": per_shift,
        "per_outage": per_outage,
        "wall_time_s": time.perf_counter() - t_start,
    }
    return {"results": res, "three_d": three}


def plot_shifted(shifted: dict, path, *, name: str):
    """``shifted_outages.png``: :func:`jaxnav.plot.plot_shifted_outages` of a :func:`shifted_outages` result."""
    from jaxnav.plot import plot_shifted_outages

    r = shifted["results"]
    tag = "3d" if shifted["three_d"] else "h"
    rows = r["per_outage"]
    word = "3-D" if tag == "3d" else "horizontal"
    return plot_shifted_outages(
        [o["start_since_imu_start_s"] for o in rows],
        [o["shift"] for o in rows],
        [o[f"forward_max_{tag}_m"] for o in rows],
        [o[f"smoothed_max_{tag}_m"] for o in rows],
        path,
        title=f"{name}: largest {word} drift per simulated GNSS outage against "
        f"{'the reference trajectory' if tag == '3d' else 'the withheld fixed GNSS'}\n{r['shifts']} outage schedules "
        f"shifted by {r['shift_s']:g} s, each its own run",
        what=f"largest {word} drift",
        pooled=(r["forward"][f"rms_of_max_{tag}_drift_m"], r["smoothed"][f"rms_of_max_{tag}_drift_m"]),
    )


def _tuning(prep, results: dict) -> dict:
    """What was fitted on which GNSS epochs, and what was scored (the withheld fixes, never fitted on)."""
    fitted = {}
    off = prep.time_offset_info
    if off.get("source") == "estimate":
        fitted["time_offset"] = {"fitted_on": off["fitted_on"], "n_epochs": off["n_epochs_used"]}
    cal = results.get("calibration") or {}
    if cal.get("ran"):
        fitted["noise calibration"] = {
            "params": cal["params"],
            "fitted_on": cal["fitted_on"],
            "n_epochs": cal["n_epochs"],
        }
    if "tune" in results:
        t = results["tune"]
        fitted[", ".join(t["params"])] = {"fitted_on": t["fitted_on"], "n_epochs": t["n_epochs"]}
    out = {"fitted": fitted}
    if prep.withheld.any():
        out["scored_on"] = (
            "the fixed-quality GNSS epochs inside the [evaluate] outages, withheld from the filter and "
            "from every fit, scored after fitting"
        )
        out["n_withheld"] = int(np.count_nonzero(prep.withheld))
    return out


def _offset_note(o: dict) -> str:
    """'config', or 'estimate +- sigma ms from N GNSS epochs, K dropped at the search span's edges'."""
    if o.get("source") != "estimate" or "sigma_s" not in o:
        return o.get("source", "config")
    return (
        f"estimate +- {1e3 * o['sigma_s']:.1f} ms from {o['n_epochs_used']} GNSS epochs, "
        f"{o['n_epochs_dropped_at_span_edges']} dropped at the search span's edges"
    )


def format_ins(results: dict) -> str:
    """Summary of :func:`process` with units."""
    from jaxnav import status_words

    r = results
    lines = [
        f"jaxnav ins: {r['provenance']['config_file']}",
        f"  IMU {r['imu']['n_samples']} samples, GNSS {r['gnss']['n_epochs_used']} of "
        f"{r['gnss']['n_epochs_in_imu_span']} epochs used ({r['gnss']['n_withheld']} withheld on simulated outages)",
        f"  mounting: {r['mounting']['source']}; time offset {r['time_offset_s']:+.3f} s "
        f"({_offset_note(r['time_offset'])}); initial heading {r['alignment']['heading_deg']:.1f} deg",
        f"  {r['n_states']}-state filter + RTS: status {status_words(r['status'])}, log-likelihood {r['loglik']:.1f}, "
        f"{r['n_gated_gnss_epochs']} GNSS epochs ({100 * r['gnss'].get('gated_share', 0.0):.1f} %) rejected by "
        f"the chi-square gate, {r['n_skipped_updates']} epochs without update, {r['runtime_s']:.1f} s",
    ]
    lines += _calibration_lines(r.get("calibration"))
    dr = r["time_offset"].get("drift", {})
    if "drift_s_per_s" in dr:
        w = dr["windows"]
        lines.append(
            f"  time offset by halves: {w[0]['offset_s']:+.3f} / {w[1]['offset_s']:+.3f} s, clock drift "
            f"{dr['drift_s_per_s'] * 1e6:+.0f} +- {dr['drift_sigma_s_per_s'] * 1e6:.0f} ppm"
            + (f"\n  WARNING: {dr['warning']}" if dr.get("significant") else " (not significant)")
        )
    for msg in r.get("status_flags", []):
        lines.append(f"  {'note' if r.get('status_ok', True) else 'PROBLEM'}: {msg}")
    c = r.get("constraints", {})
    if "standstill_intervals" in c:
        lines.append(
            f"  standstill: {c['standstill_intervals']} intervals, {c['standstill_s']:.1f} s (SHOE GLRT) -> "
            f"ZUPT{' + ZARU' if c['zaru'] else ''} updates"
        )
        dd = c.get("detector", {})
        if dd:
            lines.append(
                f"  detector ({dd['platform']}): threshold {dd['threshold']:.1f} from {dd['threshold_source']}; "
                f"GNSS veto: {dd['vetoed_samples']} samples in {dd['vetoed_intervals']} intervals "
                f"({dd['vetoed_s']:.1f} s) where GNSS speed > {dd['gnss_k']:g} sigma, {dd['unconfirmed_intervals']} "
                f"unconfirmed by GNSS dropped; vs GNSS-static epochs: "
                f"precision {dd['precision']:.3f}, recall {dd['recall']:.3f} "
                f"(IMU alone {dd['imu_only_precision']:.3f} / {dd['imu_only_recall']:.3f})"
            )
    o = r.get("odometer")
    if o:
        sf = (
            f"; scale factor {o['scale_factor_smoothed']:.5f} +- {o['scale_factor_smoothed_sigma']:.5f} (smoothed), "
            f"{o['scale_factor']:.5f} +- {o['scale_factor_sigma']:.5f} (forward, end)"
            if "scale_factor" in o
            else "; scale factor taken as 1 (estimate_scale = false)"
        )
        lines.append(
            f"  odometer ({o['source']}): {o['imu_samples_with_reading']} of {o['imu_samples']} IMU samples "
            f"with a reading, {o['rate_hz']:g} Hz updates, sigma {o['sigma_m_s']:g} m/s{sf}"
        )
    if c.get("nhc"):
        lines.append("  non-holonomic constraint on (lateral and vertical velocity zero while moving)")

    def ev(e, tag=""):
        if e is None or "n_windows" not in e:
            return
        lines.append(
            f"  outages{tag}: {e['n_scored_windows']} of {e['n_windows']} windows scored; horizontal RMS "
            f"forward {e['forward_rms_h_m']:.2f} m (max {e['forward_max_h_m']:.2f} m), smoothed "
            f"{e['smoothed_rms_h_m']:.2f} m (max {e['smoothed_max_h_m']:.2f} m); within 3 sigma: "
            f"forward {100 * e['forward_share_within_3_sigma_h']:.0f} %, smoothed "
            f"{100 * e['smoothed_share_within_3_sigma_h']:.0f} %"
        )

    ev(r.get("evaluation"))
    tr = (r.get("evaluation") or {}).get("truth")
    if tr:
        for w in ("forward", "smoothed"):
            a, o, p = tr[w]["all"], tr[w]["outages"], tr[w]["outage_protocol"]
            line = (
                f"  vs reference ({w}): 3-D position RMS {a['pos_3d_rms_m']:.3f} m, horizontal "
                f"{a['pos_h_rms_m']:.3f} m, velocity {a['vel_3d_rms_m_s']:.3f} m/s, roll/pitch/heading RMS "
                f"{a['roll_rms_deg']:.3f}/{a['pitch_rms_deg']:.3f}/{a['heading_rms_deg']:.3f} deg, position NEES "
                f"{a['nees_pos_mean']:.2f} (expect 3), within 3 sigma {100 * a['share_pos_within_3_sigma']:.1f} %"
            )
            if p["n_scored_windows"]:
                line += (
                    f"; outages: 3-D RMS {o['pos_3d_rms_m']:.3f} m, max drift per outage RMS "
                    f"{p['rms_of_max_3d_drift_m']:.3f} m over {p['n_scored_windows']}"
                )
            lines.append(line)
    so = (r.get("evaluation") or {}).get("shifted_outages")
    if so:
        tag = "3d" if "rms_of_max_3d_drift_m" in so["forward"] else "h"
        f, s = so["forward"], so["smoothed"]
        lines.append(
            f"  shifted outages: {so['shifts']} schedules {so['shift_s']:g} s apart, {so['n_outages']} outages scored "
            f"against {'the reference' if tag == '3d' else 'withheld fixed GNSS'}; largest "
            f"{'3-D' if tag == '3d' else 'horizontal'} drift per outage: forward RMS "
            f"{f[f'rms_of_max_{tag}_drift_m']:.2f} m (mean {f[f'mean_of_max_{tag}_drift_m']:.2f}, max "
            f"{f[f'max_of_max_{tag}_drift_m']:.2f} m), smoothed RMS {s[f'rms_of_max_{tag}_drift_m']:.2f} m (mean "
            f"{s[f'mean_of_max_{tag}_drift_m']:.2f}, max {s[f'max_of_max_{tag}_drift_m']:.2f} m)"
        )
    if "tune" in r:
        t = r["tune"]
        lines.append(
            f"  --tune ({t.get('loss', 'innovations')}): log-likelihood {t['loglik_before']:.1f} -> "
            f"{t['loglik_after']:.1f} "
            f"({t['n_evals']} evaluations, {t['wall_time_s']:.1f} s); "
            + ", ".join(f"{k} {_fmt(t['before_si'][k])} -> {_fmt(t['after_si'][k])}" for k in t["params"])
        )
        if "fitted_on" in t:
            lines.append(f"  --tune fitted on {t['n_epochs']} {t['fitted_on']}")
        ev(t["evaluation_after"], " after tuning")
    return "\n".join(lines)


def _calibration_lines(c) -> list:
    """Summary lines of the ``calibration`` block: what was calibrated, from which epochs, NIS before/after."""
    if not c:
        return []
    if c.get("ran"):
        u = c["display_units"]
        vals = ", ".join(
            f"{k} {c['before_display'][k]:.4g} -> {c['after_display'][k]:.4g}{'' if u[k] == '1' else ' ' + u[k]}"
            for k in c["params"]
        )
        out = [
            f"  noise calibrated ({c['reason']}): {vals}; fitted on {c['n_epochs']} {c['fitted_on']} "
            f"(innovation likelihood without the gate, {c['n_evals']} evaluations, {c['wall_time_s']:.1f} s); "
            f"GNSS position NIS per dof {c['nis_before_per_dof']:.2f} -> {c['nis_after_per_dof']:.2f}"
            + (
                f", velocity {c['nis_vel_before_per_dof']:.2f} -> {c['nis_vel_after_per_dof']:.2f}"
                if c.get("n_nis_vel_epochs")
                else ""
            )
            + f"; beyond the gate {100 * c['share_above_gate_before']:.1f} -> {100 * c['share_above_gate_after']:.1f} %"
        ]
    else:
        nis = f" (GNSS position NIS per dof {c['nis_before_per_dof']:.2f})" if "nis_before_per_dof" in c else ""
        out = [f"  noise as configured, not calibrated: {c['reason']}{nis if 'NIS' not in c['reason'] else ''}"]
    out += [f"  WARNING: {c[k]}" for k in ("warning", "gate_warning") if c.get(k)]
    return out


def _fmt(v):
    return ("[" + ", ".join(f"{x:.4g}" for x in v) + "]") if isinstance(v, list) else f"{v:.4g}"
