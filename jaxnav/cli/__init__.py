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
    s0.add_argument("--config", default=None, help="experiment TOML (default: the shipped jaxnav/tune/s0_experiment.toml)")
    s0.add_argument("--sweep-points", type=int, default=None, help="use only the first n b values of the sweep")
    s0.add_argument("--no-progress", action="store_true", help="hide the progress bars")
    w = sub.add_parser("walk", help="the real IMU + RTK walk set: 15-state LC filter and RTS with simulated "
                                    "15 s GNSS outages, scored against the withheld RTK-fixed positions")
    w.add_argument("--data", default=None, help="folder of the rtklibexplorer-gnss-imu set "
                                                "(default ../shared/data/rtklibexplorer-gnss-imu)")
    w.add_argument("--out", default="out/walk", help="output folder; default out/walk")
    d = sub.add_parser("demo-filters", help="filter-family demonstration on a constant-velocity series "
                                            "with a change of dynamics (S1/S2 model)")
    d.add_argument("--out", default="out/demo", help="output folder (created); default out/demo")
    d.add_argument("--seeds", type=int, default=64, help="Monte Carlo seeds (vmapped); default 64")
    d.add_argument("--epochs", type=int, default=1200, help="epochs per series (1 Hz); default 1200")
    d.add_argument("--b", type=float, default=0.254, help="attenuation factor b; default 0.254 (S0)")
    d.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    r = sub.add_parser("rtk", help="S2: Kalman filtering of RTK point series (epoch-log CSV or static .pos files) "
                                   "-> per-point results CSV + JSON + figure")
    r.add_argument("files", nargs="*", help="RTKLIB .pos files (static) and/or CSV epoch logs")
    r.add_argument("--out", default="out/rtk", help="output folder; default out/rtk")
    r.add_argument("--control", default=None, help="control-point CSV (point,B,L,H,x,y,h) of the connection survey")
    r.add_argument("--levelling", default=None, help="levelling CSV (point,height) for the Table 3 comparison")
    r.add_argument("--lon0", type=float, default=None, help="central meridian, deg (default: zone of the data)")
    r.add_argument("--zone-width", type=int, default=3, choices=(3, 6), help="zone width for the default lon0")
    r.add_argument("--step", type=float, default=2.0, help=".pos files: thinning interval, s (default 2)")
    r.add_argument("--window", type=int, default=60, help=".pos files: epochs per occupation (default 60)")
    r.add_argument("--min-epochs", type=int, default=30, help=".pos files: shortest occupation kept (default 30)")
    r.add_argument("--all-epochs", action="store_true", help=".pos files: also use float (Q != 1) epochs")
    r.add_argument("--smoother", action="store_true", help="add an RTS pass after the forward filter")
    r.add_argument("--surface", default="auto", choices=("auto", "plane", "quadratic"),
                   help="height-anomaly surface (auto: quadratic with >= 7 control points)")
    r.add_argument("--simulate", type=int, default=None, metavar="SEED",
                   help="write the simulated 45-point S2 survey (epoch log, control, levelling) into --out "
                        "and process it together with FILES")
    cad = sub.add_parser("cadastral", help="S3: cadastral-survey IMU post-processing (preprocessing, stops, "
                                           "KF/RTS at stops, strapdown, reverse navigation) over Monte Carlo seeds")
    cad.add_argument("--out", required=True, help="output folder (results.json and figures)")
    cad.add_argument("--config", default=None, help="cadastral TOML (default: jaxnav/sim/scenarios/cadastral.toml)")
    cad.add_argument("--seeds", type=int, default=64, help="Monte Carlo seeds per IMU grade (vmapped); default 64")
    cad.add_argument("--grade", action="append", default=None,
                     help="IMU grade(s) of the config to run (repeatable); default all")
    cad.add_argument("--stops", default=None, help="stop-list CSV replacing the simulated one (checked against the data)")
    cad.add_argument("--legs", type=int, default=None, help="use only the first n legs (short run)")
    cad.add_argument("--chunk", type=int, default=8, help="seeds per compiled batch; default 8")
    cad.add_argument("--data", default=None, help="rtklibexplorer-gnss-imu folder for the real-walk stop detection")
    cad.add_argument("--no-progress", action="store_true", help="hide the progress bars")
    mon = sub.add_parser("monitor", help="S1 deformation monitoring: daily station files (.tenv3, .neu, .col) -> "
                                         "velocities, standard vs adaptive forecasts, S1 statistics; or --simulate")
    mon.add_argument("files", nargs="*", help="daily station series, one station per file")
    mon.add_argument("--out", default="out/monitor", help="output folder; default out/monitor")
    mon.add_argument("--simulate", action="store_true", help="the S1 experiment on simulated 1 Hz stations")
    mon.add_argument("--period", type=int, default=365, help="epochs per statistics period for files; default 365")
    mon.add_argument("--robust", action="store_true", help="add the robust filters (IGG-III, Yang)")
    mon.add_argument("--periods", type=int, default=60, help="simulated periods; default 60")
    mon.add_argument("--stations", type=int, default=2, help="simulated stations; default 2")
    mon.add_argument("--epochs", type=int, default=3600, help="epochs per simulated period; default 3600 (1 h)")
    mon.add_argument("--gross", type=float, default=0.0, help="share of 10-sigma gross errors (simulation)")
    mon.add_argument("--seed", type=int, default=2017, help="PRNG seed of the simulation")
    mon.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    for name, what in (("sweep", "vmap a parameter grid x Monte Carlo runs (chunked, sharded over devices)"),
                       ("tune", "tune filter parameters by gradient descent (optax inside lax.scan)")):
        t = sub.add_parser(name, help=f"{what}; CONFIG is a TOML file or a shipped name (s0_b, cv_noise)")
        t.add_argument("config", help="sweep/tune TOML, or the name of a shipped one: s0_b, cv_noise")
        t.add_argument("--out", default=f"out/{name}", help=f"output folder; default out/{name}")
        t.add_argument("--no-progress", action="store_true", help="hide the progress bars")
    args = parser.parse_args(argv)
    import jaxnav

    jaxnav.enable_x64()  # navigation states and absolute coordinates are float64
    if args.command == "demo":
        from jaxnav.cli._demo_s0 import run_s0_demo

        run_s0_demo(out=args.out, seeds=args.seeds, config=args.config, sweep_points=args.sweep_points,
                    progress=not args.no_progress)
    elif args.command == "walk":
        import json
        import pathlib

        from jaxnav.cli._walk import run_walk

        data = args.data or str(pathlib.Path.cwd().parent / "shared" / "data" / "rtklibexplorer-gnss-imu")
        out = pathlib.Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        scores, _ = run_walk(data, out_dir=out)
        (out / "scores.json").write_text(json.dumps(scores._asdict(), indent=1, default=lambda a: a.tolist()))
        print(f"walk set, {len(scores.windows)} simulated GNSS outages of 15 s scored against withheld RTK-fixed fixes")
        for k, (w, n) in enumerate(zip(scores.windows, scores.n_ref)):
            print(f"  outage {k + 1} [{w[0]:.1f}, {w[1]:.1f}] s, {int(n)} fixed epochs: max horizontal error "
                  f"forward {scores.fwd_max[k]:.2f} m, smoothed {scores.sm_max[k]:.2f} m")
        print(f"  RMS over outages: forward {scores.fwd_rms_all:.2f} m, smoothed {scores.sm_rms_all:.2f} m; "
              f"forward outside outages {scores.fwd_rms_outside:.3f} m")
        print(f"wrote {out / 'scores.json'} and {scores.figure}")
    elif args.command == "rtk":
        from jaxnav.cli._rtk import run_rtk, write_simulated_survey

        files, control, levelling = list(args.files), args.control, args.levelling
        if args.simulate is not None:
            f_ep, f_cp, f_lv, _ = write_simulated_survey(args.out, seed=args.simulate)
            files.append(f_ep)
            control = control or f_cp
            levelling = levelling or f_lv
        if not files:
            parser.error("rtk: give FILES or --simulate SEED")
        run_rtk(files, args.out, control=control, levelling=levelling, lon0_deg=args.lon0,
                zone_width=args.zone_width, step=args.step, window=args.window, min_epochs=args.min_epochs,
                fixed_only=not args.all_epochs, smoother=args.smoother, surface=args.surface)
    elif args.command == "cadastral":
        from jaxnav.cli._cadastral import print_summary, run_cadastral

        res = run_cadastral(args.out, config=args.config, seeds=args.seeds, grades=args.grade, stops=args.stops,
                            chunk=args.chunk, progress=not args.no_progress, n_legs=args.legs, walk_dir=args.data)
        print_summary(res)
        print(f"wrote {args.out}/results.json and figures")
    elif args.command == "monitor":
        from jaxnav.cli._monitor import run_monitor

        if not args.simulate and not args.files:
            parser.error("monitor: give daily series files (.tenv3, .neu, .col) or --simulate")
        run_monitor(args.files, args.out, simulate=args.simulate, period=args.period, robust=args.robust,
                    periods=args.periods, stations=args.stations, epochs=args.epochs, gross=args.gross,
                    seed=args.seed, progress=not args.no_progress)
    elif args.command in ("sweep", "tune"):
        from jaxnav.cli._tune import run_sweep, run_tune

        (run_sweep if args.command == "sweep" else run_tune)(args.config, args.out, progress=not args.no_progress)
    elif args.command == "demo-filters":
        from jaxnav.cli._demo_filters import run_demo

        run_demo(out=args.out, seeds=args.seeds, epochs=args.epochs, b=args.b,
                 progress=not args.no_progress)
    return 0


if __name__ == "__main__":
    sys.exit(main())
