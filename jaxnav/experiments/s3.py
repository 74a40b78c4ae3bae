"""S3: the cadastral-survey post-processing over Monte Carlo seeds (what ``jaxnav cadastral`` runs).

Per IMU grade of the config (tactical, consumer): simulate the survey, run the S3 pipeline
(:func:`jaxnav.survey.process_survey`) vmapped over seeds (:func:`jaxnav.tune.run_chunked`), score the
target points of every stage, check the stop detector against the simulated stops and on the real
walk set, identify the AR error model of a static record, and write ``results.json`` and figures.
"""

from __future__ import annotations

import math
import pathlib
import time

import jax
import jax.numpy as jnp
import numpy as np

from jaxnav.experiments.walk import WALK_SENSOR_TO_BODY
from jaxnav.geodesy import curvilinear_to_enu
from jaxnav.io import imu_increments, read_stop_list, write_json, write_stop_list
from jaxnav.plot import plot_cadastral_errors, plot_cadastral_route, plot_stop_detection
from jaxnav.sim import calibration_record, load_cadastral, short_survey, simulate_cadastral, survey_truth
from jaxnav.survey import (
    STAGES,
    DetectorParams,
    PreprocessParams,
    ar_kalman,
    cadastral_params,
    detect_stops,
    detection_scores,
    fit_ar,
    horizontal_speed,
    match_stops,
    plan_survey,
    preprocess_imu,
    process_survey,
    reject_outliers,
    select_ar_order,
    series_stats,
    simulate_ar,
    stance_statistic,
    static_spans,
    stop_records,
    summarize_errors,
    target_errors,
    white_noise_variance,
    zero_phase_lowpass,
)
from jaxnav.tune import is_writer, run_chunked

_AR2_PHI = (0.6, -0.3)


def grade_params(scn, pipe: dict):
    """S3 pipeline parameters (:class:`jaxnav.survey.CadastralParams`, SI) from a scenario's IMU grade and the
    config's [pipeline] table (outlier_k, lowpass_hz, velocity/position/ZUPT sigmas)."""
    nz, ie = scn.grade.noise, scn.grade.initial_errors
    pre = PreprocessParams(
        k_gyro=float(pipe.get("outlier_k", 6.0)),
        k_accel=float(pipe.get("outlier_k", 6.0)),
        cutoff_hz=float(pipe.get("lowpass_hz", 20.0)),
    )
    return cadastral_params(
        gyro_bias=nz.gyro_bias_initial,
        gyro_markov=nz.gyro_bias_instability,
        gyro_tau=nz.gyro_bias_tau,
        gyro_arw=nz.gyro_arw,
        accel_bias=nz.accel_bias_initial,
        accel_vrw=nz.accel_vrw,
        attitude_sigma=tuple(max(x, 1e-6) for x in ie.attitude),
        velocity_sigma=float(pipe.get("velocity_sigma0_mps", 0.01)),
        position_sigma=float(pipe.get("position_sigma0_m", 0.005)),
        zupt_sigma=float(pipe.get("zupt_sigma_mps", 0.005)),
        pre=pre,
    )


def detector_params_for(scn):
    """S3 step 2 detector levels (:class:`jaxnav.survey.DetectorParams`): the grade's white noise as a per-sample
    std at the IMU rate (m/s^2, rad/s; floored at 0.005, 5e-4); threshold 10
    (a static window averages ~5: 6 degrees of freedom less the 3 of the estimated mean force)."""
    fs = scn.imu_rate_hz
    sa = max(max(scn.grade.noise.accel_vrw) * math.sqrt(fs), 0.005)
    sg = max(max(scn.grade.noise.gyro_arw) * math.sqrt(fs), 5e-4)
    return DetectorParams(sigma_a=sa, sigma_g=sg, threshold=10.0)


