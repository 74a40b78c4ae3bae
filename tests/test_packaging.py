"""The wheel a user installs: built from this checkout, installed into a clean virtual environment.

One module-scoped build (``pip wheel --no-deps .``, hatchling from the package index in pip's
isolated build environment) and one clean venv (no system site-packages; jaxnav's dependencies
installed by pip from the index as a user would get them). Then, from a folder outside the
checkout so that the source tree is not importable:

* the wheel holds every data file of the package (``py.typed``, the shipped configs
  ``jaxnav/experiments/configs/**``, the scenario files) and the LICENSE, and its metadata
  carries the license expression, ``Requires-Python`` and the version of ``jaxnav.__version__``;
* ``jaxnav --help`` runs and lists every command;
* ``import jaxnav`` imports the installed copy, which has ``py.typed`` and the configs.

Needs the package index (or a warm pip cache); 60-90 s on a loaded 2-core machine with a warm cache.
"""

from __future__ import annotations

import email.parser
import os
import pathlib
import subprocess
import sys
import venv
import zipfile

import pytest
from _paths import ROOT

PKG = ROOT / "jaxnav"
TIMEOUT = 400  # s, per pip call (a cold cache downloads jax and jaxlib)


def _env():
    """The caller's environment minus what would leak this interpreter's packages into the clean one."""
    env = {
        k: v
        for k, v in os.environ.items()
        if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV", "PYTHONSTARTUP", "PIP_USER")
    }
    env["PIP_DISABLE_PIP_VERSION_CHECK"] = "1"
    env["JAX_PLATFORMS"] = "cpu"
    return env


def _run(cmd, cwd, timeout=TIMEOUT):
    proc = subprocess.run([str(c) for c in cmd], cwd=cwd, env=_env(), capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0, (
        f"{' '.join(map(str, cmd))} exited {proc.returncode}:\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    )
    return proc


def _data_files():
    """Every file of the source package that is not Python source or a cache: what the wheel must ship."""
    return sorted(
        p.relative_to(ROOT).as_posix()
        for p in PKG.rglob("*")
        if p.is_file() and p.suffix not in (".py", ".pyc") and "__pycache__" not in p.parts
    )


@pytest.fixture(scope="module")
def wheel(tmp_path_factory):
    out = tmp_path_factory.mktemp("wheel")
    _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--quiet", "--wheel-dir", out, ROOT], cwd=out)
    wheels = sorted(out.glob("jaxnav-*.whl"))
    assert len(wheels) == 1, f"expected one jaxnav wheel in {out}, found {[w.name for w in out.iterdir()]}"
    return wheels[0]


def _pip_has_python_option() -> bool:
    """Whether this interpreter's pip can install into another environment (``pip --python``, pip >= 22.3)."""
    import pip

    major, minor = (int(x) for x in pip.__version__.split(".")[:2])
    return (major, minor) >= (22, 3)


@pytest.fixture(scope="module")
def installed(wheel, tmp_path_factory):
    """(python, jaxnav script, working folder outside the checkout) of a clean venv with the wheel.

    The venv has no pip of its own when this pip can install into it (``--python``): bootstrapping
    one costs ~10 s. ``--no-compile`` skips byte-compiling jax, scipy and matplotlib at install
    (about half the install time); the two imports below compile only what they use.
    """
    base = tmp_path_factory.mktemp("clean")
    env_dir = base / "venv"
    outer = _pip_has_python_option()
    venv.EnvBuilder(with_pip=not outer, system_site_packages=False, clear=True).create(env_dir)
    py = env_dir / "bin" / "python"
    pip = [sys.executable, "-m", "pip", "--python", py] if outer else [py, "-m", "pip"]
    _run(pip + ["install", "--quiet", "--no-compile", wheel], cwd=base)
    return py, env_dir / "bin" / "jaxnav", base


def test_wheel_contents(wheel):
    with zipfile.ZipFile(wheel) as zf:
        names = set(zf.namelist())
        meta_name = next(n for n in names if n.endswith(".dist-info/METADATA"))
        meta = email.parser.Parser().parsestr(zf.read(meta_name).decode("utf-8"))
    data = _data_files()
    assert "jaxnav/py.typed" in data
    assert any(d.startswith("jaxnav/experiments/configs/") for d in data)
    missing = [d for d in data if d not in names]
    assert not missing, f"package data left out of the wheel: {missing}"
    modules = sorted(p.relative_to(ROOT).as_posix() for p in PKG.rglob("*.py") if "__pycache__" not in p.parts)
    assert not [m for m in modules if m not in names], "modules left out of the wheel"
    assert not [n for n in names if n.startswith(("tests/", "notebooks/", "docs/", "benchmarks/"))]
    assert any(n.endswith(".dist-info/licenses/LICENSE") for n in names), sorted(names)[-8:]
    assert meta["License-Expression"] == "MIT"
    assert meta["Requires-Python"] == ">=3.11"
    import jaxnav

    assert meta["Version"] == jaxnav.__version__
    assert meta["Name"] == "jaxnav"


def test_cli_help_in_clean_venv(installed):
    from jaxnav.cli import COMMANDS

    py, script, cwd = installed
    proc = _run([script, "--help"], cwd=cwd, timeout=120)
    for name in COMMANDS:
        assert name.replace("_", "-") in proc.stdout, f"'jaxnav --help' does not list {name}:\n{proc.stdout}"


def test_import_in_clean_venv(installed):
    py, _, cwd = installed
    code = (
        "import importlib.metadata as md, importlib.resources as r, pathlib, jaxnav\n"
        "root = r.files('jaxnav')\n"
        "print(pathlib.Path(jaxnav.__file__).resolve())\n"
        "print(root.joinpath('py.typed').is_file())\n"
        "print(sorted(p.name for p in root.joinpath('experiments', 'configs').iterdir()))\n"
        "print(md.version('jaxnav') == jaxnav.__version__)\n"
        "jaxnav.enable_x64()\n"
        "import jax.numpy as jnp\n"
        "print(jnp.zeros(1).dtype)\n"
    )
    out = _run([py, "-c", code], cwd=cwd, timeout=120).stdout.splitlines()
    where, typed, configs, version_ok, dtype = out[-5:]
    assert pathlib.Path(where).is_relative_to(py.parent.parent.resolve()), f"imported {where}, not the installed copy"
    assert typed == "True"
    shipped = sorted(p.name for p in (PKG / "experiments" / "configs").iterdir() if p.name != "__pycache__")
    assert configs == str(shipped)
    assert version_ok == "True"
    assert dtype == "float64"
