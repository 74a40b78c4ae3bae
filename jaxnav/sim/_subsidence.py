"""Mining-subsidence simulator for a GNSS monitoring network at 1 Hz (S1 scenario).

Truth: each station follows Knothe's time function W(t) = W_max (1 - exp(-c (t - t_0))) for
t > t_0 (Knothe 1953; the standard time function of mining subsidence), vertical downwards, with
horizontal displacement proportional to it, plus a constant background velocity. The velocity
jumps to c W_max at the onset and then decays: dynamics a constant-velocity filter tuned to a
quiet station does not expect.

Noise: 1 Hz GNSS positions are not white. Real CORS/RTK series show white noise plus
time-correlated errors (multipath, troposphere) with correlation times of minutes, part of it
common to stations that share a base station. The measurement error here is the sum of white
noise, a first-order Gauss-Markov process per station and axis, and a Gauss-Markov process
common to all stations.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxnav.units import MM


class SubsidenceConfig(NamedTuple):
    """Parameters of :func:`simulate_subsidence` (all array leaves; S stations).

    Attributes:
      w_max: (S,) final subsidence of the episode, m (positive = down).
      rate: (S,) Knothe rate c, 1/s (time constant 1/c).
      onset: (S,) onset time t_0, s from the first epoch.
      horizontal: (S, 2) east, north displacement per metre of subsidence (dimensionless).
      v0: (S, 3) background velocity east, north, up, m/s.
      sigma_white: (3,) white-noise std east, north, up, m.
      sigma_corr: (3,) std of the per-station Gauss-Markov noise, m.
      tau_corr: scalar correlation time of the per-station noise, s.
      sigma_common: (3,) std of the common-mode Gauss-Markov noise, m.
      tau_common: scalar correlation time of the common-mode noise, s.
    """

    w_max: jax.Array
    rate: jax.Array
    onset: jax.Array
    horizontal: jax.Array
    v0: jax.Array
    sigma_white: jax.Array
    sigma_corr: jax.Array
    tau_corr: jax.Array
    sigma_common: jax.Array
    tau_common: jax.Array


def subsidence_config(
    n_stations: int = 2,
    *,
    w_max=40 * MM,
    time_constant=600.0,
    onset=900.0,
    horizontal=(0.15, -0.25),
    v0=(0.0, 0.0, 0.0),
    sigma_white=(1.5 * MM, 1.5 * MM, 3.0 * MM),
    sigma_corr=(1.0 * MM, 1.0 * MM, 2.0 * MM),
    tau_corr=120.0,
    sigma_common=(0.5 * MM, 0.5 * MM, 1.0 * MM),
    tau_common=600.0,
) -> SubsidenceConfig:
    """A :class:`SubsidenceConfig` with every station given the same values (broadcast to S).

    Args:
      n_stations: static S.  w_max: m.  time_constant: 1/c, s.  onset: s.  horizontal: (2,).
      v0: (3,) m/s.  sigma_white, sigma_corr, sigma_common: (3,) m.  tau_corr, tau_common: s.
    Returns:
      :class:`SubsidenceConfig` (float arrays).
    """
    S = int(n_stations)
    f = lambda a, shape: jnp.broadcast_to(jnp.asarray(a, float), shape)
    return SubsidenceConfig(
        w_max=f(w_max, (S,)),
        rate=1.0 / f(time_constant, (S,)),
        onset=f(onset, (S,)),
        horizontal=f(horizontal, (S, 2)),
        v0=f(v0, (S, 3)),
        sigma_white=f(sigma_white, (3,)),
        sigma_corr=f(sigma_corr, (3,)),
        tau_corr=jnp.asarray(tau_corr, float),
        sigma_common=f(sigma_common, (3,)),
        tau_common=jnp.asarray(tau_common, float),
    )


def knothe(t, w_max, rate, onset):
    """Knothe's time function W(t) = W_max (1 - exp(-c (t - t_0))) for t > t_0, else 0.

    Args:
      t: (...) s.  w_max: m.  rate: c, 1/s.  onset: t_0, s (broadcastable).
    Returns:
      (W, dW/dt), m and m/s, broadcast shape.
    """
    tau = jnp.maximum(t - onset, 0.0)
    e = jnp.exp(-rate * tau)
    on = t > onset
    return w_max * (1.0 - e), jnp.where(on, w_max * rate * e, 0.0)


class SubsidenceSim(NamedTuple):
    """Output of :func:`simulate_subsidence` (T epochs, S stations; ENU order).

    Attributes:
      t: (T,) s.  pos: (T, S, 3) true displacement, m.  vel: (T, S, 3) true velocity, m/s.
      zs: (T, 3 S) measured positions stacked station by station (the network vector L_k), m.
      noise: (T, S, 3) total measurement error, m.
    """

    t: jax.Array
    pos: jax.Array
    vel: jax.Array
    zs: jax.Array
    noise: jax.Array


def _ar1(key, T, shape, dt, sigma, tau):
    """Stationary first-order Gauss-Markov sequence (T,) + shape, exact discretisation."""
    phi = jnp.exp(-dt / tau)
    q = sigma * jnp.sqrt(-jnp.expm1(-2.0 * dt / tau))
    k0, k1 = jax.random.split(key)
    x0 = sigma * jax.random.normal(k0, shape)
    w = jax.random.normal(k1, (T,) + shape)

    def step(x, wk):
        x = phi * x + q * wk
        return x, x

    _, xs = jax.lax.scan(step, x0, w)
    return xs


def simulate_subsidence(key, config: SubsidenceConfig, T: int, dt=1.0) -> SubsidenceSim:
    """Simulate a subsiding GNSS monitoring network (Knothe episode, correlated 1 Hz noise).

    Args:
      key: PRNG key (first argument, explicit).
      config: :class:`SubsidenceConfig` for S stations.
      T: static number of epochs.  dt: epoch interval, s.
    Returns:
      :class:`SubsidenceSim`.
    """
    S = config.w_max.shape[0]
    t = jnp.arange(T) * dt
    W, dW = knothe(t[:, None], config.w_max, config.rate, config.onset)  # (T, S)
    dirn = jnp.concatenate([config.horizontal, -jnp.ones((S, 1))], axis=1)  # (S, 3): E, N, U per metre of W
    pos = W[..., None] * dirn + t[:, None, None] * config.v0
    vel = dW[..., None] * dirn + config.v0
    kw, kc, km = jax.random.split(key, 3)
    white = config.sigma_white * jax.random.normal(kw, (T, S, 3))
    corr = _ar1(kc, T, (S, 3), dt, config.sigma_corr, config.tau_corr)
    common = _ar1(km, T, (3,), dt, config.sigma_common, config.tau_common)[:, None, :]
    noise = white + corr + common
    zs = (pos + noise).reshape(T, 3 * S)
    return SubsidenceSim(t=t, pos=pos, vel=vel, zs=zs, noise=noise)
