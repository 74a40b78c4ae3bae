"""Where the tests find the repository and the shared data (CI has ../shared beside the clone)."""

import pathlib

ROOT = pathlib.Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"
DATA_ROOT = SHARED / "data"
