"""S1's model on real daily station series: velocities with uncertainties, one-day forecasts.

Each station is filtered with the constant-velocity model on its own (uneven) epochs with the
file's per-epoch covariances (:func:`network_model_irregular`). The velocity random-walk PSD is
chosen by maximum likelihood over a grid (one vmapped run of the filter per grid value), then
the filter and the RTS smoother give the velocity and its standard deviation.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxnav import filters as jf
from jaxnav.monitoring._network import forecast, initial_state, network_model_irregular, outlier_flags
from jaxnav.monitoring._statistics import period_statistics
from jaxnav.units import MM, MM_PER_YEAR, YEAR

#: default grid of velocity random-walk PSDs searched by maximum likelihood, m^2/s^3
#: ((1e-3 .. 100 mm/yr per sqrt(yr))^2 / yr)
PSD_GRID = (np.geomspace(1e-3, 100.0, 16) * MM / YEAR) ** 2 / YEAR


class StationVelocity(NamedTuple):
    """Velocity of one station from its daily series (ENU, SI).

    Attributes:
      station: name.  n: epochs used.  span_years: first to last epoch, years.
      velocity: (3,) constant-velocity filter estimate at the last epoch (zero process noise), m/s.
      sigma: (3,) its formal std (white measurement noise as given by the file), m/s.
      sigma_ar1: (3,) std allowing for time-correlated noise: sigma x sqrt(chi^2/dof) x
        sqrt((1 + rho)/(1 - rho)), rho the lag-one autocorrelation of the residuals, m/s.
      ls_velocity: (3,) weighted least-squares slope (the outside reference for ``velocity``), m/s.
      ls_sigma: (3,) its formal std, m/s.
      reference_velocity, reference_sigma: (3,) from the file header, m/s, or None.
      accel_psd: (3,) velocity random-walk PSD of largest likelihood on the grid, m^2/s^3.
      t: (N,) s.  smoothed_velocity: (N, 3) RTS-smoothed velocity of that model, m/s.
      smoothed_sigma: (N, 3) its std, m/s.  loglik_grid: (G, 3) log-likelihoods on the grid.
      residuals: (N, 3) measurement minus the constant-velocity fit, m.
    """

    station: str
    n: int
    span_years: float
    velocity: jax.Array
    sigma: jax.Array
    sigma_ar1: jax.Array
    ls_velocity: jax.Array
    ls_sigma: jax.Array
    reference_velocity: Any | None
    reference_sigma: Any | None
    accel_psd: jax.Array
    t: jax.Array
    smoothed_velocity: jax.Array
    smoothed_sigma: jax.Array
    loglik_grid: jax.Array
    residuals: jax.Array


def weighted_slope(t, y, sigma):
    """Weighted least-squares line y = a + b t; returns (b, std of b) per column.

    Rows whose y or sigma is not finite (missing values) are left out of that column's fit; a
    column with fewer than 2 usable rows gives NaN.

    Args:
      t: (N,) s.  y: (N, k) m.  sigma: (N, k) m.
    """
    t = np.asarray(t, float)
    y, sigma = np.asarray(y, float), np.asarray(sigma, float)
    out, sd = [], []
    for j in range(y.shape[1]):
        ok = np.isfinite(y[:, j]) & np.isfinite(sigma[:, j]) & (sigma[:, j] > 0)
        if ok.sum() < 2:
            out.append(np.nan)
            sd.append(np.nan)
            continue
        tc = t[ok] - t[ok].mean()
        w = 1.0 / sigma[ok, j] ** 2
        A = np.stack([np.ones_like(tc), tc], axis=1)
        N = A.T @ (A * w[:, None])
        b = np.linalg.solve(N, A.T @ (w * y[ok, j]))
        out.append(b[1])
        sd.append(np.sqrt(np.linalg.inv(N)[1, 1]))
    return np.array(out), np.array(sd)


@jax.jit
def _loglik_grid(t, cov, z, psd_grid):
    """(G, 3) log-likelihood of the per-axis models for each PSD value (vmapped filter runs)."""
    base = network_model_irregular(t, cov[:, None], accel_psd=1.0)  # Q scales linearly with the PSD
    x0, P0 = initial_state(z[0], sigma_pos=1.0, sigma_vel=1e-6)

    def per_axis(q, axis):
        zz = jnp.where(jnp.arange(3) == axis, z, jnp.nan)
        return jf.kalman_filter(base._replace(Q=q * base.Q), x0, P0, zz, save=("valid",)).loglik

    return jax.vmap(lambda q: jax.vmap(lambda a: per_axis(q, a))(jnp.arange(3)))(psd_grid)


#: the outputs :func:`forecast` saves: one compilation serves the velocity runs and the standard forecast
_SAVE = ("means", "pred_means", "factors", "noise", "covs", "pred_covs")


def _ar1_factor(res, sig):
    """sqrt(chi^2/dof) * sqrt((1 + rho)/(1 - rho)) per column of normalised residuals (missing
    values, NaN, left out; lag-one pairs with a missing member too)."""
    r = res / sig
    ok = np.isfinite(r)
    n = ok.sum(axis=0)
    chi = np.sqrt(np.nansum(np.where(ok, r, 0.0) ** 2, axis=0) / np.maximum(n - 2, 1))
    rc = np.where(ok, r - np.nanmean(np.where(ok, r, np.nan), axis=0), 0.0)
    rho = np.sum(rc[1:] * rc[:-1], axis=0) / np.sum(rc**2, axis=0)
    rho = np.clip(rho, 0.0, 0.99)
    return chi * np.sqrt((1.0 + rho) / (1.0 - rho))


def station_velocity(series, *, psd_grid=PSD_GRID, sigma_vel0=1e-6) -> StationVelocity:
    """Velocity and its uncertainty for one daily series (S1's constant-velocity model).

    Two runs of the filter family: (1) the constant-velocity model with zero process noise, whose
    final velocity is the long-term rate (it equals the weighted least-squares slope; that is
    the check), and (2) a velocity random walk whose PSD per axis is the grid value of largest
    innovation log-likelihood (one vmapped run per grid value), smoothed by RTS to show how the
    rate changes over time.

    Args:
      series: :class:`jaxnav.io.DailySeries`.
      psd_grid: (G,) candidate velocity random-walk PSDs, m^2/s^3; None skips run (2) (the
        fields accel_psd, smoothed_*, loglik_grid are then None).
      sigma_vel0: initial velocity std, m/s (default 1e-6 m/s = 32 m/yr: uninformative).
    Returns:
      :class:`StationVelocity`.
    """
    t = jnp.asarray(series.t - series.t[0])
    cov = jnp.asarray(series.cov)
    z = jnp.asarray(series.enu)
    x0, P0 = initial_state(z[0], sigma_pos=1.0, sigma_vel=sigma_vel0)
    cv = network_model_irregular(t, cov[:, None], accel_psd=0.0)
    r0 = jf.kalman_filter(cv, x0, P0, z, save=_SAVE)
    vel = np.asarray(r0.x_final[3:])
    sig = np.sqrt(np.asarray(jnp.diagonal(r0.P_final))[3:])
    sig_xyz = np.sqrt(np.asarray(jnp.diagonal(cov, axis1=-2, axis2=-1)))
    ls, ls_s = weighted_slope(series.t, series.enu, sig_xyz)
    res = series.enu - (np.asarray(r0.x_final[:3]) + (series.t - series.t[-1])[:, None] * vel)
    if psd_grid is None:  # the long-term velocity only
        return StationVelocity(
            station=series.station,
            n=len(series.t),
            span_years=float((series.t[-1] - series.t[0]) / YEAR),
            velocity=vel,
            sigma=sig,
            sigma_ar1=sig * _ar1_factor(res, sig_xyz),
            ls_velocity=ls,
            ls_sigma=ls_s,
            reference_velocity=series.reference_velocity,
            reference_sigma=series.reference_velocity_sigma,
            accel_psd=None,
            t=np.asarray(series.t),
            smoothed_velocity=None,
            smoothed_sigma=None,
            loglik_grid=None,
            residuals=res,
        )
    ll = np.asarray(_loglik_grid(t, cov * jnp.eye(3), z, jnp.asarray(psd_grid)))
    psd = np.asarray(psd_grid)[np.argmax(ll, axis=0)]
    model = network_model_irregular(t, cov[:, None], accel_psd=jnp.asarray(psd))
    rf = jf.kalman_filter(model, x0, P0, z, save=_SAVE)
    sm = jf.rts_smoother(model, rf, save=("means", "covs"))
    return StationVelocity(
        station=series.station,
        n=len(series.t),
        span_years=float((series.t[-1] - series.t[0]) / YEAR),
        velocity=vel,
        sigma=sig,
        sigma_ar1=sig * _ar1_factor(res, sig_xyz),
        ls_velocity=ls,
        ls_sigma=ls_s,
        reference_velocity=series.reference_velocity,
        reference_sigma=series.reference_velocity_sigma,
        accel_psd=psd,
        t=np.asarray(series.t),
        smoothed_velocity=np.asarray(sm.means[:, 3:]),
        smoothed_sigma=np.sqrt(np.asarray(jnp.diagonal(sm.covs, axis1=-2, axis2=-1)[:, 3:])),
        loglik_grid=ll,
        residuals=res,
    )


def daily_forecasts(series, *, accel_psd, filters: dict):
    """One-epoch-ahead forecasts of a daily series for each filter of ``filters`` (see :func:`forecast`).

    Args:
      series: :class:`jaxnav.io.DailySeries`.
      accel_psd: (3,) velocity random-walk PSD of the model, m^2/s^3.
      filters: {name: keyword dict of :func:`forecast`} (e.g. :func:`s1_filters`).
    Returns:
      {name: :class:`Forecast`} (one station).
    """
    t = jnp.asarray(series.t - series.t[0])
    model = network_model_irregular(t, jnp.asarray(series.cov)[:, None], accel_psd=jnp.asarray(accel_psd))
    z = jnp.asarray(series.enu)
    x0, P0 = initial_state(z[0], sigma_pos=1.0, sigma_vel=1e-6)
    return {name: forecast(model, x0, P0, z, **kw) for name, kw in filters.items()}


def _enu(a, unit=1.0):
    """A (3,) east/north/up array as {"east", "north", "up"} in multiples of ``unit`` (None stays None)."""
    if a is None:
        return None
    return dict(zip(("east", "north", "up"), (float(v) for v in np.asarray(a, float).reshape(3) / unit)))


def velocity_summary(velocity: StationVelocity, *, n_masked: int = 0) -> dict:
    """JSON-ready summary of a station's velocity (:func:`station_velocity`), east/north/up in mm/yr.

    Args:
      velocity: :class:`StationVelocity` (m/s inside).  n_masked: values the series file gave as missing.
    Returns:
      dict: ``epochs``, ``span_years``, ``masked_values``, ``velocity_mm_per_yr``,
      ``sigma_formal_mm_per_yr``, ``sigma_ar1_mm_per_yr``, ``ls_slope_mm_per_yr``,
      ``published_mm_per_yr`` and ``published_sigma_mm_per_yr`` (None without a published
      velocity), ``random_walk_psd_m2_per_s3`` (each a {"east", "north", "up"} dict).
    """
    v = velocity
    ref = v.reference_velocity
    return dict(
        epochs=v.n,
        span_years=v.span_years,
        masked_values=int(n_masked),
        velocity_mm_per_yr=_enu(v.velocity, MM_PER_YEAR),
        sigma_formal_mm_per_yr=_enu(v.sigma, MM_PER_YEAR),
        sigma_ar1_mm_per_yr=_enu(v.sigma_ar1, MM_PER_YEAR),
        ls_slope_mm_per_yr=_enu(v.ls_velocity, MM_PER_YEAR),
        published_mm_per_yr=_enu(ref, MM_PER_YEAR),
        published_sigma_mm_per_yr=None if ref is None else _enu(v.reference_sigma, MM_PER_YEAR),
        random_walk_psd_m2_per_s3=_enu(v.accel_psd),
    )


#: per-axis thresholds (east, north, up) of the shares in :func:`forecast_summary`, m
DAILY_THRESHOLDS_ENU = (3 * MM, 3 * MM, 10 * MM)


def forecast_summary(forecasts: dict, period: int) -> dict:
    """Statistics of one station's one-day forecasts per filter (S1 eq. (20) per period), mm.

    Args:
      forecasts: {name: :class:`Forecast`} of one station (:func:`daily_forecasts`; ``deviation`` (N, 1, 3) m).
      period: epochs per statistics period (at most N - 1 are used, at least 1).
    Returns:
      {name: {``m_P_mm``, ``m_H_mm``: (P,) lists; ``max_abs_mm``, ``mean_abs_mm``, ``share_under_3_3_10mm``
      (fraction below :data:`DAILY_THRESHOLDS_ENU`): (P, 3) lists; ``status``; ``outliers_flagged``
      (robust filters only)}}.
    """
    out = {}
    for name, r in forecasts.items():
        dev = np.asarray(r.deviation)
        if dev.ndim != 3 or dev.shape[1] != 1:
            raise ValueError(
                f"forecast_summary: {name!r} deviation has shape {dev.shape}, expected (N, 1, 3): one station"
            )
        ps = period_statistics(dev, max(1, min(period, dev.shape[0] - 1)), thresholds=DAILY_THRESHOLDS_ENU)
        out[name] = dict(
            m_P_mm=(np.asarray(ps.m_P)[:, 0] / MM).tolist(),
            m_H_mm=(np.asarray(ps.m_H)[:, 0] / MM).tolist(),
            max_abs_mm=(np.asarray(ps.max_abs)[:, 0] / MM).tolist(),
            mean_abs_mm=(np.asarray(ps.mean_abs)[:, 0] / MM).tolist(),
            share_under_3_3_10mm=np.asarray(ps.share_under)[:, 0].tolist(),
            status=int(r.status),
        )
        flags = outlier_flags(r.noise)
        if flags is not None:
            out[name]["outliers_flagged"] = int(np.sum(np.asarray(flags)))
    return out
