"""Command line: ``jaxnav demo`` (the S0 reproduction) and ``jaxnav demo-filters``."""

from __future__ import annotations

import argparse
import sys


def main(argv=None) -> int:
    """Entry point of the ``jaxnav`` command."""
    parser = argparse.ArgumentParser(prog="jaxnav", description="jaxnav command line")
    sub = parser.add_subparsers(dest="command", required=True)
    s0 = sub.add_parser("demo", help="the S0 reproduction: classic, attenuated and fading filters in "
                                     "INS/GPS integration over Monte Carlo seeds")
    s0.add_argument("--out", default="out/demo", help="output folder (created); default out/demo")
    s0.add_argument("--seeds", type=int, default=None, help="Monte Carlo seeds (vmapped); default 32")
    s0.add_argument("--config", default=None, help="experiment TOML (default: the shipped s0_experiment.toml)")
    s0.add_argument("--sweep-points", type=int, default=None, help="use only the first n b values of the sweep")
    s0.add_argument("--no-progress", action="store_true", help="hide the progress bars")
    d = sub.add_parser("demo-filters", help="filter-family demonstration on a constant-velocity series "
                                            "with a change of dynamics (S1/S2 model)")
    d.add_argument("--out", default="out/demo", help="output folder (created); default out/demo")
    d.add_argument("--seeds", type=int, default=64, help="Monte Carlo seeds (vmapped); default 64")
    d.add_argument("--epochs", type=int, default=1200, help="epochs per series (1 Hz); default 1200")
    d.add_argument("--b", type=float, default=0.254, help="attenuation factor b; default 0.254 (S0)")
    d.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    args = parser.parse_args(argv)
    if args.command == "demo":
        from jaxnav.cli._demo_s0 import run_s0_demo

        run_s0_demo(out=args.out, seeds=args.seeds, config=args.config, sweep_points=args.sweep_points,
                    progress=not args.no_progress)
    elif args.command == "demo-filters":
        from jaxnav.cli._demo_filters import run_demo

        run_demo(out=args.out, seeds=args.seeds, epochs=args.epochs, b=args.b,
                 progress=not args.no_progress)
    return 0


if __name__ == "__main__":
    sys.exit(main())
