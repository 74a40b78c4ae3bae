"""What the command modules share: the data-folder lookup and the two error kinds of ``main``.

A command's ``run(args)`` raises :class:`UsageError` for a wrong combination of arguments and
:class:`CommandError` for anything else the user must fix; ``main`` prints either as one line
``jaxnav COMMAND: message`` and exits with 2. Numeric options are checked while parsing by the
``type=`` helpers here (:func:`int_range`, :func:`float_range`), and :func:`prepare_out` creates
and checks the output folder before any work. The study commands (Monte Carlo, sweeps, tuning)
take the multi-process options of :func:`add_process_args` and join the study's processes with
:func:`start_processes` before any JAX work. A command that reads a configuration file notes it
with :func:`record_config` (``main`` writes it into the provenance block of ``results.json``);
:func:`figure_format_list` parses ``--figure-format``.
"""

from __future__ import annotations

import argparse
import math
import os
import pathlib
import uuid

#: the most Monte Carlo seeds (and batch sizes) a command accepts
MAX_SEEDS = 100_000
#: environment variable naming the folder that holds the data sets (e.g. ``rtklibexplorer-gnss-imu/``)
DATA_ENV = "JAXNAV_DATA"


class CommandError(Exception):
    """A problem the user must fix; ``jaxnav`` prints ``jaxnav COMMAND: MESSAGE`` and exits with 2."""


def begin_computation(args) -> None:
    """Note that the checks of the input are done and the computation starts: from here on a plain
    ``ValueError`` (not a reader, config or command error) is not an input problem ``main`` can name,
    so it exits with 3 and says how long the computation ran."""
    import time

    args._computing_since = time.perf_counter()


class UsageError(CommandError):
    """Wrong or missing arguments; ``jaxnav`` prints ``jaxnav COMMAND: MESSAGE (see ... --help)``, exits with 2."""


def int_range(lo: int | None = None, hi: int | None = None):
    """An argparse ``type=``: an integer in [lo, hi] (None: unbounded), else a one-line argparse error."""

    def parse(text):
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if (lo is not None and v < lo) or (hi is not None and v > hi):
            raise argparse.ArgumentTypeError(f"must be {_range_text(lo, hi)}, got {v}")
        return v

    parse.__name__ = "integer"
    return parse


def float_range(lo: float | None = None, hi: float | None = None, *, lo_open=False, hi_open=False):
    """An argparse ``type=``: a finite number in [lo, hi] (``lo_open``/``hi_open``: excluded ends)."""

    def parse(text):
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        bad = (
            not math.isfinite(v)
            or (lo is not None and (v <= lo if lo_open else v < lo))
            or (hi is not None and (v >= hi if hi_open else v > hi))
        )
        if bad:
            raise argparse.ArgumentTypeError(
                f"must be a finite number {_range_text(lo, hi, lo_open, hi_open)}, got {text}"
            )
        return v

    parse.__name__ = "number"
    return parse


def _range_text(lo, hi, lo_open=False, hi_open=False):
    if lo is not None and hi is not None:
        return f"in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
    if lo is not None:
        return f"{'>' if lo_open else '>='} {lo:g}"
    if hi is not None:
        return f"{'<' if hi_open else '<='} {hi:g}"
    return "finite"


def prepare_out(out, option: str = "--out") -> pathlib.Path:
    """Create the output folder ``out`` and check that a file can be written in it, before any work.

    Raises:
      CommandError: naming the folder and the option, if it cannot be created or written.
    """
    path = pathlib.Path(out)
    if path.exists() and not path.is_dir():
        raise CommandError(f"{path}: {option} names an existing file, not a folder")
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = path / f".jaxnav-write-test-{uuid.uuid4().hex}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise CommandError(f"{path}: cannot write the output folder ({option}): {exc.strerror or exc}") from None
    return path


def input_file(path, option: str) -> pathlib.Path:
    """``path`` if it is a readable file, else :class:`CommandError` naming it and the option."""
    p = pathlib.Path(path)
    if not p.exists():
        raise CommandError(f"{p}: no such file ({option})")
    if not p.is_file():
        raise CommandError(f"{p}: not a file ({option})")
    if not os.access(p, os.R_OK):
        raise CommandError(f"{p}: not readable ({option})")
    return p


def data_dir(args_data, subfolder: str, *, required: bool = True) -> pathlib.Path | None:
    """The folder of one data set: ``<root>/<subfolder>``, the root being ``--data`` or ``$JAXNAV_DATA``.

    Every command gives ``--data`` (and ``JAXNAV_DATA``) the same meaning: the folder that holds the
    data sets (like ``../shared/data``); a relative one is taken against the working directory.

    Args:
      args_data: the command's ``--data`` value or None.
      subfolder: the data set's folder name inside the root (e.g. "rtklibexplorer-gnss-imu").
      required: without ``--data`` and ``JAXNAV_DATA``, raise (True) or return None (False; a
        ``$JAXNAV_DATA`` without ``<subfolder>`` then also gives None, while a ``--data`` without it
        is still an error: the user asked for it).
    Returns:
      The data set's folder (absolute), or None (``required=False`` only).
    Raises:
      CommandError: neither is set (``required``), or a folder does not exist; the message names the
        folder searched and where it came from.
    """
    if args_data:
        root, source = data_root(args_data, "--data"), "--data"
    elif os.environ.get(DATA_ENV):
        root, source = data_root(os.environ[DATA_ENV], DATA_ENV), DATA_ENV
    elif required:
        raise CommandError(
            f"no data folder: give --data DIR or set {DATA_ENV} (the folder that holds the "
            f"data sets, with {subfolder}/ in it)"
        )
    else:
        return None
    path = root / subfolder
    if path.is_dir():
        return path
    if not required and source == DATA_ENV:
        return None
    hint = ""
    if root.name == subfolder:
        hint = f"; {root} looks like the data set itself: give the folder that holds it ({root.parent})"
    raise CommandError(
        f"{path}: no such data folder ({source} = {root}, the folder that holds the data sets, "
        f"has no {subfolder}/{hint})"
    )


