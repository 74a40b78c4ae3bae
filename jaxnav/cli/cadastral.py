"""``jaxnav cadastral``: the S3 cadastral-survey post-processing over Monte Carlo seeds
(:func:`jaxnav.experiments.s3.run_cadastral`)."""

from __future__ import annotations

from jaxnav.cli._common import (
    DATA_ENV,
    MAX_SEEDS,
    CommandError,
    add_process_args,
    data_dir,
    input_file,
    int_range,
    prepare_out,
    record_config,
    start_processes,
)
from jaxnav.cli.walk import WALK_SET


def register(subparsers):
    """Add the ``cadastral`` subcommand; returns its parser."""
    p = subparsers.add_parser(
        "cadastral",
        help="S3: cadastral-survey IMU post-processing (preprocessing, stops, "
        "KF/RTS at stops, strapdown, reverse navigation) over Monte Carlo "
        "seeds",
    )
    p.add_argument(
        "--out", default="out/cadastral", help="output folder (results.json and figures); default out/cadastral"
    )
    p.add_argument("--config", default=None, help="cadastral TOML (default: jaxnav/sim/scenarios/cadastral.toml)")
    p.add_argument(
        "--seeds",
        type=int_range(1, MAX_SEEDS),
        default=64,
        help="Monte Carlo seeds per IMU grade (vmapped), >= 1; default 64",
    )
    p.add_argument(
        "--grade", action="append", default=None, help="IMU grade(s) of the config to run (repeatable); default all"
    )
    p.add_argument("--stops", default=None, help="stop-list CSV replacing the simulated one (checked against the data)")
    p.add_argument("--legs", type=int_range(1), default=None, help="use only the first n (>= 1) legs (short run)")
    p.add_argument("--chunk", type=int_range(1, MAX_SEEDS), default=8, help="seeds per compiled batch, >= 1; default 8")
    p.add_argument(
        "--data",
        default=None,
        help=f"folder that holds the data sets (like ../shared/data; relative "
        f"to the working directory), for the real-walk stop detection on "
        f"its {WALK_SET}/; default ${DATA_ENV}; skipped if neither is set",
    )
    p.add_argument("--no-progress", action="store_true", help="hide the progress bars")
    add_process_args(p)
    return p


def run(args) -> int:
    """Run the S3 experiment, print its summary, write results.json and figures into ``--out``."""
    from jaxnav.experiments.s3 import format_cadastral, run_cadastral
    from jaxnav.io import loads_toml, read_stop_list
    from jaxnav.sim import load_cadastral

    writer = start_processes(args)  # several processes: all compute, process 0 writes and prints
    walk_dir = data_dir(args.data, WALK_SET, required=False)
    if args.config is not None:
        input_file(args.config, "--config")
    scns, _ = load_cadastral(args.config)  # checked before any work
    if args.config is None:
        import importlib.resources

        shipped = importlib.resources.files("jaxnav.sim").joinpath("scenarios/cadastral.toml")
        record_config(args, "jaxnav/sim/scenarios/cadastral.toml", loads_toml(shipped.read_text(encoding="utf-8")))
    else:
        record_config(args, args.config)
    unknown = [g for g in (args.grade or []) if g not in scns]
    if unknown:
        raise CommandError(f"--grade {unknown[0]!r}: the config has the IMU grades {sorted(scns)}")
    if args.stops is not None:
        read_stop_list(input_file(args.stops, "--stops"))
    prepare_out(args.out)
    res = run_cadastral(
        args.out,
        config=args.config,
        seeds=args.seeds,
        grades=args.grade,
        stops=args.stops,
        chunk=args.chunk,
        progress=not args.no_progress,
        n_legs=args.legs,
        walk_dir=walk_dir,
    )
    if not writer:
        return 0
    print(format_cadastral(res))
    n_fig = sum(len(r.get("figures", [])) for r in res.get("grades", {}).values())
    print(f"wrote {args.out}/results.json and {n_fig} figure(s) into {args.out}")
    return 0
