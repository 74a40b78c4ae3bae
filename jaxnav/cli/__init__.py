"""Command line ``jaxnav``: a registry of command modules.

Each module of :data:`COMMANDS` (``jaxnav/cli/<name>.py``) has ``register(subparsers)``, which
adds its subcommand and returns the parser, and ``run(args) -> int``; the computation lives in
:mod:`jaxnav.experiments`.

One error path (:func:`main`): a problem the user must fix -- a bad option or value
(:class:`~jaxnav.cli._common.UsageError`, argparse errors), a bad file or config
(:class:`~jaxnav.cli._common.CommandError`, :class:`jaxnav.io.ReaderError` and the other
``ValueError`` raised by jaxnav's own checks, ``OSError``) -- prints one line
``jaxnav COMMAND: FILE:LINE: message`` to stderr and exits with 2; anything else (a ValueError from
inside numpy or JAX included, and a plain ValueError raised after the command has called
:func:`~jaxnav.cli._common.begin_computation`, with the seconds it ran) is an internal error: one
line saying so, exit 3.
``--debug`` (before or after the command) shows the traceback instead.

Options of every command, accepted before or after the command's name (``jaxnav -q rtk ...`` and
``jaxnav rtk -q ...`` are the same):

* ``--version``: prints ``jaxnav X.Y.Z`` and exits with 0 (before the command only).
* ``-q/--quiet``: no progress and no info lines on stderr; warnings, errors and the command's
  summary (stdout) still show. ``-v/--verbose``: also debug lines (timings, devices, config).
  Messages go through the ``logging`` logger ``"jaxnav"`` (INFO by default, WARNING with ``-q``,
  DEBUG with ``-v``), one line each on stderr; progress follows :mod:`jaxnav._progress` (a tqdm
  bar on a terminal, plain lines otherwise). The last of ``-q``/``-v`` given wins.
* ``--figure-format FMT [FMT ...]``: also write every figure as PDF and/or SVG beside the PNG
  (png, pdf, svg; ``pdf svg``, ``pdf,svg`` or the option repeated; default png), through
  :func:`jaxnav.plot.figure_formats`. Only the words png/pdf/svg after the option are taken as
  formats, so ``--figure-format pdf FILE`` leaves FILE to the command.

Outputs: each command writes into ``--out`` (default ``out/<command>``; ``jaxnav ins``:
``out/ins/<config name>``) and, after it succeeds, :func:`main` completes ``results.json`` there
(creating it if the command wrote none) with a ``"provenance"`` block (:func:`jaxnav.io.provenance`:
version, commit, UTC date, command line, every option, the config file and its contents) and a
``"files"`` list (every file the run wrote, relative to the folder). The command's own JSON
(``rtk_results.json``, ``monitor.json``) gets the same ``"provenance"`` block.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import pathlib
import sys
import time

from jaxnav.cli._common import CommandError, UsageError, figure_format_list

#: the command modules, in the order of ``jaxnav --help``
COMMANDS = ("demo", "demo_filters", "ins", "allan", "walk", "rtk", "cadastral", "monitor", "sweep", "tune")
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


def _add_common(p, top: bool):
    """The options every command takes (see the module docstring); on a subcommand they default to
    SUPPRESS, so that a value given before the command is not overwritten by the subcommand's default."""
    d = {} if top else {"default": argparse.SUPPRESS}
    p.add_argument(
        "--debug", action="store_true", help="show the Python traceback of any error" if top else argparse.SUPPRESS, **d
    )
    p.add_argument(
        "-q",
        "--quiet",
        dest="verbosity",
        action="store_const",
        const=-1,
        help="no progress and no info lines; warnings, errors and the summary still show",
        **({"default": 0} if top else d),
    )
    p.add_argument(
        "-v",
        "--verbose",
        dest="verbosity",
        action="store_const",
        const=1,
        help="also debug lines (timings, devices, configuration)",
        **d,
    )
    p.add_argument(
        "--figure-format",
        dest="figure_formats",
        action="extend",
        type=figure_format_list,
        metavar="FMT",
        help="also write every figure in these formats beside the PNG: png, pdf, svg (several: "
        "'pdf svg' or 'pdf,svg'); default png",
        **({"default": []} if top else d),
    )


class _LineFormatter(logging.Formatter):
    """INFO lines as they are; other levels prefixed with the level name (``warning: ...``)."""

    def format(self, record):
        msg = record.getMessage()
        return msg if record.levelno == logging.INFO else f"{record.levelname.lower()}: {msg}"


