"""``jaxnav rtk``: the S2 pipeline on RTK epoch logs or RTKLIB .pos files (:func:`jaxnav.experiments.s2.run_rtk`)."""

from __future__ import annotations

import logging

from jaxnav.cli._common import UsageError, float_range, input_file, int_range, prepare_out


def register(subparsers):
    """Add the ``rtk`` subcommand; returns its parser."""
    p = subparsers.add_parser(
        "rtk",
        help="S2: Kalman filtering of RTK point series (epoch-log CSV or .pos files, "
        "moving epochs excluded) -> per-point results CSV + JSON + figure",
    )
    p.add_argument("files", nargs="*", help="RTKLIB .pos files (static parts used) and/or CSV epoch logs")
    p.add_argument("--out", default="out/rtk", help="output folder; default out/rtk")
    p.add_argument("--control", default=None, help="control-point CSV (point,B,L,H,x,y,h) of the connection survey")
    p.add_argument("--levelling", default=None, help="levelling CSV (point,height) for the Table 3 comparison")
    p.add_argument(
        "--lon0",
        type=float_range(-180.0, 360.0),
        default=None,
        help="central meridian, deg in [-180, 360] (default: zone of the data)",
    )
    p.add_argument("--zone-width", type=int, default=3, choices=(3, 6), help="zone width for the default lon0")
    p.add_argument(
        "--step",
        type=float_range(0.0, 86400.0, lo_open=True),
        default=2.0,
        help=".pos files: thinning interval, s, > 0 (default 2)",
    )
    p.add_argument(
        "--window", type=int_range(1, 10**6), default=60, help=".pos files: epochs per occupation, >= 1 (default 60)"
    )
    p.add_argument(
        "--min-epochs",
        type=int_range(1, 10**6),
        default=30,
        help=".pos files: shortest occupation kept, >= 1 (default 30)",
    )
    p.add_argument(
        "--static-speed",
        type=float_range(0.0, 1000.0, lo_open=True),
        default=0.10,
        metavar="M_PER_S",
        help=".pos files: epochs faster than this (horizontal, from successive positions) are moving "
        "and excluded, m/s (default 0.10)",
    )
    p.add_argument(
        "--static-displacement",
        type=float_range(0.0, 1e4, lo_open=True),
        default=0.10,
        metavar="M",
        help=".pos files: epochs whose positions 5 s before and after differ by more than this are "
        "moving and excluded, m (default 0.10)",
    )
    p.add_argument(
        "--no-motion-test",
        action="store_true",
        help=".pos files: take every epoch as static (no static/moving segmentation)",
    )
    p.add_argument("--all-epochs", action="store_true", help=".pos files: also use float (Q != 1) epochs")
    p.add_argument("--smoother", action="store_true", help="add an RTS pass after the forward filter")
    p.add_argument(
        "--surface",
        default="auto",
        choices=("auto", "plane", "quadratic"),
        help="height-anomaly surface (auto: quadratic with >= 7 control points)",
    )
    p.add_argument(
        "--simulate",
        type=int_range(0, 2**32 - 1),
        default=None,
        metavar="SEED",
        help="write the simulated 45-point S2 survey (epoch log, control, levelling) into --out "
        "and process it together with FILES",
    )
    return p


def run(args) -> int:
    """Optionally write the simulated survey, then run the pipeline on the files (prints a summary)."""
    from jaxnav.experiments.s2 import run_rtk, write_simulated_survey
    from jaxnav.survey import MotionParams

    if not args.files and args.simulate is None:
        raise UsageError("give FILES or --simulate SEED")
    if args.min_epochs > args.window:
        raise UsageError(
            f"--min-epochs {args.min_epochs} is more than --window {args.window}: no occupation could be kept"
        )
    files = [input_file(f, "FILES") for f in args.files]
    control = None if args.control is None else input_file(args.control, "--control")
    levelling = None if args.levelling is None else input_file(args.levelling, "--levelling")
    prepare_out(args.out)
    args._json_outputs = ("rtk_results.json",)  # main adds the provenance block to it
    if args.simulate is not None:
        logging.getLogger("jaxnav").info("simulating the 45-point S2 survey (seed %d) into %s", args.simulate, args.out)
        f_ep, f_cp, f_lv, _ = write_simulated_survey(args.out, seed=args.simulate)
        files.append(f_ep)
        control = control or f_cp
        levelling = levelling or f_lv
    run_rtk(
        files,
        args.out,
        control=control,
        levelling=levelling,
        lon0_deg=args.lon0,
        zone_width=args.zone_width,
        step=args.step,
        window=args.window,
        min_epochs=args.min_epochs,
        fixed_only=not args.all_epochs,
        smoother=args.smoother,
        surface=args.surface,
        motion=None if args.no_motion_test else MotionParams(v_max=args.static_speed, d_max=args.static_displacement),
    )
    return 0
