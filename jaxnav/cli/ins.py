"""``jaxnav ins CONFIG``: INS/GNSS post-processing of a real recording from a config file alone.

CONFIG is a TOML file (keys: :func:`jaxnav.io.load_ins_config`) or the name of a shipped one
(``walk_0827``). Paths in the config are relative to it; ``${JAXNAV_DATA}`` is ``--data`` or the
environment variable: the folder that holds the data sets, a relative one taken against the working
directory (as in every command).
"""

from __future__ import annotations

import logging
import os
import pathlib

from jaxnav.cli._common import DATA_ENV, CommandError, begin_computation, data_root, prepare_out, record_config


def register(subparsers):
    """Add the ``ins`` subcommand; returns its parser."""
    p = subparsers.add_parser(
        "ins",
        help="INS/GNSS post-processing of your own IMU + GNSS logs from a config file: loosely coupled "
        "filter + RTS smoother, optional simulated-outage evaluation and likelihood tuning",
    )
    p.add_argument("config", help="ins TOML file, or a shipped config name: walk_0827")
    p.add_argument("--out", default=None, help="output folder (created and checked first); default out/ins/<name>")
    p.add_argument(
        "--tune",
        action="store_true",
        help="tune the [tune] params (noise densities, lever arm) by maximising the GNSS innovation "
        "likelihood over the whole run, then rerun and report before/after",
    )
    p.add_argument(
        "--no-calibrate",
        action="store_true",
        help="use the configured noise as given: no NIS check and no automatic noise calibration "
        "(same as [tune] calibrate = false)",
    )
    p.add_argument(
        "--data",
        default=None,
        help=f"folder that holds the data sets (like ../shared/data; relative to the working directory); "
        f"stands for ${{{DATA_ENV}}} in the paths of CONFIG",
    )
    return p


def run(args) -> int:
    """Check the config and the output folder, run, write the outputs, print the summary."""
    from jaxnav.io import load_ins_config

    variables = None
    if args.data:  # the folder that holds the data sets, as in every command (relative: to the working dir)
        variables = {DATA_ENV: str(data_root(args.data, "--data"))}
    elif os.environ.get(DATA_ENV):  # not checked here: a config of the user's may not use it
        variables = {DATA_ENV: os.path.abspath(os.path.expanduser(os.environ[DATA_ENV]))}
    cfg = load_ins_config(args.config, variables=variables)
    check_input_files(cfg)
    record_config(args, cfg.path, cfg.raw)
    return run_config(args, cfg, args.out or f"out/ins/{cfg.name}", tune=args.tune)


def check_input_files(cfg) -> None:
    """Every file the config names exists and is a file, else :class:`CommandError` naming it and its key."""
    truth = cfg.evaluate.truth if cfg.evaluate is not None else None
    for p, key in (
        (cfg.imu.file, "imu.file"),
        (cfg.gnss.file, "gnss.file"),
        (cfg.imu.tag, "imu.tag"),
        (truth, "evaluate.truth"),
    ):
        if p is not None and not p.is_file():
            raise CommandError(f"{p}: {'a folder, not a file' if p.is_dir() else 'no such file'} ({cfg.path}: {key})")


def run_config(args, cfg, out, *, tune: bool = False) -> int:
    """``jaxnav ins`` / ``jaxnav walk`` on a checked config: the stages as INFO lines, the summary on stdout;
    ``args.no_calibrate`` (``--no-calibrate``) overrides ``[tune] calibrate`` with false."""
    from jaxnav.experiments.ins_output import format_ins, process
    from jaxnav.io import files_snapshot

    args._snapshot = files_snapshot(out)  # before anything is written (main lists the files written)
    out = prepare_out(out)
    args.out = str(out)
    begin_computation(args)
    calibrate = False if getattr(args, "no_calibrate", False) else None
    results = process(cfg, out, tune=tune, calibrate=calibrate, progress=logging.getLogger("jaxnav").info)
    print(format_ins(results))
    print(f"wrote {len(results['files'])} files into {pathlib.Path(out)}")
    return 0
