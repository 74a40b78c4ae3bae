"""Sweeps, Monte Carlo and gradient tuning of filter parameters (b, rho, noise scales).

S0 chose its attenuation factor b = 0.254 by trial and error. Here the same question is a
function of array leaves:

* losses (:func:`rms`, :func:`innovation_nll`, :func:`nis_consistency`, :func:`nees_consistency`)
  that accept the result of any filter variant of :mod:`jaxnav.filters` or
  :func:`jaxnav.ins.loosely_coupled`;
* bijectors (:func:`unit` for b, :func:`positive`/:func:`log` for scales) and a :class:`Space`
  of named parameters with a trainable mask;
* :func:`minimize`: an optax loop inside one jitted ``lax.scan``, gradients in forward mode for
  a few scalars (no tape) or reverse mode (with ``LCPropagation(remat=True)`` of the INS/GNSS run);
* :func:`minimize_lbfgs`: L-BFGS with a strong-Wolfe line search advanced one loss evaluation
  per scan step, so an expensive loss is compiled once (``optax.lbfgs`` compiles it three times);
* :func:`sweep`: ``vmap`` over a parameter :func:`grid` x Monte Carlo keys, chunked with a
  progress bar, sharded over all devices (``jax.sharding``), with :func:`table` for tidy rows;
* :func:`run_chunked`: ``vmap`` of a function of one PRNG key over many keys, in chunks of one
  compiled size with a progress bar, sharded over all devices (:func:`map_sharded` is the
  compile-shard-gather step behind both, :func:`map_chunked` the loop);
* several processes and hosts (JAX's ``jax.distributed``): :func:`initialize` joins the
  processes of a study, after which :func:`sweep`, :func:`run_chunked` and
  :func:`monte_carlo_mean` (a tuning loss whose Monte Carlo runs are sharded over all processes)
  spread their batch over every process's devices and return the same numbers on each;
  :func:`is_writer` is the one test of who writes the results (process 0);
* :func:`cv_nll`: a ready-made tuning target (constant-velocity noise scales); the S0
  experiment's targets (``S0Setup``, ``s0_metrics``) are in :mod:`jaxnav.experiments.s0`.
"""

from jaxnav.tune._bijectors import Bijector, Space, bijector, interval, log, positive, real, unit
from jaxnav.tune._distributed import batch_mesh, initialize, is_writer, monte_carlo_mean
from jaxnav.tune._lbfgs import minimize_lbfgs
from jaxnav.tune._lc_noise import LCNoiseFit, calibrate_lc_noise, fit_lc_noise
from jaxnav.tune._losses import innovation_nll, nees, nees_consistency, nis_consistency, rms
from jaxnav.tune._montecarlo import Sharded, map_chunked, map_sharded, run_chunked
from jaxnav.tune._optimize import TuneResult, forward_gradient, minimize, value_and_grad
from jaxnav.tune._problems import cv_nll, simulate_cv_batch
from jaxnav.tune._sweep import SweepResult, grid, sweep, table

__all__ = [
    "Bijector",
    "LCNoiseFit",
    "Sharded",
    "Space",
    "SweepResult",
    "TuneResult",
    "batch_mesh",
    "bijector",
    "calibrate_lc_noise",
    "cv_nll",
    "fit_lc_noise",
    "forward_gradient",
    "grid",
    "initialize",
    "innovation_nll",
    "interval",
    "is_writer",
    "log",
    "map_chunked",
    "map_sharded",
    "minimize",
    "minimize_lbfgs",
    "monte_carlo_mean",
    "nees",
    "nees_consistency",
    "nis_consistency",
    "positive",
    "real",
    "rms",
    "run_chunked",
    "simulate_cv_batch",
    "sweep",
    "table",
    "unit",
    "value_and_grad",
]
