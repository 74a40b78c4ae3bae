"""Station velocities with coloured noise beside Hector (issue 19).

A script, not a test. It runs in the environment with the bench extra (hector-ts):

    .venv/bin/python benchmarks/bench_monitoring.py                 # all three parts, prints a report
    .venv/bin/python benchmarks/bench_monitoring.py --part real     # only part 1 (or mc, batch)
    .venv/bin/python benchmarks/bench_monitoring.py --json out.json # also write the numbers

1. **Real series beside Hector.** The five daily series of ``../shared/data/gnss_daily_timeseries``
   (LHAS tenv3, BJFS .neu, MRHK/UH01/UHCR .col), screened by jaxnav (the same cleaned days go to
   both programs), white + flicker noise (Hector ``NoiseModels FlickerGGM White``,
   ``GGM_1mphi 6.9e-6``, RMLE; jaxnav ``fit_station(random_walk=False)``), offset, rate, annual
   and semi-annual terms: rate, rate sigma, white sigma and flicker amplitude per component, and
   the wall time per station (jaxnav: the three components in one vmap, compiled program reused;
   its first call with compilation given apart; Hector: three ``estimatetrend`` runs, process
   start included). jaxnav's default model (with a random walk) is listed too. Part ``kappa``:
   the spectral index estimated (MRHK) beside Hector's ``GGM White``.
2. **Coverage.** 500 simulated 10-year series (white 2 mm + flicker 6 mm/yr^0.25, Williams
   power law started at the first day, 10 % days missing, rate 3 mm/yr): share of 95 % rate
   intervals covering the truth, spread of the standardised errors, beside white-noise sigmas.
3. **Batch.** 1000 simulated stations x 3 components (3000 series) of 10 years in one call
   (``fit_series_batch``, vmap in chunks of 250 series for memory, one host thread per core), wall time with compilation,
   peak resident memory of the process.
4. **Stations** (``--part stations``): the command's own path, :func:`jaxnav.monitoring.fit_stations`
   with ``jaxnav monitor``'s defaults (outlier screening, white + flicker + random walk, REML, up
   to 5 steps detected per station, a misfit scan after the last fit) on ``--stations`` simulated
   ten-year stations with 0-4 steps each in the up component (the step study's simulator,
   ``bench_step_detection.station``), then MIDAS beside each fit (:func:`jaxnav.monitoring.midas_check`);
   wall time with compilation, peak memory, steps found; Hector's ``findoffsets`` (three
   components) on ``--hector-sample`` of the same stations for the time per station.
   ``--part refits``: the same stations (``--stations``, 100 suggested) fitted twice, each in its own
   process: with the library's warm-started refits after a detected step, and with cold refits (40
   iterations from the default start, the behaviour before the warm start, switched on in the
   child process by replacing :func:`jaxnav.monitoring._station.refit_iterations` and the start);
   wall times, steps found, and the differences of rates, rate sigmas and ln L_R.
5. **Network** (``--part network``): ``jaxnav monitor`` with its defaults on the five real series
   (``run_monitor_velocities``, the function behind the command: white + flicker + random walk,
   REML, up to 5 steps detected per station by the BIC criterion), writing ``monitor.json``,
   ``velocities.csv`` and ``velocity_map.png`` into ``--out``: the steps found (date, size and
   sigma per component, likelihood gain) and MIDAS beside the model rate. ``--from-json`` formats
   an existing ``monitor.json`` instead of running.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import time
from pathlib import Path

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "benchmarks"))

from _harness import cpu_model, package_version
from reference.hector_run import run_hector

from jaxnav import io
from jaxnav import monitoring as mon
from jaxnav.units import DAY, MM, MM_PER_YEAR, YEAR

DATA = ROOT.parent / "shared/data/gnss_daily_timeseries"
FILES = ["LHAS.tenv3", "bjfsCleanUnf.neu", "MRHK_GOM20_neu_cm.col", "UH01_GOM20_neu_cm.col", "UHCR_GOM20_neu_cm.col"]


def part_real():
    rows, times = [], []
    for _i, name in enumerate(FILES):
        s = io.read_daily(DATA / name)
        t0 = time.perf_counter()
        fit = mon.fit_station(s, random_walk=False)
        t_first = time.perf_counter() - t0
        t0 = time.perf_counter()
        fit = mon.fit_station(s, random_walk=False)
        t_j = time.perf_counter() - t0
        t0 = time.perf_counter()
        fit_rw = mon.fit_station(s, random_walk=True)
        t_rw = time.perf_counter() - t0
        g = fit.grid
        t_h = 0.0
        for c, comp in enumerate(mon.COMPONENTS):
            v = g.valid[:, c]
            h = run_hector(g.t[v], g.y[v, c])
            t_h += h["wall_s"]
            rows.append(
                dict(
                    station=s.station,
                    component=comp,
                    days=int(v.sum()),
                    span_yr=(g.n_days - 1) / 365.25,
                    jaxnav_rate=float(fit.velocity[c] / MM_PER_YEAR),
                    hector_rate=h["trend"],
                    jaxnav_sigma=float(fit.velocity_sigma[c] / MM_PER_YEAR),
                    hector_sigma=h["trend_sigma"],
                    white_only_sigma=float(fit.velocity_sigma_white[c] / MM_PER_YEAR),
                    jaxnav_white=float(fit.white_sigma[c] / MM),
                    hector_white=h["NoiseModel"]["White"]["sigma"],
                    jaxnav_flicker=float(fit.powerlaw_amplitude[c] * YEAR**0.25 / MM),
                    hector_flicker=h["NoiseModel"]["FlickerGGM"]["sigma"],
                    rw_model_rate=float(fit_rw.velocity[c] / MM_PER_YEAR),
                    rw_model_sigma=float(fit_rw.velocity_sigma[c] / MM_PER_YEAR),
                    rw_mm_sqrt_yr=float(fit_rw.random_walk[c] * np.sqrt(YEAR) / MM),
                    outliers=sum(1 for d in fit.screening.records if d["component"] == comp),
                )
            )
        times.append(
            dict(
                station=s.station,
                jaxnav_first_s=t_first,
                jaxnav_s=t_j,
                jaxnav_rw_s=t_rw,
                hector_s=t_h,
                warnings=fit.warnings + fit_rw.warnings,
            )
        )
        print(
            f"{s.station}: jaxnav {t_j:.1f} s (first call {t_first:.1f} s), with random walk {t_rw:.1f} s, "
            f"Hector {t_h:.1f} s",
            flush=True,
        )
    return dict(rows=rows, times=times)


def part_kappa(name="MRHK_GOM20_neu_cm.col"):
    """Spectral index estimated: jaxnav (kappa=None) beside Hector's ``NoiseModels GGM White``."""
    s = io.read_daily(DATA / name)
    t0 = time.perf_counter()
    fit = mon.fit_station(s, kappa=None, random_walk=False)
    wall = time.perf_counter() - t0
    g, rows = fit.grid, []
    for c, comp in enumerate(mon.COMPONENTS):
        v = g.valid[:, c]
        h = run_hector(g.t[v], g.y[v, c], noise="GGM White")
        k = float(fit.kappa[c])
        rows.append(
            dict(
                station=s.station,
                component=comp,
                jaxnav_rate=float(fit.velocity[c] / MM_PER_YEAR),
                hector_rate=h["trend"],
                jaxnav_sigma=float(fit.velocity_sigma[c] / MM_PER_YEAR),
                hector_sigma=h["trend_sigma"],
                jaxnav_kappa=k,
                hector_kappa=h["NoiseModel"]["GGM"]["kappa"],
                jaxnav_amp=float(fit.powerlaw_amplitude[c] * YEAR ** (-k / 4) / MM),
                hector_amp=h["NoiseModel"]["GGM"]["sigma"],
                hector_s=h["wall_s"],
            )
        )
    return dict(rows=rows, wall_s=wall)