def survey_monte_carlo(
    scn,
    pipe: dict,
    seeds: int,
    *,
    stops=None,
    chunk: int = 8,
    progress: bool = True,
    seed0: int = 0,
    route_every: int = 50,
):
    """Run the S3 pipeline on ``seeds`` simulated surveys (vmapped, chunked by :func:`jaxnav.tune.run_chunked`).

    Returns:
      dict with truth, plan, per-seed target errors (stage -> (S, T, 3) E, N, U m), sigmas, weights, wild-value
      counts, status, static masks and the detector statistic (float32, (S, N)) for detection, seed-0 routes
      and timing.
    """
    truth = survey_truth(scn)
    stop_list = truth.stops if stops is None else stops
    plan = plan_survey(
        stop_list,
        truth.t_imu,
        meas_rate_hz=float(pipe.get("meas_rate_hz", 1.0)),
        margin_s=float(pipe.get("margin_s", 0.5)),
    )
    tpos = jnp.asarray(truth.pos[plan.arrival])
    params = grade_params(scn, pipe)
    det = detector_params_for(scn)
    dt = scn.dt
    user_known = None if stops is None else jnp.asarray(stops.pos)

    def one(key):
        run = simulate_cadastral(scn, key, truth)
        kp = run.known_pos if user_known is None else user_known
        out = process_survey(plan, run.nav0, run.dtheta, run.dv, kp, params, return_route=True)
        errs = target_errors(out, tpos)
        # segmentation follows preprocessing (S3 steps 1-2): wild values would look like motion
        pre = preprocess_imu(run.dtheta, run.dv, dt, params.pre, lowpass=False)
        stat = stance_statistic(pre.dv / dt, pre.dtheta / dt, det, window=int(round(0.5 / dt)))
        route = {k: v[route_every - 1 :: route_every] for k, v in out.route.items()}
        return dict(
            errors=errs,
            sigma_f=out.sigma_forward,
            sigma_b=out.sigma_backward,
            weight=out.weight_forward,
            n_rejected=out.n_rejected,
            n_wild=run.n_wild,
            status=out.status,
            static=stat < det.threshold,
            statistic=stat.astype(jnp.float32),
            route=route,
        )

    keys = jax.random.split(jax.random.PRNGKey(seed0), seeds)
    t0 = time.perf_counter()
    res = run_chunked(one, keys, chunk=chunk, desc=f"S3 {scn.grade.name}", progress=progress)
    wall = time.perf_counter() - t0
    return dict(truth=truth, plan=plan, res=res, wall=wall, detector=det)


def ar_identification(seed: int = 0, n: int = 20000, reps: int = 200):
    """S3 step 1 check: fit a simulated AR(2) of ``n`` samples (Yule-Walker and LS), and the standard errors'
    coverage over ``reps`` draws of 2000 samples; returns a JSON-ready dict."""
    phi = jnp.asarray(_AR2_PHI)
    x = simulate_ar(jax.random.PRNGKey(seed), phi, 1.0, n)
    out = {"phi_true": list(_AR2_PHI), "n": n}
    sel = select_ar_order(x, 6, criterion="bic")
    sel_aic = select_ar_order(x, 6, criterion="aic")
    out["order_bic"] = sel.order
    out["order_aic"] = sel_aic.order
    for m in ("yule_walker", "ls"):
        f = fit_ar(x, 2, m)
        out[m] = {
            "phi": np.asarray(f.phi).tolist(),
            "se": np.asarray(f.se).tolist(),
            "z": (np.asarray(f.phi - phi) / np.asarray(f.se)).tolist(),
            "sigma2": float(f.sigma2),
        }
    keys = jax.random.split(jax.random.PRNGKey(seed + 1), reps)
    fits = jax.jit(jax.vmap(lambda k: fit_ar(simulate_ar(k, phi, 1.0, 2000), 2, "yule_walker")))(keys)
    z = np.abs(np.asarray(fits.phi - phi) / np.asarray(fits.se))
    out["coverage"] = {
        "reps": reps,
        "n": 2000,
        "within_1se": float((z < 1).mean()),
        "within_2se": float((z < 2).mean()),
        "expected_1se": 0.6827,
        "expected_2se": 0.9545,
    }
    return out


