"""mkdocs hook: publish ``notebooks/*.ipynb`` (and their README as the section's index) as pages.

The notebooks stay where they are (``notebooks/`` at the repository root, where
``tests/test_notebooks.py`` executes them); this hook adds them to the site's files at build time
so that mkdocs-jupyter renders them, without copies under ``docs/``: the executed copy that
``tests/test_notebooks.py`` leaves in ``build/executed/notebooks/`` (outputs and figures of the
short run) when it is newer than the notebook, else the notebook as stored (without outputs).
``.ci/run`` runs ``make test`` before ``make docs``, so CI's site shows the executed notebooks.
"""

from __future__ import annotations

import logging
import pathlib

from mkdocs.plugins import event_priority
from mkdocs.structure.files import File

ROOT = pathlib.Path(__file__).resolve().parents[2]
NB_DIR = ROOT / "notebooks"
# executed copies written by tests/test_notebooks.py (short horizons), rendered when up to date
EXECUTED = ROOT / "build" / "executed"
log = logging.getLogger("mkdocs.hooks.notebooks")


@event_priority(100)  # before mkdocs-jupyter's on_files, which turns .ipynb files into pages
def on_files(files, config):
    """Add each notebook as ``notebooks/<name>.ipynb`` and the README as the section's index page.

    The files are ordinary (not generated) files whose source folder is the repository root, so
    their source path is ``notebooks/...`` both on disk and in the site.
    """
    paths = sorted(NB_DIR.glob("*.ipynb")) + [NB_DIR / "README.md"]
    stale = []
    for path in paths:
        if path.is_file():
            src = ROOT
            run = EXECUTED / path.relative_to(ROOT)
            if path.suffix == ".ipynb":
                if run.is_file() and run.stat().st_mtime >= path.stat().st_mtime:
                    src = EXECUTED
                else:
                    stale.append(path.name)
            files.append(
                File(
                    path.relative_to(ROOT).as_posix(),
                    src_dir=str(src),
                    dest_dir=config["site_dir"],
                    use_directory_urls=config["use_directory_urls"],
                )
            )
    if stale:
        log.info(
            "notebooks rendered without outputs (no executed copy newer than the notebook; "
            "`make test` writes them to build/executed/): %s",
            ", ".join(stale),
        )
    return files
