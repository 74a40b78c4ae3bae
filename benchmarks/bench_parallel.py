"""Parallel-in-time (associative-scan) filter and smoother vs the sequential scan, and cost growth.

A script, not a test. From the repository root:

    .venv-bench/bin/python benchmarks/bench_parallel.py            # full run, rewrites its RESULTS.md section
    .venv-bench/bin/python benchmarks/bench_parallel.py --quick    # smoke run, writes nothing

Problem: the constant-velocity model of bench_filters.py (n = 6, m = 3, dt = 1 s, 3 mm noise),
one sequence of T epochs, float64. For T = 3600 (an hour at 1 Hz), 86 400 (a day) and 864 000
(ten days): jaxnav's sequential ``kalman_filter`` (+ ``rts_smoother``) and its
``parallel_filter`` (+ ``parallel_smoother``) with the default blocked schedule, and the
``lax.associative_scan`` ("tree") schedule where its compile time is bearable. Then the cost
growth of the sequential filter: time against T (single sequence) and against the batch size
B under ``vmap`` (T = 3600), with least-squares slopes.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from _harness import device_banner, matmul_rate, time_jit, write_section
from bench_filters import simulate  # the same problem and data generator as bench_filters

import jaxnav

jaxnav.enable_x64()
jax.config.update("jax_enable_compilation_cache", False)

from jaxnav import filters as jf

HERE = Path(__file__).resolve().parent
BEGIN = "<!-- BEGIN bench_parallel results (generated; rerun the script to refresh) -->"
END = "<!-- END bench_parallel results -->"
SAVE_RTS = ("means", "covs", "pred_means", "pred_covs")


def _fmt(s):
    if s >= 1.0:
        return f"{s:.2f} s"
    if s >= 1e-3:
        return f"{s * 1e3:.1f} ms"
    return f"{s * 1e6:.0f} µs"


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--Ts", default="3600,86400,864000", help="series lengths")
    p.add_argument("--tree-max-T", type=int, default=86400, help="largest T for the tree schedule")
    p.add_argument("--batches", default="16,64,256", help="batch sizes for the growth in B (T = 3600)")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--quick", action="store_true", help="T = 300, 3000; batches 4, 16; writes nothing")
    p.add_argument("--no-write", action="store_true")
    args = p.parse_args(argv)
    Ts = [int(t) for t in args.Ts.split(",")]
    batches = [int(b) for b in args.batches.split(",")]
    if args.quick:
        Ts, batches, args.repeats, args.tree_max_T = [300, 3000], [4, 16], 2, 300
    t_start = time.perf_counter()
    log = lambda s: print(f"[{time.perf_counter() - t_start:6.1f} s] {s}", file=sys.stderr, flush=True)

    banner = device_banner()
    rate0 = matmul_rate()
    model = jf.constant_velocity(1.0, sigma=0.003, q=1e-6)
    x0 = jnp.zeros(6)
    P0 = jnp.diag(jnp.array([1.0] * 3 + [0.01] * 3))

    seq_f = jax.jit(lambda z: jf.kalman_filter(model, x0, P0, z, save=("means",)).means)
    par_f = jax.jit(lambda z: jf.parallel_filter(model, x0, P0, z, save=("means",)).means)
    tree_f = jax.jit(lambda z: jf.parallel_filter(model, x0, P0, z, save=("means",), method="tree").means)
    seq_s = jax.jit(
        lambda z: jf.rts_smoother(model, jf.kalman_filter(model, x0, P0, z, save=SAVE_RTS), save=("means",)).means
    )
    par_s = jax.jit(
        lambda z: (
            jf.parallel_smoother(model, jf.parallel_filter(model, x0, P0, z, save=SAVE_RTS), save=("means",)).means
        )
    )
    rows, seq_single = [], []
    for T in Ts:
        z = jnp.asarray(simulate(T, 1)[0])
        reps = args.repeats if T <= 100_000 else max(2, args.repeats // 2)
        res = {}
        cases = [("filter", "sequential", seq_f), ("filter", "parallel (blocked)", par_f)]
        if T <= args.tree_max_T:
            cases.append(("filter", "parallel (tree)", tree_f))
        cases += [("filter + RTS", "sequential", seq_s), ("filter + RTS", "parallel (blocked)", par_s)]
        for what, name, fn in cases:
            log(f"T={T} {what} {name}")
            tm, out = time_jit(fn, (z,), reps)
            res[(what, name)] = (tm, np.asarray(out))
        for (what, name), (tm, out) in res.items():
            ref = res[(what, "sequential")]
            d = float(np.max(np.abs(out - ref[1])))
            rows.append((T, what, name, tm, ref[0].min / tm.min, d))
            if what == "filter" and name == "sequential":
                seq_single.append((T, tm.min))

    log("growth in B")
    TB = 3600
    zB = jnp.asarray(simulate(TB, max(batches)))
    grow_B = []
    fb = jax.jit(jax.vmap(lambda z: jf.kalman_filter(model, x0, P0, z, save=("means",), check_finite=False).means))
    fbm = jax.jit(jax.vmap(lambda z: jf.kalman_filter(model, x0, P0, z, save=("means",)).means))
    fbb = jax.jit(lambda z: jf.kalman_filter_batch(model, x0, P0, z, save=("means",)).means)
    for B in batches:
        t1, _ = time_jit(fbb, (zB[:B],), max(3, args.repeats // 2))  # the batch entry point: shared P
        t2, _ = time_jit(fbm, (zB[:B],), 2)  # vmap with NaN masking: P per sequence
        t0, _ = time_jit(fb, (zB[:B],), max(3, args.repeats // 2))  # vmap, data trusted: vmap shares P
        grow_B.append((B, t1.min, t2.min, t0.min))
    rate1 = matmul_rate()
    rate = max(rate0, rate1)

    out = [
        f"Generated by `benchmarks/bench_parallel.py{' ' + ' '.join(sys.argv[1:]) if sys.argv[1:] else ''}`.",
        "",
        banner,
        f"| dense float64 matmul 1024² (jnp) | {rate:.1f} GFLOP/s (best of start and end of run) |",
        f"| total wall time | {time.perf_counter() - t_start:.0f} s |",
        "",
        "### Parallel (associative scan) vs sequential scan, one sequence",
        "",
        "`parallel (blocked)`: the default two-level blocked schedule of the associative operator "
        "(chunks of round(√T) scanned side by side, then the chunk totals); `parallel (tree)`: "
        "`lax.associative_scan`, O(log T) depth. Times are min of the repeats; compile is the AOT "
        "trace + lower + compile. Speed-up = sequential / this (> 1: faster than the sequential scan).",
        "",
        "| T | case | implementation | compile | run min | run median | per epoch | speed-up vs sequential "
        "| max abs Δ means vs sequential (m) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for T, what, name, tm, sp, d in rows:
        out.append(
            f"| {T} | {what} | {name} | {_fmt(tm.compile_s)} | {_fmt(tm.min)} | {_fmt(tm.median)} | "
            f"{tm.min / T * 1e9:.0f} ns | {sp:.2f} | {d:.1e} |"
        )
    out += ["", "### Cost growth of the sequential filter", ""]
    if len(seq_single) >= 2:
        Tv = np.array([t for t, _ in seq_single], float)
        tv = np.array([s for _, s in seq_single])
        slope, icpt = np.polyfit(Tv, tv, 1)
        out.append(
            f"Single sequence: least-squares time = {slope * 1e9:.0f} ns × T + {icpt * 1e3:.1f} ms over "
            f"T = {', '.join(str(int(t)) for t in Tv)}; per-epoch time at each T: "
            + ", ".join(f"{s / t * 1e9:.0f} ns" for t, s in seq_single)
            + "."
        )
    Bv = np.array([g[0] for g in grow_B], float)
    t1 = np.array([g[1] for g in grow_B])
    t2 = np.array([g[2] for g in grow_B])
    s1, i1 = np.polyfit(Bv, t1, 1)
    s2, i2 = np.polyfit(Bv, t2, 1)
    out += [
        "",
        "Batches, T = 3600 (run min): `kalman_filter_batch` runs one shared covariance recursion and the "
        "means in blocks; `jax.vmap(kalman_filter)` with NaN masking (the default) gives every sequence its "
        "own covariance recursion; with `check_finite=False` nothing in it depends on the batched data and "
        "`vmap` runs it once.",
        "",
        "| B | kalman_filter_batch (shared covariance recursion) | vmap(kalman_filter) (per-sequence covariances) "
        "| vmap(kalman_filter, check_finite=False) |",
        "|---|---|---|---|",
    ]
    for B, a, c, d in grow_B:
        out.append(
            f"| {B} | {_fmt(a)} ({a / (B * TB) * 1e9:.0f} ns per sequence-step) | "
            f"{_fmt(c)} ({c / (B * TB) * 1e9:.0f} ns per sequence-step) | {_fmt(d)} |"
        )
    out += [
        "",
        f"Least-squares slopes: {s1 * 1e3:.3f} ms per sequence (+ {i1 * 1e3:.1f} ms) shared; "
        f"{s2 * 1e3:.3f} ms per sequence (+ {i2 * 1e3:.1f} ms) per-sequence covariances.",
    ]
    report = "\n".join(out)
    print(report)
    if not (args.quick or args.no_write):
        write_section(HERE / "RESULTS.md", report, BEGIN, END)
        log("wrote RESULTS.md")
    return 0


if __name__ == "__main__":
    sys.exit(main())