def preprocessing_check(scn, seed: int = 0, n: int = 60000, axis: int = 0):
    """S3 step 1 on a static record of ``n`` samples (axis ``axis``): AR identification and the residual error
    variance ((rad/s)^2, (m/s^2)^2) after each preprocessing step; returns a JSON-ready dict."""
    rec = calibration_record(scn, jax.random.PRNGKey(seed), n)
    out = {"n": n, "rate_hz": scn.imu_rate_hz, "n_wild": int(rec.n_wild)}
    for name, y, col, floor in (
        ("gyro", rec.gyro[:, axis], rec.gyro_coloured[:, axis], 1e-4),
        ("accel", rec.accel[:, axis], rec.accel_coloured[:, axis], 1e-3),
    ):
        clean = reject_outliers(y, 6.0, floor)
        c = clean.clean
        lp = zero_phase_lowpass(c, scn.dt, 20.0)
        sel = select_ar_order(c, 6, criterion="bic")
        R = white_noise_variance(c)
        kf = ar_kalman(c, sel.fit.phi, sel.fit.sigma2, R)
        st_raw = series_stats(y)
        st = series_stats(c)
        v = lambda a: float(jnp.var(a))
        # decimated to 1 s means (low-pass + resampling): the correlated drift becomes visible to the
        # AR identification, and the filter estimates it (compared with the simulated drift)
        m = int(round(scn.imu_rate_hz))
        nb = c.shape[0] // m
        yd = c[: nb * m].reshape(nb, m).mean(1)
        cd = col[: nb * m].reshape(nb, m).mean(1)
        seld = select_ar_order(yd, 6, criterion="bic")
        Rd = R / m
        kfd = ar_kalman(yd, seld.fit.phi, seld.fit.sigma2, Rd)
        dec = {
            "block_s": 1.0,
            "n": nb,
            "ar_order_bic": seld.order,
            "ar_phi": np.asarray(seld.fit.phi).tolist(),
            "ar_se": np.asarray(seld.fit.se).tolist(),
            "white_variance": float(Rd),
            "var_error_raw_minus_drift": v(yd - cd),
            "var_error_ar_kalman_minus_drift": v(kfd.error - cd),
            "var_drift": v(cd),
        }
        out[name] = {
            "var_raw": v(y),
            "var_outliers_rejected": v(c),
            "var_lowpass_20hz": v(lp),
            "var_ar_kalman": v(kf.error),
            "reduction_total": v(y) / v(kf.error),
            "n_rejected": int(clean.n_rejected),
            "var_coloured_truth": v(col),
            "var_ar_kalman_minus_coloured": v(kf.error - col),
            "ar_order_bic": sel.order,
            "ar_phi": np.asarray(sel.fit.phi).tolist(),
            "ar_se": np.asarray(sel.fit.se).tolist(),
            "white_variance": float(R),
            "decimated_1s": dec,
            "stats_raw": {
                k: float(getattr(st_raw, k)) for k in ("mean", "var", "skew", "kurt", "jb", "jb_p", "runs_z", "runs_p")
            },
            "stats_clean": {
                k: float(getattr(st, k)) for k in ("mean", "var", "skew", "kurt", "jb", "jb_p", "runs_z", "runs_p")
            },
        }
    return out


def walk_detection(data_dir, out_dir=None):
    """S3 step 2 on real data: the stop detector on the walk set (``data_dir``, see :func:`jaxnav.experiments.walk.load_walk`)
    against the stops seen by RTK (horizontal speed < 0.1 m/s); spans in s from the IMU start; the figure goes
    to ``out_dir`` if given."""
    from jaxnav.experiments.walk import load_walk

    w = load_walk(data_dir)
    t, dth, dv, dt = imu_increments(w.imu, WALK_SENSOR_TO_BODY)
    f, g = dv / dt[:, None], dth / dt[:, None]
    prm = DetectorParams(sigma_a=0.05, sigma_g=0.01, threshold=10.0)
    win = int(round(0.5 / np.median(dt)))
    r = detect_stops(t, f, g, prm, window=win, min_duration=2.0, min_gap=0.5)
    p = w.pos
    gt = np.asarray(p.t, float)
    speed = horizontal_speed(gt, np.stack([np.asarray(p.lat), np.asarray(p.lon), np.asarray(p.h)], -1))
    sel = (gt >= t[0]) & (gt <= t[-1])
    ref = static_spans(speed[sel] < 0.1, gt[sel], min_duration=2.0, min_gap=0.5)
    sc = match_stops(r.spans, ref, min_overlap=0.5)
    fig = None
    if out_dir is not None:
        fig = str(pathlib.Path(out_dir) / "cadastral_walk_detection.png")
        plot_stop_detection(
            fig,
            t - t[0],
            r.statistic,
            prm.threshold,
            r.spans - t[0],
            ref - t[0],
            title="stop detector (GLRT) on the real walk set walk_0827",
            extra=(gt[sel] - t[0], speed[sel], "RTK horizontal speed, m/s"),
            true_label="RTK static (speed < 0.1 m/s)",
        )
    return {
        "n_samples": int(t.size),
        "rate_hz": float(1 / np.median(dt)),
        "threshold": float(prm.threshold),
        "window": win,
        "detected_spans_s": (r.spans - t[0]).round(2).tolist(),
        "rtk_static_spans_s": (ref - t[0]).round(2).tolist(),
        "precision": sc.precision,
        "recall": sc.recall,
        "n_detected": sc.n_detected,
        "n_rtk": sc.n_true,
        "start_error_s": sc.start_error.round(2).tolist(),
        "end_error_s": sc.end_error.round(2).tolist(),
        "figure": fig,
    }


