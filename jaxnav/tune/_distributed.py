"""Several processes and hosts: JAX's multi-process runtime (``jax.distributed``) behind the studies.

JAX runs one program per process ("multi-controller"): every process executes the same Python
code, ``jax.devices()`` lists the devices of all processes, and a computation placed on a mesh of
those devices runs each process's shards on its own devices, with XLA's collectives (gloo over
TCP on CPU, NCCL on GPU) moving data between them. This module holds the few pieces the studies
need on top of that:

* :func:`initialize`: join the processes of one study (``jax.distributed.initialize``), from
  arguments or the environment variables ``JAX_COORDINATOR_ADDRESS`` (read by JAX itself),
  ``JAX_NUM_PROCESSES`` and ``JAX_PROCESS_ID`` (read here); what is still missing JAX takes from
  the cluster (SLURM, Open MPI, Kubernetes).
* :func:`is_writer`: the one test of "this process writes the results" (process 0).
* :func:`batch_mesh`: the 1-D mesh named "batch" over all processes' devices, used by
  :func:`jaxnav.tune.sweep`, :func:`jaxnav.tune.run_chunked` and :func:`monte_carlo_mean`.
* :func:`monte_carlo_mean`: the mean of a per-run function over PRNG keys with the keys' axis
  sharded over that mesh, differentiable, for :func:`jaxnav.tune.minimize` and friends: every
  process gets the same loss, gradient and (after an optax step) the same parameters.

Results do not depend on the number of processes or devices: the PRNG keys are made on the host
from a seed (identical on every process), the pairing of grid points and keys is fixed by their
index, and every run is computed by the same ``vmap`` of one function; only the order of the
final sums of :func:`monte_carlo_mean` may differ (relative differences ~1e-16).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

#: environment variables read by :func:`initialize` when an argument is None (the coordinator's is JAX's own)
ENV_COORDINATOR = "JAX_COORDINATOR_ADDRESS"
ENV_NUM_PROCESSES = "JAX_NUM_PROCESSES"
ENV_PROCESS_ID = "JAX_PROCESS_ID"


def _env_int(name: str) -> int | None:
    text = os.environ.get(name, "").strip()
    if not text:
        return None
    try:
        return int(text)
    except ValueError:
        raise ValueError(f"environment variable {name}={text!r} is not an integer") from None


def _check_coordinator(address: str) -> str:
    host, sep, port = str(address).strip().rpartition(":")
    if not sep or not host or not port.isdigit() or not 1 <= int(port) <= 65535:
        raise ValueError(f"coordinator address must be HOST:PORT with a port in 1..65535, got {address!r}")
    return f"{host}:{port}"


def initialize(
    coordinator: str | None = None,
    num_processes: int | None = None,
    process_id: int | None = None,
    *,
    timeout_s: int = 300,
) -> int:
    """Join this process to a multi-process study (``jax.distributed.initialize``); call before any JAX work.

    Nothing is started when neither an argument nor one of the environment variables
    ``JAX_COORDINATOR_ADDRESS``, ``JAX_NUM_PROCESSES``, ``JAX_PROCESS_ID`` is set (a plain
    single-process run, also inside a SLURM job). Otherwise the missing values are left to JAX's
    cluster detection (SLURM: ``SLURM_NTASKS``, ``SLURM_PROCID``; Open MPI; Kubernetes). On CPU the
    cross-process collectives are gloo (TCP). Calling it again in an initialized process is a no-op.

    Args:
      coordinator: ``HOST:PORT`` of process 0's coordination service (every process gives the same).
      num_processes: number of processes (>= 1).  process_id: this process, 0 .. num_processes - 1.
      timeout_s: how long to wait for all processes to join before failing.
    Returns:
      The number of processes (1 when nothing was started).
    Raises:
      ValueError: a malformed address or an inconsistent count / id.
    """
    if jax.distributed.is_initialized():
        return jax.process_count()
    coordinator = coordinator or os.environ.get(ENV_COORDINATOR) or None
    num_processes = _env_int(ENV_NUM_PROCESSES) if num_processes is None else int(num_processes)
    process_id = _env_int(ENV_PROCESS_ID) if process_id is None else int(process_id)
    if coordinator is None and num_processes is None and process_id is None:
        return 1
    if coordinator is not None:
        coordinator = _check_coordinator(coordinator)
    if num_processes is not None and num_processes < 1:
        raise ValueError(f"number of processes must be >= 1, got {num_processes}")
    if process_id is not None and process_id < 0:
        raise ValueError(f"process id must be >= 0, got {process_id}")
    if process_id is not None and num_processes is not None and process_id >= num_processes:
        raise ValueError(
            f"process id must be in 0 .. {num_processes - 1} (the number of processes - 1), got {process_id}"
        )
    if not getattr(jax.config, "jax_cpu_collectives_implementation", None):  # older JAX: no default
        jax.config.update("jax_cpu_collectives_implementation", "gloo")
    jax.distributed.initialize(
        coordinator_address=coordinator,
        num_processes=num_processes,
        process_id=process_id,
        initialization_timeout=int(timeout_s),
    )
    return jax.process_count()


def is_writer() -> bool:
    """Whether this process writes the results (files, tables, figures, progress bars): process 0.

    The one place where a study decides who writes; in a single-process run it is always True.
    """
    return jax.process_index() == 0


def batch_mesh(devices: Sequence | None = None) -> Mesh:
    """The 1-D mesh named "batch" over ``devices`` (default ``jax.devices()``: all processes' devices)."""
    return Mesh(np.asarray(list(jax.devices() if devices is None else devices)), ("batch",))


def spans_processes(mesh: Mesh) -> bool:
    """Whether ``mesh`` holds devices of other processes (then arrays on it are not all addressable here)."""
    me = jax.process_index()
    return any(d.process_index != me for d in mesh.devices.flat)


def monte_carlo_mean(fn: Callable, keys, *, devices: Sequence | None = None) -> Callable:
    """``params -> mean over k of fn(params, keys[k])`` with the runs sharded over all processes' devices.

    Inside a ``jax.jit`` (as in :func:`jaxnav.tune.minimize`, :func:`jaxnav.tune.minimize_lbfgs` or
    ``jax.jit(jax.value_and_grad(...))``) the keys' axis is constrained to the "batch" axis of
    :func:`batch_mesh` (``jax.lax.with_sharding_constraint``): each device computes its runs, XLA
    adds the partial sums across devices and processes (an all-reduce of one scalar per
    derivative direction), and every process holds the same value and gradient, hence the same
    parameters after each optimiser step. On one device it is ``mean(vmap(fn)(keys))``.

    Args:
      fn: pure ``(params, key) -> scalar``.
      keys: (K, 2) raw uint32 PRNG keys (``jax.random.split(jax.random.PRNGKey(seed), K)``), the
        same on every process (K need not be a multiple of the device count).
      devices: the devices to shard over (default all).
    Returns:
      The loss function of ``params``.
    """
    keys = np.asarray(keys)
    sh = NamedSharding(batch_mesh(devices), PartitionSpec("batch"))

    def loss(params):
        k = jax.lax.with_sharding_constraint(jnp.asarray(keys), sh)
        return jnp.mean(jax.vmap(lambda kk: fn(params, kk))(k))

    return loss
