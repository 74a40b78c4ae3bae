"""Chunked, vmapped Monte Carlo with a progress bar (host side)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from tqdm.auto import tqdm


def run_chunked(fn, keys, *, chunk: int = 16, desc: str = "Monte Carlo", progress: bool = True):
    """Apply ``jax.vmap(fn)`` to ``keys`` in chunks of ``chunk``, showing a progress bar.

    The compiled function is reused for every full chunk; the last chunk is padded to the same
    size so there is a single compilation. Results are moved to host memory per chunk, so device
    memory stays bounded by one chunk.

    Args:
      fn: pure function of one PRNG key returning a pytree of arrays.
      keys: (B, ...) PRNG keys.
      chunk: batch size per compiled call.
      desc: progress-bar label.  progress: show the bar.
    Returns:
      The pytree of numpy arrays with leading axis B.
    """
    B = keys.shape[0]
    chunk = max(1, min(int(chunk), B))
    f = jax.jit(jax.vmap(fn))
    outs = []
    with tqdm(total=B, desc=desc, disable=not progress, unit="run") as bar:
        for s in range(0, B, chunk):
            k = keys[s:s + chunk]
            pad = chunk - k.shape[0]
            if pad:
                k = jnp.concatenate([k, jnp.broadcast_to(k[-1:], (pad,) + k.shape[1:])])
            out = jax.tree_util.tree_map(np.asarray, f(k))
            if pad:
                out = jax.tree_util.tree_map(lambda a: a[: chunk - pad], out)
            outs.append(out)
            bar.update(chunk - pad)
    return jax.tree_util.tree_map(lambda *a: np.concatenate(a, axis=0), *outs)
