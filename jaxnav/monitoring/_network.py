"""S1 network model and forecasting: block-diagonal constant velocity, standard vs adaptive filters.

State of a network of S stations (S1 eqs. (1)-(6)): X = [xi_1, lambda_1, ..., xi_S, lambda_S],
each block 3 positions (m) and 3 velocities (m/s) in the order of the input (ENU here, Gauss
x, y, H in S1); measurements L_k = B X_k + Delta_k are the stacked positions.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from jaxnav import filters as jf
from jaxnav.filters import LinearGaussian


def _per_station(a, S, name):
    a = jnp.asarray(a, float)
    if a.ndim == 0:
        a = jnp.broadcast_to(a, (3,))
    if a.shape == (3,):
        a = jnp.broadcast_to(a, (S, 3))
    if a.shape != (S, 3):
        raise ValueError(f"{name} has shape {a.shape}; expected (), (3,) or ({S}, 3)")
    return a


def network_model(n_stations: int, dt, *, sigma, accel_var) -> LinearGaussian:
    """Block-diagonal constant-velocity model of an S-station network (S1 eqs. (3)-(6)).

    Phi = I_S kron [[I, dt I], [0, I]], Gamma = I_S kron [[dt^2/2 I], [dt I]], B = I_S kron [I 0],
    D_Delta = diag(sigma^2), D_Omega = diag(accel_var).

    Args:
      n_stations: static S.
      dt: epoch interval, s (scalar).
      sigma: measurement std, m: scalar, (3,) per axis or (S, 3).
      accel_var: per-epoch acceleration variance D_Omega, m^2/s^4: scalar, (3,) or (S, 3).
    Returns:
      :class:`jaxnav.filters.LinearGaussian` with n = 6 S, m = p = 3 S.
    Raises:
      ValueError: sigma or accel_var of another shape (naming it).
    """
    S = int(n_stations)
    if S < 1:
        raise ValueError(f"network_model(): n_stations must be >= 1, got {n_stations!r}")
    one = jf.constant_velocity(dt, sigma=1.0, accel_var=1.0)
    I_S = jnp.eye(S)
    sig = _per_station(sigma, S, "sigma").reshape(-1)
    q = _per_station(accel_var, S, "accel_var").reshape(-1)
    return LinearGaussian(
        F=jnp.kron(I_S, one.F), H=jnp.kron(I_S, one.H), Q=jnp.diag(q), R=jnp.diag(sig**2), G=jnp.kron(I_S, one.G)
    )


def network_model_irregular(t, cov, *, accel_psd, dt_min=1.0) -> LinearGaussian:
    """Time-varying network model for uneven epochs with per-epoch covariances (daily series).

    Phi_k and Gamma_k use dt_k = t_k - t_{k-1} (dt_0 = 0: the first measurement updates x0
    directly); D_Delta[k] is block diagonal from the per-station (3, 3) covariances, and
    D_Omega[k] = diag(accel_psd) / max(dt_k, dt_min), so that the velocity variance grows by
    accel_psd * dt_k over any gap (a velocity random walk of PSD accel_psd, m^2/s^3; the position
    part is dt^3/4 instead of the continuous dt^3/3).

    Args:
      t: (T,) epoch times, s, increasing.
      cov: (T, S, 3, 3) measurement covariances, m^2 (any finite PD value where a station has
        no measurement; its update is masked).
      accel_psd: velocity random-walk PSD, m^2/s^3: scalar, (3,) or (S, 3).
      dt_min: s, lower bound of dt_k in the division (the first epoch has dt_0 = 0).
    Returns:
      :class:`LinearGaussian` with (T, ...) leaves F, G, Q, R and a static H.
    Raises:
      ValueError: t, cov of inconsistent shapes.
    """
    t = jnp.asarray(t, float)
    cov = jnp.asarray(cov, float)
    if cov.ndim != 4 or t.shape != cov.shape[:1] or cov.shape[2:] != (3, 3):
        raise ValueError(f"t has shape {t.shape} and cov {cov.shape}; expected (T,) and (T, S, 3, 3)")
    S = cov.shape[1]
    dt = jnp.concatenate([jnp.zeros(1), jnp.diff(t)])
    I3, Z3 = jnp.eye(3), jnp.zeros((3, 3))
    I_S = jnp.eye(S)

    def blocks(d):
        F1 = jnp.block([[I3, d * I3], [Z3, I3]])
        G1 = jnp.concatenate([0.5 * d**2 * I3, d * I3], axis=0)
        return jnp.kron(I_S, F1), jnp.kron(I_S, G1)

    F, G = jax.vmap(blocks)(dt)
    eye = jnp.eye(S)
    R = jnp.einsum("tiab,ij->tiajb", cov, eye).reshape(cov.shape[0], 3 * S, 3 * S)
    q = _per_station(accel_psd, S, "accel_psd").reshape(-1)
    Q = jax.vmap(lambda d: jnp.diag(q / jnp.maximum(d, dt_min)))(dt)
    H = jnp.kron(I_S, jnp.concatenate([I3, Z3], axis=1))
    return LinearGaussian(F=F, H=H, Q=Q, R=R, G=G)


def initial_state(z0, *, sigma_pos, sigma_vel):
    """x0 from the first network measurement (zero velocity) and a diagonal P0.

    Args:
      z0: (3 S,) first measurement, m (NaN components give position 0 with a huge variance).
      sigma_pos: scalar or (3 S,) std of the initial positions, m.
      sigma_vel: scalar or (3 S,) std of the initial velocities, m/s.
    Returns:
      (x0 (6 S,), P0 (6 S, 6 S)).
    """
    z0 = jnp.asarray(z0, float)
    S = z0.shape[0] // 3
    ok = jnp.isfinite(z0)
    sp = jnp.broadcast_to(jnp.asarray(sigma_pos, float), z0.shape)
    sp = jnp.where(ok, sp, 1e3)
    sv = jnp.broadcast_to(jnp.asarray(sigma_vel, float), z0.shape)
    x0 = jnp.concatenate([jnp.where(ok, z0, 0.0).reshape(S, 3), jnp.zeros((S, 3))], axis=1).reshape(-1)
    var = jnp.concatenate([(sp**2).reshape(S, 3), (sv**2).reshape(S, 3)], axis=1).reshape(-1)
    return x0, jnp.diag(var)


class Forecast(NamedTuple):
    """Output of :func:`forecast` (T epochs, S stations, axes in the input order).

    Attributes:
      forecast: (T, S, 3) B X(k/k-1), the one-step forecast of the positions, m.
      filtered: (T, S, 3) B X(k/k), m.
      velocity: (T, S, 3) filtered velocities, m/s.
      velocity_sigma: (T, S, 3) their standard deviations, m/s.
      forecast_sigma: (T, S, 3) std of the forecast positions (sqrt diag of D_X(k/k-1)), m.
      deviation: (T, S, 3) forecast minus measurement B X(k/k-1) - L_k, m (NaN where masked).
      factors: (T,) inflation factor of the epoch (1 for the standard filter).
      noise: the estimator's per-epoch output (VCInfo, RobustInfo, ChainInfo or ()).
      loglik: scalar innovation log-likelihood.
      status: int32 flags.
    """

    forecast: jax.Array
    filtered: jax.Array
    velocity: jax.Array
    velocity_sigma: jax.Array
    forecast_sigma: jax.Array
    deviation: jax.Array
    factors: jax.Array
    noise: Any
    loglik: jax.Array
    status: jax.Array


def forecast(
    model: LinearGaussian, x0, P0, zs, *, estimator=None, inflation=None, mask=None, uncertainty: bool = True
) -> Forecast:
    """Run one filter of the family over a network series and return forecasts (S1 eqs. (7)-(11)).

    The standard filter is ``estimator=None``; S1's adaptive filter is
    ``estimator=jaxnav.filters.variance_compensation(...)`` (eqs. (12)-(19)); robust variants
    add :func:`jaxnav.filters.igg3` (alone or in a :func:`jaxnav.filters.chain`) and
    :func:`jaxnav.filters.yang_factor`. Pure and jit/vmap-able (``kalman_filter`` is jitted).

    Args:
      model: network model (:func:`network_model` or :func:`network_model_irregular`).
      x0: (6 S,) initial state.  P0: (6 S, 6 S).
      zs: (T, 3 S) stacked positions, m (NaN = missing, masked and counted).
      estimator, inflation: plug-ins of :func:`jaxnav.filters.kalman_filter`.
      mask: optional (T,) or (T, 3 S) bool.
      uncertainty: static; False skips saving the (T, n, n) covariances (the sigma fields are
        then None), which keeps long vmapped runs small.
    Returns:
      :class:`Forecast`.
    """
    zs = jnp.asarray(zs, float)
    T, m = zs.shape
    if m % 3:
        raise ValueError(f"zs has shape {zs.shape}; expected (T, 3 S) stacked station positions")
    S = m // 3
    save = ("means", "pred_means", "factors", "noise") + (("covs", "pred_covs") if uncertainty else ())
    plug = {k: v for k, v in dict(estimator=estimator, inflation=inflation, mask=mask).items() if v is not None}
    r = jf.kalman_filter(model, x0, P0, zs, save=save, **plug)  # same call as a plain run: shares its compilation
    blk = lambda a: a.reshape(T, S, 2, 3)
    mean, pred = blk(r.means), blk(r.pred_means)
    if uncertainty:
        psig = jnp.sqrt(blk(jnp.diagonal(r.pred_covs, axis1=-2, axis2=-1))[:, :, 0])
        vsig = jnp.sqrt(blk(jnp.diagonal(r.covs, axis1=-2, axis2=-1))[:, :, 1])
    else:
        psig = vsig = None
    z = zs.reshape(T, S, 3)
    dev = pred[:, :, 0] - z
    if mask is not None:
        mk = jnp.asarray(mask, bool)
        mk = jnp.broadcast_to(mk[:, None], (T, m)) if mk.ndim == 1 else mk
        dev = jnp.where(mk.reshape(T, S, 3), dev, jnp.nan)
    return Forecast(
        forecast=pred[:, :, 0],
        filtered=mean[:, :, 0],
        velocity=mean[:, :, 1],
        velocity_sigma=vsig,
        forecast_sigma=psig,
        deviation=dev,
        factors=r.factors,
        noise=r.noise,
        loglik=r.loglik,
        status=r.status,
    )


def s1_filters(
    *, window: int = 30, horizon: int = 10, floor_rel=1.0, robust: bool = False, k0=2.0, k1=4.5, c0=1.0, c1=3.0
) -> dict:
    """The filters compared in S1 (and robust variants) as :func:`forecast` keyword sets.

    * "standard": the classic filter (S1 eqs. (7)-(11));
    * "adaptive": variance compensation (S1 eqs. (12)-(19)), ``window`` epochs, i-step residuals
      up to ``horizon``; ``floor_rel`` = 1 keeps D_Omega at least at the model's value (it only
      compensates missing variance);
    * with ``robust``: "standard_robust" (IGG-III on the classic filter), "adaptive_robust"
      (variance compensation, then IGG-III standardised with the compensated noise) and
      "yang_robust" (IGG-III with Yang's adaptive factor).

    Notes:
      IGG-III alone on the standard filter rejects a real change of dynamics as if it were a
      gross error (the standardised innovations of a lagging filter are large in every
      component), so it diverges when the dynamics change; the order matters in a chain for the
      same reason: variance compensation first lets the estimate of D_Omega follow the dynamics
      before the innovations are judged.

    Returns:
      {name: dict(estimator=..., inflation=...)}.
    """
    vc = jf.variance_compensation(window, horizon=horizon, floor_rel=floor_rel)
    out = {"standard": dict(), "adaptive": dict(estimator=vc)}
    if robust:
        out["standard_robust"] = dict(estimator=jf.igg3(k0, k1))
        out["adaptive_robust"] = dict(estimator=jf.chain(vc, jf.igg3(k0, k1)))
        out["yang_robust"] = dict(estimator=jf.igg3(k0, k1), inflation=jf.yang_factor(c0, c1))
    return out


def outlier_flags(noise) -> Any | None:
    """(T, m) bool outlier flags from a forecast's ``noise`` (IGG-III alone or in a chain), else None."""
    if isinstance(noise, jf.RobustInfo):
        return noise.rejected
    if isinstance(noise, jf.ChainInfo):
        for part in noise.parts:
            if isinstance(part, jf.RobustInfo):
                return part.rejected
    return None
