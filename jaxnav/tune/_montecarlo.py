"""Chunked Monte Carlo on the host: one compiled batch size, the last chunk padded, a progress bar.

:func:`map_chunked` is the one chunk-pad-gather loop of the package (used by :func:`run_chunked`,
:func:`jaxnav.tune.sweep` and the S1 experiment); :func:`run_chunked` is the common case of a
function of one PRNG key.
"""

from __future__ import annotations

from typing import Callable

import jax
import numpy as np
from tqdm.auto import tqdm


def map_chunked(call: Callable, n: int, *, chunk: int, desc: str = "Monte Carlo", progress: bool = True,
                unit: str = "run"):
    """Evaluate ``call`` on index chunks of ``range(n)``, each padded to ``chunk``; gather on the host.

    Every call gets exactly ``chunk`` indices (the last chunk repeats index ``n - 1``), so a
    compiled batched function is compiled once; the padded rows are dropped. Results move to host
    memory per chunk, so device memory stays bounded by one chunk.

    Args:
      call: ``idx -> pytree`` of arrays with leading axis ``chunk``; ``idx`` is a (chunk,) int
        numpy array of positions in ``0 .. n-1``, ascending, with ``idx[0]`` the chunk's start.
      n: number of items.  chunk: items per call (>= 1).
      desc: progress-bar label.  progress: show the bar.  unit: progress-bar unit.
    Returns:
      The pytree of numpy arrays with leading axis n.
    """
    n, chunk = int(n), max(1, int(chunk))
    outs = []
    with tqdm(total=n, desc=desc, disable=not progress, unit=unit) as bar:
        for s in range(0, n, chunk):
            m = min(chunk, n - s)
            idx = np.minimum(np.arange(s, s + chunk), n - 1)
            outs.append(jax.tree_util.tree_map(lambda a: np.asarray(a)[:m], call(idx)))
            bar.update(m)
    return jax.tree_util.tree_map(lambda *a: np.concatenate(a, axis=0), *outs)


def run_chunked(fn: Callable, keys, *, chunk: int = 16, desc: str = "Monte Carlo", progress: bool = True):
    """Apply ``jax.vmap(fn)`` to ``keys`` in chunks of ``chunk``, showing a progress bar.

    The compiled function is reused for every chunk (the last one is padded to the same size),
    so there is a single compilation; device memory stays bounded by one chunk.

    Args:
      fn: pure function of one PRNG key returning a pytree of arrays.
      keys: (B, ...) PRNG keys.
      chunk: batch size per compiled call (at most B).
      desc: progress-bar label.  progress: show the bar.
    Returns:
      The pytree of numpy arrays with leading axis B.
    """
    B = keys.shape[0]
    f = jax.jit(jax.vmap(fn))
    return map_chunked(lambda idx: f(keys[idx]), B, chunk=min(max(1, int(chunk)), B), desc=desc,
                       progress=progress)
