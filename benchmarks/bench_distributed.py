"""Scaling of a Monte Carlo study over processes (``jax.distributed``) on this machine, and what
1000 Monte Carlo runs of the full S0 study would cost on N hosts.

A script, not a test. From the repository root:

    .venv/bin/python benchmarks/bench_distributed.py                    # appends/refreshes its RESULTS.md section
    .venv/bin/python benchmarks/bench_distributed.py --seeds 2 --no-write

Workload: the program of ``jaxnav demo`` (S0, three filters picked by ``jaxnav.filters.switch``,
per-epoch navigation errors, 1-sigma bands and factors saved) as a ``jaxnav.tune.sweep`` over
3 filters x SEEDS seeds of the first DURATION s of the S0 timeline, in one chunk. Three layouts,
each in fresh processes (the device count is fixed when JAX starts): 1 process x 1 device,
1 process x 2 devices (``--xla_force_host_platform_device_count=2``), 2 processes x 1 device
(two processes joined by ``jaxnav.tune.initialize`` on 127.0.0.1, gloo collectives). Compile time
is the sweep's first call; run time is the median of REPEATS further calls of the compiled
program (host placement, compute, all-gather, transfer to numpy). The per-run output size is
measured on the results; it sets the all-gather volume.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import pathlib
import platform
import socket
import subprocess
import sys
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from _harness import cpu_model, git_revision, write_section
from _harness import package_version as _version

BEGIN, END = "<!-- BEGIN bench_distributed -->", "<!-- END bench_distributed -->"
LAYOUTS = ((1, 1), (1, 2), (2, 1))  # (processes, devices per process)


def worker(a):
    """One process of one layout: time the study; process 0 prints a JSON line."""
    import jax

    import jaxnav

    jaxnav.enable_x64()
    jax.config.update("jax_enable_compilation_cache", False)
    import jax.numpy as jnp
    import numpy as np

    from jaxnav import filters as jf
    from jaxnav import tune
    from jaxnav.experiments.s0 import S0Setup, inflated_states, load_experiment, rules
    from jaxnav.geodesy import curvilinear_to_enu
    from jaxnav.ins import error_model_for

    if a.processes > 1:
        tune.initialize(f"127.0.0.1:{a.port}", a.processes, a.process_id, timeout_s=120)
    exp = load_experiment()
    S = S0Setup(exp, duration=a.duration)
    states = inflated_states(exp)
    fading = rules(exp)["fading"]
    idx = error_model_for(exp["filter"]["n_states"]).idx

    def one(p, key):  # the summary of jaxnav demo's s0_run
        res = S.run(
            key, jf.switch(p["rule"], [jf.attenuated(p["b"], states=states), fading]), save=("nav", "covs", "factors")
        )
        pe, ve = S.errors(res)
        var = jnp.diagonal(res.epochs.covs, axis1=-2, axis2=-1)
        sig_p = jnp.abs(curvilinear_to_enu(S.truth.pos[S.gidx], jnp.sqrt(var[:, idx.dpos])))
        sig_v = jnp.sqrt(var[:, idx.dv])
        return dict(rms=S.rms_of(res), pos_err=pe, vel_err=ve, sig_pos=sig_p, sig_vel=sig_v, factors=res.epochs.factors)

    grid = {"b": np.asarray([0.0, exp["filter"]["b"], 0.0]), "rule": np.asarray([0.0, 0.0, 1.0])}
    keys = jax.random.split(jax.random.PRNGKey(2019), a.seeds)
    first = tune.sweep(one, grid, keys, progress=False)
    times = []
    for _ in range(a.repeats):
        t0 = time.perf_counter()
        r = tune.sweep(one, grid, keys, progress=False)
        times.append(time.perf_counter() - t0)
    runs = 3 * a.seeds
    M = len(S.t_gnss)
    per_run_epochs = sum(v[0, 0].nbytes for v in r.values.values() if v.ndim >= 3 and v.shape[2] == M)
    fixed = sum(v[0, 0].nbytes for v in r.values.values()) - per_run_epochs
    per_epoch = per_run_epochs // M
    if tune.is_writer():
        print(
            json.dumps(
                dict(
                    processes=a.processes,
                    devices=r.n_devices,
                    compile_s=first.compile_time_s,
                    run_s=float(np.median(times)),
                    runs=runs,
                    epochs=M,
                    bytes_fixed=int(fixed),
                    bytes_per_epoch=int(per_epoch),
                    mean_pos_rms_m=[float(r.values["rms"][i, :, :3].mean()) for i in range(3)],
                )
            ),
            flush=True,
        )


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def layout(a, processes, devices):
    """Run one layout in fresh processes; returns process 0's JSON."""
    env = dict(os.environ, JAX_PLATFORMS="cpu", XLA_FLAGS=f"--xla_force_host_platform_device_count={devices}")
    port = str(_free_port())
    cmd = [
        sys.executable,
        __file__,
        "--worker",
        "--processes",
        str(processes),
        "--port",
        port,
        "--seeds",
        str(a.seeds),
        "--duration",
        str(a.duration),
        "--repeats",
        str(a.repeats),
    ]
    procs = [
        subprocess.Popen(
            cmd + ["--process-id", str(i)], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
        )
        for i in range(processes)
    ]
    outs = [p.communicate(timeout=a.timeout) for p in procs]
    for p, (_, err) in zip(procs, outs):
        if p.returncode != 0:
            raise SystemExit(f"layout {processes}x{devices} failed:\n{err[-3000:]}")
    return json.loads(outs[0][0].strip().splitlines()[-1])


