"""``jaxnav tune CONFIG --out DIR``: gradient tuning of filter parameters (:func:`jaxnav.experiments.tuning.run_tune`).

CONFIG is a TOML file or the name of a shipped one (``s0_b``, ``cv_noise``; see
``jaxnav/experiments/configs/``); writes ``DIR/results.json`` and figures.
"""

from __future__ import annotations

import pathlib

from jaxnav.cli._common import add_config_parser, prepare_out, record_config, start_processes


def register(subparsers):
    """Add the ``tune`` subcommand; returns its parser."""
    return add_config_parser(subparsers, "tune", "tune filter parameters by gradient descent (optax inside lax.scan)")


def run(args) -> int:
    """Run the tuning, print its summary, write results.json and figures into ``--out``."""
    from jaxnav.experiments.tuning import format_tune, load_config, run_tune

    writer = start_processes(args)  # several processes: all compute, process 0 writes and prints
    cfg = load_config(args.config)  # every section and key checked before any work
    record_config(args, cfg.get("_path", args.config), cfg)
    prepare_out(args.out)
    res = run_tune(args.config, args.out, progress=not args.no_progress)
    out = pathlib.Path(args.out)
    if not writer:
        return 0
    print(format_tune(res))
    print(f"wrote {out / 'results.json'} and {len(res['figures'])} figure(s)")
    return 0
