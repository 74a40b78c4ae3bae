"""``jaxnav demo-filters``: the filter family on a CV series (:func:`jaxnav.experiments.filter_family.run_filter_family`)."""

from __future__ import annotations

import pathlib

from jaxnav.cli._common import MAX_SEEDS, add_process_args, float_range, int_range, prepare_out, start_processes


def register(subparsers):
    """Add the ``demo-filters`` subcommand; returns its parser."""
    p = subparsers.add_parser(
        "demo-filters",
        help="filter-family demonstration on a constant-velocity series with a change of dynamics (S1/S2 model)",
    )
    p.add_argument("--out", default="out/demo-filters", help="output folder (created); default out/demo-filters")
    p.add_argument(
        "--seeds", type=int_range(1, MAX_SEEDS), default=64, help="Monte Carlo seeds (vmapped), >= 1; default 64"
    )
    p.add_argument(
        "--epochs", type=int_range(100, 10**6), default=1200, help="epochs per series (1 Hz), 100 .. 1e6; default 1200"
    )
    p.add_argument(
        "--b",
        type=float_range(0.0, 1.0, hi_open=True),
        default=0.254,
        help="attenuation factor b in [0, 1); default 0.254 (S0)",
    )
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    add_process_args(p)
    return p


def run(args) -> int:
    """Run the demonstration, print its table, write results.json and filter_family.png into ``--out``."""
    from jaxnav.experiments.filter_family import format_filter_family, run_filter_family

    writer = start_processes(args)  # several processes: all compute, process 0 writes and prints
    prepare_out(args.out)
    res = run_filter_family(out=args.out, seeds=args.seeds, epochs=args.epochs, b=args.b, progress=not args.no_progress)
    out = pathlib.Path(args.out)
    if not writer:
        return 0
    print(format_filter_family(res))
    print(
        f"\nwrote {out / 'filter_family.png'} and {out / 'results.json'} ({res['wall_time_s']:.1f} s incl. compilation)"
    )
    return 0
