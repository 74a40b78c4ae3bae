"""mkdocs hook: publish ``notebooks/*.ipynb`` (and their README as the section's index) as pages.

The notebooks stay where they are (``notebooks/`` at the repository root, where
``tests/test_notebooks.py`` executes them); this hook adds them to the site's files at build time
so that mkdocs-jupyter renders them as stored, without copies under ``docs/``.
"""

from __future__ import annotations

import pathlib

from mkdocs.plugins import event_priority
from mkdocs.structure.files import File

ROOT = pathlib.Path(__file__).resolve().parents[2]
NB_DIR = ROOT / "notebooks"


@event_priority(100)  # before mkdocs-jupyter's on_files, which turns .ipynb files into pages
def on_files(files, config):
    """Add each notebook as ``notebooks/<name>.ipynb`` and the README as the section's index page.

    The files are ordinary (not generated) files whose source folder is the repository root, so
    their source path is ``notebooks/...`` both on disk and in the site.
    """
    paths = sorted(NB_DIR.glob("*.ipynb")) + [NB_DIR / "README.md"]
    for path in paths:
        if path.is_file():
            files.append(File(path.relative_to(ROOT).as_posix(), src_dir=str(ROOT), dest_dir=config["site_dir"],
                              use_directory_urls=config["use_directory_urls"]))
    return files