def _enu(pos, ref):
    """(..., 3) local ENU, m, of geodetic pos (..., 3) about ref (3,) (radii at ref)."""
    pos, ref = np.asarray(pos), np.asarray(ref)
    return np.asarray(curvilinear_to_enu(ref, pos - ref))


def run_cadastral(
    out,
    *,
    config=None,
    seeds: int = 64,
    grades=None,
    stops=None,
    chunk: int = 8,
    progress: bool = True,
    n_legs: int | None = None,
    walk_dir=None,
    ar_reps: int = 200,
    calib_samples: int = 60000,
) -> dict:
    """The whole S3 experiment; writes ``out/results.json`` and figures, returns the results dict.

    Args:
      out: output folder (created).  config: cadastral TOML (None: the shipped one).
      seeds: Monte Carlo seeds per grade (vmapped).  grades: names to run (None: all in the config).
      stops: optional stop-list CSV replacing the simulated one (checked against the data's span).
      chunk: seeds per compiled batch.  n_legs: keep only the first n legs (short runs).
      walk_dir: the rtklibexplorer-gnss-imu folder for :func:`walk_detection` (None, or a folder
        without ``walk_0827``: skipped, and said so in the results).
    """
    t_start = time.perf_counter()
    out = pathlib.Path(out)
    writer = is_writer()  # several processes: all compute, process 0 writes (stop lists, figures, results)
    if writer:
        out.mkdir(parents=True, exist_ok=True)
    scns, pipe = load_cadastral(config)
    names = list(scns) if grades is None else list(grades)
    for g in names:
        if g not in scns:
            raise ValueError(f"unknown IMU grade {g!r}; the config has {list(scns)}")
    user_stops = None if stops is None else read_stop_list(stops)
    results = {
        "command": "jaxnav cadastral",
        "seeds": seeds,
        "config": str(config or "jaxnav/sim/scenarios/cadastral.toml"),
        "stages": {
            "forward": "(a) raw data, pure strapdown from the last known-coordinate point",
            "preprocessed": "(a) on preprocessed data (wild values, 20 Hz zero-phase low-pass)",
            "smoothed": "(b) + class-1 KF/RTS at stops -> sensor errors compensated, strapdown from the "
            "smoothed state at the last known-coordinate point",
            "fused": "(c) + reverse navigation from the next known-coordinate point, inverse-variance fusion",
            "filtered": "diagnostic: causal class-1 filter at the target stop (uses the target's ZUPT)",
            "rts": "diagnostic: RTS-smoothed class-1 solution at the target stop",
        },
        "grades": {},
        "devices": [str(d) for d in jax.devices()],
    }
    for g in names:
        scn = scns[g]
        if n_legs:
            scn = short_survey(scn, n_legs)
        mc = survey_monte_carlo(scn, pipe, seeds, stops=user_stops, chunk=chunk, progress=progress)
        truth, plan, res = mc["truth"], mc["plan"], mc["res"]
        if writer:
            write_stop_list(out / f"stops_{g}.csv", truth.stops)
        errs = {s: res["errors"][s] for s in STAGES}
        summ = summarize_errors(errs)
        tnames = [plan.stops.name[k] for k in plan.targets]
        per_seed = {
            s: {
                "horizontal_m": np.hypot(errs[s][..., 0], errs[s][..., 1]).round(5).tolist(),
                "vertical_m": np.abs(errs[s][..., 2]).round(5).tolist(),
            }
            for s in STAGES
        }
        # stop detection on the simulated data
        t_imu = truth.t_imu
        true_spans = np.stack([truth.stops.t_start, truth.stops.t_end], 1)
        det = {**detection_scores(res["static"], t_imu, true_spans), "threshold": float(mc["detector"].threshold)}
        a, c = summ["forward"], summ["fused"]
        check = {
            "fused_over_forward_h": c["rms_h"] / a["rms_h"],
            "fused_over_forward_v": c["rms_v"] / a["rms_v"],
            "fused_over_preprocessed_h": c["rms_h"] / summ["preprocessed"]["rms_h"],
            "fused_over_smoothed_h": c["rms_h"] / summ["smoothed"]["rms_h"],
            "fused_over_smoothed_v": c["rms_v"] / summ["smoothed"]["rms_v"],
        }
        check["pass_c_le_0.7a"] = bool(check["fused_over_forward_h"] <= 0.7 and check["fused_over_forward_v"] <= 0.7)
        # figures
        ref = truth.pos[0]
        route = _enu(truth.pos, ref)
        st_enu = _enu(truth.stop_pos, ref)
        est = {
            "(b) strapdown from known points, seed 0": _enu(res["route"]["smoothed"][0], ref)[:, :2],
            "(c) reverse navigation, seed 0": _enu(res["route"]["backward"][0], ref)[:, :2],
        }
        f_route = out / f"cadastral_route_{g}.png"
        f_err = out / f"cadastral_errors_{g}.png"
        f_det = out / f"cadastral_detection_{g}.png"
        if writer:
            plot_cadastral_route(
                f_route,
                route[:, :2],
                st_enu[:, :2],
                plan.stops.kind,
                plan.stops.name,
                estimates=est,
                title=f"S3 cadastral survey, {g} IMU (seed 0)",
                target_errors={s: errs[s][0] for s in ("forward", "preprocessed", "smoothed", "fused", "rts")},
            )
            plot_cadastral_errors(
                f_err,
                errs,
                title=f"S3 target errors, {g} IMU, {seeds} seed{'s' if seeds != 1 else ''} x "
                f"{len(tnames)} target{'s' if len(tnames) != 1 else ''} (boxes: quartiles, "
                f"whiskers: 1.5 IQR)",
            )
            plot_stop_detection(
                f_det,
                t_imu,
                np.asarray(res["statistic"][0], float),
                float(mc["detector"].threshold),
                static_spans(res["static"][0], t_imu, min_duration=2.0, min_gap=0.5),
                true_spans,
                title=f"stop detector (GLRT) on the simulated survey, {g} IMU, seed 0 of {seeds}",
            )
        status = np.bitwise_or.reduce(np.asarray(res["status"]).ravel())
        results["grades"][g] = {
            "survey": {
                "duration_s": scn.duration,
                "n_imu": int(t_imu.size),
                "n_stops": len(plan.stops.t_start),
                "stops": stop_records(plan.stops),
                "targets": tnames,
                "class3": [bool(x) for x in plan.class3],
            },
            "summary": summ,
            "check": check,
            "per_seed": per_seed,
            "fusion_weight_forward_mean": np.asarray(res["weight"]).mean(axis=(0,)).round(4).tolist(),
            "sigma_forward_mean_m": np.asarray(res["sigma_f"]).mean(0).round(4).tolist(),
            "sigma_backward_mean_m": np.asarray(res["sigma_b"]).mean(0).round(4).tolist(),
            "wild_values_injected_mean": float(np.mean(res["n_wild"])),
            "wild_values_rejected_mean": float(np.mean(res["n_rejected"])),
            "status_flags": int(status),
            "detection": det,
            "wall_s": mc["wall"],
            "figures": [str(f_route), str(f_err), str(f_det)],
            "preprocessing": preprocessing_check(scn, n=calib_samples),
        }
    results["ar_identification"] = ar_identification(reps=ar_reps)
    if walk_dir is None:
        results["walk_detection"] = {"skipped": "no walk set given (walk_dir; --data or JAXNAV_DATA)"}
    elif (pathlib.Path(walk_dir) / "walk_0827").is_dir():
        results["walk_detection"] = walk_detection(walk_dir, out if writer else None)
    else:
        results["walk_detection"] = {"skipped": f"walk set not found (looked in {walk_dir})"}
    results["wall_s_total"] = time.perf_counter() - t_start
    if writer:
        write_json(out / "results.json", results)
    return results


