"""The statistics of S1's tables, over periods of a forecast series (pure jnp, vmap-able).

Deviations are per epoch, station and axis (T, S, 3); a period is ``period`` consecutive epochs
(S1: 3600 epochs = one hour at 1 Hz; 14 400 for the internal precision). NaN deviations (masked
epochs) are left out of every statistic.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

#: S1 Tables 3-5 thresholds in the order x (north), y (east), H (up), m
S1_THRESHOLDS_XYH = (0.5e-3, 0.4e-3, 1.0e-3)


def _periods(a, period):
    """(T, ...) -> (P, period, ...) keeping whole periods only."""
    period = int(period)
    T = a.shape[0]
    P = T // period
    if P < 1:
        raise ValueError(f"series of {T} epochs is shorter than one period of {period} epochs")
    return a[: P * period].reshape((P, period) + a.shape[1:])


class PeriodStatistics(NamedTuple):
    """Forecast statistics per period, station and axis (S1 Tables 1-5, eq. (20)).

    Attributes:
      max_abs: (P, S, 3) largest |deviation|, m.
      mean_abs: (P, S, 3) mean |deviation|, m.
      share_under: (P, S, 3) fraction of epochs with |deviation| < threshold (0..1).
      rms: (P, S, 3) sqrt(mean deviation^2) per axis, m.
      m_P: (P, S) plane forecast RMS sqrt(sum(m_x^2 + m_y^2) / k) over the first two axes, m.
      m_H: (P, S) height forecast RMS sqrt(sum(m_H^2) / k) over the third axis, m.
      count: (P, S) epochs with a deviation.
    """

    max_abs: jax.Array
    mean_abs: jax.Array
    share_under: jax.Array
    rms: jax.Array
    m_P: jax.Array
    m_H: jax.Array
    count: jax.Array


def period_statistics(dev, period: int, thresholds=S1_THRESHOLDS_XYH) -> PeriodStatistics:
    """Max, mean, share under threshold and m_P, m_H of forecast deviations per period (S1 eq. (20)).

    Args:
      dev: (T, S, 3) forecast deviations, m (axes: two plane axes, then height). NaN = none.
      period: static epochs per period.
      thresholds: (3,) per-axis thresholds, m (default S1's 0.5, 0.4, 1 mm).
    Returns:
      :class:`PeriodStatistics`.
    """
    dev = jnp.asarray(dev, float)
    if dev.ndim != 3 or dev.shape[-1] != 3:
        raise ValueError(f"dev has shape {dev.shape}; expected (T, S, 3)")
    d = _periods(dev, period)  # (P, k, S, 3)
    ok = jnp.isfinite(d)
    a = jnp.where(ok, jnp.abs(d), 0.0)
    n = jnp.sum(ok, axis=1)
    nn = jnp.maximum(n, 1)
    thr = jnp.asarray(thresholds, float)
    ms = jnp.sum(a**2, axis=1) / nn
    both = ok[..., 0] & ok[..., 1]
    kP = jnp.maximum(jnp.sum(both, axis=1), 1)
    m_P = jnp.sqrt(jnp.sum(jnp.where(both, a[..., 0] ** 2 + a[..., 1] ** 2, 0.0), axis=1) / kP)
    return PeriodStatistics(
        max_abs=jnp.max(a, axis=1),
        mean_abs=jnp.sum(a, axis=1) / nn,
        share_under=jnp.sum(ok & (a < thr), axis=1) / nn,
        rms=jnp.sqrt(ms),
        m_P=m_P,
        m_H=jnp.sqrt(ms[..., 2]),
        count=n[..., 2],
    )


class InternalPrecision(NamedTuple):
    """Internal precision per period (S1 eqs. (21)-(22)).

    Attributes:
      sigma: (P, S, 3) sqrt(sum (x_i - mean)^2 / (k - 1)) per axis, m.
      plane: (P, S) sqrt(sigma_x^2 + sigma_y^2), m.
      height: (P, S) sigma of the third axis, m.
    """

    sigma: jax.Array
    plane: jax.Array
    height: jax.Array


def internal_precision(values, period: int) -> InternalPrecision:
    """Scatter of a series about its period mean (S1 eqs. (21)-(22)).

    Args:
      values: (T, S, 3) filtered or forecast positions, m (NaN left out).
      period: static epochs per period (S1: 14 400).
    Returns:
      :class:`InternalPrecision`.
    """
    v = _periods(jnp.asarray(values, float), period)
    ok = jnp.isfinite(v)
    n = jnp.sum(ok, axis=1)
    mean = jnp.sum(jnp.where(ok, v, 0.0), axis=1) / jnp.maximum(n, 1)
    ss = jnp.sum(jnp.where(ok, (v - mean[:, None]) ** 2, 0.0), axis=1)
    sig = jnp.sqrt(ss / jnp.maximum(n - 1, 1))
    return InternalPrecision(sigma=sig, plane=jnp.hypot(sig[..., 0], sig[..., 1]), height=sig[..., 2])


def improvement(standard, adaptive):
    """Improvement in percent, 100 (standard - adaptive) / standard (S1 Table 6)."""
    standard = jnp.asarray(standard, float)
    return 100.0 * (standard - jnp.asarray(adaptive, float)) / standard


def rms(a, axis=None):
    """sqrt(mean a^2) ignoring NaN."""
    a = jnp.asarray(a, float)
    ok = jnp.isfinite(a)
    return jnp.sqrt(jnp.sum(jnp.where(ok, a**2, 0.0), axis=axis) / jnp.maximum(jnp.sum(ok, axis=axis), 1))
