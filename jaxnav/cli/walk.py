"""``jaxnav walk``: the real IMU + RTK walk set with simulated GNSS outages (:func:`jaxnav.experiments.run_walk`)."""

from __future__ import annotations

from jaxnav.cli._common import DATA_ENV, data_dir, prepare_out

#: the walk set's folder inside ``$JAXNAV_DATA``
WALK_SET = "rtklibexplorer-gnss-imu"


def register(subparsers):
    """Add the ``walk`` subcommand; returns its parser."""
    p = subparsers.add_parser("walk", help="the real IMU + RTK walk set: 15-state LC filter and RTS with simulated "
                                           "15 s GNSS outages, scored against the withheld RTK-fixed positions")
    p.add_argument("--data", default=None, help=f"folder of the {WALK_SET} set (default ${DATA_ENV}/{WALK_SET})")
    p.add_argument("--out", default="out/walk", help="output folder; default out/walk")
    return p


def run(args) -> int:
    """Run and score the walk, print the scores, write scores.json and the figure into ``--out``."""
    from jaxnav.experiments import format_walk, run_walk, write_walk_scores
    from jaxnav.io import load_walk

    data = data_dir(args.data, WALK_SET)
    out = prepare_out(args.out)
    walk = load_walk(data)  # both files read and checked before any work
    scores, _ = run_walk(walk, out_dir=out)
    path = write_walk_scores(out, scores)
    print(format_walk(scores))
    if walk.imu.n_skipped_lines:
        print(f"IMU log: {walk.imu.n_skipped_lines} line(s) skipped: "
              + "; ".join(f"line {n}: {why}" for n, why in walk.imu.skipped[:3])
              + (" ..." if walk.imu.n_skipped_lines > 3 else ""))
    print(f"wrote {path} and {scores.figure}")
    return 0