def _simulate(key, B, n, gap=0.1):
    sim = jax.vmap(
        lambda k: mon.simulate_powerlaw_series(
            k, n, rate=3 * MM_PER_YEAR, sigma_white=2 * MM, amplitude=6 * MM / YEAR**0.25, kappa=-1.0, gap_fraction=gap
        )
    )
    y, t = sim(jax.random.split(key, B))
    return np.asarray(y), np.asarray(t[0])


def part_mc(B=500, n=3653):
    y, t = _simulate(jax.random.PRNGKey(500), B, n)
    valid = np.isfinite(y)
    D = mon.design_matrix(t)
    spec = mon.noise_spec(n)
    t0 = time.perf_counter()
    fit = mon.fit_series_batch(np.nan_to_num(y), valid, D.A, spec, np.full(B, 4 * MM), random_walk=False, chunk=250)
    jax.block_until_ready(fit)
    wall = time.perf_counter() - t0
    rate = 3 * MM_PER_YEAR
    est = np.asarray(fit.beta[:, 1]) / YEAR
    sd = np.sqrt(np.asarray(fit.beta_cov[:, 1, 1])) / YEAR
    z = (est - rate) / sd
    sdw = []
    for i in range(B):
        v = valid[i]
        A = D.A[v]
        b, res, *_ = np.linalg.lstsq(A, y[i, v], rcond=None)
        sdw.append(np.sqrt(res[0] / (v.sum() - A.shape[1]) * np.linalg.inv(A.T @ A)[1, 1]) / YEAR)
    zw = (est - rate) / np.array(sdw)
    amp = np.asarray(mon._trajectory.powerlaw_amplitude(fit.theta)) * YEAR**0.25 / MM
    return dict(
        B=B,
        n_days=n,
        wall_s=wall,
        coverage=float(np.mean(np.abs(z) <= 1.96)),
        z_std=float(np.std(z)),
        z_mean=float(np.mean(z)),
        coverage_white=float(np.mean(np.abs(zw) <= 1.96)),
        zw_std=float(np.std(zw)),
        mean_sigma=float(np.mean(sd) / MM_PER_YEAR),
        rms_error=float(np.sqrt(np.mean((est - rate) ** 2)) / MM_PER_YEAR),
        flicker_median=float(np.median(amp)),
        white_median=float(np.median(np.exp(fit.theta[:, 0])) / MM),
        at_bound=int(np.sum(np.asarray(fit.at_lower | fit.at_upper)[:, :2])),
    )


