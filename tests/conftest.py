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
