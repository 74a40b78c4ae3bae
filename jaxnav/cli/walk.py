"""``jaxnav walk``: the real IMU + RTK walk set, i.e. ``jaxnav ins walk_0827`` (the shipped config)."""

from __future__ import annotations

import shlex
import sys

from jaxnav.cli._common import DATA_ENV, data_dir, prepare_out

#: the walk set's folder inside ``$JAXNAV_DATA``
WALK_SET = "rtklibexplorer-gnss-imu"


def register(subparsers):
    """Add the ``walk`` subcommand; returns its parser."""
    p = subparsers.add_parser("walk", help="the real IMU + RTK walk set (same as `jaxnav ins walk_0827`): 15-state "
                                           "LC filter and RTS with simulated 15 s GNSS outages, scored against the "
                                           "withheld RTK-fixed positions")
    p.add_argument("--data", default=None, help=f"folder of the {WALK_SET} set (default ${DATA_ENV}/{WALK_SET})")
    p.add_argument("--out", default="out/walk", help="output folder; default out/walk")
    return p


def run(args) -> int:
    """Run the shipped ``walk_0827`` config of ``jaxnav ins`` on the walk set, write its outputs into ``--out``."""
    from jaxnav.experiments import format_ins, process, walk_config

    data = data_dir(args.data, WALK_SET)
    cfg = walk_config(data.resolve().parent)
    out = prepare_out(args.out)
    results = process(cfg, out, command=" ".join(shlex.quote(a) for a in ["jaxnav", *sys.argv[1:]]),
                      progress=lambda m: print(m, flush=True))
    print(format_ins(results))
    print(f"wrote {len(results['files'])} files into {out}")
    return 0
