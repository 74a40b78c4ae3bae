"""Step detection on simulated ten-year stations: jaxnav's BIC search beside Hector's ``findoffsets``.

A script, not a test (hours of CPU for the full 200 stations on a small machine). Each part appends
one JSON line per station to ``OUT/<part>.jsonl`` and skips stations already there, so a run can be
stopped and resumed, or split over processes with ``--start``/``--stop``:

    .venv/bin/python benchmarks/bench_step_detection.py --part jaxnav --out bench_steps
    .venv/bin/python benchmarks/bench_step_detection.py --part hector --out bench_steps --workers 2
    .venv/bin/python benchmarks/bench_step_detection.py --part post --out bench_steps --stations 10
    .venv/bin/python benchmarks/bench_step_detection.py --part report --out bench_steps

**Simulation** (fixed seeds, station ``i`` from seed ``i``): 3653 days (ten years), east, north and
up each rate + white noise (2 mm) + flicker noise (6 mm/yr^0.25, Williams' power law started at the
first day, :func:`jaxnav.monitoring.simulate_powerlaw_series`), 5 % of days missing at random.
Station ``i`` has ``i % 5`` steps (0-4) in the up component only (an antenna change shows mostly in
height), at random days at least 90 days apart and 60 days from either end, each of a size drawn
uniformly from 1 to 10 white-noise sigmas (2-20 mm) with a random sign.

**jaxnav**: :func:`jaxnav.monitoring.fit_station` with the simulated noise model (white + flicker,
no random walk, REML) and ``detect=8``: steps added one at a time while the likelihood gain of the
best epoch, summed over the three components, beats the BIC penalty 4 ln(n) (about 37 here).
**Hector** (its own process per series): ``findoffsets`` on the up component, ``NoiseModels
FlickerGGM White``, RMLE, annual + semi-annual terms, its default ``OffsetThreshold`` 20
(Delta ln L, i.e. 40 in 2 Delta ln L), ``MaxOffsets`` 8. jaxnav sees all three components (and pays
for three step sizes in its penalty); Hector sees the up component, the only one with steps.

A true step counts as found when a detected step lies within ``--match-days`` (default 30) days of
it (each detection matched once, nearest first); other detections are false steps.

**Post-seismic part** (``--part post``): ten-year stations with an earthquake at a random day in the
middle third: a coseismic step of 5 white sigmas in each component and a logarithmic transient
a ln(1 + dt / tau) with amplitudes of 5-15 white sigmas (random signs) and tau from 20 to 200 days;
fitted with the step and the transient given and tau estimated (``postseismic=[(t_eq, "log",
None)]``): each amplitude within 10 % of the truth, each rate within its sigma.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from jaxnav import io
from jaxnav import monitoring as mon
from jaxnav.units import DAY, MM, MM_PER_YEAR, YEAR

N_DAYS = 3653
WHITE = 2.0 * MM
FLICKER = 6.0 * MM / YEAR**0.25
GAPS = 0.05
RATES = np.array([3.0, -2.0, 1.0])  # mm/yr
T0 = 10 * YEAR  # first day, s since J2000 (2010)
MJD_J2000 = 51544.5
SIZE_BINS = (1.0, 2.0, 3.0, 4.0, 6.0, 10.0)


def _noise(seed, n=N_DAYS):
    """(n, 3) m: rate + white + flicker, 5 % gaps (NaN); component c from key (seed, c)."""
    cols = [
        np.asarray(
            mon.simulate_powerlaw_series(
                jax.random.fold_in(jax.random.PRNGKey(seed), c),
                n,
                rate=RATES[c] * MM_PER_YEAR,
                sigma_white=WHITE,
                amplitude=FLICKER,
                gap_fraction=GAPS,
            )[0]
        )
        for c in range(3)
    ]
    return np.stack(cols, axis=1)


def steps_of(i, n=N_DAYS):
    """(first day index of each step, size in white sigmas with sign) of station i, sorted by day."""
    rng = np.random.default_rng(10_000 + i)
    k = i % 5
    days = []
    while len(days) < k:
        d = int(rng.integers(60, n - 60))
        if all(abs(d - e) >= 90 for e in days):
            days.append(d)
    sizes = rng.uniform(1.0, 10.0, k) * rng.choice([-1.0, 1.0], k)
    o = np.argsort(days)
    return np.array(days, int)[o], sizes[o]


def station(i):
    """Simulated station i: (t (n,) s since J2000, y (n, 3) m, step days, step sizes in white sigmas)."""
    t = T0 + np.arange(N_DAYS) * DAY
    y = _noise(i)
    days, sizes = steps_of(i)
    for d, s in zip(days, sizes):
        y[d:, 2] += s * WHITE
    return t, y, days, sizes


def as_series(t, y, name):
    n = len(t)
    return io.DailySeries(
        station=name,
        path="simulated",
        fmt="tenv3",
        t=t,
        year=2000.0 + t / YEAR,
        enu=y,
        cov=np.tile(np.eye(3) * WHITE**2, (n, 1, 1)),
        origin=np.zeros(3),
        llh=np.full((n, 3), np.nan),
        n_masked=int(np.isnan(y).sum()),
    )


def _done(path):
    if not path.exists():
        return set()
    return {json.loads(line)["station"] for line in path.read_text().splitlines() if line.strip()}


def part_jaxnav(out, start, stop, detect=8, block=100):
    """jaxnav's detection on stations start..stop, ``block`` stations per :func:`jaxnav.monitoring.fit_stations`
    call (batched fits); ``wall_s`` of a station is its block's wall time over the block's size."""
    path = out / "jaxnav.jsonl"
    done = _done(path)
    todo = [i for i in range(start, stop) if i not in done]
    t_all = time.perf_counter()
    for b0 in range(0, len(todo), block):
        ids = todo[b0 : b0 + block]
        sims = [station(i) for i in ids]
        t0 = time.perf_counter()
        fits = mon.fit_stations(
            [as_series(t, y, f"S{i:03d}") for i, (t, y, _, _) in zip(ids, sims)],
            detect=detect,
            random_walk=False,
            progress=True,
        )
        wall = (time.perf_counter() - t0) / len(ids)
        with path.open("a") as f:
            for i, (t, _y, days, sizes), fit in zip(ids, sims, fits):
                found = np.round((np.asarray(fit.steps) - t[0]) / DAY).astype(int).tolist()
                rec = dict(
                    station=i,
                    true_days=days.tolist(),
                    true_sizes=sizes.tolist(),
                    found_days=found,
                    found_up_mm=(fit.step_sizes[2] / MM).tolist(),
                    gains=np.asarray(fit.step_gains).tolist(),
                    wall_s=wall,
                    load=os.getloadavg()[0],
                )
                f.write(json.dumps(rec) + "\n")
        el = time.perf_counter() - t_all
        print(
            f"jaxnav stations {ids[0]}-{ids[-1]} ({b0 + len(ids)}/{len(todo)}): {wall:.1f} s per station "
            f"(elapsed {el:.0f} s, load {os.getloadavg()[0]:.1f})",
            flush=True,
        )


def _findoffsets_exe():
    cand = Path(sys.executable).parent / "findoffsets"
    return str(cand) if cand.exists() else shutil.which("findoffsets")


def run_findoffsets(t, x, *, threshold=20.0, max_offsets=8, timeout=900):
    """Hector's findoffsets on one component (t s since J2000 of valid days, x m); (day MJDs found, wall s)."""
    exe = _findoffsets_exe()
    if exe is None:
        raise RuntimeError("hector-ts is not installed (pip install hector-ts)")
    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        (d / "pre").mkdir()
        mjd = np.asarray(t) / DAY + MJD_J2000
        (d / "pre/S.mom").write_text(
            "# sampling period 1.0\n" + "".join(f"{m:.4f} {v * 1e3:.6f}\n" for m, v in zip(mjd, x))
        )
        (d / "findoffsets.ctl").write_text(
            "DataFile S.mom\nDataDirectory pre\nOutputFile out.mom\ninterpolate no\nPhysicalUnit mm\n"
            "TimeUnit days\nScaleFactor 1.0\nperiodicsignals 365.25 182.625\nestimateoffsets yes\n"
            f"NoiseModels FlickerGGM White\nGGM_1mphi 6.9e-06\nuseRMLE yes\nOffsetThreshold {threshold}\n"
            f"MaxOffsets {max_offsets}\nVerbose no\n"
        )
        t0 = time.perf_counter()
        r = subprocess.run([exe, "-i", "findoffsets.ctl"], cwd=d, capture_output=True, text=True, timeout=timeout)
        wall = time.perf_counter() - t0
        if r.returncode != 0 or not (d / "findoffsets.json").exists():
            raise RuntimeError(f"findoffsets failed ({r.returncode}): {r.stderr[-2000:]}{r.stdout[-2000:]}")
        return json.loads((d / "findoffsets.json").read_text())["offsets"], wall


