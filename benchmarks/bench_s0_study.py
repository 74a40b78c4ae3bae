"""The full S0 study: three filters x 64 Monte Carlo seeds x the 2000 s INS/GPS run, timed.

A script, not a test (issue "performance": "the full S0 study (three filters x 64 seeds x 2000 s)
in under 60 s after compilation; compile under 15 s"). Runs in the main test environment:

    .venv/bin/python benchmarks/bench_s0_study.py              # refreshes RESULTS.md
    .venv/bin/python benchmarks/bench_s0_study.py --seeds 8 --no-write

The workload is what ``make demo`` computes for its table: the experiment of
``jaxnav/experiments/s0_experiment.toml`` (IMU 100 Hz, GPS 1 Hz, 18 states, the experiment's model
mismatch), the classic (b = 0), attenuated (b = 0.254) and fading filters, per-epoch navigation
state, covariances and fading factors saved, the per-run RMS and error series reduced on the
device. One compiled program (``jaxnav.filters.switch`` picks the rule by an array index; the
attenuated rule with b = 0 is the classic filter), a ``jaxnav.tune.sweep`` over the three filters x
the seeds in chunks; compile time is the sweep's AOT compilation, run time is the rest. Three
configurations in one run: the per-epoch Taylor series (default), the same with the two-speed
mechanization between fixes (``loosely_coupled(..., nav_every=10)``), and the Van Loan matrix
exponential.

``--per-seed`` instead times the cost per seed of the vmapped filter (issue "Monte Carlo at full
speed": the INS/GNSS filter over 64 seeds at most half of 64 single runs per seed): the classic
filter alone (Taylor series), the 64 seeds in chunks of ``--chunk`` against ``--singles`` seeds one
per compiled call, each side compiled once (compile time apart), simulation included on both
sides; written to its own section of RESULTS.md.
"""

from __future__ import annotations

import argparse
import datetime
import pathlib
import platform
import sys
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import jax
from _harness import cpu_model, git_revision, loadavg, write_section
from _harness import package_version as _version

import jaxnav

jaxnav.enable_x64()
jax.config.update("jax_enable_compilation_cache", False)

import jax.numpy as jnp
import numpy as np

from jaxnav import filters as jf
from jaxnav import (
    sim,
    tune,
)
from jaxnav.experiments.s0 import S0Setup, inflated_states, load_experiment, rules, s0_measurements
from jaxnav.ins import LCDiscretization, LCPropagation, LCSave, error_model_for, loosely_coupled

BEGIN, END = "<!-- BEGIN bench_s0_study -->", "<!-- END bench_s0_study -->"


PER_SEED_BEGIN, PER_SEED_END = "<!-- BEGIN bench_s0_per_seed -->", "<!-- END bench_s0_per_seed -->"


def study(exp, seeds, chunk, discretization, nav_every=1, classic_only=False):
    """Time the three filters (or the classic one) over ``seeds`` seeds; returns (mean position RMS per
    filter, timings)."""
    S = S0Setup(exp)
    states = inflated_states(exp)
    keys = jax.random.split(jax.random.PRNGKey(2019), seeds)
    save = ("nav", "covs", "factors")

    def run(key, rule):
        r = sim.simulate(S.cfg, key, trajectory=S.truth)
        return loosely_coupled(
            r.nav0,
            S.t_imu,
            r.imu.dtheta,
            r.imu.dv,
            s0_measurements(S.cfg, r.gnss, S.t_gnss),
            S.params,
            dt_imu=S.cfg.dt,
            error_model=error_model_for(exp["filter"]["n_states"]),
            inflation=rule,
            save=LCSave(save),
            discretization=LCDiscretization(discretization),
            propagation=LCPropagation(nav_every=nav_every),
        )

    def summary(res):
        pe, ve = S.errors(res)
        cov = res.epochs.covs
        return dict(
            rms=jnp.sqrt(jnp.mean(pe**2, 0)),
            pos_err=pe,
            vel_err=ve,
            sig=jnp.sqrt(jnp.diagonal(cov, axis1=1, axis2=2)),
            factors=res.epochs.factors,
        )

    def one(p, k):  # rule 0: attenuated (b = 0: classic), 1: fading; one program for all three
        rule = jf.switch(p["rule"], [jf.attenuated(p["b"], states=states), rules(exp)["fading"]])
        return summary(run(k, rule))

    grid = {"b": np.asarray([0.0, exp["filter"]["b"], 0.0]), "rule": np.asarray([0.0, 0.0, 1.0])}
    if classic_only:
        grid = {k: v[:1] for k, v in grid.items()}
    sw = tune.sweep(one, grid, keys, chunk=chunk, progress=False)
    names = ("classic", "attenuated", "fading")[: len(grid["b"])]
    rms = {n: sw.values["rms"][i] for i, n in enumerate(names)}
    t = dict(compile=sw.compile_time_s, run=sw.wall_time_s - sw.compile_time_s)
    return {k: float(np.mean(v)) for k, v in rms.items()}, t


