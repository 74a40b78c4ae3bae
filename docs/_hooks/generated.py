"""mkdocs hook: page content generated from the code at build time, so it cannot drift from it.

* ``<!-- jaxnav-cli-reference -->``: ``jaxnav --help`` and one section per command of
  ``jaxnav.cli.COMMANDS`` with its ``--help`` text, from the real entry point (``--help`` only
  parses and exits; no command runs).
* ``<!-- jaxnav-status-flags -->``: the table of status bit flags and their messages.
* ``<!-- jaxnav-reexports PACKAGE MODULE[,MODULE...] -->``: a mkdocstrings ``::: PACKAGE.NAME``
  block for each of the names PACKAGE's ``__init__`` imports from those modules, for a package without
  ``__all__`` (mkdocstrings shows only ``__all__`` re-exports by itself), read from the source
  so that a new re-export appears without editing the page.
"""

from __future__ import annotations

import argparse
import ast
import importlib
import os
import pathlib
import re

MARKER = "<!-- jaxnav-cli-reference -->"
FLAGS_MARKER = "<!-- jaxnav-status-flags -->"
REEXPORTS = re.compile(r"<!-- jaxnav-reexports (?P<pkg>[\w.]+) (?P<mods>[\w.,]+) -->")
ROOT = pathlib.Path(__file__).resolve().parents[2]


def _help(argv):
    """What ``jaxnav ARGV`` prints on stdout (argparse prints the help and exits with 0)."""
    import contextlib
    import io

    from jaxnav import cli

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        try:
            status = cli.main(list(argv))
        except SystemExit as exc:
            status = exc.code
    if status not in (0, None):
        raise RuntimeError(f"jaxnav {' '.join(argv)} exited with {status}")
    return buf.getvalue()


def _help_texts():
    """(command line, help text) for ``jaxnav --help`` and ``jaxnav COMMAND --help``, at 100 columns.

    The texts come from running the real entry point, so options that ``jaxnav.cli.main`` adds
    itself appear as well as each command's own.
    """
    from jaxnav import cli

    old = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = "100"  # argparse wraps at $COLUMNS; fixed for a reproducible page
    try:
        out = [("jaxnav", _help(["--help"]))]
        for name in cli.COMMANDS:
            mod = importlib.import_module(f"jaxnav.cli.{name}")
            # the subcommand's name as registered (demo_filters -> demo-filters)
            sub = argparse.ArgumentParser(prog="jaxnav").add_subparsers()
            command = mod.register(sub).prog.split()[-1]
            out.append((f"jaxnav {command}", _help([command, "--help"])))
    finally:
        if old is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = old
    return out


def _flags_table():
    """Markdown table of the status flags: bit value, name, whether it is informational, message."""
    from jaxnav import _status

    names = {v: k for k, v in vars(_status).items() if k.isupper() and isinstance(v, int) and v in _status._MESSAGES}
    rows = ["| bit | flag | kind | meaning |", "|---:|---|---|---|"]
    for bit, msg in _status._MESSAGES.items():
        kind = "information" if bit & _status.INFO_FLAGS else "error"
        rows.append(f"| {bit} | `{names.get(bit, '?')}` | {kind} | {msg.replace('|', '/')} |")
    return "\n".join(rows) + "\n"


def _reexports(m: re.Match) -> str:
    """The ``:::`` block for one reexports marker (see the module docstring)."""
    pkg, mods = m["pkg"], set(m["mods"].split(","))
    init = ROOT.joinpath(*pkg.split(".")) / "__init__.py"
    names = []
    for node in ast.parse(init.read_text(encoding="utf-8")).body:
        if isinstance(node, ast.ImportFrom) and node.module in mods:
            names += [a.asname or a.name for a in node.names]
    if not names:
        raise ValueError(f"{init}: imports nothing from {sorted(mods)}")
    # one block per name (a block for the package would repeat the package's docstring)
    return "\n".join(f"::: {pkg}.{n}\n    options:\n      heading_level: 3\n" for n in names)


def on_page_markdown(markdown, page, config, files):
    """Replace the marker lines with the generated content."""
    markdown = REEXPORTS.sub(_reexports, markdown)
    if FLAGS_MARKER in markdown:
        markdown = markdown.replace(FLAGS_MARKER, _flags_table())
    if MARKER not in markdown:
        return markdown
    parts = []
    for prog, text in _help_texts():
        title = prog if prog == "jaxnav" else f"`{prog}`"
        parts.append(f"## {title}\n\n```text\n{text.rstrip()}\n```\n")
    return markdown.replace(MARKER, "\n".join(parts))
