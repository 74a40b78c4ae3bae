"""Every fenced ```python block of README.md and docs/ runs as written (short sizes), so none can rot.

The blocks of one page run in order in one fresh interpreter (they share a namespace, as a reader
typing them into one session would), with the working directory a temporary folder and
``JAXNAV_DATA`` naming the shared data sets (what the README tells users to set). A page fails
with the block and the line that raised.
"""

import os
import pathlib
import re
import subprocess
import sys

import jax
import pytest
from _paths import DATA_ROOT, ROOT

FENCE = re.compile(r"^```python[ \t]*\n(.*?)^```[ \t]*$", re.M | re.S)


def _pages():
    pages = [ROOT / "README.md"] + sorted((ROOT / "docs").rglob("*.md"))
    return [p for p in pages if FENCE.search(p.read_text(encoding="utf-8"))]


def _script(page: pathlib.Path) -> str:
    """The page's blocks, each announced on stderr so that a failure names its block."""
    text = page.read_text(encoding="utf-8")
    parts = []
    for i, m in enumerate(FENCE.finditer(text), 1):
        line = text.count("\n", 0, m.start()) + 2
        parts.append(f"import sys as _s; print('--- {page.name} block {i} (line {line})', file=_s.stderr, flush=True)")
        parts.append(m.group(1))
    return "\n".join(parts)


def test_the_pages_have_python_blocks():
    names = {p.name for p in _pages()}
    assert "README.md" in names and len(names) >= 3, names


@pytest.mark.parametrize("page", _pages(), ids=lambda p: str(p.relative_to(ROOT)))
def test_page_runs_as_written(page, tmp_path):
    env = dict(os.environ, JAXNAV_DATA=str(DATA_ROOT), MPLBACKEND="Agg", PYTHONHASHSEED="0")
    cache = jax.config.jax_compilation_cache_dir
    if cache:
        env["JAX_COMPILATION_CACHE_DIR"] = str(cache)
        env["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"] = "0.5"
    for k in ("JAX_COORDINATOR_ADDRESS", "JAX_NUM_PROCESSES", "JAX_PROCESS_ID"):
        env.pop(k, None)
    script = tmp_path / "page.py"
    script.write_text(_script(page), encoding="utf-8")
    proc = subprocess.run(
        [sys.executable, str(script)], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=900
    )
    blocks = [ln for ln in proc.stderr.splitlines() if ln.startswith("--- ")]
    assert proc.returncode == 0, f"{page.name}: failed in {blocks[-1] if blocks else 'no block'}\n{proc.stderr[-3000:]}"