def format_cadastral(results: dict) -> str:
    """The per-stage target errors (m) and the checks of :func:`run_cadastral` as text."""
    lines = []
    for g, r in results["grades"].items():
        s = r["summary"]
        lines.append(
            f"\n{g} IMU, {results['seeds']} seeds x {len(r['survey']['targets'])} targets "
            f"({r['survey']['duration_s']:.0f} s survey, {r['wall_s']:.1f} s Monte Carlo)"
        )
        lines.append(
            f"  {'stage':<14}{'RMS h m':>10}{'RMS v m':>10}{'median h':>10}{'p95 h':>10}{'h/(a)':>8}{'v/(a)':>8}"
        )
        for st in STAGES:
            x = s[st]
            lines.append(
                f"  {st:<14}{x['rms_h']:>10.3f}{x['rms_v']:>10.3f}{x['median_h']:>10.3f}{x['p95_h']:>10.3f}"
                f"{x['ratio_h_vs_forward']:>8.3f}{x['ratio_v_vs_forward']:>8.3f}"
            )
        c = r["check"]
        lines.append(
            f"  (c)/(a): h {c['fused_over_forward_h']:.4f}, v {c['fused_over_forward_v']:.4f} -> "
            f"{'PASS' if c['pass_c_le_0.7a'] else 'FAIL'} (<= 0.7); "
            f"(c)/(b): h {c['fused_over_smoothed_h']:.3f}, v {c['fused_over_smoothed_v']:.3f}"
        )
        d = r["detection"]
        lines.append(
            f"  stop detector (simulated): precision {d['precision_mean']:.3f} "
            f"(min {d['precision_min']:.3f}), recall {d['recall_mean']:.3f} (min {d['recall_min']:.3f}), "
            f"sample precision {d['sample_precision_mean']:.3f} / recall {d['sample_recall_mean']:.3f}"
        )
        p = r["preprocessing"]
        for sn, unit in (("gyro", "(rad/s)^2"), ("accel", "(m/s^2)^2")):
            q = p[sn]
            lines.append(
                f"  preprocessing {sn}: residual variance {unit} raw {q['var_raw']:.3e} -> outliers "
                f"{q['var_outliers_rejected']:.3e} -> AR({q['ar_order_bic']}) Kalman {q['var_ar_kalman']:.3e} "
                f"(x{q['reduction_total']:.1f} lower)"
            )
    a = results["ar_identification"]
    lines.append(
        f"\nAR(2) phi = {a['phi_true']}: Yule-Walker {np.round(a['yule_walker']['phi'], 4).tolist()} +- "
        f"{np.round(a['yule_walker']['se'], 4).tolist()} (z = {np.round(a['yule_walker']['z'], 2).tolist()}); "
        f"BIC order {a['order_bic']}; coverage within 1 SE {a['coverage']['within_1se']:.3f} (0.683), "
        f"2 SE {a['coverage']['within_2se']:.3f} (0.954)"
    )
    w = results["walk_detection"]
    if "skipped" in w:
        lines.append(f"walk set: {w['skipped']}")
    else:
        lines.append(
            f"walk set: detected stops {w['detected_spans_s']} s; RTK static {w['rtk_static_spans_s']} s; "
            f"precision {w['precision']:.2f}, recall {w['recall']:.2f}"
        )
    lines.append(f"total wall time {results['wall_s_total']:.1f} s")
    return "\n".join(lines)
