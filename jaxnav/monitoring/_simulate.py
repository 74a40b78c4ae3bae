"""Simulated daily series with power-law noise of known parameters (for coverage checks)."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jaxnav.units import DAY, YEAR


def simulate_powerlaw_series(
    key, n_days: int, *, rate, sigma_white, amplitude, kappa=-1.0, random_walk=0.0, annual=0.0, gap_fraction=0.0
):
    """One daily series: rate x t + annual cosine + white + power-law (+ random walk) noise, with gaps.

    The power-law noise is the fractionally integrated white noise of Williams (2003, J. Geod. 76,
    eq. (7)-(9)) started at the first day: p_k = sum_{j<=k} h_j e_(k-j), h_0 = 1,
    h_j = h_(j-1) (j - 1 - kappa/2) / j, e ~ N(0, (amplitude dt^(-kappa/4))^2), dt one day (the
    non-stationary process Hector's own ``simulatenoise`` draws; the fit models it by the
    stationary GGM approximation, so the check includes that approximation). Computed by FFT.

    Args:
      key: PRNG key.  n_days: length (static).
      rate: m/s.  sigma_white: m.  amplitude: power-law amplitude, m / s^(-kappa/4).
      kappa: spectral index.  random_walk: m/sqrt(s).  annual: amplitude of a cosine, m.
      gap_fraction: share of days missing at random (NaN).
    Returns:
      (y (n_days,) m with NaN on missing days, t (n_days,) s from the first day).
    """
    k1, k2, k3, k4 = jax.random.split(key, 4)
    t = jnp.arange(n_days) * DAY
    j = jnp.arange(1, n_days, dtype=jnp.float64)
    h = jnp.concatenate([jnp.ones(1), jnp.cumprod((j - 1.0 - 0.5 * kappa) / j)])
    e = jax.random.normal(k1, (n_days,)) * amplitude * DAY ** (-kappa / 4.0)
    m = 2 * n_days
    p = jnp.fft.irfft(jnp.fft.rfft(h, m) * jnp.fft.rfft(e, m), m)[:n_days]
    rw = jnp.cumsum(jax.random.normal(k2, (n_days,))) * random_walk * jnp.sqrt(DAY)
    w = jax.random.normal(k3, (n_days,)) * sigma_white
    y = rate * (t - 0.5 * t[-1]) + annual * jnp.cos(2.0 * jnp.pi * t / YEAR) + p + rw + w
    gaps = jax.random.uniform(k4, (n_days,)) < gap_fraction
    return jnp.where(gaps, jnp.nan, y), t
