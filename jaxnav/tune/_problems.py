"""Ready-made tuning target: maximum-likelihood noise scales of a constant-velocity model (S1/S2 model).

The S0 INS/GNSS target is :func:`jaxnav.experiments.s0.s0_metrics`.
"""

from __future__ import annotations

from collections.abc import Mapping

import jax
import jax.numpy as jnp

from jaxnav import filters as jf
from jaxnav.sim import simulate_linear
from jaxnav.tune._losses import innovation_nll


def simulate_cv_batch(key, n_series: int, T: int, *, dt=1.0, sigma=0.003, q=1e-8, ndim: int = 3):
    """Measurement series of a constant-velocity model with continuous white-noise acceleration.

    Args:
      key: PRNG key.  n_series, T: static batch size and epochs.
      dt: s.  sigma: measurement standard deviation, m.  q: acceleration PSD, m^2/s^3.
    Returns:
      (n_series, T, ndim) measured positions, m.
    """
    model = jf.constant_velocity(dt, sigma=sigma, q=q, ndim=ndim)
    x0 = jnp.zeros(2 * ndim)
    return jax.vmap(lambda k: simulate_linear(k, model, x0, T)[1])(jax.random.split(key, n_series))


def cv_nll(params: Mapping, zs, *, dt=1.0, sigma=0.003, q=1e-8, P0_scale=1.0):
    """Mean innovation negative log-likelihood of a batch of series under scaled CV noise.

    The model is ``constant_velocity(dt, sigma=sqrt(r_scale) sigma, q=q_scale q)``: the scales
    multiply the nominal measurement variance and acceleration PSD, so the truth is 1 when the
    data came from the nominal values (maximum-likelihood noise identification).

    Args:
      params: dict with ``q_scale`` and ``r_scale`` (scalars > 0).
      zs: (B, T, ndim) measured positions, m.
      dt, sigma, q: nominal values.  P0_scale: initial position std, m (velocity: P0_scale / dt).
    Returns:
      scalar mean over series of the per-component NLL.

    The series share one covariance recursion (:func:`jaxnav.filters.kalman_filter_batch`): a
    NaN/inf element of one series masks that element in every series.
    """
    zs = jnp.asarray(zs)
    if zs.ndim != 3:
        raise ValueError(f"cv_nll(): zs must be (B, T, ndim), got shape {zs.shape}")
    ndim = zs.shape[-1]
    model = jf.constant_velocity(dt, sigma=jnp.sqrt(params["r_scale"]) * sigma, q=params["q_scale"] * q, ndim=ndim)
    P0 = jnp.diag(jnp.concatenate([jnp.full(ndim, P0_scale**2), jnp.full(ndim, (P0_scale / dt) ** 2)]))

    # the series share the model and P0, so one covariance recursion serves them all
    # (kalman_filter_batch; a NaN/inf of one series masks that element in every series)
    x0 = jnp.concatenate([zs[:, 0], jnp.zeros_like(zs[:, 0])], axis=-1)
    res = jf.kalman_filter_batch(model, x0, P0, zs, save=("valid",))
    return jnp.mean(innovation_nll(res))