def per_seed(exp, seeds, chunk, singles, write):
    """Run cost per seed: ``seeds`` seeds vmapped in chunks of ``chunk`` against ``singles`` seeds one by one."""
    load0 = loadavg()
    _, tb = study(exp, seeds, chunk, "taylor", classic_only=True)
    _, t1 = study(exp, singles, 1, "taylor", classic_only=True)
    b, one = tb["run"] / seeds, t1["run"] / singles
    print(
        f"vmapped: {b * 1e3:.0f} ms per seed ({seeds} seeds, chunks of {chunk}; compile {tb['compile']:.1f} s); "
        f"single: {one * 1e3:.0f} ms per seed ({singles} runs; compile {t1['compile']:.1f} s); ratio {b / one:.2f}",
        flush=True,
    )
    if not write:
        return
    when = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
    lines = [
        "## Cost per seed of the vmapped INS/GNSS filter (`benchmarks/bench_s0_study.py --per-seed`)",
        "",
        f"{when}, {cpu_model()}, {jax.device_count()} device(s) `{jax.devices()[0].platform}`, jax "
        f"{_version('jax')}, jaxnav {git_revision()}; load average {load0} at the start, {loadavg()} at the end.",
        "",
        "The S0 experiment's classic filter (18 states, Taylor series, 2000 s: 200 000 IMU samples, 2000 GPS "
        "fixes; navigation, covariances and factors saved; the run's simulation included), one compiled "
        "program per side.",
        "",
        "| how | seeds | compile | run | per seed | against single |",
        "|---|---|---|---|---|---|",
        f"| vmapped, chunks of {chunk} | {seeds} | {tb['compile']:.1f} s | {tb['run']:.1f} s | {b * 1e3:.0f} ms | "
        f"{b / one:.2f}x |",
        f"| single (chunk 1) | {singles} | {t1['compile']:.1f} s | {t1['run']:.1f} s | {one * 1e3:.0f} ms | 1 |",
    ]
    write_section(pathlib.Path(__file__).with_name("RESULTS.md"), "\n".join(lines), PER_SEED_BEGIN, PER_SEED_END)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", type=int, default=64)
    p.add_argument("--chunk", type=int, default=16, help="runs per compiled call (default 16)")
    p.add_argument("--per-seed", action="store_true", help="only the cost per seed, vmapped against single runs")
    p.add_argument("--singles", type=int, default=8, help="--per-seed: single runs timed")
    p.add_argument("--no-write", action="store_true")
    a = p.parse_args(argv)
    exp = load_experiment()
    if a.per_seed:
        per_seed(exp, a.seeds, a.chunk, a.singles, not a.no_write)
        return 0
    load0 = loadavg()
    t_all = time.perf_counter()
    rows = []
    for disc, k in (("taylor", 1), ("taylor", 10), ("van_loan", 1)):
        rms, t = study(exp, a.seeds, a.chunk, disc, k)
        disc = disc if k == 1 else f"{disc}, nav_every={k}"
        rows.append((disc, rms, t))
        print(
            f"{disc:9s}: compile {t['compile']:.1f} s, run {t['run']:.1f} s; mean position RMS "
            + ", ".join(f"{k} {v:.3f} m" for k, v in rms.items()),
            flush=True,
        )
    wall = time.perf_counter() - t_all
    if a.no_write:
        return 0
    when = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
    lines = [
        "## The full S0 study (`benchmarks/bench_s0_study.py`)",
        "",
        f"{when}, {cpu_model()}, {jax.device_count()} device(s) `{jax.devices()[0].platform}`, Python "
        f"{platform.python_version()}, jax {_version('jax')}, jaxnav {git_revision()}; load average {load0} at "
        f"the start; whole script {wall:.0f} s.",
        "",
        f"Three filters (classic, attenuated b = {exp['filter']['b']}, fading) x {a.seeds} seeds x 2000 s "
        f"(200 000 IMU samples, 2000 GPS fixes each), per-epoch navigation, covariances and factors saved; "
        f"one compiled program (`jaxnav.filters.switch` picks the rule), chunks of {a.chunk} runs. "
        "Targets: run < 60 s, compile < 15 s.",
        "",
        "| per-epoch discretisation (mechanization) | compile | run | runs per second | mean position RMS "
        "classic / attenuated "
        "/ fading (m) |",
        "|---|---|---|---|---|",
        *[
            f"| {d} | {t['compile']:.1f} s | {t['run']:.1f} s | {3 * a.seeds / t['run']:.1f} | "
            f"{r['classic']:.3f} / {r['attenuated']:.3f} / {r['fading']:.3f} |"
            for d, r, t in rows
        ],
    ]
    write_section(pathlib.Path(__file__).with_name("RESULTS.md"), "\n".join(lines), BEGIN, END)
    return 0


if __name__ == "__main__":
    sys.exit(main())
