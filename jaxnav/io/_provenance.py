"""Provenance of an output folder (host side): who wrote it, from what, when.

Every ``jaxnav`` command writes ``results.json`` into its output folder with a top-level
``"provenance"`` block (:func:`provenance`) and a ``"files"`` list (:func:`files_written`); the
other JSON files a command writes (``rtk_results.json``, ``monitor.json``) carry the same
``"provenance"`` block. Keys of the block:

* ``jaxnav_version``, ``git_commit`` (short hash of the jaxnav checkout, ``+dirty`` for local
  changes to ``jaxnav/``; null outside a git checkout), ``python_version``, ``jax_version``;
* ``date_utc`` (ISO 8601, start of the run), ``finished_utc``, ``wall_time_s``;
* ``command`` (the command line as one shell-quoted string), ``argv`` (its words),
  ``cwd`` (the working folder, against which relative paths are read);
* ``options`` (every parsed option of the command, defaults included);
* ``config_file`` and ``config`` (the configuration file's path and its full contents, where the
  command reads one; null otherwise).
"""

from __future__ import annotations

import datetime as _dt
import os
import pathlib
import platform
import shlex
import subprocess
from collections.abc import Iterable
from importlib import metadata

_ROOT = pathlib.Path(__file__).resolve().parents[2]


def git_commit(root=None) -> str | None:
    """Short git commit of the jaxnav checkout (with ``+dirty`` for local changes to ``jaxnav/``),
    or None outside a checkout or without git."""
    root = pathlib.Path(root) if root is not None else _ROOT
    if not (root / ".git").exists():
        return None
    try:
        rev = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=root, capture_output=True, text=True, timeout=10
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--", "jaxnav"], cwd=root, capture_output=True, text=True, timeout=10
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return (rev + ("+dirty" if dirty else "")) or None


def utc_now() -> str:
    """The current UTC time, ISO 8601 to the second (e.g. ``2026-01-31T12:00:00+00:00``)."""
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")


def _version(dist: str) -> str | None:
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return None


def provenance(
    *,
    argv: Iterable[str] | None = None,
    options: dict | None = None,
    config_file=None,
    config=None,
    date_utc: str | None = None,
) -> dict:
    """The provenance block (keys in the module docstring).

    Args:
      argv: the words after ``jaxnav`` (default: none recorded).  options: the parsed options.
      config_file, config: the configuration file and its contents, where there is one.
      date_utc: start time (default now).
    """
    import jaxnav

    words = None if argv is None else [str(a) for a in argv]
    return {
        "jaxnav_version": jaxnav.__version__,
        "git_commit": git_commit(),
        "python_version": platform.python_version(),
        "jax_version": _version("jax"),
        "date_utc": date_utc or utc_now(),
        "command": None if words is None else shlex.join(["jaxnav", *words]),
        "argv": words,
        "cwd": os.getcwd(),
        "options": options,
        "config_file": None if config_file is None else str(config_file),
        "config": config,
    }


def files_snapshot(folder) -> dict:
    """{relative path: (mtime_ns, size)} of every file under ``folder`` (empty if it does not exist)."""
    folder = pathlib.Path(folder)
    if not folder.is_dir():
        return {}
    snap = {}
    for p in folder.rglob("*"):
        try:
            if p.is_file():
                st = p.stat()
                snap[p.relative_to(folder).as_posix()] = (st.st_mtime_ns, st.st_size)
        except OSError:
            continue
    return snap


def files_written(folder, before: dict | None, since_ns: int) -> list:
    """Files under ``folder`` created or changed since the snapshot ``before`` (:func:`files_snapshot`;
    None: no snapshot) or modified at or after ``since_ns`` (``time.time_ns()``): sorted paths relative
    to ``folder``."""
    now = files_snapshot(folder)
    return sorted(k for k, v in now.items() if (before is not None and before.get(k) != v) or v[0] >= since_ns)
