"""``jaxnav walk``: the real IMU + RTK walk set, i.e. ``jaxnav ins walk_0827`` (the shipped config)."""

from __future__ import annotations

from jaxnav.cli._common import DATA_ENV, data_dir, record_config

#: the walk set's folder inside ``$JAXNAV_DATA``
WALK_SET = "rtklibexplorer-gnss-imu"


def register(subparsers):
    """Add the ``walk`` subcommand; returns its parser."""
    p = subparsers.add_parser(
        "walk",
        help="the real IMU + RTK walk set (same as `jaxnav ins walk_0827`): 15-state "
        "LC filter and RTS with simulated 15 s GNSS outages, scored against the "
        "withheld RTK-fixed positions",
    )
    p.add_argument(
        "--data",
        default=None,
        help=f"folder that holds the data sets, with {WALK_SET}/ in it (like "
        f"../shared/data; relative to the working directory); default "
        f"${DATA_ENV}",
    )
    p.add_argument("--out", default="out/walk", help="output folder; default out/walk")
    return p


def run(args) -> int:
    """Run the shipped ``walk_0827`` config of ``jaxnav ins`` on the walk set, write its outputs into ``--out``."""
    from jaxnav.cli.ins import check_input_files, run_config
    from jaxnav.experiments.walk import walk_config

    data = data_dir(args.data, WALK_SET)  # <root>/rtklibexplorer-gnss-imu, root absolute
    cfg = walk_config(data.parent)
    check_input_files(cfg)
    record_config(args, cfg.path, cfg.raw)
    return run_config(args, cfg, args.out)
