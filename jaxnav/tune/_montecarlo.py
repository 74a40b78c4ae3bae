"""Chunked Monte Carlo on the host: one compiled batch size, the last chunk padded, a progress bar,
the batch axis sharded over all devices of all processes.

:func:`map_chunked` is the one chunk-pad-gather loop of the package (used by :func:`map_sharded`
and the S1 experiment); :func:`map_sharded` is the one compile-shard-gather step on top of it (used
by :func:`run_chunked` and :func:`jaxnav.tune.sweep`); :func:`run_chunked` is the common case of a
function of one PRNG key.
"""

from __future__ import annotations

import time
import weakref
import zlib
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.experimental import multihost_utils
from jax.sharding import NamedSharding, PartitionSpec

from jaxnav._progress import Progress, stage
from jaxnav.tune._distributed import batch_mesh, is_writer, spans_processes


def map_chunked(
    call: Callable, n: int, *, chunk: int, desc: str = "Monte Carlo", progress: bool = True, unit: str = "run"
):
    """Evaluate ``call`` on index chunks of ``range(n)``, each padded to ``chunk``; gather on the host.

    Every call gets exactly ``chunk`` indices (the last chunk repeats index ``n - 1``), so a
    compiled batched function is compiled once; the padded rows are dropped. Results move to host
    memory per chunk, so device memory stays bounded by one chunk. Progress (:class:`jaxnav._progress.Progress`:
    a tqdm bar on a terminal, plain lines otherwise, none under ``jaxnav -q``) shows on the writing
    process only (:func:`jaxnav.tune.is_writer`).

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
    with Progress(n, desc, unit=unit, enabled=progress and is_writer()) as bar:
        for s in range(0, n, chunk):
            m = min(chunk, n - s)
            idx = np.minimum(np.arange(s, s + chunk), n - 1)
            outs.append(jax.tree_util.tree_map(lambda a, m=m: np.asarray(a)[:m], call(idx)))
            bar.update(m)
    return jax.tree_util.tree_map(lambda *a: np.concatenate(a, axis=0), *outs)


class Sharded(NamedTuple):
    """Result of :func:`map_sharded`.

    Attributes:
      values: the pytree of numpy arrays with leading axis n (on every process).
      compile_time_s: time spent compiling (near 0 when an earlier call of the same fn compiled it).
      n_devices: devices the batch axis was spread over (all processes together).
      n_processes: processes those devices belong to.
      chunk: items per compiled call (a multiple of n_devices).
      peak_bytes: XLA's memory estimate of one chunk call per device (arguments + outputs + temporaries).
    """

    values: Any
    compile_time_s: float
    n_devices: int
    n_processes: int
    chunk: int
    peak_bytes: int


def map_sharded(
    fn: Callable,
    take: Callable,
    n: int,
    *,
    chunk: int | None = None,
    devices: Sequence | None = None,
    desc: str = "Monte Carlo",
    progress: bool = True,
    unit: str = "run",
) -> Sharded:
    """``jax.vmap(fn)`` over n items in chunks, the batch axis sharded over ``devices`` of all processes.

    Each chunk's inputs ``take(idx)`` are placed on :func:`jaxnav.tune.batch_mesh` with the batch
    axis split over the devices (``NamedSharding``); each process transfers and computes only
    the shards of its own devices. With one process the outputs stay sharded and are assembled on
    the host; when the mesh spans processes, they are gathered inside the compiled call (an
    all-gather, output sharding replicated) so that every process returns all values. Every
    process must call it with the same ``fn``, ``n``, chunk and inputs (JAX's single-program
    model); the first chunk's inputs, ``n`` and ``chunk`` are compared across processes
    (a ValueError instead of wrong results or a hang).

    Args:
      fn: pure function of one item's arguments (the unbatched ``take`` outputs) -> pytree.
      take: ``idx -> tuple`` of arrays with leading axis ``len(idx)``: the arguments of the
        items ``idx`` (numpy or JAX arrays; raw uint32 PRNG keys, not typed key arrays, across
        processes).
      n: number of items.  chunk: items per compiled call (default n), rounded up to a
        multiple of the device count; one compilation per (fn, chunk, devices), cached per ``fn``.
      devices: default ``jax.devices()``.  desc, progress, unit: the progress bar.
    Returns:
      :class:`Sharded`.
    """
    n = int(n)
    mesh = batch_mesh(devices)
    devs = list(mesh.devices.flat)
    nd = len(devs)
    chunk = n if chunk is None else max(1, int(chunk))
    chunk = -(-chunk // nd) * nd
    multi = spans_processes(mesh)
    sh = NamedSharding(mesh, PartitionSpec("batch")) if nd > 1 else None
    out_sh = NamedSharding(mesh, PartitionSpec()) if multi else sh

    def place(args):
        """The chunk's arguments on the mesh (each process builds the shards of its own devices)."""
        if sh is None:
            return jax.tree_util.tree_map(jnp.asarray, args)
        if not multi:
            return jax.device_put(args, sh)
        return jax.tree_util.tree_map(lambda a: _global(a, sh), args)

    first = tuple(take(np.minimum(np.arange(chunk), n - 1)))
    if multi:
        _same_on_every_process(first, n, chunk)
    t0 = time.perf_counter()
    if progress and is_writer():  # compiling can take longer than the runs: say what the wait is
        stage("%s: compiling the batched computation (%d per call) before the first chunk", desc, chunk)
    compiled = _compiled(fn, place(first), devs, sh, out_sh)
    compile_time = time.perf_counter() - t0
    values = map_chunked(
        lambda idx: compiled(*place(tuple(take(idx)))), n, chunk=chunk, desc=desc, progress=progress, unit=unit
    )
    n_proc = len({d.process_index for d in devs})
    return Sharded(
        values=values,
        compile_time_s=compile_time,
        n_devices=nd,
        n_processes=n_proc,
        chunk=chunk,
        peak_bytes=_peak_bytes(compiled),
    )


