"""IMU sensor error models applied to ideal increments (gyro and accelerometer alike).

Per axis, in SI: random constant bias (drawn once per run), first-order Gauss-Markov drift
(exact discrete AR(1)), white noise given as angle/velocity random walk, optional scale-factor
error, and two deliberately *unmodelled* effects: a first-order bandwidth limit and saturation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxnav.sim._trajectory import _vec3


@dataclass(frozen=True)
class SensorErrorModel:
    """Error model of one sensor triad (SI; every entry per axis, scalars broadcast to 3).

    The noise terms are those of :class:`jaxnav.ins.ImuNoise`, per triad: ``bias_sigma`` is its turn-on
    bias, ``markov_sigma`` / ``markov_tau`` its bias instability and correlation time, ``white`` its
    ARW / VRW, ``scale_sigma`` its scale-factor sigma; :func:`jaxnav.sim.imu_noise` gives a scenario's
    gyro and accelerometer as that record.

    Attributes:
      bias_sigma: std of the random constant bias, drawn per run from N(0, sigma^2)
        (rad/s for a gyro, m/s^2 for an accelerometer).
      markov_sigma: steady-state std of the first-order Gauss-Markov drift (same unit).
      markov_tau: correlation time of the Gauss-Markov drift, s.
      white: white noise density: angle random walk, rad/sqrt(s), or velocity random walk,
        m/s/sqrt(s) (= m/s^2/sqrt(Hz)). The increment noise std is ``white * sqrt(dt)``.
      scale_sigma: std of the random scale-factor error (dimensionless; 1e-6 = 1 ppm).
      saturation: None, or the largest |rate| / |specific force| the sensor reports (the
        interval-mean output is clipped).
      bandwidth: None, or the -3 dB cut-off (Hz) of a first-order low-pass on the sensed rate.
    """

    bias_sigma: tuple = (0.0, 0.0, 0.0)
    markov_sigma: tuple = (0.0, 0.0, 0.0)
    markov_tau: tuple = (3600.0, 3600.0, 3600.0)
    white: tuple = (0.0, 0.0, 0.0)
    scale_sigma: tuple = (0.0, 0.0, 0.0)
    saturation: tuple | None = None
    bandwidth: tuple | None = None

    def __post_init__(self):
        for f in ("bias_sigma", "markov_sigma", "white", "scale_sigma"):
            object.__setattr__(self, f, _vec3(getattr(self, f), f"sensor.{f}", nonneg=True))
        object.__setattr__(self, "markov_tau", _vec3(self.markov_tau, "sensor.markov_tau", positive=True))
        for f in ("saturation", "bandwidth"):
            v = getattr(self, f)
            if v is not None:
                object.__setattr__(self, f, _vec3(v, f"sensor.{f}", positive=True))


class SensorDraw(NamedTuple):
    """The random part of one run's sensor errors (``None`` where the model term is zero).

    Attributes:
      bias: (3,) random constant bias (rad/s or m/s^2).
      markov: (N, 3) Gauss-Markov drift, constant over each interval, or None.
      scale: (3,) scale-factor error, or None.
      white: (N, 3) white-noise increments (rad or m/s), or None.
    """

    bias: jax.Array
    markov: jax.Array | None
    scale: jax.Array | None
    white: jax.Array | None


def _any(v):
    return v is not None and any(a != 0.0 for a in v)


def _block_size(n: int, target: int = 1024) -> int:
    """Largest divisor of n in [target/4, target] (0 if none: then the sequence is padded)."""
    for d in range(min(n, target), max(target // 4, 1) - 1, -1):
        if n % d == 0:
            return d
    return 0


def markov_ar1(key, n: int, dt, sigma, tau, dtype=jnp.float64):
    """Exact discrete first-order Gauss-Markov sequence, stationary from the start.

    x_0 ~ N(0, sigma^2),  x_{k+1} = phi x_k + sigma sqrt(1 - phi^2) w_k,  phi = exp(-dt / tau),
    which samples the continuous process dx/dt = -x/tau + noise exactly at the sample times.
    The driving noise is drawn block by block inside the scan (``fold_in(key, block)``), so no
    (n, 3) noise array is held besides the output.

    Args:
      key: PRNG key.  n: static length.  dt: s.  sigma, tau: (3,) steady std and correlation time.
    Returns:
      (n, 3) array (x_k used over interval k).
    """
    sigma = jnp.asarray(sigma, dtype)
    a = jnp.asarray(dt, dtype) / jnp.asarray(tau, dtype)
    phi = jnp.exp(-a)
    q = sigma * jnp.sqrt(-jnp.expm1(-2.0 * a))
    k0, k1 = jax.random.split(key)
    x0 = sigma * jax.random.normal(k0, (3,), dtype)
    B = _block_size(n) or min(n, 1024)
    nb = -(-n // B)

    def step(x, wk):
        return phi * x + q * wk, x

    def block(x, b):
        w = jax.random.normal(jax.random.fold_in(k1, b), (B, 3), dtype)
        return jax.lax.scan(step, x, w)

    _, xs = jax.lax.scan(block, x0, jnp.arange(nb))
    xs = xs.reshape(nb * B, 3)
    return xs if nb * B == n else xs[:n]


def lowpass(rate, dt, cutoff_hz):
    """First-order low-pass y_k = alpha y_{k-1} + (1 - alpha) x_k, alpha = exp(-2 pi f_c dt).

    Zero-order-hold discretization of a first-order lag applied to interval-mean rates (N, 3);
    starts in steady state (y_{-1} = x_0).
    """
    alpha = jnp.exp(-2.0 * jnp.pi * jnp.asarray(cutoff_hz, rate.dtype) * dt)

    def step(y, x):
        y = alpha * y + (1.0 - alpha) * x
        return y, y

    _, ys = jax.lax.scan(step, rate[0], rate)
    return ys


def draw_sensor_errors(key, model: SensorErrorModel, n: int, dt, dtype=jnp.float64) -> SensorDraw:
    """Draw one run's random sensor errors.

    The key is split into fixed sub-keys (constants, Markov, white noise): switching one term on
    or off does not change the draws of the others. One (2, 3) standard-normal draw gives the
    bias (row 0) and the scale factor (row 1).
    """
    kc, km, kw = jax.random.split(key, 3)
    small = jax.random.normal(kc, (2, 3), dtype)
    bias = jnp.asarray(model.bias_sigma, dtype) * small[0]
    scale = jnp.asarray(model.scale_sigma, dtype) * small[1] if _any(model.scale_sigma) else None
    markov = markov_ar1(km, n, dt, model.markov_sigma, model.markov_tau, dtype) if _any(model.markov_sigma) else None
    white = (
        jnp.asarray(model.white, dtype) * jnp.sqrt(jnp.asarray(dt, dtype)) * jax.random.normal(kw, (n, 3), dtype)
        if _any(model.white)
        else None
    )
    return SensorDraw(bias=bias, markov=markov, scale=scale, white=white)


def apply_sensor_errors(ideal, dt, model: SensorErrorModel, draw: SensorDraw, unsensed=None):
    """Measured increments from ideal ones (all (N, 3)).

    Order: r = (ideal - unsensed) / dt (interval-mean rate); r = lowpass(r) [bandwidth];
    r = (1 + scale) r + bias + markov_k; inc = r dt + white; inc = clip(inc, +-saturation dt).

    Args:
      ideal: (N, 3) ideal increments (rad or m/s).  dt: s.
      model: :class:`SensorErrorModel`.  draw: :class:`SensorDraw`.
      unsensed: optional (N, 3) part of ``ideal`` the sensor does not see.
    """
    x = ideal if unsensed is None else ideal - unsensed
    if model.bandwidth is not None:
        x = lowpass(x / dt, dt, model.bandwidth) * dt
    if draw.scale is not None:
        x = x * (1.0 + draw.scale)
    x = x + draw.bias * dt
    if draw.markov is not None:
        x = x + draw.markov * dt
    if draw.white is not None:
        x = x + draw.white
    if model.saturation is not None:
        lim = jnp.asarray(model.saturation, x.dtype) * dt
        x = jnp.clip(x, -lim, lim)
    return x


def corrupt_increments(key, ideal, dt, model: SensorErrorModel, unsensed=None):
    """Draw sensor errors and apply them: returns (measured (N, 3), :class:`SensorDraw`)."""
    draw = draw_sensor_errors(key, model, ideal.shape[0], dt, ideal.dtype)
    return apply_sensor_errors(ideal, dt, model, draw, unsensed), draw


# ------------------------------------------------------------------------------------------
# theory for checks


def allan_variance_theory(dt: float, m, *, white=0.0, markov_sigma=0.0, markov_tau=1.0):
    """Exact Allan variance of the simulated rate error r_k = w_k + x_k (interval means).

    For averaging time tau = m dt: white noise of density N contributes N^2 / tau (exactly, for
    increments of std N sqrt(dt)); the discrete AR(1) drift of steady variance s^2 and
    phi = exp(-dt / T) contributes Var(mean of m) - Cov(adjacent means):

        s^2 / m^2 [m + 2 (phi (m (1 - phi) - (1 - phi^m))) / (1 - phi)^2 - phi (1 - phi^m)^2 / (1 - phi)^2].

    A random constant contributes nothing. Returns an array like ``m`` (unit^2).
    """
    m = np.asarray(m, dtype=float)
    tau = m * dt
    av = np.asarray(white, float) ** 2 / tau
    s2 = float(markov_sigma) ** 2
    if s2 > 0:
        a = dt / float(markov_tau)
        phi = math.exp(-a)
        om = -math.expm1(-a)  # 1 - phi
        omm = -np.expm1(-a * m)  # 1 - phi^m
        var = (m + 2.0 * phi * (m * om - omm) / om**2) / m**2
        cov = phi * omm**2 / om**2 / m**2
        av = av + s2 * (var - cov)
    return av
