"""Overlapping Allan deviation in JAX (batched over leading axes, jit-compiled per set of m).

For rate samples y_k (interval means over dt) the "phase" is x_0 = 0, x_k = dt sum_{i<k} y_i
(for IMU data: the running sum of increments). For an averaging time tau = m dt,

    AVAR(tau) = sum_{i=0}^{N-2m} (x_{i+2m} - 2 x_{i+m} + x_i)^2 / (2 tau^2 (N - 2m + 1)),

the fully overlapping estimator (IEEE Std 952 / allantools ``oadev`` with ``data_type="freq"``).
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np


@partial(jax.jit, static_argnames=("ms",))
def _oavar(x, dt, ms):
    out = []
    for m in ms:
        d = x[..., 2 * m:] - 2.0 * x[..., m:-m] + x[..., :-2 * m]
        tau = m * dt
        out.append(jnp.mean(d * d, axis=-1) / (2.0 * tau * tau))
    return jnp.stack(out, axis=-1)


def octave_ms(n: int, max_fraction: float = 0.5):
    """Averaging factors 1, 2, 4, ... with 2m <= max_fraction * 2 * n (at least 2 clusters)."""
    ms, m = [], 1
    while 2 * m <= int(2 * max_fraction * n) and 2 * m <= n:
        ms.append(m)
        m *= 2
    return tuple(ms)


def allan_variance(y, dt, ms=None, *, kind: str = "rate"):
    """Overlapping Allan variance of a rate series.

    Args:
      y: (..., N) samples along the last axis: interval-mean rates (kind="rate") or increments
        (kind="increment", divided by dt first).
      dt: sample interval, s.
      ms: averaging factors (static ints, tau = m dt); default octaves 1, 2, 4, ... up to N/2.
      kind: "rate" or "increment".
    Returns:
      (taus (k,) s as numpy, avar (..., k)) in the rate unit squared.
    """
    if kind not in ("rate", "increment"):
        raise ValueError(f"kind must be 'rate' or 'increment', got {kind!r}")
    y = jnp.asarray(y)
    n = y.shape[-1]
    ms = octave_ms(n) if ms is None else tuple(int(m) for m in ms)
    for m in ms:
        if m < 1 or 2 * m > n:
            raise ValueError(f"averaging factor m={m} needs 1 <= m <= N/2 = {n // 2}")
    inc = y if kind == "increment" else y * dt
    x = jnp.concatenate([jnp.zeros(y.shape[:-1] + (1,), y.dtype), jnp.cumsum(inc, axis=-1)], axis=-1)
    return np.asarray(ms, float) * float(dt), _oavar(x, dt, ms)


def allan_deviation(y, dt, ms=None, *, kind: str = "rate"):
    """Overlapping Allan deviation; see :func:`allan_variance` (returns (taus, adev))."""
    taus, av = allan_variance(y, dt, ms, kind=kind)
    return taus, jnp.sqrt(av)
