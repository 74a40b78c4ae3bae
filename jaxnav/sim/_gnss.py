"""GNSS position/velocity fixes from a simulated trajectory: noise, outages, injected outliers.

Epoch times lie on IMU sample times (the GNSS interval and first epoch must be whole multiples of
the IMU interval, which is what an INS/GNSS integration with an outer scan over GNSS epochs and an
inner scan over the IMU samples between them wants); the truth at an epoch is the trajectory at
that sample, so no interpolation error enters.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxnav.geodesy import WGS84, Ellipsoid, enu_to_curvilinear, geodetic_to_enu
from jaxnav.sim._trajectory import ScenarioError, Trajectory, _num, _vec3


@dataclass(frozen=True)
class GnssConfig:
    """GNSS fix simulation (SI).

    Attributes:
      rate_hz: fix rate, Hz.
      first_epoch: time of the first fix, s (None: one GNSS interval after the start, so the
        first update follows the INS initialisation at t = 0).
      pos_sigma: (3,) white position noise std per ENU axis, m.
      vel_sigma: (3,) white velocity noise std per ENU axis, m/s.
      outages: ((start, end), ...) s; fixes with start <= t < end are missing.
      outlier_prob: probability that a (valid) fix carries an outlier.
      outlier_pos: m, magnitude of a position outlier (random direction, uniform on the sphere).
      outlier_vel: m/s, magnitude of a velocity outlier (independent random direction).
    """

    rate_hz: float = 1.0
    first_epoch: float | None = None
    pos_sigma: tuple = (5.0, 5.0, 8.0)
    vel_sigma: tuple = (0.1, 0.1, 0.15)
    outages: tuple = ()
    outlier_prob: float = 0.0
    outlier_pos: float = 0.0
    outlier_vel: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "rate_hz", _num(self.rate_hz, "gnss.rate_hz", positive=True))
        if self.first_epoch is not None:
            object.__setattr__(self, "first_epoch", _num(self.first_epoch, "gnss.first_epoch", nonneg=True))
        object.__setattr__(self, "pos_sigma", _vec3(self.pos_sigma, "gnss.pos_sigma", nonneg=True))
        object.__setattr__(self, "vel_sigma", _vec3(self.vel_sigma, "gnss.vel_sigma", nonneg=True))
        outs = []
        for i, o in enumerate(self.outages):
            try:
                a, b = o
            except (TypeError, ValueError):
                raise ScenarioError(f"gnss.outages[{i}] must be a pair [start, end], got {o!r}") from None
            a, b = _num(a, f"gnss.outages[{i}][0]"), _num(b, f"gnss.outages[{i}][1]")
            if not b > a:
                raise ScenarioError(f"gnss.outages[{i}] must have end > start, got {o!r}")
            outs.append((a, b))
        object.__setattr__(self, "outages", tuple(outs))
        p = _num(self.outlier_prob, "gnss.outlier_prob", nonneg=True)
        if p > 1:
            raise ScenarioError(f"gnss.outlier_prob must be in [0, 1], got {p}")
        object.__setattr__(self, "outlier_prob", p)
        object.__setattr__(self, "outlier_pos", _num(self.outlier_pos, "gnss.outlier_pos", nonneg=True))
        object.__setattr__(self, "outlier_vel", _num(self.outlier_vel, "gnss.outlier_vel", nonneg=True))


class GnssEpochs(NamedTuple):
    """Host-side epoch layout: sample index (M,), time (M,) s, not-in-outage mask (M,)."""

    index: np.ndarray
    t: np.ndarray
    available: np.ndarray


def _multiple(x, dt, name):
    k = round(x / dt)
    if abs(k * dt - x) > 1e-9 * max(1.0, abs(x)):
        raise ScenarioError(
            f"{name} = {x} s is not a whole number of IMU intervals ({dt} s): GNSS epochs must fall on IMU sample times"
        )
    return int(k)


def gnss_epochs(cfg: GnssConfig, dt: float, n_intervals: int) -> GnssEpochs:
    """Indices of the IMU samples that carry a GNSS fix (host side)."""
    step = _multiple(1.0 / cfg.rate_hz, dt, "gnss interval 1/rate_hz")
    if step < 1:
        raise ScenarioError(f"gnss.rate_hz = {cfg.rate_hz} is faster than the IMU")
    first = step if cfg.first_epoch is None else _multiple(cfg.first_epoch, dt, "gnss.first_epoch")
    idx = np.arange(first, n_intervals + 1, step, dtype=np.int64)
    t = idx * dt
    avail = np.ones(idx.shape, bool)
    for a, b in cfg.outages:
        avail &= ~((t >= a - 1e-9) & (t < b - 1e-9))
    return GnssEpochs(index=idx, t=t, available=avail)


class GnssData(NamedTuple):
    """Simulated GNSS fixes (M epochs). Missing fixes (outages) are NaN in pos/enu/vel.

    Attributes:
      t: (M,) s.  index: (M,) IMU sample index of each fix (truth.t[index] == t).
      pos: (M, 3) measured [lat rad, lon rad, h m].
      enu: (M, 3) measured position in the local ENU frame about the scenario origin, m.
      vel: (M, 3) measured ENU velocity, m/s.
      valid: (M,) bool, fix present (not in an outage).
      outlier: (M,) bool, an outlier was injected (only at valid fixes).
      pos_error: (M, 3) injected ENU position error (noise + outlier), m (also in outages).
      vel_error: (M, 3) injected ENU velocity error, m/s.
    """

    t: jax.Array
    index: jax.Array
    pos: jax.Array
    enu: jax.Array
    vel: jax.Array
    valid: jax.Array
    outlier: jax.Array
    pos_error: jax.Array
    vel_error: jax.Array


def simulate_gnss(
    key, cfg: GnssConfig, truth: Trajectory, epochs: GnssEpochs, origin, ellipsoid: Ellipsoid = WGS84
) -> GnssData:
    """Draw GNSS fixes from the truth (jit/vmap-able; ``epochs`` is static host data).

    The noise is drawn in the local ENU frame at the true point and added to the geodetic
    position through the radii of curvature (dlat = dN / (R_M + h), dlon = dE / ((R_N + h) cos
    lat), dh = dU); ``enu`` is the measured geodetic point expressed about ``origin``.

    Args:
      key: PRNG key.  cfg: :class:`GnssConfig`.  truth: :class:`Trajectory`.
      epochs: :class:`GnssEpochs`.  origin: (3,) [lat rad, lon rad, h m] of the local ENU frame.
    """
    dtype = truth.pos.dtype
    M = int(epochs.index.shape[0])
    kn, ko, kd = jax.random.split(key, 3)
    idx = jnp.asarray(epochs.index)
    pos_t, vel_t = truth.pos[idx], truth.v_n[idx]
    avail = jnp.asarray(epochs.available)
    z = jax.random.normal(kn, (M, 6), dtype)
    perr = jnp.asarray(cfg.pos_sigma, dtype) * z[:, :3]
    verr = jnp.asarray(cfg.vel_sigma, dtype) * z[:, 3:]
    if cfg.outlier_prob > 0:
        out = jax.random.bernoulli(ko, cfg.outlier_prob, (M,)) & avail
        u = jax.random.normal(kd, (M, 2, 3), dtype)
        u = u / jnp.linalg.norm(u, axis=-1, keepdims=True)  # uniform directions on the sphere
        perr = perr + jnp.where(out[:, None], cfg.outlier_pos * u[:, 0], 0.0)
        verr = verr + jnp.where(out[:, None], cfg.outlier_vel * u[:, 1], 0.0)
    else:
        out = jnp.zeros((M,), bool)
    pos_m = pos_t + enu_to_curvilinear(pos_t, perr, ellipsoid)
    vel_m = vel_t + verr
    o = jnp.asarray(origin, dtype)
    enu = jnp.stack(geodetic_to_enu(pos_m[:, 0], pos_m[:, 1], pos_m[:, 2], o[0], o[1], o[2], ellipsoid=ellipsoid), -1)
    nan = jnp.asarray(math.nan, dtype)
    gate = avail[:, None]
    return GnssData(
        t=jnp.asarray(epochs.t, dtype),
        index=idx,
        pos=jnp.where(gate, pos_m, nan),
        enu=jnp.where(gate, enu, nan),
        vel=jnp.where(gate, vel_m, nan),
        valid=avail,
        outlier=out,
        pos_error=perr,
        vel_error=verr,
    )
