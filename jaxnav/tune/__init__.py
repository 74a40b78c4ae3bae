"""Sweeps, Monte Carlo and gradient tuning of filter parameters (b, rho, noise scales).

S0 chose its attenuation factor b = 0.254 by trial and error. Here the same question is a
function of array leaves:

* losses (:func:`rms`, :func:`innovation_nll`, :func:`nis_consistency`, :func:`nees_consistency`)
  that accept the result of any filter variant of :mod:`jaxnav.filters` or
  :func:`jaxnav.ins.loosely_coupled`;
* bijectors (:func:`unit` for b, :func:`positive`/:func:`log` for scales) and a :class:`Space`
  of named parameters with a trainable mask;
* :func:`minimize`: an optax loop inside one jitted ``lax.scan``, gradients in forward mode for
  a few scalars (no tape) or reverse mode (with ``remat=True`` of the INS/GNSS run);
* :func:`minimize_lbfgs`: L-BFGS with a strong-Wolfe line search advanced one loss evaluation
  per scan step, so an expensive loss is compiled once (``optax.lbfgs`` compiles it three times);
* :func:`sweep`: ``vmap`` over a parameter :func:`grid` x Monte Carlo keys, chunked with a
  progress bar, sharded over all devices (``jax.sharding``), with :func:`table` for tidy rows;
* :func:`run_chunked`: ``vmap`` of a function of one PRNG key over many keys, in chunks of one
  compiled size with a progress bar (:func:`map_chunked` is the loop behind both);
* :func:`cv_nll`: a ready-made tuning target (constant-velocity noise scales); the S0
  experiment's targets (``S0Setup``, ``s0_metrics``) are in :mod:`jaxnav.experiments`.
"""

from jaxnav.tune._bijectors import Bijector, Space, bijector, interval, log, positive, real, unit
from jaxnav.tune._losses import innovation_nll, nees, nees_consistency, nis_consistency, rms
from jaxnav.tune._lbfgs import minimize_lbfgs
from jaxnav.tune._montecarlo import map_chunked, run_chunked
from jaxnav.tune._optimize import TuneResult, forward_gradient, minimize, value_and_grad
from jaxnav.tune._problems import cv_nll, simulate_cv_batch
from jaxnav.tune._sweep import SweepResult, grid, sweep, table

__all__ = [
    "Bijector", "Space", "SweepResult", "TuneResult", "bijector", "cv_nll", "forward_gradient", "grid",
    "innovation_nll", "interval", "log", "map_chunked", "minimize", "minimize_lbfgs", "nees", "nees_consistency",
    "nis_consistency", "positive", "real", "rms", "run_chunked", "simulate_cv_batch", "sweep", "table", "unit",
    "value_and_grad",
]