def _global(a, sh):
    """A host array as a global array on ``sh``: this process supplies the shards of its devices."""
    if jax.dtypes.issubdtype(getattr(a, "dtype", np.float64), jax.dtypes.prng_key):
        raise ValueError(
            "typed PRNG key arrays (jax.random.key) cannot be placed across processes; pass raw "
            "uint32 keys (jax.random.PRNGKey / jax.random.key_data)"
        )
    a = np.asarray(a)
    return jax.make_array_from_callback(a.shape, sh, lambda index: a[index])


def _same_on_every_process(first, n, chunk):
    """ValueError unless every process has the same n, chunk and first-chunk inputs (a crc32 of them)."""
    crc = 0
    for a in jax.tree_util.tree_leaves(first):
        crc = zlib.crc32(np.ascontiguousarray(np.asarray(a)).tobytes(), crc)
    try:
        multihost_utils.assert_equal(np.asarray([n, chunk, crc], np.int64), fail_message="")
    except AssertionError:
        raise ValueError(
            f"the processes of this study disagree on its items (n = {n}, chunk = {chunk}, "
            f"inputs crc32 {crc:#010x} here): every process must run the same command with "
            f"the same config and seeds"
        ) from None


_CACHE: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _compiled(fn, args, devices, sh, out_sh):
    """The compiled ``vmap(fn)`` for these shapes, devices and shardings, cached per ``fn``."""
    sig = (
        tuple(d.id for d in devices),
        out_sh is not sh,
        jax.tree_util.tree_structure(args),
        tuple((a.shape, a.dtype) for a in jax.tree_util.tree_leaves(args)),
    )
    try:
        per_fn = _CACHE.setdefault(fn, {})
    except TypeError:  # not weak-referenceable: no cache
        per_fn = {}
    if sig not in per_fn:
        vf = jax.vmap(fn)
        shs = tuple(sh for _ in args)
        f = jax.jit(vf, in_shardings=shs, out_shardings=out_sh) if sh is not None else jax.jit(vf)
        per_fn[sig] = f.lower(*args).compile()
    return per_fn[sig]


def _peak_bytes(compiled) -> int:
    try:
        m = compiled.memory_analysis()
        return int(m.argument_size_in_bytes + m.output_size_in_bytes + m.temp_size_in_bytes)
    except Exception:  # backends without a memory analysis
        return -1


def run_chunked(
    fn: Callable,
    keys,
    *,
    chunk: int = 16,
    desc: str = "Monte Carlo",
    progress: bool = True,
    devices: Sequence | None = None,
):
    """Apply ``jax.vmap(fn)`` to ``keys`` in chunks of ``chunk``, sharded over all devices, with a progress bar.

    The compiled function is reused for every chunk (the last one is padded to the same size),
    so there is a single compilation; device memory stays bounded by one chunk. The keys' axis
    is split over ``devices`` (default all devices of all processes, see :func:`map_sharded`);
    ``chunk`` is rounded up to a multiple of their number.

    Args:
      fn: pure function of one PRNG key returning a pytree of arrays.
      keys: (B, ...) PRNG keys.
      chunk: batch size per compiled call (at most B, before the rounding).
      desc: progress-bar label.  progress: show the bar.  devices: default ``jax.devices()``.
    Returns:
      The pytree of numpy arrays with leading axis B (on every process).
    """
    B = keys.shape[0]
    return map_sharded(
        fn, lambda idx: (keys[idx],), B, chunk=min(max(1, int(chunk)), B), devices=devices, desc=desc, progress=progress
    ).values
