"""Simulation of linear Gaussian models and of a constant-velocity series with a change of dynamics."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxnav.filters import LinearGaussian


def _chol_psd(A):
    """Cholesky factor of a PSD matrix that may be singular (eigen route)."""
    w, V = jnp.linalg.eigh(0.5 * (A + A.T))
    return V * jnp.sqrt(jnp.maximum(w, 0.0))


def simulate_linear(key, model: LinearGaussian, x0, T: int, *, P0=None):
    """Draw a state and measurement series from a static linear Gaussian model (S0 eqs. (1)-(3)).

    Args:
      key: PRNG key.
      model: :class:`LinearGaussian` with static leaves.
      x0: (n,) initial state mean.  P0: optional (n, n) initial covariance (x0 drawn from it).
      T: static number of epochs.
    Returns:
      (xs (T, n) true states at k = 1..T, zs (T, m) measurements).
    """
    k0, kx, kz = jax.random.split(key, 3)
    n = x0.shape[0]
    G = jnp.eye(n) if model.G is None else model.G
    Lq = _chol_psd(model.Q)
    Lr = jnp.linalg.cholesky(model.R)
    x = x0 if P0 is None else x0 + _chol_psd(P0) @ jax.random.normal(k0, (n,), x0.dtype)
    w = jax.random.normal(kx, (T, Lq.shape[0]), x0.dtype) @ Lq.T
    e = jax.random.normal(kz, (T, Lr.shape[0]), x0.dtype) @ Lr.T

    def body(x, we):
        wk, ek = we
        x = model.F @ x + G @ wk
        return x, (x, model.H @ x + ek)

    _, (xs, zs) = jax.lax.scan(body, x, (w, e))
    return xs, zs


class CVScenario(NamedTuple):
    """A constant-velocity monitoring series with an unmodelled change of dynamics.

    Attributes:
      t: (T,) epoch times, s.  x_true: (T, 6) true [position, velocity], m and m/s.
      zs: (T, 3) measured positions, m.  accel: (T, 3) true acceleration applied, m/s^2.
      change: (T,) bool, epochs inside the change of dynamics.
    """

    t: jax.Array
    x_true: jax.Array
    zs: jax.Array
    accel: jax.Array
    change: jax.Array


def simulate_cv_scenario(
    key,
    *,
    T: int = 600,
    dt=1.0,
    sigma=0.003,
    accel_std=1e-5,
    change_start=0.4,
    change_len=0.1,
    change_accel=(2e-4, -1.5e-4, -4e-4),
    v0=(1e-3, -5e-4, -2e-3),
) -> CVScenario:
    """Simulate the S1/S2 constant-velocity model with an acceleration burst the model does not expect.

    Positions follow dxi/dt = lambda, dlambda/dt = Omega (S1 eq. (3)) with white acceleration of
    standard deviation ``accel_std`` per epoch, plus a constant extra acceleration
    ``change_accel`` during ``[change_start, change_start + change_len)`` of the series (fractions
    of T) — e.g. the onset of mining subsidence — which a filter tuned to ``accel_std`` does not
    explain. Measurements are positions with white noise ``sigma``.

    Args:
      key: PRNG key.  T: static number of epochs.  dt: epoch interval, s.
      sigma: measurement noise std, m (scalar or (3,)).  accel_std: process acceleration std, m/s^2.
      change_start, change_len: fractions of T.  change_accel: (3,) m/s^2.  v0: (3,) m/s.
    Returns:
      :class:`CVScenario`.
    """
    kw, kv = jax.random.split(key)
    t = jnp.arange(1, T + 1) * dt
    i = jnp.arange(T)
    change = (i >= int(change_start * T)) & (i < int((change_start + change_len) * T))
    a_extra = jnp.where(change[:, None], jnp.asarray(change_accel, float), 0.0)
    a = accel_std * jax.random.normal(kw, (T, 3)) + a_extra

    def body(x, ak):
        p, v = x[:3], x[3:]
        p = p + dt * v + 0.5 * dt**2 * ak
        v = v + dt * ak
        x = jnp.concatenate([p, v])
        return x, x

    x0 = jnp.concatenate([jnp.zeros(3), jnp.asarray(v0, float)])
    _, xs = jax.lax.scan(body, x0, a)
    zs = xs[:, :3] + jnp.asarray(sigma, float) * jax.random.normal(kv, (T, 3))
    return CVScenario(t=t, x_true=xs, zs=zs, accel=a, change=change)