def part_hector(out, start, stop, workers=1):
    path = out / "hector.jsonl"
    done = _done(path)
    todo = [i for i in range(start, stop) if i not in done]
    t_all = time.perf_counter()

    def one(i):
        t, y, days, sizes = station(i)
        v = np.isfinite(y[:, 2])
        mjds, wall = run_findoffsets(t[v], y[v, 2])
        found = sorted(int(round(m - (t[0] / DAY + MJD_J2000))) for m in mjds)
        return dict(
            station=i,
            true_days=days.tolist(),
            true_sizes=sizes.tolist(),
            found_days=found,
            wall_s=wall,
            load=os.getloadavg()[0],
        )

    with ThreadPoolExecutor(max_workers=workers) as ex:
        for k, rec in enumerate(ex.map(one, todo)):
            with path.open("a") as f:
                f.write(json.dumps(rec) + "\n")
            print(
                f"hector {k + 1}/{len(todo)} station {rec['station']}: {len(rec['true_days'])} true, found "
                f"{len(rec['found_days'])} in {rec['wall_s']:.1f} s (elapsed {time.perf_counter() - t_all:.0f} s, "
                f"load {rec['load']:.1f})",
                flush=True,
            )


def part_post(out, start, stop):
    path = out / "post.jsonl"
    done = _done(path)
    for i in [i for i in range(start, stop) if i not in done]:
        rng = np.random.default_rng(20_000 + i)
        t = T0 + np.arange(N_DAYS) * DAY
        d = int(rng.integers(N_DAYS // 3, 2 * N_DAYS // 3))
        te = t[d] - 0.5 * DAY
        tau = float(rng.uniform(20.0, 200.0)) * DAY
        amp = rng.uniform(5.0, 15.0, 3) * rng.choice([-1.0, 1.0], 3) * WHITE
        y = (
            _noise(50_000 + i)
            + 5.0 * WHITE * (t >= te)[:, None]
            + amp * np.asarray(mon.postseismic_column(t, te, "log", tau))[:, None]
        )
        t0 = time.perf_counter()
        fit = mon.fit_station(
            as_series(t, y, f"P{i:03d}"), steps=[te], postseismic=[(te, "log", None)], random_walk=False
        )
        wall = time.perf_counter() - t0
        (p,) = fit.postseismic
        v, sd = fit.velocity / MM_PER_YEAR, fit.velocity_sigma / MM_PER_YEAR
        rec = dict(
            station=i,
            tau_days=tau / DAY,
            tau_est_days=p.tau / DAY,
            tau_range_days=(p.tau_range / DAY).tolist(),
            amp_mm=(amp / MM).tolist(),
            amp_est_mm=(p.amplitude / MM).tolist(),
            amp_sigma_mm=(p.amplitude_sigma / MM).tolist(),
            rate=RATES.tolist(),
            rate_est=v.tolist(),
            rate_sigma=sd.tolist(),
            wall_s=wall,
            load=os.getloadavg()[0],
        )
        with path.open("a") as f:
            f.write(json.dumps(rec) + "\n")
        print(
            f"post {i}: tau {tau / DAY:.0f} d -> {p.tau / DAY:.0f} d, amplitude error "
            f"{np.max(np.abs(p.amplitude / amp - 1)) * 100:.1f} %, rate errors / sigma "
            f"{np.round(np.abs(v - RATES) / sd, 2).tolist()} ({wall:.0f} s)",
            flush=True,
        )


def match(true_days, found_days, tol):
    """Greedy nearest matching: ({true index: day error}, number of unmatched detections)."""
    pairs = sorted((abs(f - d), a, b) for a, d in enumerate(true_days) for b, f in enumerate(found_days))
    used_t, used_f, err = set(), set(), {}
    for dist, a, b in pairs:
        if dist <= tol and a not in used_t and b not in used_f:
            used_t.add(a)
            used_f.add(b)
            err[a] = found_days[b] - true_days[a]
    return err, len(found_days) - len(used_f)


def summarise(recs, tol):
    bins = SIZE_BINS
    hit = np.zeros(len(bins) - 1)
    tot = np.zeros(len(bins) - 1)
    errs, false = [], []
    for r in recs:
        err, nf = match(r["true_days"], r["found_days"], tol)
        false.append(nf)
        for a, s in enumerate(r["true_sizes"]):
            b = min(np.searchsorted(bins, abs(s), side="right") - 1, len(bins) - 2)
            tot[b] += 1
            if a in err:
                hit[b] += 1
                errs.append(abs(err[a]))
    errs = np.array(errs, float)
    false = np.array(false)
    no_step = np.array([len(r["true_days"]) == 0 for r in recs])
    return dict(
        n=len(recs),
        hit=hit,
        tot=tot,
        false_mean=float(false.mean()) if len(false) else np.nan,
        false_no_step=float(false[no_step].mean()) if no_step.any() else np.nan,
        series_with_false=int(np.sum(false > 0)),
        err_median=float(np.median(errs)) if errs.size else np.nan,
        err_0=float(np.mean(errs == 0)) if errs.size else np.nan,
        err_le3=float(np.mean(errs <= 3)) if errs.size else np.nan,
        err_p90=float(np.percentile(errs, 90)) if errs.size else np.nan,
        wall=float(np.mean([r["wall_s"] for r in recs])) if recs else np.nan,
        load=(float(min(r["load"] for r in recs)), float(max(r["load"] for r in recs))) if recs else (0, 0),
    )


def report(out, tol):
    L = []
    res = {}
    for name in ("jaxnav", "hector"):
        p = out / f"{name}.jsonl"
        if p.exists():
            res[name] = [json.loads(x) for x in p.read_text().splitlines() if x.strip()]
    if "jaxnav" in res and "hector" in res:  # compare on the stations both have
        common = {r["station"] for r in res["jaxnav"]} & {r["station"] for r in res["hector"]}
        sets = [(f"{k} (stations both ran)", [r for r in res[k] if r["station"] in common]) for k in res]
        sets += [(f"{k} (all its stations)", res[k]) for k in res if len(res[k]) > len(common)]
    else:
        sets = [(k, v) for k, v in res.items()]
    if sets:
        labels = [f"{a:g}-{b:g}" for a, b in zip(SIZE_BINS[:-1], SIZE_BINS[1:])]
        L += [
            "| program | stations | "
            + " | ".join(f"found, {x} sigma" for x in labels)
            + " | false steps per station (stations with none true) | stations with a false step | "
            "date error median / share 0 d / <= 3 d / 90th pct (d) | s per station (load) |",
            "|---|---|" + "---|" * len(labels) + "---|---|---|---|",
        ]
        for name, recs in sets:
            s = summarise(recs, tol)
            cells = " | ".join(
                f"{100 * h / t:.0f} % ({int(h)}/{int(t)})" if t else "-" for h, t in zip(s["hit"], s["tot"])
            )
            L.append(
                f"| {name} | {s['n']} | {cells} | {s['false_mean']:.2f} ({s['false_no_step']:.2f}) | "
                f"{s['series_with_false']} | {s['err_median']:.0f} / {100 * s['err_0']:.0f} % / "
                f"{100 * s['err_le3']:.0f} % / {s['err_p90']:.0f} | {s['wall']:.1f} "
                f"({s['load'][0]:.1f}-{s['load'][1]:.1f}) |"
            )
    p = out / "post.jsonl"
    if p.exists():
        recs = [json.loads(x) for x in p.read_text().splitlines() if x.strip()]
        ok_amp = [np.all(np.abs(np.array(r["amp_est_mm"]) / np.array(r["amp_mm"]) - 1) <= 0.10) for r in recs]
        ok_rate = [
            np.all(np.abs(np.array(r["rate_est"]) - np.array(r["rate"])) <= np.array(r["rate_sigma"])) for r in recs
        ]
        ok_tau = [r["tau_range_days"][0] <= r["tau_days"] <= r["tau_range_days"][1] for r in recs]
        worst = max(float(np.max(np.abs(np.array(r["amp_est_mm"]) / np.array(r["amp_mm"]) - 1))) for r in recs)
        L.append(
            f"\npost-seismic log transient, {len(recs)} ten-year stations: amplitudes within 10 % in "
            f"{sum(ok_amp)}/{len(recs)} (worst {100 * worst:.1f} %), all three rates within 1 sigma in "
            f"{sum(ok_rate)}/{len(recs)}, tau interval covers the truth in {sum(ok_tau)}/{len(recs)}; "
            f"{np.mean([r['wall_s'] for r in recs]):.0f} s per station"
        )
        zr = np.concatenate([(np.array(r["rate_est"]) - np.array(r["rate"])) / np.array(r["rate_sigma"]) for r in recs])
        za = np.concatenate(
            [(np.array(r["amp_est_mm"]) - np.array(r["amp_mm"])) / np.array(r["amp_sigma_mm"]) for r in recs]
        )
        L.append(
            f"standardised errors over the {zr.size} components: rates RMS {np.sqrt(np.mean(zr**2)):.2f}, "
            f"within 1 sigma {100 * np.mean(np.abs(zr) <= 1):.0f} % (68 % expected); amplitudes RMS "
            f"{np.sqrt(np.mean(za**2)):.2f}, within 1 sigma {100 * np.mean(np.abs(za) <= 1):.0f} %"
        )
        for r in recs:
            L.append(
                f"  P{r['station']:03d}: tau {r['tau_days']:.0f} -> {r['tau_est_days']:.0f} d "
                f"[{r['tau_range_days'][0]:.0f}, {r['tau_range_days'][1]:.0f}], amplitude mm "
                + ", ".join(
                    f"{a:+.1f} -> {b:+.1f} +- {c:.1f}"
                    for a, b, c in zip(r["amp_mm"], r["amp_est_mm"], r["amp_sigma_mm"])
                )
                + ", rate error / sigma "
                + ", ".join(f"{abs(a - b) / c:.2f}" for a, b, c in zip(r["rate_est"], r["rate"], r["rate_sigma"]))
            )
    return "\n".join(L)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", choices=["jaxnav", "hector", "post", "report"], default="report")
    ap.add_argument("--out", default="bench_steps", help="folder of the per-station JSON lines")
    ap.add_argument("--start", type=int, default=0)
    ap.add_argument("--stop", type=int, default=None, help="default 200 (10 for --part post)")
    ap.add_argument("--workers", type=int, default=1, help="findoffsets processes at once (at most 2)")
    ap.add_argument("--match-days", type=int, default=30)
    a = ap.parse_args()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    stop = a.stop if a.stop is not None else (10 if a.part == "post" else 200)
    if a.part == "jaxnav":
        part_jaxnav(out, a.start, stop)
    elif a.part == "hector":
        part_hector(out, a.start, stop, workers=min(max(a.workers, 1), 2))
    elif a.part == "post":
        part_post(out, a.start, stop)
    print(report(out, a.match_days))


if __name__ == "__main__":
    main()
