"""IMU sensor errors applied to ideal increments (gyro and accelerometer alike).

The noise terms are those of :class:`jaxnav.ins.ImuNoise`, per axis, in SI: turn-on bias (a random
constant drawn once per run), first-order Gauss-Markov bias instability (exact discrete AR(1)),
angle / velocity random walk (white noise), scale-factor error. :class:`SensorLimits` adds two
deliberately *unmodelled* effects: a first-order bandwidth limit and saturation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxnav.ins.noise import ImuNoise
from jaxnav.sim._trajectory import ScenarioError, _vec3

#: the :class:`jaxnav.ins.ImuNoise` random walks the simulator does not draw (they must be 0)
_NOT_SIMULATED = ("gyro_bias_rw", "accel_bias_rw", "gyro_sf_rw", "accel_sf_rw")


def simulator_noise(noise: ImuNoise) -> ImuNoise:
    """``noise`` with every term a (3,) tuple of floats (hashable: a static argument of ``jit``).

    Raises:
      ScenarioError: for a negative term, a non-positive correlation time, or a non-zero bias or
        scale-factor random walk (the simulator draws none).
    """
    if not isinstance(noise, ImuNoise):
        raise TypeError(f"noise must be a jaxnav.ins.ImuNoise, got {type(noise).__name__}")
    out = {f: _vec3(v, f"noise.{f}", nonneg=True, positive=f.endswith("_tau")) for f, v in zip(ImuNoise._fields, noise)}
    for f in _NOT_SIMULATED:
        if any(out[f]):
            raise ScenarioError(f"noise.{f} = {out[f]} is not simulated: the simulator draws no random walk of it")
    return ImuNoise(**out)


@dataclass(frozen=True)
class SensorLimits:
    """Sensor effects outside :class:`jaxnav.ins.ImuNoise` (unmodelled by the filters); None = absent.

    Attributes:
      gyro_saturation: largest |rate| the gyro reports, rad/s, (3,) (the interval-mean output is clipped).
      accel_saturation: largest |specific force| the accelerometer reports, m/s^2, (3,).
      gyro_bandwidth, accel_bandwidth: -3 dB cut-off of a first-order low-pass on the sensed rate, Hz, (3,).
    """

    gyro_saturation: tuple | None = None
    accel_saturation: tuple | None = None
    gyro_bandwidth: tuple | None = None
    accel_bandwidth: tuple | None = None

    def __post_init__(self):
        for f in ("gyro_saturation", "accel_saturation", "gyro_bandwidth", "accel_bandwidth"):
            v = getattr(self, f)
            if v is not None:
                object.__setattr__(self, f, _vec3(v, f"limits.{f}", positive=True))


class _Triad(NamedTuple):
    """One sensor triad's terms, (3,) tuples (``saturation`` / ``bandwidth`` None when absent)."""

    bias_sigma: tuple
    markov_sigma: tuple
    markov_tau: tuple
    white: tuple
    scale_sigma: tuple
    saturation: tuple | None
    bandwidth: tuple | None


def _triad(noise: ImuNoise, sensor: str, limits: SensorLimits | None) -> _Triad:
    if sensor not in ("gyro", "accel"):
        raise ValueError(f"sensor must be 'gyro' or 'accel', got {sensor!r}")
    n, lim = simulator_noise(noise), limits or SensorLimits()
    white = n.gyro_arw if sensor == "gyro" else n.accel_vrw
    return _Triad(
        bias_sigma=getattr(n, f"{sensor}_bias_initial"),
        markov_sigma=getattr(n, f"{sensor}_bias_instability"),
        markov_tau=getattr(n, f"{sensor}_bias_tau"),
        white=white,
        scale_sigma=getattr(n, f"{sensor}_sf"),
        saturation=getattr(lim, f"{sensor}_saturation"),
        bandwidth=getattr(lim, f"{sensor}_bandwidth"),
    )


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


def draw_sensor_errors(key, noise: ImuNoise, sensor: str, n: int, dt, dtype=jnp.float64) -> SensorDraw:
    """Draw one run's random errors of one sensor triad.

    The key is split into fixed sub-keys (constants, Markov, white noise): switching one term on
    or off does not change the draws of the others. One (2, 3) standard-normal draw gives the
    bias (row 0) and the scale factor (row 1).

    Args:
      key: PRNG key.  noise: :class:`jaxnav.ins.ImuNoise` (concrete values).
      sensor: ``"gyro"`` or ``"accel"``.  n: number of intervals (static).  dt: s.
    """
    m = _triad(noise, sensor, None)
    kc, km, kw = jax.random.split(key, 3)
    small = jax.random.normal(kc, (2, 3), dtype)
    bias = jnp.asarray(m.bias_sigma, dtype) * small[0]
    scale = jnp.asarray(m.scale_sigma, dtype) * small[1] if _any(m.scale_sigma) else None
    markov = markov_ar1(km, n, dt, m.markov_sigma, m.markov_tau, dtype) if _any(m.markov_sigma) else None
    white = (
        jnp.asarray(m.white, dtype) * jnp.sqrt(jnp.asarray(dt, dtype)) * jax.random.normal(kw, (n, 3), dtype)
        if _any(m.white)
        else None
    )
    return SensorDraw(bias=bias, markov=markov, scale=scale, white=white)


def apply_sensor_errors(ideal, dt, draw: SensorDraw, sensor: str, limits: SensorLimits | None = None, *, unsensed=None):
    """Measured increments from ideal ones (all (N, 3)).

    Order: r = (ideal - unsensed) / dt (interval-mean rate); r = lowpass(r) [bandwidth];
    r = (1 + scale) r + bias + markov_k; inc = r dt + white; inc = clip(inc, +-saturation dt).

    Args:
      ideal: (N, 3) ideal increments (rad or m/s).  dt: s.  draw: :class:`SensorDraw`.
      sensor: ``"gyro"`` or ``"accel"`` (which limits apply).  limits: :class:`SensorLimits` or None.
      unsensed: optional (N, 3) part of ``ideal`` the sensor does not see.
    """
    m = _triad(ImuNoise(0.0, 0.0), sensor, limits)
    x = ideal if unsensed is None else ideal - unsensed
    if m.bandwidth is not None:
        x = lowpass(x / dt, dt, m.bandwidth) * dt
    if draw.scale is not None:
        x = x * (1.0 + draw.scale)
    x = x + draw.bias * dt
    if draw.markov is not None:
        x = x + draw.markov * dt
    if draw.white is not None:
        x = x + draw.white
    if m.saturation is not None:
        lim = jnp.asarray(m.saturation, x.dtype) * dt
        x = jnp.clip(x, -lim, lim)
    return x


def corrupt_increments(
    key, ideal, dt, noise: ImuNoise, sensor: str, limits: SensorLimits | None = None, *, unsensed=None
):
    """Draw one triad's sensor errors and apply them: returns (measured (N, 3), :class:`SensorDraw`).

    Args:
      key: PRNG key.  ideal: (N, 3) ideal increments (rad or m/s).  dt: s.
      noise: :class:`jaxnav.ins.ImuNoise`.  sensor: ``"gyro"`` or ``"accel"``.
      limits: :class:`SensorLimits` or None.  unsensed: optional (N, 3) part of ``ideal`` not sensed.
    """
    draw = draw_sensor_errors(key, noise, sensor, ideal.shape[0], dt, ideal.dtype)
    return apply_sensor_errors(ideal, dt, draw, sensor, limits, unsensed=unsensed), draw


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