def part_batch(stations=1000, n=3653, chunk=250, hector_sample=0):
    B = 3 * stations
    y, t = _simulate(jax.random.PRNGKey(1000), B, n)
    valid = np.isfinite(y)
    D = mon.design_matrix(t)
    spec = mon.noise_spec(n)
    t0 = time.perf_counter()
    fit = mon.fit_series_batch(np.nan_to_num(y), valid, D.A, spec, np.full(B, 4 * MM), random_walk=False, chunk=chunk)
    jax.block_until_ready(fit)
    wall = time.perf_counter() - t0
    hector = []
    for i in range(hector_sample):  # estimatetrend on the first stations' three components, in its own process
        v = valid[3 * i : 3 * i + 3]
        hector.append(sum(run_hector(t[v[c]] + 10 * YEAR, y[3 * i + c, v[c]])["wall_s"] for c in range(3)))
        print(f"Hector station {i + 1}/{hector_sample}: {hector[-1]:.1f} s (load {os.getloadavg()[0]:.1f})", flush=True)
    return dict(
        stations=stations,
        series=B,
        n_days=n,
        chunk=chunk,
        wall_s=wall,
        hector_station_s=hector,
        per_station_s=wall / stations,
        grad_ok=float(np.mean(np.asarray(fit.grad_norm) < 1e-3)),
        peak_rss_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        load=os.getloadavg(),
    )


def part_stations(stations=1000, hector_sample=0, match_days=30):
    from bench_step_detection import as_series, match, run_findoffsets, station

    from jaxnav.cli.monitor import DETECT_DEFAULT

    t0 = time.perf_counter()
    sims = [station(i) for i in range(stations)]
    ser = [as_series(t, y, f"S{i:04d}") for i, (t, y, _, _) in enumerate(sims)]
    sim_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    fits = mon.fit_stations(ser, detect=DETECT_DEFAULT, progress=True)
    wall = time.perf_counter() - t0
    t0 = time.perf_counter()
    midas = [mon.midas_check(f) for f in fits]
    midas_s = time.perf_counter() - t0
    n_true = n_hit = n_false = 0
    for (t, _, days, _), f in zip(sims, fits):
        found = np.round((np.asarray(f.steps) - t[0]) / DAY).astype(int)
        hit, false = match(days, found, match_days)
        n_true += len(days)
        n_hit += len(hit)
        n_false += false
    hector = []
    for i in range(hector_sample):  # findoffsets on the station's three components, one process each
        t, y, _, _ = sims[i]
        w = 0.0
        for c in range(3):
            v = np.isfinite(y[:, c])
            w += run_findoffsets(t[v], y[v, c])[1]
        hector.append(w)
        print(
            f"Hector findoffsets station {i + 1}/{hector_sample}: {w:.1f} s (load {os.getloadavg()[0]:.1f})", flush=True
        )
    return dict(
        stations=stations,
        detect=DETECT_DEFAULT,
        simulate_s=sim_s,
        wall_s=wall,
        per_station_s=wall / stations,
        midas_s=midas_s,
        steps_true=n_true,
        steps_found=n_hit,
        false_steps=n_false,
        midas_warnings=sum(len(m[1]) for m in midas),
        hector_station_s=hector,
        peak_rss_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        load=os.getloadavg(),
    )


