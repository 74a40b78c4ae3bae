"""What the command modules share: the data-folder lookup and the two error kinds of ``main``.

A command's ``run(args)`` raises :class:`UsageError` for a wrong combination of arguments
(``main`` prints the command's usage and the message, exit status 2, as argparse does) and
:class:`CommandError` for anything else the user must fix (``main`` prints one line, status 2).
"""

from __future__ import annotations

import os
import pathlib
from typing import Optional

#: environment variable naming the folder that holds the data sets (e.g. ``rtklibexplorer-gnss-imu/``)
DATA_ENV = "JAXNAV_DATA"


class CommandError(Exception):
    """A problem the user must fix; ``jaxnav`` prints ``jaxnav COMMAND: error: MESSAGE`` and exits with 2."""


class UsageError(CommandError):
    """Wrong or missing arguments; ``jaxnav`` prints the command's usage and the message and exits with 2."""


def data_dir(args_data, subfolder: str, *, required: bool = True) -> Optional[pathlib.Path]:
    """The data folder of a command: ``--data`` if given, else ``$JAXNAV_DATA/<subfolder>``.

    Args:
      args_data: the command's ``--data`` value (the data set's own folder) or None.
      subfolder: the data set's folder name inside ``$JAXNAV_DATA`` (e.g. "rtklibexplorer-gnss-imu").
      required: without ``--data`` and ``JAXNAV_DATA``, raise (True) or return None (False; a
        missing ``$JAXNAV_DATA/<subfolder>`` then also gives None).
    Returns:
      The folder, or None (``required=False`` only).
    Raises:
      CommandError: neither is set (``required``), or the folder does not exist.
    """
    if args_data:
        path, source = pathlib.Path(args_data), "--data"
    elif os.environ.get(DATA_ENV):
        path, source = pathlib.Path(os.environ[DATA_ENV]) / subfolder, DATA_ENV
        if not required and not path.is_dir():
            return None
    elif required:
        raise CommandError(f"no data folder: give --data DIR (the {subfolder} folder) or set {DATA_ENV} "
                           f"to the folder that holds {subfolder}/")
    else:
        return None
    if not path.is_dir():
        raise CommandError(f"{path}: no such data folder (from {source})")
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
    p.add_argument("--out", default=f"out/{name}", help=f"output folder; default out/{name}")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bars")
    return p
