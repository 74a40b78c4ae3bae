"""The JSON-ready record of a station fit (``monitor.json`` of ``jaxnav monitor``), in mm and mm/yr."""

from __future__ import annotations

import math

import numpy as np

from jaxnav.monitoring import COMPONENTS, StationFit, midas_check
from jaxnav.monitoring._station import decimal_year, iso_date, period_amplitudes, polynomial_terms
from jaxnav.units import DAY, MM, MM_PER_YEAR, YEAR, powerlaw_amplitude_to_mm_yr, random_walk_to_mm_per_sqrt_yr


def _enu(a, scale=1.0):
    return {c: (None if not np.isfinite(v) else float(v) / scale) for c, v in zip(COMPONENTS, np.asarray(a, float))}


def _per_yr_power(a, p):
    """m/s^p -> mm/yr^p (the output edge of polynomial coefficients)."""
    return np.asarray(a, float) * YEAR**p / MM


def _days(t):
    """s -> days (the output edge of time constants)."""
    return float(t) / DAY


def station_fit_record(fit: StationFit, *, file, figure=None, step_labels=None) -> dict:
    """The JSON-ready record of one :class:`jaxnav.monitoring.StationFit` (mm, mm/yr, labelled components).

    What ``jaxnav monitor`` writes per station into ``monitor.json``: data counts, the model and MIDAS
    rates (:func:`jaxnav.monitoring.midas_check`) with sigmas, noise, seasonal, step, post-seismic,
    polynomial and outlier terms, warnings. ``file`` and ``figure`` are copied as text.
    ``step_labels``: {step epoch s: (kind, origin)} of the given steps (their kind and where they
    were given), copied into each step's record.
    """
    nf = fit.noise
    noise = {}
    names = ("white_mm", "powerlaw_amplitude", "random_walk_mm_per_sqrt_yr", "spectral_index")
    for c, comp in enumerate(COMPONENTS):
        kap = float(fit.kappa[c])
        lo, hi = np.asarray(nf.lo[c]), np.asarray(nf.hi[c])
        bounds = {}
        for j, nm in enumerate(names):
            if not nf.free[c, j]:
                continue
            f = (1.0, 365.25 ** (-kap / 4.0), math.sqrt(365.25))[j] if j < 3 else 1.0  # per day -> per yr units
            bounds[nm] = (
                [float(lo[j]), float(hi[j])] if j == 3 else [math.exp(lo[j]) * f / MM, math.exp(hi[j]) * f / MM]
            )
        at = [
            names[j] + (" (upper)" if nf.at_upper[c, j] else " (lower)")
            for j in range(4)
            if nf.at_lower[c, j] or nf.at_upper[c, j]
        ]
        noise[comp] = dict(
            white_mm=float(fit.white_sigma[c] / MM),
            powerlaw_amplitude=float(powerlaw_amplitude_to_mm_yr(fit.powerlaw_amplitude[c], kap)),
            powerlaw_amplitude_unit=f"mm/yr^{-kap / 4:.3f}",
            spectral_index=kap,
            spectral_index_estimated=bool(nf.free[c, 3]),
            random_walk_mm_per_sqrt_yr=float(random_walk_to_mm_per_sqrt_yr(fit.random_walk[c])),
            bounds=bounds,
            at_bound=at,
            loglik_reml=float(nf.loglik_reml[c]),
            loglik_ml=float(nf.loglik[c]),
            bfgs_steps_accepted=int(nf.iterations[c]),
            gradient_max=float(nf.grad_norm[c]),
        )
    seasonal = {
        comp: dict(
            annual_amplitude_mm=float(fit.annual_amplitude[c] / MM),
            annual_amplitude_sigma_mm=float(fit.annual_amplitude_sigma[c] / MM),
            annual_phase_deg=float(np.degrees(fit.annual_phase[c])),
            semiannual_amplitude_mm=float(fit.semiannual_amplitude[c] / MM),
            semiannual_amplitude_sigma_mm=float(fit.semiannual_amplitude_sigma[c] / MM),
            semiannual_phase_deg=float(np.degrees(fit.semiannual_phase[c])),
        )
        for c, comp in enumerate(COMPONENTS)
    }
    for per, (a, asd, ph) in period_amplitudes(fit).items():
        for c, comp in enumerate(COMPONENTS):
            seasonal[comp][f"period_{per}_amplitude_mm"] = float(a[c] / MM)
            seasonal[comp][f"period_{per}_amplitude_sigma_mm"] = float(asd[c] / MM)
            seasonal[comp][f"period_{per}_phase_deg"] = float(np.degrees(ph[c]))

    gains = np.asarray(fit.step_gains, float) if len(fit.step_gains) else np.full(len(fit.steps), np.nan)
    labels = step_labels or {}
    steps = [
        dict(
            date=iso_date(ts),
            decimal_year=float(decimal_year(ts)),
            source=src,
            kind=labels.get(float(ts), ("unknown", None))[0] if src == "given" else None,
            given_by=labels.get(float(ts), (None, None))[1] if src == "given" else None,
            size_mm=_enu(fit.step_sizes[:, j], MM),
            sigma_mm=_enu(fit.step_sigmas[:, j], MM),
            gain_2lnL=None if not np.isfinite(gains[j]) else float(gains[j]),
        )
        for j, (ts, src) in enumerate(zip(fit.steps, fit.step_sources))
    ]
    post = [
        dict(
            date=iso_date(p.epoch),
            decimal_year=float(decimal_year(p.epoch)),
            form=p.form,
            equation=("a log(1 + (t - t_eq) / tau)" if p.form == "log" else "a (1 - exp(-(t - t_eq) / tau))"),
            tau_days=_days(p.tau),
            tau_estimated=bool(p.estimated),
            tau_range_days=[_days(p.tau_range[0]), _days(p.tau_range[1])],
            tau_at_edge=bool(p.tau_at_edge),
            amplitude_mm=_enu(p.amplitude, MM),
            amplitude_sigma_mm=_enu(p.amplitude_sigma, MM),
        )
        for p in fit.postseismic
    ]
    poly_terms = polynomial_terms(fit)
    polynomial = dict(
        degree=int(fit.poly_degree),
        reference_epoch=iso_date(fit.t_ref),
        rate_is_the_velocity_at="reference_epoch",
        terms=[
            dict(
                power=p,
                equation=f"c (t - t_ref)^{p}",
                coefficient_mm_per_yr_power=_enu(_per_yr_power(c, p)),
                sigma_mm_per_yr_power=_enu(_per_yr_power(sd, p)),
            )
            for p, (c, sd) in poly_terms.items()
        ],
    )
    if 2 in poly_terms:
        polynomial["acceleration_mm_per_yr2"] = _enu(2.0 * _per_yr_power(poly_terms[2][0], 2))
        polynomial["acceleration_sigma_mm_per_yr2"] = _enu(2.0 * _per_yr_power(poly_terms[2][1], 2))
    scr = fit.screening
    outl = [
        dict(
            date=d["date"],
            decimal_year=d["decimal_year"],
            component=d["component"],
            reason=d["reason"],
            value_mm=d["value_m"] / MM,
            sigma_mm=d["sigma_m"] / MM,
            residual_mm=None if d["residual_m"] is None else d["residual_m"] / MM,
            threshold_mm=d["threshold_m"] / MM,
        )
        for d in scr.records
    ]
    g = fit.grid
    mid, mid_warn = midas_check(fit)
    return dict(
        file=str(file),
        format=fit.fmt,
        model=fit.model,
        span_years=float((g.n_days - 1) / 365.25),
        grid_days=int(g.n_days),
        days_used=_enu(g.valid.sum(axis=0)),
        missing_days=int(g.n_days - g.valid.any(axis=1).sum()),
        duplicate_epochs_dropped=int(g.duplicates),
        masked_values=int(scr.counts["missing"]),
        reference_epoch=iso_date(fit.t_ref),
        velocity_mm_per_yr=_enu(fit.velocity / MM_PER_YEAR),
        velocity_sigma_mm_per_yr=_enu(fit.velocity_sigma / MM_PER_YEAR),
        velocity_sigma_white_noise_only_mm_per_yr=_enu(fit.velocity_sigma_white / MM_PER_YEAR),
        residual_trend_mm_per_yr=_enu(np.asarray(fit.residual_trend, float) / MM_PER_YEAR),
        midas_velocity_mm_per_yr=_enu(mid.velocity, MM),
        midas_velocity_sigma_mm_per_yr=_enu(mid.sigma, MM),
        midas_pairs=dict(zip(COMPONENTS, mid.pairs_kept.tolist())),
        noise=noise,
        seasonal=seasonal,
        steps=steps,
        postseismic=post,
        polynomial=polynomial,
        outliers=dict(
            count=len(outl),
            by_reason={k: v for k, v in scr.counts.items() if k != "missing"},
            sigma_limit_mm=_enu(scr.sigma_limit_m, MM),
            residual_limit_mm=_enu(scr.residual_limit_m, MM),
            list=outl,
        ),
        warnings=list(fit.warnings) + mid_warn,
        gauss_markov_max_relative_error=float(fit.gm_max_rel_error),
        figure=None if figure is None else str(figure),
    )
