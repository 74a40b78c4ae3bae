"""Sweeps: ``vmap`` over a parameter grid x Monte Carlo keys, chunked, sharded over devices and processes.

One compiled function evaluates a chunk of (grid point, key) pairs; chunks run one after the
other on the host with a progress bar, so memory is bounded by the chunk, not the sweep. When
more than one device is visible, each chunk's batch axis is split over all of them with
``jax.sharding`` (:func:`jaxnav.tune.map_sharded`: a 1-D ``Mesh`` named "batch" and
``NamedSharding``); the results are the same as on one device.

Several processes or hosts: start every process with :func:`jaxnav.tune.initialize` (JAX's
``jax.distributed``) before calling :func:`sweep`; ``jax.devices()`` then lists the devices of all
processes, the mesh spans them, each process computes the shards of its own devices and the
chunk's results are all-gathered, so every process returns the whole sweep (and
:func:`jaxnav.tune.is_writer` says which one writes it). Every process must call :func:`sweep`
with the same grid, keys and chunk (JAX's single-program model; checked on the first chunk).
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any, NamedTuple

import jax
import numpy as np

from jaxnav.tune._montecarlo import map_sharded


class SweepResult(NamedTuple):
    """Result of :func:`sweep`.

    Attributes:
      grid: dict name -> (G,) parameter values of the flattened grid.
      values: the function's output pytree, numpy arrays with leading axes (G, K) (K keys).
      wall_time_s: host wall time of the sweep (compilation included).
      compile_time_s: time spent compiling (near 0 when an earlier sweep of the same fn compiled it).
      n_devices: devices the batch axis was spread over (all processes together).
      chunk: (grid point, key) pairs per compiled call.
      peak_bytes: XLA's memory estimate of one chunk call per device (arguments + outputs + temporaries).
      n_processes: processes the devices belong to (1 without :func:`jaxnav.tune.initialize`).
    """

    grid: Mapping
    values: Any
    wall_time_s: float
    compile_time_s: float
    n_devices: int
    chunk: int
    peak_bytes: int
    n_processes: int = 1


def grid(**axes) -> dict:
    """Cartesian product of 1-D axes, flattened: ``grid(b=[...], q=[...])`` -> {b: (G,), q: (G,)}.

    The first axis varies slowest (``itertools.product`` order).
    """
    if not axes:
        raise ValueError("grid() needs at least one axis")
    vals = {k: np.atleast_1d(np.asarray(v, float)) for k, v in axes.items()}
    for k, v in vals.items():
        if v.ndim != 1 or v.size == 0:
            raise ValueError(f"grid axis {k} must be a non-empty 1-D sequence, got shape {v.shape}")
    prod = list(itertools.product(*vals.values()))
    return {k: np.asarray([p[i] for p in prod]) for i, k in enumerate(vals)}


def sweep(
    fn: Callable,
    params: Mapping,
    keys,
    *,
    chunk: int | None = None,
    progress: bool = True,
    desc: str = "sweep",
    devices: Sequence | None = None,
) -> SweepResult:
    """Evaluate ``fn(params_point, key)`` at every grid point x every key.

    Args:
      fn: pure function (dict of scalar parameters, PRNG key) -> pytree of arrays.
      params: dict name -> (G,) values (e.g. from :func:`grid`); all the same length.
      keys: (K, ...) PRNG keys (the same keys at every grid point: common random numbers).
      chunk: pairs per compiled call (default all G*K); rounded up to a multiple of the
        device count. Every call is padded (with repeats) to ``chunk`` pairs, so there is one
        compilation per (fn, chunk, devices), reused by later sweeps of the same ``fn``.
      progress: show a progress bar (one tick per chunk).
      devices: devices to spread the batch over (default ``jax.devices()``: those of all
        processes after :func:`jaxnav.tune.initialize`).
    Returns:
      :class:`SweepResult` (the whole sweep, on every process).
    """
    t_start = time.perf_counter()
    params = {k: np.atleast_1d(np.asarray(v, float)) for k, v in params.items()}
    sizes = {k: v.shape for k, v in params.items()}
    G = next(iter(params.values())).shape[0] if params else 0
    if not params or any(s != (G,) for s in sizes.values()):
        raise ValueError(f"sweep(): params must be 1-D arrays of one length G, got shapes {sizes}")
    if not jax.dtypes.issubdtype(getattr(keys, "dtype", np.float64), jax.dtypes.prng_key):
        keys = np.asarray(keys)  # raw keys: indexed on the host, placed per chunk
    K = keys.shape[0]
    gi = np.repeat(np.arange(G), K)
    ki = np.tile(np.arange(K), G)

    def take(idx):
        """The (params, keys) of the pair indices ``idx``."""
        return {k: v[gi[idx]] for k, v in params.items()}, keys[ki[idx]]

    r = map_sharded(fn, take, G * K, chunk=chunk, devices=devices, desc=desc, progress=progress)
    values = jax.tree_util.tree_map(lambda a: a.reshape((G, K) + a.shape[1:]), r.values)
    return SweepResult(
        grid=params,
        values=values,
        wall_time_s=time.perf_counter() - t_start,
        compile_time_s=r.compile_time_s,
        n_devices=r.n_devices,
        chunk=r.chunk,
        peak_bytes=r.peak_bytes,
        n_processes=r.n_processes,
    )


def table(result: SweepResult, metric: Callable = lambda v: v) -> list:
    """Tidy rows, one per grid point: parameters, then mean/std/min/max over keys of each scalar metric.

    Args:
      result: :class:`SweepResult`.
      metric: values pytree -> dict name -> (G, K) array (default: the values themselves,
        which must then be a dict of (G, K) arrays).
    Returns:
      List of dicts (write with ``csv.DictWriter`` or ``json``).
    """
    m = metric(result.values)
    if not isinstance(m, Mapping):
        raise ValueError("table(): metric must return a dict name -> (G, K) array")
    rows = []
    G = len(next(iter(result.grid.values())))
    for g in range(G):
        row = {k: float(v[g]) for k, v in result.grid.items()}
        for name, a in m.items():
            a = np.asarray(a)
            if a.shape[:1] != (G,) or a.ndim != 2:
                raise ValueError(f"table(): metric {name} must be (G, K) = ({G}, K), got {a.shape}")
            row.update(
                {
                    f"{name}_mean": float(a[g].mean()),
                    f"{name}_std": float(a[g].std()),
                    f"{name}_min": float(a[g].min()),
                    f"{name}_max": float(a[g].max()),
                }
            )
        rows.append(row)
    return rows
