"""``jaxnav sweep CONFIG --out DIR``: a parameter grid x Monte Carlo runs (:func:`jaxnav.experiments.tuning.run_sweep`).

CONFIG is a TOML file or the name of a shipped one (``s0_b``, ``cv_noise``; see
``jaxnav/experiments/configs/``); writes ``DIR/results.json``, ``DIR/table.csv`` and figures.
"""

from __future__ import annotations

import pathlib

from jaxnav.cli._common import add_config_parser, prepare_out, record_config, start_processes


def register(subparsers):
    """Add the ``sweep`` subcommand; returns its parser."""
    return add_config_parser(
        subparsers, "sweep", "vmap a parameter grid x Monte Carlo runs (chunked, sharded over devices)"
    )


def run(args) -> int:
    """Run the sweep, print its summary, write results.json, table.csv and figures into ``--out``."""
    from jaxnav.experiments.tuning import format_sweep, load_config, run_sweep

    writer = start_processes(args)  # several processes: all compute, process 0 writes and prints
    cfg = load_config(args.config)  # every section and key checked before any work
    record_config(args, cfg.get("_path", args.config), cfg)
    prepare_out(args.out)
    res = run_sweep(args.config, args.out, progress=not args.no_progress)
    out = pathlib.Path(args.out)
    if not writer:
        return 0
    print(format_sweep(res))
    print(f"wrote {out / 'results.json'}, {out / 'table.csv'} and {len(res['figures'])} figure(s)")
    return 0
