"""Test configuration: float64 everywhere, persistent compilation cache for local reruns."""

import os
import pathlib

import jax

import jaxnav

jaxnav.enable_x64()
_cache = pathlib.Path(__file__).resolve().parents[1] / ".jax_cache"
jax.config.update("jax_compilation_cache_dir", os.environ.get("JAXNAV_JAX_CACHE", str(_cache)))
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)

SHARED = pathlib.Path(__file__).resolve().parents[2] / "shared"


def pytest_collection_modifyitems(config, items):
    """Group tests for ``pytest -n 2 --dist loadgroup`` (what ``make test`` runs): one group per
    module, so module-scoped fixtures (and their compilations) are built once, except the
    notebooks, one group each, so the longest file does not serialise the run."""
    import pytest

    for item in items:
        if item.get_closest_marker("xdist_group") is not None:
            continue
        group = item.module.__name__
        if group.endswith("test_notebooks") and hasattr(item, "callspec"):
            group += "::" + item.callspec.id
        item.add_marker(pytest.mark.xdist_group(group))