class _StderrHandler(logging.StreamHandler):
    """A handler that writes to whatever ``sys.stderr`` is at the time of the record."""

    @property
    def stream(self):
        return sys.stderr

    @stream.setter
    def stream(self, value):
        pass


def _setup_logging(verbosity: int):
    """Level and handler of the ``"jaxnav"`` logger for one command; returns the undo function."""
    log = logging.getLogger("jaxnav")
    saved = (log.level, log.propagate)
    handler = _StderrHandler()
    handler.setFormatter(_LineFormatter())
    log.addHandler(handler)
    log.setLevel(logging.WARNING if verbosity < 0 else logging.DEBUG if verbosity > 0 else logging.INFO)
    log.propagate = False

    def undo():
        log.removeHandler(handler)
        log.setLevel(saved[0])
        log.propagate = saved[1]

    return undo


def main(argv=None) -> int:
    """Entry point of the ``jaxnav`` command: parse, enable float64, dispatch to the command's ``run``,
    complete ``results.json`` in the output folder.

    Returns:
      0 on success, 2 for an error the user must fix (one line on stderr), 3 for an internal error.
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    import matplotlib

    matplotlib.use("Agg")  # the commands write figures to files; the library leaves the backend to the user
    head = argv[: argv.index("--")] if "--" in argv else argv
    debug = "--debug" in head
    first_command = next((i for i, a in enumerate(head) if a in _command_names()), len(head))
    if "--version" in head[:first_command]:
        import jaxnav

        print(f"jaxnav {jaxnav.__version__}")
        return 0
    parser = _Parser(
        prog="jaxnav",
        description="jaxnav command line",
        epilog=(
            "-q, -v, --debug and --figure-format go before or after the command. Each command writes into --out "
            "(default out/<command>) and records there results.json: jaxnav version, git commit, UTC date, the "
            "command line, every option, the config file and its contents, and the files written. Messages and "
            "progress go to stderr (a bar on a terminal, plain lines otherwise), the summary to stdout."
        ),
    )
    parser.add_argument("--version", action="store_true", help="print 'jaxnav X.Y.Z' and exit")
    _add_common(parser, top=True)
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for mod in _modules():
        p = mod.register(sub)
        _add_common(p, top=False)
        p.set_defaults(_run=mod.run, _parser=p)
    prog = "jaxnav"
    undo = args = None
    try:
        args, extra = parser.parse_known_args(_join_figure_formats(argv))
        prog = args._parser.prog
        if extra:
            raise UsageError(f"unrecognized arguments: {' '.join(extra)}", prog)
        undo = _setup_logging(args.verbosity)
        import jaxnav
        from jaxnav.plot import figure_formats

        jaxnav.enable_x64()  # navigation states and absolute coordinates are float64
        args._argv = argv  # the words after "jaxnav", as given
        start = _Start(args)
        log = logging.getLogger("jaxnav")
        if log.isEnabledFor(logging.DEBUG):  # no jax.devices() here: it would start JAX before jax.distributed
            from jaxnav.io import git_commit

            log.debug(
                "jaxnav %s (commit %s), Python %s, command: jaxnav %s",
                jaxnav.__version__,
                git_commit(),
                sys.version.split()[0],
                " ".join(argv),
            )
            log.debug(
                "options: %s",
                ", ".join(
                    f"{k}={v!r}" for k, v in sorted(vars(args).items()) if not k.startswith("_") and k != "version"
                ),
            )
            log.debug("figures written as: %s", ", ".join(["png", *[f for f in args.figure_formats if f != "png"]]))
        with figure_formats(*args.figure_formats):
            rc = args._run(args)
        if rc == 0:
            start.finish(args, argv)
        return rc
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
        since = getattr(args, "_computing_since", None) if args is not None else None
        if type(exc) is ValueError and since is not None:
            return _internal(prog, exc, after_s=time.perf_counter() - since)
        print(f"{prog}: {_message(exc)}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        if debug:
            raise
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # the one place that turns a bug into a message
        if debug:
            raise
        return _internal(prog, exc)
    finally:
        if undo is not None:
            undo()


def _join_figure_formats(argv):
    """``--figure-format pdf svg`` -> ``--figure-format pdf,svg``: the format words after the option (png,
    pdf, svg, or comma lists of them) become its one value; anything else is left to the command."""
    from jaxnav.plot._save import FORMATS

    def is_formats(word):
        parts = [w.strip().lower().lstrip(".") for w in word.split(",") if w.strip()]
        return bool(parts) and all(w in FORMATS for w in parts)

    out, i = [], 0
    while i < len(argv):
        a = argv[i]
        if a == "--":
            return out + argv[i:]
        out.append(a)
        i += 1
        if a == "--figure-format":
            j = i
            while j < len(argv) and is_formats(argv[j]):
                j += 1
            if j > i + 1:
                out.append(",".join(argv[i:j]))
                i = j
    return out


def _command_names():
    return {c.replace("_", "-") for c in COMMANDS}


class _Start:
    """What :func:`main` records before a command runs, to complete its ``results.json`` afterwards."""

    def __init__(self, args):
        from jaxnav.io import files_snapshot, utc_now

        self.date_utc = utc_now()
        self.t0 = time.perf_counter()
        self.ns = time.time_ns()
        out = getattr(args, "out", None)
        self.snapshot = files_snapshot(out) if out else None

    def finish(self, args, argv):
        """Write the provenance block and the files list into ``<out>/results.json`` (and the command's own
        JSON); process 0 only in a multi-process study."""
        out = getattr(args, "out", None)
        if not out or not pathlib.Path(out).is_dir() or not _is_writer():
            return
        from jaxnav.io import files_written, provenance, utc_now

        out = pathlib.Path(out)
        options = {k: v for k, v in vars(args).items() if not k.startswith("_") and k not in ("command", "version")}
        prov = provenance(
            argv=argv,
            options=options,
            config_file=getattr(args, "_config_file", None),
            config=getattr(args, "_config", None),
            date_utc=self.date_utc,
        )
        prov["subcommand"] = args.command
        prov["finished_utc"] = utc_now()
        prov["wall_time_s"] = time.perf_counter() - self.t0
        snapshot = getattr(args, "_snapshot", self.snapshot)  # a command that resolves --out itself takes its own
        written = set(files_written(out, snapshot, self.ns))
        own = tuple(n for n in getattr(args, "_json_outputs", ()) if n in written)
        for name in own:
            _complete(out / name, prov, None)
        # a results.json left by an earlier run (of another command) in the same folder is replaced, not merged
        _complete(
            out / "results.json",
            prov,
            sorted(written | {"results.json"}),
            results_in=own,
            fresh="results.json" not in written,
        )
        files = written | {"results.json"}
        logging.getLogger("jaxnav").info(
            "wrote the provenance and the list of the %d files written into %s", len(files), out / "results.json"
        )


def _is_writer() -> bool:
    """True unless this is a non-zero process of a multi-process study (checked only if JAX is loaded)."""
    if "jax" not in sys.modules:
        return True
    from jaxnav import tune

    return tune.is_writer()


def _complete(path: pathlib.Path, prov: dict, files, results_in=(), fresh=False):
    """Add ``provenance`` (merged over one the command wrote) and ``files`` to the JSON object at ``path``
    (created -- or replaced with ``fresh`` -- if ``files`` is given, then with ``results_in``: the
    command's own JSON files)."""
    import json

    from jaxnav.io import write_json

    if path.is_file() and not fresh:
        data = json.loads(path.read_text(encoding="utf-8"))
        if not isinstance(data, dict):
            data = {"results": data}
    elif files is not None:
        data = {"results_in": list(results_in)} if results_in else {}
    else:
        return
    own = data.get("provenance") if isinstance(data.get("provenance"), dict) else {}
    merged = {**own, **{k: v for k, v in prov.items() if v is not None or k not in own}}
    data = {"provenance": merged, **{k: v for k, v in data.items() if k != "provenance"}}
    if files is not None:
        data["files"] = files
    write_json(path, data)


def _internal(prog: str, exc: BaseException, after_s: float | None = None) -> int:
    """Print the one line of an internal error (``after_s``: raised that long into the computation,
    after the input was checked); returns :data:`EXIT_INTERNAL`."""
    if after_s is not None:
        print(
            f"{prog}: stopped {after_s:.1f} s into the computation, after the input was checked: "
            f"{_one_line(exc)[:300]} (if this names a setting or file of yours, change it; otherwise it is a bug "
            f"in jaxnav: rerun with --debug for the traceback and report it)",
            file=sys.stderr,
        )
        return EXIT_INTERNAL
    print(
        f"{prog}: internal error: {type(exc).__name__}: {_one_line(exc)[:300]} (a bug in jaxnav: rerun with "
        f"--debug for the traceback and report it)",
        file=sys.stderr,
    )
    return EXIT_INTERNAL


if __name__ == "__main__":
    sys.exit(main())
