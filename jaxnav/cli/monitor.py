"""``jaxnav monitor``: S1 deformation monitoring on daily station files or on simulated 1 Hz stations.

* ``jaxnav monitor FILES... --out DIR``: each file (NGL ``.tenv3``, SIO ``.neu``, ``.col`` table)
  is a station: velocities, one-day forecasts and S1 statistics
  (:func:`jaxnav.experiments.run_monitor_files`).
* ``jaxnav monitor --simulate --out DIR``: the S1 experiment on simulated stations, S1's
  Tables 1-6 (:func:`jaxnav.experiments.run_monitor_simulation`).

Both write ``monitor.json`` (statistics) and PNG figures to ``--out``.
"""

from __future__ import annotations

from jaxnav.cli._common import MAX_SEEDS, UsageError, float_range, input_file, int_range, prepare_out


def register(subparsers):
    """Add the ``monitor`` subcommand; returns its parser."""
    p = subparsers.add_parser("monitor", help="S1 deformation monitoring: daily station files (.tenv3, .neu, .col) "
                                              "-> velocities, standard vs adaptive forecasts, S1 statistics; "
                                              "or --simulate")
    p.add_argument("files", nargs="*", help="daily station series, one station per file")
    p.add_argument("--out", default="out/monitor", help="output folder; default out/monitor")
    p.add_argument("--simulate", action="store_true", help="the S1 experiment on simulated 1 Hz stations")
    p.add_argument("--period", type=int_range(1), default=365,
                   help="epochs per statistics period for files, >= 1; default 365")
    p.add_argument("--robust", action="store_true", help="add the robust filters (IGG-III, Yang)")
    p.add_argument("--periods", type=int_range(1, MAX_SEEDS), default=60, help="simulated periods, >= 1; default 60")
    p.add_argument("--stations", type=int_range(1, 1000), default=2, help="simulated stations, 1 .. 1000; default 2")
    p.add_argument("--epochs", type=int_range(2, 10**6), default=3600,
                   help="epochs per simulated period, 2 .. 1e6; default 3600 (1 h)")
    p.add_argument("--gross", type=float_range(0.0, 1.0), default=0.0,
                   help="share of 10-sigma gross errors in [0, 1] (simulation)")
    p.add_argument("--seed", type=int_range(0, 2**32 - 1), default=2017,
                   help="PRNG seed of the simulation (0 .. 2^32-1)")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    return p


def run(args) -> int:
    """Process the files (or simulate), print the statistics, write monitor.json and figures into ``--out``."""
    from jaxnav.experiments import run_monitor_files, run_monitor_simulation

    if not args.simulate and not args.files:
        raise UsageError("give daily series files (.tenv3, .neu, .col) or --simulate")
    if args.simulate and args.files:
        raise UsageError("give either daily series files or --simulate, not both")
    files = [input_file(f, "FILES") for f in args.files]
    out = prepare_out(args.out)
    if args.simulate:
        res = run_monitor_simulation(out, periods=args.periods, stations=args.stations, epochs=args.epochs,
                                     robust=args.robust, gross=args.gross, seed=args.seed,
                                     progress=not args.no_progress)
        print(res["text"])
        print(f"\nwrote {out / 'monitor.json'}, {out / 's1_statistics.png'}, {out / 's1_period.png'} "
              f"({res['wall_time_s']:.1f} s)")
        return 0
    res = run_monitor_files(files, out, period=args.period, robust=args.robust)
    print(res["text"])
    print(f"wrote {out / 'monitor.json'} and {len(args.files)} figure(s) in {out}")
    return 0
