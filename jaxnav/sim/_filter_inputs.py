"""What a loosely coupled filter needs from a simulated run: GNSS measurements, P0/Qc, inputs.

These are the public counterparts of what the S0 experiment builds internally, so that a
simulated run can be filtered in three lines (README "INS/GNSS on a simulated run").
"""

from __future__ import annotations

from typing import Any, NamedTuple, Optional

import jax.numpy as jnp
import numpy as np

from jaxnav.geodesy import meridian_radius, prime_vertical_radius
from jaxnav.ins import error_model_Qc, error_model_Qc15
from jaxnav.ins.integration import LCParams, PVMeasurements


def _v3(x):
    return np.broadcast_to(np.asarray(x, float), (3,))


def gnss_measurements(cfg, gnss, t=None, *, lever=None) -> PVMeasurements:
    """GNSS position/velocity measurements of a simulated run, R from the scenario's sigmas.

    Args:
      cfg: :class:`ScenarioConfig` (``gnss.pos_sigma`` m and ``gnss.vel_sigma`` m/s give the
        diagonal R, (M, 6, 6)).
      gnss: :class:`GnssData` with ``pos`` (M, 3) lat, lon (rad), h (m); ``vel`` (M, 3) ENU m/s;
        ``valid`` (M,) bool (outage epochs are masked).
      t: (M,) epoch times, s; default ``gnss.t``. Under ``jit``/``vmap`` pass concrete times
        (they shape the filter's scan), e.g. those of one run outside the transformation.
      lever: optional (3,) antenna lever arm in the body frame (right, forward, up), m; default 0.
    Returns:
      :class:`jaxnav.ins.PVMeasurements`.
    """
    t = gnss.t if t is None else t
    M = np.shape(t)[0]
    R = np.diag(np.concatenate([_v3(cfg.gnss.pos_sigma) ** 2, _v3(cfg.gnss.vel_sigma) ** 2]))
    lever = jnp.zeros(3) if lever is None else jnp.asarray(lever, float)
    if lever.shape != (3,):
        raise ValueError(f"gnss_measurements(): lever must have shape (3,), got {lever.shape}")
    return PVMeasurements(t=t, pos=gnss.pos, vel=gnss.vel, R=jnp.broadcast_to(R, (M, 6, 6)),
                          mask=jnp.broadcast_to(gnss.valid[:, None], (M, 6)),
                          lever=jnp.broadcast_to(lever, (M, 3)))


def lc_params(cfg, *, n_states: int = 18, q_scale=1.0, r_scale=1.0) -> LCParams:
    """Filter parameters matching a scenario's error sigmas (S0 Sec. 4: P0 from the initial errors).

    P0 is diagonal: attitude (rad^2), velocity ((m/s)^2), position (lat, lon rad^2, h m^2) from
    ``cfg.initial_errors``; gyro bias, (18 states: gyro Gauss-Markov) and accelerometer bias from
    ``cfg.gyro`` / ``cfg.accel``. Qc is the continuous process noise of the error model
    (S0 eq. (3)), times ``q_scale``; ``r_scale`` multiplies every measurement R.

    Args:
      cfg: :class:`ScenarioConfig`.  n_states: 18 (S0) or 15 (no gyro Markov state).
      q_scale, r_scale: scalars (array leaves: ``vmap``/``grad`` reach them).
    Returns:
      :class:`jaxnav.ins.LCParams`.
    """
    if n_states not in (15, 18):
        raise ValueError(f"lc_params(): n_states must be 15 or 18, got {n_states}")
    ie, g, a = cfg.initial_errors, cfg.gyro, cfg.accel
    lat, h = float(cfg.origin[0]), float(cfg.origin[2])
    RM, RN = float(meridian_radius(lat)) + h, float(prime_vertical_radius(lat)) + h
    pe = _v3(ie.position)
    p0 = [_v3(ie.attitude) ** 2, _v3(ie.velocity) ** 2,
          np.array([pe[1] / RM, pe[0] / (RN * np.cos(lat)), pe[2]]) ** 2, _v3(g.bias_sigma) ** 2]
    if n_states == 18:
        p0.append(_v3(g.markov_sigma) ** 2)
        Qc = error_model_Qc(_v3(g.white), _v3(g.markov_sigma), _v3(g.markov_tau), _v3(a.white))
    else:
        Qc = error_model_Qc15(_v3(g.white), _v3(a.white))
    p0.append(_v3(a.bias_sigma) ** 2)
    return LCParams(P0=jnp.diag(jnp.asarray(np.concatenate(p0))), Qc=Qc * q_scale,
                    tau_markov=jnp.asarray(_v3(g.markov_tau)), R_scale=r_scale)


class LCInputs(NamedTuple):
    """The positional inputs of :func:`jaxnav.ins.loosely_coupled` for one simulated run.

    Attributes:
      nav0: :class:`jaxnav.ins.NavState` at t = 0 (truth plus the drawn initial errors).
      t_imu: (N,) end time of each IMU sample, s.  dtheta, dv: (N, 3) measured increments (rad, m/s).
      meas: :class:`jaxnav.ins.PVMeasurements` of the GNSS fixes.
    """

    nav0: Any
    t_imu: Any
    dtheta: Any
    dv: Any
    meas: PVMeasurements


def lc_inputs(cfg, run, *, t_imu=None, t_gnss=None, lever=None) -> LCInputs:
    """Everything :func:`jaxnav.ins.loosely_coupled` needs from a :func:`simulate` result.

    ``ins.loosely_coupled(*sim.lc_inputs(cfg, run), sim.lc_params(cfg), dt_imu=cfg.dt)``.

    Args:
      cfg: :class:`ScenarioConfig`.  run: :class:`SimResult`.
      t_imu, t_gnss: optional concrete (N,) / (M,) times, s (default from ``run``; pass them
        under ``jit``/``vmap``, where the run's arrays are traced).
      lever: optional (3,) body-frame lever arm, m (see :func:`gnss_measurements`).
    """
    t_imu = np.asarray(run.truth.t[1:]) if t_imu is None else t_imu
    return LCInputs(run.nav0, t_imu, run.imu.dtheta, run.imu.dv,
                    gnss_measurements(cfg, run.gnss, t_gnss, lever=lever))