def estimate(base, rows, runs_total=3000, epochs_full=2000, hosts=(1, 4, 16, 64, 256), gbit=10.0):
    """Lines of the cost estimate of ``runs_total`` filter runs of the full S0 study on N hosts."""
    scale = epochs_full / base["epochs"]
    c1 = base["run_s"] / base["runs"] * scale  # s per filter run of 2000 s on one device of this machine
    out_run = base["bytes_fixed"] + base["bytes_per_epoch"] * epochs_full  # bytes gathered per filter run
    vol = runs_total * out_run  # every host receives every run's outputs (all-gather)
    bw = gbit * 1e9 / 8
    comp = base["compile_s"]
    lines = [
        f"- measured here: {c1:.2f} s per filter run of 2000 s on one CPU device (the 1 x 1 row, "
        f"{base['run_s'] / base['runs']:.3f} s per {base['epochs']} s run, scaled by {scale:.2f}: the run is "
        f"one `lax.scan`, its cost proportional to its length); compile {comp:.0f} s, paid once per process, "
        f"in parallel on all hosts;",
        f"- output per filter run (what the all-gather moves): {base['bytes_fixed']} B + "
        f"{base['bytes_per_epoch']} B per GPS epoch = {out_run / 1e3:.0f} kB for 2000 epochs; "
        f"{runs_total} runs = {vol / 1e9:.2f} GB received by every host (input: 24 B per run); the table assumes "
        f"hosts like this one (one CPU device each) and a {gbit:g} Gbit/s network;",
        "",
        f"| hosts N (1 device each) | compute {runs_total} runs | all-gather at {gbit:g} Gbit/s | compile | total |",
        "|---|---|---|---|---|",
    ]
    for n in hosts:
        compute = runs_total * c1 / n
        comm = 0.0 if n == 1 else vol * (n - 1) / n / bw
        lines.append(f"| {n} | {compute:.0f} s | {comm:.1f} s | {comp:.0f} s | {compute + comm + comp:.0f} s |")
    return lines


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", type=int, default=4, help="seeds per filter (3 filters); default 4")
    p.add_argument("--duration", type=float, default=300.0, help="s of the S0 timeline; default 300")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--timeout", type=float, default=1800.0, help="s per layout before it counts as hung")
    p.add_argument("--no-write", action="store_true")
    p.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--processes", type=int, default=1, help=argparse.SUPPRESS)
    p.add_argument("--process-id", type=int, default=0, help=argparse.SUPPRESS)
    p.add_argument("--port", default="0", help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.worker:
        return worker(a)
    t_all = time.perf_counter()
    rows = []
    for n, d in LAYOUTS:
        l0 = os.getloadavg()[0]
        r = layout(a, n, d)
        r["load"] = (l0, os.getloadavg()[0])
        rows.append(r)
        print(
            f"{n} process(es) x {d} device(s): compile {r['compile_s']:.1f} s, run {r['run_s']:.2f} s for "
            f"{r['runs']} runs; load {r['load'][0]:.1f} -> {r['load'][1]:.1f}",
            flush=True,
        )
    base = rows[0]
    for r in rows[1:]:
        same = max(abs(x - y) for x, y in zip(r["mean_pos_rms_m"], base["mean_pos_rms_m"]))
        assert same <= 1e-9 * max(base["mean_pos_rms_m"]), (r, base)
    wall = time.perf_counter() - t_all
    when = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
    lines = [
        "## Several processes and hosts (`benchmarks/bench_distributed.py`)",
        "",
        f"{when}, {cpu_model()}, {os.cpu_count()} CPUs (shared with other sessions), Python "
        f"{platform.python_version()}, jax {_version('jax')}, jaxnav {git_revision()}; whole script {wall:.0f} s.",
        "",
        f"S0 study program (3 filters x {a.seeds} seeds = {base['runs']} runs of the first {a.duration:g} s, "
        f"{base['epochs']} GPS epochs each), one chunk; run = median of {a.repeats} calls after the compile.",
        "",
        "| layout | devices | compile | run | runs per second | speed-up vs 1 x 1 | load average (1 min) before -> after |",
        "|---|---|---|---|---|---|---|",
        *[
            f"| {r['processes']} process(es) x {r['devices'] // r['processes']} device(s) | {r['devices']} | "
            f"{r['compile_s']:.1f} s | {r['run_s']:.2f} s | {r['runs'] / r['run_s']:.2f} | "
            f"{base['run_s'] / r['run_s']:.2f} | {r['load'][0]:.1f} -> {r['load'][1]:.1f} |"
            for r in rows
        ],
        "",
        "Mean position RMS (classic / attenuated / fading) equal in all layouts: "
        + " / ".join(f"{v:.4f}" for v in base["mean_pos_rms_m"])
        + " m.",
        "",
        "Estimate: 1000 Monte Carlo seeds of the full S0 study (3 filters x 2000 s = 3000 filter runs) on N hosts, "
        "from the 1 x 1 row:",
        "",
        *estimate(base, rows),
    ]
    report = "\n".join(lines)
    print(report)
    if not a.no_write:
        write_section(pathlib.Path(__file__).with_name("RESULTS.md"), report, BEGIN, END)
    return 0


if __name__ == "__main__":
    sys.exit(main())
