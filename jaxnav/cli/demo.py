"""``jaxnav demo``: the S0 reproduction (:func:`jaxnav.experiments.s0.run_s0`)."""

from __future__ import annotations

import pathlib

from jaxnav.cli._common import (
    MAX_SEEDS,
    add_process_args,
    input_file,
    int_range,
    prepare_out,
    record_config,
    start_processes,
)


def register(subparsers):
    """Add the ``demo`` subcommand; returns its parser."""
    p = subparsers.add_parser(
        "demo",
        help="the S0 reproduction: classic, attenuated and fading filters in "
        "INS/GPS integration over Monte Carlo seeds",
    )
    p.add_argument("--out", default="out/demo", help="output folder (created); default out/demo")
    p.add_argument(
        "--seeds", type=int_range(1, MAX_SEEDS), default=None, help="Monte Carlo seeds (vmapped), >= 1; default 32"
    )
    p.add_argument(
        "--config", default=None, help="experiment TOML (default: the shipped jaxnav/experiments/s0_experiment.toml)"
    )
    p.add_argument(
        "--sweep-points", type=int_range(1), default=None, help="use only the first n (>= 1) b values of the sweep"
    )
    p.add_argument("--no-progress", action="store_true", help="hide the progress bars")
    add_process_args(p)
    return p


def run(args) -> int:
    """Run the reproduction, print its table, write results.json and figures into ``--out``."""
    from jaxnav.experiments.s0 import EXPERIMENT, format_s0, load_experiment, run_s0

    writer = start_processes(args)  # several processes: all compute, process 0 writes and prints
    if args.config is not None:
        input_file(args.config, "--config")
    load_experiment(args.config or EXPERIMENT)  # every key checked before any work
    record_config(args, args.config or EXPERIMENT)
    prepare_out(args.out)
    res = run_s0(
        args.out, seeds=args.seeds, config=args.config, sweep_points=args.sweep_points, progress=not args.no_progress
    )
    out = pathlib.Path(args.out)
    if not writer:
        return 0
    print(format_s0(res))
    print(
        f"\nwrote {out / 'results.json'} and {len(res['figures'])} figures to {out} "
        f"({res['wall_time_s']['total']:.0f} s in all)"
    )
    return 0
