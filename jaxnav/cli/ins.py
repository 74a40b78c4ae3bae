"""``jaxnav ins CONFIG``: INS/GNSS post-processing of a real recording from a config file alone.

CONFIG is a TOML file (keys: :mod:`jaxnav.experiments.ins_config`) or the name of a shipped one
(``walk_0827``). Paths in the config are relative to it; ``${JAXNAV_DATA}`` is taken from the
environment or from ``--data``.
"""

from __future__ import annotations

import os
import shlex
import sys

from jaxnav.cli._common import DATA_ENV, CommandError, prepare_out


def register(subparsers):
    """Add the ``ins`` subcommand; returns its parser."""
    p = subparsers.add_parser(
        "ins", help="INS/GNSS post-processing of your own IMU + GNSS logs from a config file: loosely coupled "
                    "filter + RTS smoother, optional simulated-outage evaluation and likelihood tuning")
    p.add_argument("config", help="ins TOML file, or a shipped config name: walk_0827")
    p.add_argument("--out", default=None, help="output folder (created and checked first); default out/ins/<name>")
    p.add_argument("--tune", action="store_true",
                   help="tune the [tune] params (noise densities, lever arm) by maximising the GNSS innovation "
                        "likelihood over the whole run, then rerun and report before/after")
    p.add_argument("--data", default=None,
                   help=f"folder that holds the data sets; sets ${{{DATA_ENV}}} for the paths in CONFIG")
    p.add_argument("-q", "--quiet", action="store_true", help="print only the summary")
    return p


def run(args) -> int:
    """Check the config and the output folder, run, write the outputs, print the summary."""
    from jaxnav.experiments.ins_config import load_ins_config
    from jaxnav.experiments.ins_output import format_ins, process

    if args.data:
        if not os.path.isdir(args.data):
            raise CommandError(f"{args.data}: no such data folder (--data)")
        os.environ[DATA_ENV] = os.path.abspath(args.data)
    cfg = load_ins_config(args.config)
    for p, key in ((cfg.imu.file, "imu.file"), (cfg.gnss.file, "gnss.file"), (cfg.imu.tag, "imu.tag")):
        if p is not None and not p.is_file():
            raise CommandError(f"{p}: no such file ({cfg.path}: {key})")
    out = prepare_out(args.out or f"out/ins/{cfg.name}")
    say = None if args.quiet else (lambda msg: print(msg, flush=True))
    results = process(cfg, out, tune=args.tune, command=" ".join(shlex.quote(a) for a in ["jaxnav", *sys.argv[1:]]),
                      progress=say)
    print(format_ins(results))
    print(f"wrote {len(results['files'])} files into {out}")
    return 0
