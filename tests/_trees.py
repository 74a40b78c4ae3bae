"""Pytree helpers of the loop-equality tests: stacking single runs and comparing results leaf by leaf."""

import jax
import jax.numpy as jnp
import numpy as np


def stack(results):
    """The single runs' results stacked along a new leading axis (what ``jax.vmap`` returns)."""
    return jax.tree_util.tree_map(lambda *a: jnp.stack(a), *results)


def assert_tree_close(got, want, rtol=1e-12, atol=1e-12):
    """Same tree structure, shapes and dtypes, and every leaf equal within the tolerances."""
    gl, gt = jax.tree_util.tree_flatten(got)
    wl, wt = jax.tree_util.tree_flatten(want)
    assert gt == wt
    for a, b in zip(gl, wl):
        assert a.shape == b.shape and a.dtype == b.dtype
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=rtol, atol=atol)
