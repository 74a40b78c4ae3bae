"""Execute every notebook under notebooks/ (short horizons) and check it is stored stripped.

Each notebook runs with nbclient in a fresh kernel, with ``JAXNAV_NB_SHORT=1`` in its
environment and a temporary directory as its working directory (figures land there).

The kernel is always *this* interpreter: a private ``python3`` kernelspec whose argv starts
with ``sys.executable`` is written to a temporary directory put first on ``JUPYTER_PATH``, so
neither a hand-made ``jupyter kernelspec install`` nor a user-level ``python3`` kernelspec
(which might point at another Python without jaxnav) is involved.
"""

from __future__ import annotations

import json
import pathlib
import re
import sys

import jax
import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")
pytest.importorskip("ipykernel")

ROOT = pathlib.Path(__file__).resolve().parents[1]
NB_DIR = ROOT / "notebooks"
NOTEBOOKS = sorted(p for p in NB_DIR.rglob("*.ipynb") if ".ipynb_checkpoints" not in p.parts)
IDS = [str(p.relative_to(NB_DIR)) for p in NOTEBOOKS]
KERNEL = "python3"
CELL_TIMEOUT = 300  # s per cell
EXECUTED = ROOT / "build" / "executed" / "notebooks"  # git-ignored; read by docs/_hooks/notebooks.py


@pytest.fixture
def kernel_env(tmp_path_factory, monkeypatch):
    """A ``python3`` kernelspec for this interpreter, first on JUPYTER_PATH; the short-run flag."""
    jpath = tmp_path_factory.mktemp("jupyter")
    spec_dir = jpath / "kernels" / KERNEL
    spec_dir.mkdir(parents=True)
    spec = {
        "argv": [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"],
        "display_name": f"Python 3 ({sys.executable})",
        "language": "python",
        "metadata": {"debugger": False},
    }
    (spec_dir / "kernel.json").write_text(json.dumps(spec))
    monkeypatch.setenv("JUPYTER_PATH", str(jpath))
    monkeypatch.setenv("JAXNAV_NB_SHORT", "1")
    # share the test suite's persistent compilation cache (see conftest.py) with the kernel
    cache = jax.config.jax_compilation_cache_dir
    if cache:
        monkeypatch.setenv("JAX_COMPILATION_CACHE_DIR", str(cache))
        monkeypatch.setenv("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.5")
    return jpath


def _execute(nb, cwd):
    client = nbclient.NotebookClient(
        nb,
        kernel_name=KERNEL,
        timeout=CELL_TIMEOUT,
        resources={"metadata": {"path": str(cwd)}},
    )
    client.execute()
    return nb


def test_notebooks_found():
    assert NOTEBOOKS, f"no notebooks found under {NB_DIR}"


def test_kernel_is_this_interpreter(kernel_env, tmp_path):
    """The kernel the notebooks run in is sys.executable, sees the short flag and the temp cwd."""
    code = "import os, sys; print(sys.executable); print(os.environ.get('JAXNAV_NB_SHORT')); print(os.getcwd())"
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(code)])
    _execute(nb, tmp_path)
    lines = "".join(o.get("text", "") for o in nb.cells[0].outputs).split()
    assert lines[0] == sys.executable
    assert lines[1] == "1"
    assert pathlib.Path(lines[2]).resolve() == tmp_path.resolve()


@pytest.mark.parametrize("path", NOTEBOOKS, ids=IDS)
def test_notebook_stored_stripped(path):
    """Notebooks are committed valid and without outputs, so the repository stays clean."""
    nb = nbformat.read(path, as_version=4)
    nbformat.validate(nb)
    dirty = [
        i
        for i, cell in enumerate(nb.cells)
        if cell.cell_type == "code" and (cell.get("outputs") or cell.get("execution_count") is not None)
    ]
    assert not dirty, f"{path.name}: code cells {dirty} carry outputs or execution counts; strip them"
    assert nb.metadata.get("kernelspec", {}).get("name", KERNEL) == KERNEL


def test_stripped_notebooks_say_where_the_rendered_ones_are():
    """Read on a forge, a stripped notebook shows no number or figure: notebooks/README.md and the
    README say first where the rendered ones are (the docs site that `make docs` builds)."""
    head = (NB_DIR / "README.md").read_text(encoding="utf-8").split("| notebook |")[0]
    assert "without outputs" in head and "make docs" in head and "site/notebooks/" in head
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert re.search(r"Notebooks \(`notebooks/`.*?stored without outputs.*?make docs", readme, re.S)


@pytest.mark.parametrize("path", NOTEBOOKS, ids=IDS)
def test_notebook_text_has_no_development_history_and_agrees_with_the_readme(path):
    """No "(issue N)" in a heading or text; a number also stated in the README is the README's."""
    nb = nbformat.read(path, as_version=4)
    text = "\n".join(c.source for c in nb.cells if c.cell_type == "markdown")
    assert not re.search(r"\bissue\s*#?\d+", text, re.I), path.name
    hector = re.findall(r"rates agree within ([\d.]+) mm/yr", text)
    if hector:
        stated = re.search(r"agrees with\s+Hector to ([\d.]+) mm/yr", (ROOT / "README.md").read_text(encoding="utf-8"))
        assert stated and hector[0] == stated.group(1), (path.name, hector, stated)


def _executes(path):
    @pytest.mark.slow
    def test_executes(self, kernel_env, tmp_path):
        """Run the notebook top to bottom (short horizons); any cell error fails the test."""
        nb = nbformat.read(path, as_version=4)
        _execute(nb, tmp_path)
        errors = [
            o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []) if o.output_type == "error"
        ]
        assert not errors
        # kept for the docs: `make docs` renders the executed copy when it is newer than the notebook
        EXECUTED.mkdir(parents=True, exist_ok=True)
        nbformat.write(nb, EXECUTED / path.name)

    return test_executes


# one class per notebook, so that `pytest --dist loadscope` gives each notebook its own scope
for _path in NOTEBOOKS:
    _name = "TestNotebook" + re.sub(r"\W", "_", _path.stem)
    globals()[_name] = type(_name, (), {"test_executes": _executes(_path), "path": _path})
