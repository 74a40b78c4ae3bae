"""Sweeps: ``vmap`` over a parameter grid x Monte Carlo keys, chunked, sharded over devices.

One compiled function evaluates a chunk of (grid point, key) pairs; chunks run one after the
other on the host with a progress bar, so memory is bounded by the chunk, not the sweep. When
more than one device is visible, each chunk's batch axis is split over all of them with
``jax.sharding`` (a 1-D ``Mesh`` named "batch" and ``NamedSharding``); the results are the
same as on one device.

Multi-host: start every process with ``jax.distributed.initialize()`` (coordinator address,
process count and id from the cluster environment) before calling :func:`sweep`;
``jax.devices()`` then lists the devices of all hosts, the mesh spans them, and each process
computes the shards of its own devices. Every process must call :func:`sweep` with the same
grid, keys and chunk (JAX's single-program model); the gathered results are returned on every
process.
"""

from __future__ import annotations

import itertools
import time
import weakref
from typing import Any, Callable, Mapping, NamedTuple, Optional, Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from jaxnav.tune._montecarlo import map_chunked


class SweepResult(NamedTuple):
    """Result of :func:`sweep`.

    Attributes:
      grid: dict name -> (G,) parameter values of the flattened grid.
      values: the function's output pytree, numpy arrays with leading axes (G, K) (K keys).
      wall_time_s: host wall time of the sweep (compilation included).
      compile_time_s: time spent compiling (near 0 when an earlier sweep of the same fn compiled it).
      n_devices: devices the batch axis was spread over.
      chunk: (grid point, key) pairs per compiled call.
      peak_bytes: XLA's memory estimate of one chunk call (arguments + outputs + temporaries).
    """

    grid: Any
    values: Any
    wall_time_s: float
    compile_time_s: float
    n_devices: int
    chunk: int
    peak_bytes: int


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


def _mesh(devices):
    return Mesh(np.asarray(devices), ("batch",))


def sweep(fn: Callable, params: Mapping, keys, *, chunk: Optional[int] = None, progress: bool = True,
          desc: str = "sweep", devices: Optional[Sequence] = None) -> SweepResult:
    """Evaluate ``fn(params_point, key)`` at every grid point x every key.

    Args:
      fn: pure function (dict of scalar parameters, PRNG key) -> pytree of arrays.
      params: dict name -> (G,) values (e.g. from :func:`grid`); all the same length.
      keys: (K, ...) PRNG keys (the same keys at every grid point: common random numbers).
      chunk: pairs per compiled call (default all G*K); rounded up to a multiple of the
        device count. Every call is padded (with repeats) to ``chunk`` pairs, so there is one
        compilation per (fn, chunk, devices), reused by later sweeps of the same ``fn``.
      progress: show a progress bar (one tick per chunk).
      devices: devices to spread the batch over (default ``jax.devices()``).
    Returns:
      :class:`SweepResult`.
    """
    t_start = time.perf_counter()
    params = {k: np.atleast_1d(np.asarray(v, float)) for k, v in params.items()}
    sizes = {k: v.shape for k, v in params.items()}
    G = next(iter(params.values())).shape[0] if params else 0
    if not params or any(s != (G,) for s in sizes.values()):
        raise ValueError(f"sweep(): params must be 1-D arrays of one length G, got shapes {sizes}")
    keys = jnp.asarray(keys)
    K = keys.shape[0]
    N = G * K
    devices = list(jax.devices() if devices is None else devices)
    nd = len(devices)
    chunk = N if chunk is None else max(1, int(chunk))
    chunk = -(-chunk // nd) * nd
    gi = np.repeat(np.arange(G), K)
    ki = np.tile(np.arange(K), G)

    sh = NamedSharding(_mesh(devices), PartitionSpec("batch")) if nd > 1 else None

    def batch(idx):
        """The (params, keys) of the padded pair indices ``idx``, placed on the mesh."""
        p = {k: jnp.asarray(v[gi[idx]]) for k, v in params.items()}
        kk = keys[ki[idx]]
        if sh is not None:
            p = jax.device_put(p, sh)
            kk = jax.device_put(kk, sh)
        return p, kk

    t0 = time.perf_counter()
    compiled = _compiled(fn, *batch(np.minimum(np.arange(chunk), N - 1)), devices, sh)
    compile_time = time.perf_counter() - t0
    peak = _peak_bytes(compiled)
    flat = map_chunked(lambda idx: compiled(*batch(idx)), N, chunk=chunk, desc=desc, progress=progress)
    values = jax.tree_util.tree_map(lambda a: a.reshape((G, K) + a.shape[1:]), flat)
    return SweepResult(grid=params, values=values, wall_time_s=time.perf_counter() - t_start,
                       compile_time_s=compile_time, n_devices=nd, chunk=chunk, peak_bytes=peak)


_CACHE: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def _compiled(fn, p, k, devices, sh):
    """The compiled ``vmap(fn)`` for these shapes and devices, cached per ``fn``."""
    sig = (tuple(d.id for d in devices), jax.tree_util.tree_structure(p),
           tuple((a.shape, a.dtype) for a in jax.tree_util.tree_leaves((p, k))))
    try:
        per_fn = _CACHE.setdefault(fn, {})
    except TypeError:  # not weak-referenceable: no cache
        per_fn = {}
    if sig not in per_fn:
        vf = jax.vmap(fn)
        f = jax.jit(vf, in_shardings=(sh, sh), out_shardings=sh) if sh is not None else jax.jit(vf)
        per_fn[sig] = f.lower(p, k).compile()
    return per_fn[sig]


def _peak_bytes(compiled) -> int:
    try:
        m = compiled.memory_analysis()
        return int(m.argument_size_in_bytes + m.output_size_in_bytes + m.temp_size_in_bytes)
    except Exception:  # backends without a memory analysis
        return -1


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
            row.update({f"{name}_mean": float(a[g].mean()), f"{name}_std": float(a[g].std()),
                        f"{name}_min": float(a[g].min()), f"{name}_max": float(a[g].max())})
        rows.append(row)
    return rows
