"""Command line ``jaxnav``: a registry of command modules.

Each module of :data:`COMMANDS` (``jaxnav/cli/<name>.py``) has ``register(subparsers)``, which
adds its subcommand and returns the parser, and ``run(args) -> int``; the computation lives in
:mod:`jaxnav.experiments`. Errors a user must fix are :class:`~jaxnav.cli._common.CommandError`
(one line, exit status 2) or :class:`~jaxnav.cli._common.UsageError` (usage and message, 2).
"""

from __future__ import annotations

import argparse
import importlib
import sys

from jaxnav.cli._common import CommandError, UsageError

#: the command modules, in the order of ``jaxnav --help``
COMMANDS = ("demo", "demo_filters", "walk", "rtk", "cadastral", "monitor", "sweep", "tune")


def _modules():
    """The command modules of :data:`COMMANDS` (each imports its experiment only in ``run``)."""
    return [importlib.import_module(f"jaxnav.cli.{c}") for c in COMMANDS]


def main(argv=None) -> int:
    """Entry point of the ``jaxnav`` command: parse, enable float64, dispatch to the command's ``run``."""
    parser = argparse.ArgumentParser(prog="jaxnav", description="jaxnav command line")
    sub = parser.add_subparsers(dest="command", required=True)
    for mod in _modules():
        p = mod.register(sub)
        p.set_defaults(_run=mod.run, _parser=p)
    args = parser.parse_args(argv)
    import jaxnav

    jaxnav.enable_x64()  # navigation states and absolute coordinates are float64
    try:
        return args._run(args)
    except UsageError as exc:
        args._parser.error(str(exc))
    except CommandError as exc:
        print(f"{args._parser.prog}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
