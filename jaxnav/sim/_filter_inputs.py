"""What a loosely coupled filter needs from a simulated run: the IMU noise record and the inputs.

A simulated run is filtered in three lines (README "INS/GNSS on a simulated run"): the scenario's
IMU noise as an :class:`jaxnav.ins.ImuNoise` of arrays (:func:`imu_noise`), the filter parameters from
:func:`jaxnav.ins.lc_params`, the inputs from :func:`lc_inputs`.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxnav.ins import ImuNoise, NavState, gnss_measurements
from jaxnav.ins.integration import PVMeasurements


def _v3(x):
    return np.broadcast_to(np.asarray(x, float), (3,))


def imu_noise(cfg) -> ImuNoise:
    """The scenario's :class:`jaxnav.ins.ImuNoise` (``cfg.noise``) with (3,) float arrays for leaves.

    Args:
      cfg: :class:`ScenarioConfig` (or :class:`ImuGrade`): its ``noise`` holds (3,) tuples, SI.
    """
    return ImuNoise(*(np.asarray(v, float) for v in cfg.noise))


class LCInputs(NamedTuple):
    """The positional inputs of :func:`jaxnav.ins.loosely_coupled` for one simulated run.

    Attributes:
      nav0: :class:`jaxnav.ins.NavState` at t = 0 (truth plus the drawn initial errors).
      t_imu: (N,) end time of each IMU sample, s.  dtheta, dv: (N, 3) measured increments (rad, m/s).
      meas: :class:`jaxnav.ins.PVMeasurements` of the GNSS fixes (R diagonal from the scenario's
        ``gnss.pos_sigma`` m and ``gnss.vel_sigma`` m/s; outage epochs masked).
    """

    nav0: NavState
    t_imu: jax.Array
    dtheta: jax.Array
    dv: jax.Array
    meas: PVMeasurements


def lc_inputs(cfg, run, *, t_imu=None, t_gnss=None, lever=None) -> LCInputs:
    """Everything :func:`jaxnav.ins.loosely_coupled` needs from a :func:`simulate` result besides its parameters.

    ``ins.loosely_coupled(*sim.lc_inputs(cfg, run), params, dt_imu=cfg.dt)``.

    Args:
      cfg: :class:`ScenarioConfig`.  run: :class:`SimResult`.
      t_imu, t_gnss: optional concrete (N,) / (M,) times, s (default from ``run``; pass them
        under ``jit``/``vmap``, where the run's arrays are traced).
      lever: optional (3,) antenna lever arm in the body frame (right, forward, up), m; default 0.
    """
    t_imu = np.asarray(run.truth.t[1:]) if t_imu is None else t_imu
    gnss = run.gnss
    t = gnss.t if t_gnss is None else t_gnss
    meas = gnss_measurements(
        t,
        gnss.pos,
        gnss.vel,
        jnp.diag(jnp.asarray(_v3(cfg.gnss.pos_sigma) ** 2)),
        jnp.diag(jnp.asarray(_v3(cfg.gnss.vel_sigma) ** 2)),
        use=gnss.valid,
        lever=jnp.zeros(3) if lever is None else lever,
    )
    return LCInputs(run.nav0, t_imu, run.imu.dtheta, run.imu.dv, meas)
