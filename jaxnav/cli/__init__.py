"""Command line ``jaxnav``: a registry of command modules.

Each module of :data:`COMMANDS` (``jaxnav/cli/<name>.py``) has ``register(subparsers)``, which
adds its subcommand and returns the parser, and ``run(args) -> int``; the computation lives in
:mod:`jaxnav.experiments`.

One error path (:func:`main`): a problem the user must fix -- a bad option or value
(:class:`~jaxnav.cli._common.UsageError`, argparse errors), a bad file or config
(:class:`~jaxnav.cli._common.CommandError`, :class:`jaxnav.io.ReaderError` and the other
``ValueError`` raised by jaxnav's own checks, ``OSError``) -- prints one line
``jaxnav COMMAND: FILE:LINE: message`` to stderr and exits with 2; anything else (a ValueError from
inside numpy or JAX included) is an internal error: one line saying so, exit 3.
``--debug`` (before or after the command) shows the traceback instead.
"""

from __future__ import annotations

import argparse
import importlib
import pathlib
import sys

from jaxnav.cli._common import CommandError, UsageError

#: the command modules, in the order of ``jaxnav --help``
COMMANDS = ("demo", "demo_filters", "ins", "walk", "rtk", "cadastral", "monitor", "sweep", "tune")
#: exit status of an error the user must fix (bad option, value, file or config)
EXIT_USAGE = 2
#: exit status of an internal error (a bug: please report it with the ``--debug`` traceback)
EXIT_INTERNAL = 3


class _Parser(argparse.ArgumentParser):
    """argparse, but an error raises :class:`UsageError` (one line, no usage block) instead of exiting."""

    def error(self, message):
        raise UsageError(message, self.prog)


def _modules():
    """The command modules of :data:`COMMANDS` (each imports its experiment only in ``run``)."""
    return [importlib.import_module(f"jaxnav.cli.{c}") for c in COMMANDS]


_PACKAGE = pathlib.Path(__file__).resolve().parents[1]


def _raised_by_jaxnav(exc: BaseException) -> bool:
    """True if the innermost frame of ``exc`` is jaxnav's own code (a deliberate check of the input),
    False if it came from inside numpy, JAX or another library (then it is a bug, not bad input)."""
    tb = exc.__traceback__
    if tb is None:
        return True
    while tb.tb_next is not None:
        tb = tb.tb_next
    try:
        return pathlib.Path(tb.tb_frame.f_code.co_filename).resolve().is_relative_to(_PACKAGE)
    except (OSError, ValueError):
        return False


def _one_line(text: str) -> str:
    """The message on one line (inner line breaks become ' | ')."""
    return " | ".join(s.strip() for s in str(text).strip().splitlines() if s.strip())


def _message(exc: BaseException) -> str:
    """What the user reads for an expected error."""
    if isinstance(exc, OSError) and exc.filename is not None:
        return f"{exc.filename}: {exc.strerror or exc}"
    return _one_line(exc)


def main(argv=None) -> int:
    """Entry point of the ``jaxnav`` command: parse, enable float64, dispatch to the command's ``run``.

    Returns:
      0 on success, 2 for an error the user must fix (one line on stderr), 3 for an internal error.
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv[: argv.index("--")] if "--" in argv else "--debug" in argv
    parser = _Parser(prog="jaxnav", description="jaxnav command line")
    parser.add_argument("--debug", action="store_true", help="show the Python traceback of any error")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for mod in _modules():
        p = mod.register(sub)
        p.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help=argparse.SUPPRESS)
        p.set_defaults(_run=mod.run, _parser=p)
    prog = "jaxnav"
    try:
        args, extra = parser.parse_known_args(argv)
        prog = args._parser.prog
        if extra:
            raise UsageError(f"unrecognized arguments: {' '.join(extra)}", prog)
        import jaxnav

        jaxnav.enable_x64()  # navigation states and absolute coordinates are float64
        return args._run(args)
    except UsageError as exc:
        if debug:
            raise
        where = exc.args[1] if len(exc.args) > 1 else prog
        print(f"{where}: {_one_line(exc.args[0])} (see '{where} --help')", file=sys.stderr)
        return EXIT_USAGE
    except (CommandError, ValueError, OSError) as exc:
        if debug:
            raise
        if isinstance(exc, ValueError) and not _raised_by_jaxnav(exc):
            return _internal(prog, exc)
        print(f"{prog}: {_message(exc)}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        if debug:
            raise
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - the one place that turns a bug into a message
        if debug:
            raise
        return _internal(prog, exc)


def _internal(prog: str, exc: BaseException) -> int:
    """Print the one line of an internal error; returns :data:`EXIT_INTERNAL`."""
    print(f"{prog}: internal error: {type(exc).__name__}: {_one_line(exc)[:300]} (a bug in jaxnav: rerun with "
          f"--debug for the traceback and report it)", file=sys.stderr)
    return EXIT_INTERNAL


if __name__ == "__main__":
    sys.exit(main())
