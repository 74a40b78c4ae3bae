"""Ready-made linear models: the constant-velocity model of S1 / S2."""

from __future__ import annotations

import jax.numpy as jnp

from jaxnav.filters._model import LinearGaussian


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
