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
