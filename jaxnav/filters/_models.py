"""Ready-made models: the constant-velocity model of S1 / S2 (linear) and a coordinated-turn vehicle
model with position measurements (nonlinear)."""

from __future__ import annotations

from functools import cache

import jax.numpy as jnp

from jaxnav.filters._model import LinearGaussian
from jaxnav.filters._nonlinear import NonlinearGaussian


def constant_velocity(dt, *, sigma, accel_var=None, q=None, ndim: int = 3) -> LinearGaussian:
    """Constant-velocity model, state [position (ndim), velocity (ndim)] (S1 eqs. (3)-(6)).

    F = [[I, dt I], [0, I]], H = [I 0], R = sigma^2 I. The acceleration is the random
    disturbance, given one of two ways:

    * ``accel_var``: discrete per-epoch acceleration variance D_Omega (S1, S2 eq. (17)):
      G = [[dt^2/2 I], [dt I]], Q = D_Omega (m^2/s^4; scalar or (ndim,) diagonal);
    * ``q``: continuous white-noise acceleration PSD (m^2/s^3): G = None and
      Q = q [[dt^3/3, dt^2/2], [dt^2/2, dt]] kron I.

    Args:
      dt: epoch interval, s (scalar; for uneven epochs build a time-varying model).
      sigma: measurement standard deviation, m (scalar or (ndim,)).
      accel_var: see above.  q: see above (exactly one of the two).
      ndim: static number of position axes.
    Returns:
      :class:`LinearGaussian` with n = 2 ndim, m = ndim.
    Raises:
      ValueError: if not exactly one of ``accel_var`` and ``q`` is given.
    """
    if (accel_var is None) == (q is None):
        raise ValueError("constant_velocity(): give exactly one of accel_var= (discrete) or q= (continuous PSD)")
    dt = jnp.asarray(dt, dtype=float)
    I = jnp.eye(ndim)
    Z = jnp.zeros((ndim, ndim))
    F = jnp.block([[I, dt * I], [Z, I]])
    H = jnp.concatenate([I, Z], axis=1)
    R = jnp.diag(jnp.broadcast_to(jnp.asarray(sigma, float) ** 2, (ndim,)))
    if accel_var is not None:
        G = jnp.concatenate([0.5 * dt**2 * I, dt * I], axis=0)
        Q = jnp.diag(jnp.broadcast_to(jnp.asarray(accel_var, float), (ndim,)))
        return LinearGaussian(F=F, H=H, Q=Q, R=R, G=G)
    Qc = jnp.asarray(q, float) * jnp.array([[dt**3 / 3.0, dt**2 / 2.0], [dt**2 / 2.0, dt]])
    return LinearGaussian(F=F, H=H, Q=jnp.kron(Qc, I), R=R)


@cache
def _ct_functions(dt: float):
    """(f, h) of :func:`coordinated_turn` for the step ``dt`` s, one pair per step so that jit caches hold."""

    def transition(x, t):
        e, n, v, th, om = x
        return jnp.stack([e + v * jnp.cos(th) * dt, n + v * jnp.sin(th) * dt, v, th + om * dt, om])

    def position(x, t):
        return x[:2]

    return transition, position


def coordinated_turn(dt: float, R, *, accel_std=1.0, turn_std=0.1, pos_std=0.1) -> NonlinearGaussian:
    """Coordinated-turn vehicle model, state [east m, north m, speed m/s, heading rad, turn rate rad/s].

    Heading counter-clockwise from east; one step of ``dt`` s (Bar-Shalom, Li, Kirubarajan 2001, sect. 11.7):

        e' = e + v cos(th) dt,  n' = n + v sin(th) dt,  v' = v,  th' = th + om dt,  om' = om,

    measured position h(x) = [e, n]; white along-track acceleration (``accel_std`` m/s^2) and turn-rate
    change (``turn_std`` rad/s^2), plus ``pos_std`` m per step of unmodelled lateral motion:
    Q = diag(pos_std^2, pos_std^2, (accel_std dt)^2, (turn_std dt^2 / 2)^2, (turn_std dt)^2).

    Args:
      dt: step, s (a Python number: static).  R: (2, 2) or (T, 2, 2) measurement covariance, m^2.
    Returns:
      :class:`NonlinearGaussian` with n = 5, m = 2.
    """
    dt = float(dt)
    q = jnp.array([pos_std**2, pos_std**2, (accel_std * dt) ** 2, (turn_std * dt**2 / 2) ** 2, (turn_std * dt) ** 2])
    R = jnp.asarray(R)
    if R.shape[-2:] != (2, 2):
        raise ValueError(f"coordinated_turn: R has shape {R.shape}, expected (2, 2) or (T, 2, 2)")
    f, h = _ct_functions(dt)
    return NonlinearGaussian(f, h, jnp.diag(q), R)
