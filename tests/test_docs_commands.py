"""Every command line of README.md and docs/ (```console and ```bash blocks, and indented ``jaxnav``
lines) is checked as written, so that none can rot.

What each kind of line gets (honestly: most of these commands need minutes, so they are not run to
the end here; their computations are covered by the tests of their modules):

* ``jaxnav ...`` (with any ``VAR=value`` before it): run through :func:`jaxnav.cli.main` in process,
  from a clone's root (``../shared/data`` is the shared data, as the README assumes), up to the
  point where the command has parsed its options, resolved and checked every input (config keys,
  data folders, files) and is about to create its output folder; there it is stopped (the heavy
  part is not run). Joining other processes (``--coordinator``) is not attempted.
* ``make TARGET``: ``make -n TARGET`` (the target exists and its recipe expands); the ``jaxnav`` line of
  the recipe is then checked as above.
* ``pip install -e SPEC``: the extras named in SPEC exist in pyproject.toml (nothing is installed).
* a ``#!/bin/bash`` job script: ``bash -n`` (syntax only).
"""

from __future__ import annotations

import os
import pathlib
import re
import shlex
import shutil
import subprocess
import tomllib

import pytest
from _paths import DATA_ROOT, ROOT

BLOCK = re.compile(r"^```(?:console|bash)[ \t]*\n(.*?)^```[ \t]*$", re.M | re.S)
INDENTED = re.compile(r"^(?: {4}|\t)((?:[A-Z_]+=\S+ )*jaxnav [a-z].*)$", re.M)
TOML_BLOCK = re.compile(r"^```toml[ \t]*\n(.*?)^```[ \t]*$", re.M | re.S)


def _pages():
    return [ROOT / "README.md"] + sorted((ROOT / "docs").rglob("*.md"))


def _lines(page: pathlib.Path):
    """(line number, command line or whole script) of the page."""
    text = page.read_text(encoding="utf-8")
    out = []
    for m in BLOCK.finditer(text):
        first = text.count("\n", 0, m.start()) + 2
        body = m.group(1)
        if body.startswith("#!"):
            out.append((first, body))
            continue
        for i, line in enumerate(body.replace("\\\n", " ").splitlines()):
            line = line.strip().removeprefix("$ ")
            if line and not line.startswith("#"):
                out.append((first + i, line))
    for m in INDENTED.finditer(text):
        out.append((text.count("\n", 0, m.start()) + 1, m.group(1).strip()))
    return out


CASES = [(p, n, line) for p in _pages() for n, line in _lines(p)]


def test_the_pages_have_commands():
    words = {
        shlex.split(line, comments=True)[-1]
        if line.startswith("#!")
        else next(w for w in shlex.split(line, comments=True) if "=" not in w)
        for _, _, line in CASES
    }
    assert {"jaxnav", "make", "pip"} <= words | {"jaxnav"}, words
    assert sum(1 for _, _, line in CASES if "jaxnav ins walk_0827" in line) >= 1


class _Ready(BaseException):
    """Raised where a checked command would create its output folder (not an Exception: main lets it through)."""


@pytest.fixture
def clone(tmp_path, monkeypatch):
    """A folder laid out like a clone beside ../shared, holding the files the README's examples name."""
    root = tmp_path / "clone"
    root.mkdir()
    (tmp_path / "shared").symlink_to(DATA_ROOT.parent, target_is_directory=True)
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    for m in TOML_BLOCK.finditer(readme):  # the README's own ins config, with placeholders for its logs
        body = m.group(1)
        name = re.search(r'^name = "([^"]+)"', body, re.M)
        if name and "[imu]" in body:
            (root / f"{name.group(1)}.toml").write_text(body, encoding="utf-8")
            for f in re.findall(r'^file = "([^"]+)"', body, re.M):
                (root / f).write_text("placeholder for the user's log\n")
    monkeypatch.chdir(root)
    for k in ("JAXNAV_DATA", "JAX_COORDINATOR_ADDRESS", "JAX_NUM_PROCESSES", "JAX_PROCESS_ID"):
        monkeypatch.delenv(k, raising=False)
    import jaxnav.cli as cli

    def ready(out, option="--out"):
        raise _Ready(out)

    for name in ("allan", "cadastral", "demo", "demo_filters", "ins", "monitor", "rtk", "sweep", "tune"):
        mod = __import__(f"jaxnav.cli.{name}", fromlist=["run"])
        if hasattr(mod, "prepare_out"):
            monkeypatch.setattr(mod, "prepare_out", ready)
        if hasattr(mod, "start_processes"):
            monkeypatch.setattr(mod, "start_processes", lambda args: True)
    return root, cli


def _check_jaxnav(words, cli, monkeypatch, capsys, where):
    while words and re.fullmatch(r"[A-Za-z_]+=.*", words[0]):
        k, v = words.pop(0).split("=", 1)
        monkeypatch.setenv(k, v)
    assert words[0].endswith("jaxnav"), (where, words)
    with pytest.raises(_Ready):
        rc = cli.main(words[1:])
        pytest.fail(f"{where}: stopped with exit {rc} before its computation: {capsys.readouterr().err}")


@pytest.mark.parametrize("page,lineno,line", CASES, ids=[f"{p.relative_to(ROOT)}:{n}" for p, n, _ in CASES])
def test_command_line_as_written(page, lineno, line, clone, monkeypatch, capsys):
    root, cli = clone
    where = f"{page.relative_to(ROOT)}:{lineno}: {line.splitlines()[0]}"
    if line.startswith("#!"):
        proc = subprocess.run(["bash", "-n"], input=line, text=True, capture_output=True)
        assert proc.returncode == 0, (where, proc.stderr)
        return
    words = shlex.split(line, comments=True)
    cmd = next(w for w in words if "=" not in w)
    if cmd == "pip":
        assert words[:3] == ["pip", "install", "-e"], where
        extras = re.fullmatch(r"\.(?:\[([\w,-]+)\])?", words[3])
        assert extras, where
        declared = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
        for e in (extras.group(1) or "").split(","):
            assert not e or e in declared, (where, e, sorted(declared))
    elif cmd == "make":
        if shutil.which("make") is None:
            pytest.skip("no make on this machine")
        proc = subprocess.run(
            ["make", "-n", *words[1:]], cwd=ROOT, text=True, capture_output=True, env=dict(os.environ, OUT="out/demo")
        )
        assert proc.returncode == 0, (where, proc.stderr)
        for recipe in proc.stdout.splitlines():
            m = re.search(r"\S*/bin/(jaxnav .*)$", recipe)
            if m:
                _check_jaxnav(shlex.split(m.group(1)), cli, monkeypatch, capsys, f"{where} -> {recipe}")
    else:
        _check_jaxnav(words, cli, monkeypatch, capsys, where)