def data_root(value, source: str) -> pathlib.Path:
    """``--data`` / ``$JAXNAV_DATA`` as an absolute folder (relative: against the working directory).

    Raises:
      CommandError: not an existing folder (naming the folder searched and ``source``).
    """
    path = pathlib.Path(os.path.abspath(os.path.expanduser(os.fspath(value))))
    if not path.is_dir():
        what = "a file, not a folder" if path.exists() else "no such data folder"
        raise CommandError(f"{path}: {what} ({source} = {value})")
    return path


def add_config_parser(subparsers, name: str, what: str):
    """Add ``jaxnav NAME CONFIG [--out DIR] [--no-progress]`` (the ``sweep`` and ``tune`` commands).

    Args:
      subparsers: from ``ArgumentParser.add_subparsers``.  name: the command.  what: its help text.
    Returns:
      The subcommand's parser.
    """
    p = subparsers.add_parser(name, help=f"{what}; CONFIG is a TOML file or a shipped name (s0_b, cv_noise)")
    p.add_argument("config", help="sweep/tune TOML, or the name of a shipped one: s0_b, cv_noise")
    p.add_argument(
        "--out", default=f"out/{name}", help=f"output folder (created and checked first); default out/{name}"
    )
    p.add_argument("--no-progress", action="store_true", help="hide the progress bars")
    add_process_args(p)
    return p


def add_process_args(p):
    """Add ``--coordinator HOST:PORT --num-processes N --process-id I`` (one study over several processes/hosts).

    Each defaults to the environment variable ``JAX_COORDINATOR_ADDRESS``, ``JAX_NUM_PROCESSES``,
    ``JAX_PROCESS_ID``; values still missing come from the cluster (SLURM, Open MPI) through
    ``jax.distributed.initialize``. Without any of them the command runs as one process.
    """
    g = p.add_argument_group("several processes or hosts (jax.distributed; process 0 writes the results)")
    g.add_argument(
        "--coordinator",
        default=None,
        metavar="HOST:PORT",
        help="address of process 0's coordinator, the same for all processes (default $JAX_COORDINATOR_ADDRESS)",
    )
    g.add_argument(
        "--num-processes",
        type=int_range(1, 100_000),
        default=None,
        metavar="N",
        help="number of processes, >= 1 (default $JAX_NUM_PROCESSES, or from SLURM/Open MPI)",
    )
    g.add_argument(
        "--process-id",
        type=int_range(0, 99_999),
        default=None,
        metavar="I",
        help="this process, 0 .. N-1 (default $JAX_PROCESS_ID, or from SLURM/Open MPI)",
    )
    g.add_argument(
        "--join-timeout",
        type=int_range(1, 86_400),
        default=300,
        metavar="S",
        help="seconds to wait for all processes to join; default 300",
    )
    return g


def start_processes(args) -> bool:
    """Join the study's processes (:func:`jaxnav.tune.initialize`) from the options of :func:`add_process_args`.

    Call first in ``run(args)``, before any JAX work. Returns whether this process writes the
    results and prints the summary (process 0; always True for a single process).

    Raises:
      UsageError: a malformed address or an id outside 0 .. N-1.
      CommandError: the processes could not join (coordinator unreachable, timeout).
    """
    from jaxnav import tune

    try:
        tune.initialize(args.coordinator, args.num_processes, args.process_id, timeout_s=args.join_timeout)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    except Exception as exc:  # JAX's runtime errors (timeouts, unreachable coordinator)
        where = args.coordinator or os.environ.get("JAX_COORDINATOR_ADDRESS") or "the cluster's coordinator"
        raise CommandError(
            f"cannot join the processes of this study at {where}: {type(exc).__name__}: "
            f"{str(exc).strip().splitlines()[0] if str(exc).strip() else ''}"
        ) from None
    return tune.is_writer()


def figure_format_list(text: str) -> list:
    """An argparse ``type=``: ``"pdf,svg"`` -> ["pdf", "svg"] (each one of png, pdf, svg), else a one-line error."""
    from jaxnav.plot._save import FORMATS

    out = []
    for f in str(text).split(","):
        f = f.strip().lower().lstrip(".")
        if not f:
            continue
        if f not in FORMATS:
            raise argparse.ArgumentTypeError(
                f"unknown figure format {f!r}; choose from {', '.join(FORMATS)} (several: pdf,svg)"
            )
        out.append(f)
    if not out:
        raise argparse.ArgumentTypeError(f"expected figure formats ({', '.join(FORMATS)}), got {text!r}")
    return out


def record_config(args, path, contents=None) -> None:
    """Note the configuration a command runs with, for the provenance block of its ``results.json``.

    Args:
      args: the command's parsed arguments (``_config_file`` and ``_config`` are set on it).
      path: the configuration file (a shipped default included), or None.
      contents: its contents as a dict (default: the TOML file read again).
    """
    from jaxnav.io import load_toml

    args._config_file = None if path is None else str(path)
    if contents is None and path is not None:
        contents = load_toml(path)
    args._config = None if contents is None else {k: v for k, v in dict(contents).items() if not str(k).startswith("_")}