def _refits_child(stations, mode, path):
    """One side of ``--part refits`` (in its own process): fit_stations with warm or cold refits."""
    from bench_step_detection import as_series, match, station

    from jaxnav.cli.monitor import DETECT_DEFAULT
    from jaxnav.monitoring import _station

    if mode == "cold":
        start = _station._start
        _station.refit_iterations = lambda iterations: iterations
        _station._start = lambda scale, spec, random_walk, theta0=None: start(scale, spec, random_walk, None)
        _station._hinv_start = lambda hinv0, shape: np.full(tuple(shape) + (4, 4), np.nan)
    sims = [station(i) for i in range(stations)]
    ser = [as_series(t, y, f"S{i:04d}") for i, (t, y, _, _) in enumerate(sims)]
    t0 = time.perf_counter()
    fits = mon.fit_stations(ser, detect=DETECT_DEFAULT)
    wall = time.perf_counter() - t0
    hit = false = 0
    for (t, _, days, _), f in zip(sims, fits):
        h, nf = match(days, np.round((np.asarray(f.steps) - t[0]) / DAY).astype(int), 30)
        hit, false = hit + len(h), false + nf
    out = dict(
        mode=mode,
        wall_s=wall,
        steps_found=hit,
        false_steps=false,
        n_steps=[len(f.steps) for f in fits],
        rate=[f.velocity.tolist() for f in fits],
        rate_sigma=[f.velocity_sigma.tolist() for f in fits],
        loglik_reml=[np.asarray(f.noise.loglik_reml).tolist() for f in fits],
    )
    Path(path).write_text(json.dumps(out))


def part_refits(stations=100):
    """Warm against cold refits on the same stations, each side in a fresh process (no shared compile cache)."""
    import subprocess
    import tempfile

    res = {}
    with tempfile.TemporaryDirectory() as tmp:
        for mode in ("cold", "warm"):
            path = Path(tmp) / f"{mode}.json"
            cmd = [sys.executable, __file__, "--part", "refits-child", "--refit-mode", mode]
            subprocess.run(cmd + ["--stations", str(stations), "--json", str(path)], check=True)
            res[mode] = json.loads(path.read_text())
    c, w = res["cold"], res["warm"]
    same = np.array(c["n_steps"]) == np.array(w["n_steps"])
    sel = same & (np.array(c["n_steps"]) > 0)
    sc = np.array(c["rate_sigma"])[sel]
    d = np.abs(np.array(w["rate"])[sel] - np.array(c["rate"])[sel]) / sc
    ratio = np.array(w["rate_sigma"])[sel] / sc
    dll = np.array(w["loglik_reml"])[sel] - np.array(c["loglik_reml"])[sel]
    return dict(
        stations=stations,
        cold_s=c["wall_s"],
        warm_s=w["wall_s"],
        steps_found=(c["steps_found"], w["steps_found"]),
        false_steps=(c["false_steps"], w["false_steps"]),
        stations_same_steps=int(same.sum()),
        components_compared=int(d.size),
        rate_diff_over_sigma_max=float(d.max()) if d.size else 0.0,
        rate_diff_over_sigma_median=float(np.median(d)) if d.size else 0.0,
        sigma_ratio_range=(float(ratio.min()), float(ratio.max())) if d.size else (1.0, 1.0),
        sigma_within_1pct=int(np.sum(np.abs(ratio - 1) < 0.01)),
        loglik_reml_diff_range=(float(dll.min()), float(dll.max())) if d.size else (0.0, 0.0),
    )


def part_network(out, from_json=None):
    """jaxnav monitor (defaults) on the five real series; the monitor.json it wrote."""
    if from_json:
        return json.loads(Path(from_json).read_text())
    from jaxnav.experiments.velocities import run_monitor_velocities

    t0 = time.perf_counter()
    res = run_monitor_velocities([DATA / f for f in FILES], out, detect=5, command="bench_monitoring.py --part network")
    res["bench_wall_s"] = time.perf_counter() - t0
    return res


def network_report(res):
    """Markdown tables: steps found per station and MIDAS beside the model rate."""
    L = ["| station | step date | source | east mm | north mm | up mm | 2 ln L gain |", "|---|---|---|---|---|---|---|"]
    for name, st in res["stations"].items():
        for d in st["steps"]:
            sz, sg = d["size_mm"], d["sigma_mm"]
            L.append(
                f"| {name} | {d['date']} | {d['source']} | "
                + " | ".join(f"{sz[c]:+.1f} +- {sg[c]:.1f}" for c in mon.COMPONENTS)
                + f" | {'-' if d['gain_2lnL'] is None else format(d['gain_2lnL'], '.0f')} |"
            )
        if not st["steps"]:
            L.append(f"| {name} | none | | | | | |")
    L += [
        "",
        "| station | comp | model rate +- sigma | MIDAS rate +- sigma | difference / combined sigma | "
        "residual trend | MIDAS pairs kept |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, st in res["stations"].items():
        for c in mon.COMPONENTS:
            v, s = st["velocity_mm_per_yr"][c], st["velocity_sigma_mm_per_yr"][c]
            m, ms = st["midas_velocity_mm_per_yr"][c], st["midas_velocity_sigma_mm_per_yr"][c]
            L.append(
                f"| {name} | {c} | {v:+.2f} +- {s:.2f} | {m:+.2f} +- {ms:.2f} | "
                f"{(m - v) / np.hypot(s, ms):+.2f} | {st['residual_trend_mm_per_yr'][c]:+.2f} | "
                f"{st['midas_pairs'][c]} |"
            )
    L.append("")
    for name, st in res["stations"].items():
        for w in st["warnings"]:
            L.append(f"{name}: {w}")
    if "wall_time_s" in res:
        L.append(f"\nwall time of the monitor run: {res['wall_time_s']:.0f} s")
    return "\n".join(L)


def report(res):
    L = [f"machine: {cpu_model()}, jax {jax.__version__}, hector-ts {package_version('hector-ts')}"]
    if "real" in res:
        L += [
            "",
            "| station | comp | days | rate jaxnav | rate Hector | sigma jaxnav | sigma Hector | ratio | "
            "white-only sigma | white jaxnav / Hector (mm) | flicker jaxnav / Hector (mm/yr^0.25) | "
            "with RW: rate +- sigma, RW (mm/sqrt yr) | outliers |",
            "|" + "---|" * 13,
        ]
        for r in res["real"]["rows"]:
            L.append(
                f"| {r['station']} | {r['component']} | {r['days']} | {r['jaxnav_rate']:.3f} | "
                f"{r['hector_rate']:.3f} | {r['jaxnav_sigma']:.3f} | {r['hector_sigma']:.3f} | "
                f"{r['jaxnav_sigma'] / r['hector_sigma']:.3f} | {r['white_only_sigma']:.3f} | "
                f"{r['jaxnav_white']:.2f} / {r['hector_white']:.2f} | {r['jaxnav_flicker']:.2f} / "
                f"{r['hector_flicker']:.2f} | {r['rw_model_rate']:.2f} +- {r['rw_model_sigma']:.2f}, "
                f"{r['rw_mm_sqrt_yr']:.2f} | {r['outliers']} |"
            )
        L += ["", "| station | jaxnav s (first call) | jaxnav with RW s | Hector s (3 runs) |", "|---|---|---|---|"]
        for t in res["real"]["times"]:
            L.append(
                f"| {t['station']} | {t['jaxnav_s']:.1f} ({t['jaxnav_first_s']:.1f}) | {t['jaxnav_rw_s']:.1f} | "
                f"{t['hector_s']:.1f} |"
            )
        d = np.array([abs(r["jaxnav_rate"] - r["hector_rate"]) for r in res["real"]["rows"]])
        q = np.array([r["jaxnav_sigma"] / r["hector_sigma"] for r in res["real"]["rows"]])
        L.append(f"\nmax |rate difference| {d.max():.4f} mm/yr; sigma ratio {q.min():.3f} .. {q.max():.3f}")
    if "kappa" in res:
        L += [
            "",
            "| station | comp | rate jaxnav / Hector | sigma jaxnav / Hector | kappa jaxnav / Hector | "
            "amplitude jaxnav / Hector (mm/yr^(-kappa/4)) |",
            "|---|---|---|---|---|---|",
        ]
        for r in res["kappa"]["rows"]:
            L.append(
                f"| {r['station']} | {r['component']} | {r['jaxnav_rate']:.3f} / {r['hector_rate']:.3f} | "
                f"{r['jaxnav_sigma']:.3f} / {r['hector_sigma']:.3f} | {r['jaxnav_kappa']:.3f} / "
                f"{r['hector_kappa']:.3f} | {r['jaxnav_amp']:.2f} / {r['hector_amp']:.2f} |"
            )
        L.append(
            f"jaxnav with kappa estimated: {res['kappa']['wall_s']:.0f} s for the station (tabulating the GGM "
            f"covariance for 19 values of d and compiling included)"
        )
    if "mc" in res:
        m = res["mc"]
        L.append(
            f"\ncoverage: {m['B']} series x {m['n_days']} days: 95 % interval covers the truth in "
            f"{100 * m['coverage']:.1f} % (white-noise sigmas: {100 * m['coverage_white']:.1f} %), std of "
            f"standardised errors {m['z_std']:.3f} (white: {m['zw_std']:.2f}), mean {m['z_mean']:+.3f}; "
            f"mean sigma {m['mean_sigma']:.3f} mm/yr vs RMS error {m['rms_error']:.3f} mm/yr; median "
            f"white {m['white_median']:.2f} mm, flicker {m['flicker_median']:.2f} mm/yr^0.25; "
            f"{m['at_bound']} estimates at a bound; {m['wall_s']:.0f} s"
        )
    if "batch" in res:
        b = res["batch"]
        L.append(
            f"\nbatch: {b['stations']} stations x 3 components ({b['series']} series) x {b['n_days']} days, "
            f"chunks of {b['chunk']}: {b['wall_s']:.0f} s with compilation ({b['per_station_s']:.2f} s per "
            f"station); {100 * b['grad_ok']:.1f} % with gradient < 1e-3; peak resident memory "
            f"{b['peak_rss_mb']:.0f} MB; load average at the end {b['load'][0]:.1f}"
        )
        if b["hector_station_s"]:
            h = np.array(b["hector_station_s"])
            L.append(
                f"Hector estimatetrend, 3 components of {h.size} of these stations: {h.mean():.1f} s per station "
                f"({h.min():.1f}-{h.max():.1f}); {b['stations']} stations in turn: {h.mean() * b['stations']:.0f} s"
            )
    return "\n".join(L)


def main():
    ap = argparse.ArgumentParser()
    parts = ["real", "kappa", "mc", "batch", "stations", "refits", "refits-child", "network", "all"]
    ap.add_argument("--part", choices=parts, default="all")
    ap.add_argument("--refit-mode", choices=["cold", "warm"], help="refits-child: the side to run")
    ap.add_argument("--out", default="bench_monitor_network", help="output folder of the network part")
    ap.add_argument("--from-json", help="network part: format this monitor.json instead of running")
    ap.add_argument("--json")
    ap.add_argument("--stations", type=int, default=1000)
    ap.add_argument("--days", type=int, default=3653, help="length of the batch part's series")
    ap.add_argument("--chunk", type=int, default=250, help="series per vmap chunk in the batch part")
    ap.add_argument("--hector-sample", type=int, default=3, help="batch part: stations also run through Hector")
    a = ap.parse_args()
    res = {}
    if a.part in ("real", "all"):
        res["real"] = part_real()
    if a.part in ("kappa", "all"):
        res["kappa"] = part_kappa()
    if a.part in ("mc", "all"):
        res["mc"] = part_mc()
        print(report({"mc": res["mc"]}), flush=True)
    if a.part in ("batch", "all"):
        res["batch"] = part_batch(stations=a.stations, n=a.days, chunk=a.chunk, hector_sample=a.hector_sample)
    if a.part == "stations":
        import logging

        logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")  # fit_stations' step lines
        res["stations"] = part_stations(stations=a.stations, hector_sample=a.hector_sample)
        print(json.dumps(res["stations"], indent=1))
        if a.json:
            Path(a.json).write_text(json.dumps(res, indent=1))
        return
    if a.part == "refits-child":
        _refits_child(a.stations, a.refit_mode, a.json)
        return
    if a.part == "refits":
        res["refits"] = part_refits(stations=a.stations)
        print(json.dumps(res["refits"], indent=1))
        if a.json:
            Path(a.json).write_text(json.dumps(res, indent=1))
        return
    if a.part == "network":
        res["network"] = part_network(Path(a.out), a.from_json)
        print(network_report(res["network"]))
        return
    print(report(res))
    if a.json:
        Path(a.json).write_text(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
