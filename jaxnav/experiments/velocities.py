"""Station velocities with coloured noise on daily files (``jaxnav monitor FILES``).

:func:`run_monitor_velocities` reads each file, screens outliers, fits the trajectory model with
white + power-law (+ random-walk) noise by maximum likelihood (:func:`jaxnav.monitoring.fit_station`),
writes ``monitor.json`` (labelled east/north/up values, mm and mm/yr) and one figure per station.
With ``s1=True`` the S1 adaptive-filter analysis of the same files
(:func:`jaxnav.experiments.run_monitor_files`) runs as well, into ``OUT/s1``, and its per-station
results are copied under ``s1_adaptive_filter``.
"""

from __future__ import annotations

import logging
import math
import pathlib
import time

import numpy as np

from jaxnav import io
from jaxnav.monitoring import COMPONENTS, fit_station, midas_velocity
from jaxnav.units import DAY, MM, MM_PER_YEAR, YEAR, powerlaw_amplitude_to_mm_yr, random_walk_to_mm_per_sqrt_yr

UNITS = {
    "velocity": "mm/yr",
    "positions, sigmas, amplitudes, steps": "mm",
    "powerlaw_amplitude": "mm/yr^(-kappa/4) (Hector's unit; mm/yr^0.25 for flicker)",
    "random_walk": "mm/sqrt(yr)",
    "phase": "deg, of A cos(2 pi h (t - 2000.0 yr) - phase)",
    "dates": "ISO 8601 calendar day of the daily solution",
    "tau": "days",
    "polynomial coefficients": "mm/yr^p for the power p of (t - t_ref) in years",
}
_log = logging.getLogger(__name__)


def _enu(a, scale=1.0):
    return {c: (None if not np.isfinite(v) else float(v) / scale) for c, v in zip(COMPONENTS, np.asarray(a, float))}


def station_midas(fit):
    """MIDAS rates of a fitted station's screened daily values, with the fit's steps (m/yr, (3,) each).

    Where the fit has post-seismic terms, MIDAS (whose model is a rate and steps) runs on the
    values less the fitted transients, so that the comparison tests the rest of the model.

    Returns:
      (:class:`jaxnav.monitoring.MidasVelocity`, warnings): a warning per component where MIDAS and
      the model rate differ by more than their combined sigma sqrt(s_midas^2 + s_fit^2), and where
      the ordinary least-squares rate of the residuals exceeds 3 MIDAS sigmas (a misfit that an
      inflated random walk would hide from the model's own sigma).
    """
    from jaxnav.monitoring._station import decimal_year

    g = fit.grid
    t_yr = decimal_year(g.t[: g.n_days])
    y = np.where(g.valid, g.y, np.nan)[: g.n_days]
    for i, nm in enumerate(fit.design_names):  # MIDAS has no transient: it sees the series less the fitted ones
        if nm.startswith("postseismic_"):
            y = y - np.outer(fit.A[: g.n_days, i], np.asarray(fit.noise.beta)[:, i])
    m = midas_velocity(t_yr, y, decimal_year(fit.steps))
    v_fit, s_fit = fit.velocity * YEAR, fit.velocity_sigma * YEAR
    warnings = []
    for c, comp in enumerate(COMPONENTS):
        d, s = m.velocity[c] - v_fit[c], math.hypot(m.sigma[c], s_fit[c])
        if np.isfinite(d) and abs(d) > s:
            warnings.append(
                f"{comp}: MIDAS rate {m.velocity[c] / MM:+.2f} +- {m.sigma[c] / MM:.2f} mm/yr differs from "
                f"the model rate {v_fit[c] / MM:+.2f} +- {s_fit[c] / MM:.2f} mm/yr by more than their "
                "combined sigma: a step, transient or outliers the model misses?"
            )
    span = (g.n_days - 1) / 365.25
    for c, comp in enumerate(COMPONENTS):
        r = float(fit.residual_trend[c] * YEAR)
        if np.isfinite(r) and np.isfinite(m.sigma[c]) and abs(r) > 3.0 * m.sigma[c]:
            warnings.append(
                f"{comp}: the residuals keep a trend of {r / MM:+.2f} mm/yr ({r * span / MM:+.0f} mm over "
                f"{span:.1f} yr), more than 3 x the MIDAS rate sigma {m.sigma[c] / MM:.2f} mm/yr: the "
                "model misfits (a missed step or transient, absorbed by the noise model?)"
            )
    return m, warnings


def _per_yr_power(a, p):
    """m/s^p -> mm/yr^p (the output edge of polynomial coefficients)."""
    return np.asarray(a, float) * YEAR**p / MM


def _days(t):
    """s -> days (the output edge of time constants)."""
    return float(t) / DAY


def station_record(fit, *, file, figure=None, step_labels=None) -> dict:
    """The JSON-ready record of one :class:`jaxnav.monitoring.StationFit` (mm, mm/yr, labelled components).

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
    from jaxnav.monitoring._station import decimal_year, iso_date, period_amplitudes, polynomial_terms

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
    mid, mid_warn = station_midas(fit)
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


def write_velocity_table(path, records: dict, *, command: str = "") -> pathlib.Path:
    """``velocities.csv``: one row per station (coordinates, model and MIDAS rates with sigmas, noise, span).

    Args:
      path: output file.  records: {station: :func:`station_record` dict with latitude_deg, longitude_deg}.
      command: the command line, for the header.
    """
    cols = [
        "station",
        "latitude_deg",
        "longitude_deg",
        "ve_mm_per_yr",
        "vn_mm_per_yr",
        "vu_mm_per_yr",
        "se_mm_per_yr",
        "sn_mm_per_yr",
        "su_mm_per_yr",
        "corr_en",
        "midas_ve_mm_per_yr",
        "midas_vn_mm_per_yr",
        "midas_vu_mm_per_yr",
        "midas_se_mm_per_yr",
        "midas_sn_mm_per_yr",
        "midas_su_mm_per_yr",
        "first_day",
        "last_day",
        "span_yr",
        "steps",
        "noise_model",
        "file",
    ]

    def num(v, fmt=".3f"):
        return "" if v is None or not np.isfinite(v) else format(v, fmt)

    lines = [
        "# jaxnav station velocities" + (f": {command}" if command else ""),
        "# units: rates and sigmas mm/yr (1 sigma), latitude/longitude deg (geodetic, from the file; empty where "
        "the file has none), span yr, dates ISO 8601",
        "# reference frame: as in each input file (not transformed); east/north/up local to the station",
        "# ve..su: trajectory model (offset, rate, annual, semi-annual, steps) with the coloured noise named in "
        "noise_model; corr_en: east-north rate correlation (0: the components are fitted independently)",
        "# midas_*: MIDAS (Blewitt et al. 2016, with the same steps); steps: steps in the model (given + detected)",
    ]
    extra = sorted(
        {
            f"polynomial of degree {r['polynomial']['degree']} (rate at the reference epoch, mid-span)"
            for r in records.values()
            if r.get("polynomial", {}).get("degree", 1) > 1
        }
        | {
            f"post-seismic terms at {n} (its midas_* from the series less them)"
            for n, r in records.items()
            if r.get("postseismic")
        }
    )
    if extra:
        lines.append("# the model also has: " + "; ".join(extra))
    lines.append(",".join(cols))
    for name, r in records.items():
        v, sd = r["velocity_mm_per_yr"], r["velocity_sigma_mm_per_yr"]
        mv, ms = r["midas_velocity_mm_per_yr"], r["midas_velocity_sigma_mm_per_yr"]
        row = [
            name,
            num(r.get("latitude_deg"), ".7f"),
            num(r.get("longitude_deg"), ".7f"),
            *(num(v[c]) for c in COMPONENTS),
            *(num(sd[c]) for c in COMPONENTS),
            "0",
            *(num(mv[c]) for c in COMPONENTS),
            *(num(ms[c]) for c in COMPONENTS),
            r["first_day"],
            r["last_day"],
            num(r["span_years"], ".2f"),
            str(len(r["steps"])),
            '"' + r["model"].replace('"', "'") + '"',
            '"' + r["file"] + '"',
        ]
        lines.append(",".join(row))
    path = pathlib.Path(path)
    path.write_text("\n".join(lines) + "\n")
    return path


_KIND_RANK = {"unknown": 0, "equipment": 1, "earthquake": 2}


def merge_known_steps(items) -> list:
    """Known steps of one station merged by calendar day, in time order.

    Steps on the same day (a steps file and ``--step``, or two files) become one: the earliest
    epoch, the most specific kind (earthquake > equipment > unknown), the post-seismic terms of
    all with one per form (a command-line option's before a file's), the origins joined by "; "
    (options first).

    Args:
      items: :class:`jaxnav.io.KnownStep` of one station.
    Returns:
      list of :class:`jaxnav.io.KnownStep`.
    """
    groups = {}
    for k in items:
        groups.setdefault(int(np.floor(k.epoch / DAY + 0.5)), []).append(k)  # a date's epoch: its start, -0.5 d
    out = []
    for day in sorted(groups):
        g = sorted(groups[day], key=lambda k: (not _explicit(k), k.epoch))
        terms = {}
        for k in g:
            for form, tau in k.postseismic:
                terms.setdefault(form, tau)
        out.append(
            io.KnownStep(
                g[0].station,
                min(k.epoch for k in g),
                max((k.kind for k in g), key=_KIND_RANK.get),
                tuple(terms.items()),
                "; ".join(k.origin for k in g),
            )
        )
    return out


def _explicit(k) -> bool:
    """A step given on the command line (an option, not a file): its mistakes are errors, not warnings."""
    return k.origin.startswith("--")


def _known_step_dict(k) -> dict:
    from jaxnav.monitoring._station import decimal_year, iso_date

    return dict(
        station=k.station,
        date=iso_date(k.epoch),
        decimal_year=float(decimal_year(k.epoch)),
        kind=k.kind,
        postseismic=[dict(form=f, tau_days=None if tau is None else _days(tau)) for f, tau in k.postseismic],
        given_by=k.origin,
    )


def run_monitor_velocities(
    files,
    out,
    *,
    steps=None,
    detect: int = 0,
    kappa=-1.0,
    random_walk: bool = True,
    reml: bool = True,
    screen: bool = True,
    sigma_factor: float = 5.0,
    residual_k: float = 5.0,
    s1: bool = False,
    period: int = 365,
    robust: bool = False,
    command: str = "",
    periods_days=(),
    known_steps=(),
    steps_files=(),
    poly_degree: int = 1,
) -> dict:
    """Velocities with coloured noise of daily station files; writes ``monitor.json`` and figures.

    Args:
      files: paths of daily series (.tenv3, .neu, .col, PBO .pos).
      out: output folder (``monitor.json``, ``STATION_fit.png``).
      steps: {station: [epochs s since J2000]} of known steps (given as ``--step``).
      known_steps: further :class:`jaxnav.io.KnownStep` (from steps files, ``--postseismic``),
        merged by day with ``steps`` (:func:`merge_known_steps`). Every known step is in the model;
        detection adds on top. A step from a file for a station not among ``files``, or outside its
        series, is listed in the output's warnings and ``known_steps`` (never dropped silently);
        the same mistakes in a step given by an option (origin "--...") raise ValueError.
        An earthquake's post-seismic terms enter the model with its step.
      steps_files: the steps files read (recorded in the settings).
      poly_degree: degree of the polynomial in time (:func:`jaxnav.monitoring.fit_station`).
      detect, kappa, random_walk, reml, screen, sigma_factor, residual_k: see
        :func:`jaxnav.monitoring.fit_station`.
      s1, period, robust: also run the S1 adaptive-filter analysis (into ``out/s1``).
      command: the command line, recorded in the JSON.
      periods_days: further periodic terms of the trajectory, days.
    Returns:
      The dictionary written ("text": the table printed by ``jaxnav monitor``).
    """
    from jaxnav import __version__
    from jaxnav.monitoring._station import iso_date
    from jaxnav.plot import plot_station_fit

    out = pathlib.Path(out)
    out.mkdir(parents=True, exist_ok=True)
    steps = steps or {}
    t0 = time.perf_counter()
    _log.info("reading %d daily series file(s)", len(files))
    series = [io.read_daily(f) for f in files]  # every file read (and checked) before any work
    names = {s.station for s in series}
    unknown = sorted(set(steps) - names)
    if unknown:
        raise ValueError(
            f"--step {', '.join(unknown)}: no such station in the file(s) read (stations: {', '.join(sorted(names))})"
        )
    known = [io.KnownStep(st.upper(), float(e), "unknown", (), "--step") for st, es in steps.items() for e in es]
    known += list(known_steps)
    for k in known:
        if _explicit(k) and k.station not in names:
            raise ValueError(
                f"{k.origin} {k.station}: no such station in the file(s) read (stations: {', '.join(sorted(names))})"
            )
    unmatched = [_known_step_dict(k) for k in known if k.station not in names]
    by_station = {}
    for k in known:
        by_station.setdefault(k.station, []).append(k)
    result = dict(
        version=__version__,
        command=command,
        units=UNITS,
        settings=dict(
            kappa="estimated" if kappa is None else kappa,
            random_walk=random_walk,
            likelihood="REML" if reml else "ML",
            screen=screen,
            sigma_factor=sigma_factor,
            residual_k=residual_k,
            detect_steps=detect,
            ggm_1mphi=6.9e-6,
            extra_periods_days=[float(p) for p in periods_days],
            poly_degree=int(poly_degree),
            steps_files=[str(f) for f in steps_files],
        ),
        known_steps=dict(given=len(known), unmatched_stations=unmatched),
        stations={},
    )
    lines = [
        f"{'station':<8}{'axis':<6}{'velocity mm/yr':>15}{'+-1 sigma':>10}{'(white only)':>13}"
        f"{'white mm':>9}{'PL mm/yr^-k/4':>14}{'kappa':>7}{'RW mm/yr^.5':>12}{'outliers':>9}"
    ]
    for u in unmatched:
        lines.append(
            f"warning: known step of {u['station']} at {u['date']} ({u['kind']}, {u['given_by']}): no such "
            "station among the files; not used"
        )
    for k, (f, s) in enumerate(zip(files, series)):
        _log.info(
            "station %d/%d %s: %d days, fitting trajectory model and %s noise (%s)",
            k + 1,
            len(files),
            s.station,
            int(np.size(s.t)),
            "white + power-law" + (" + random-walk" if random_walk else ""),
            "REML" if reml else "ML",
        )
        t_st = time.perf_counter()
        from jaxnav.monitoring._station import _day_index

        first, last = float(s.t[0]), float(s.t[0]) + float(_day_index(s)[-1]) * DAY  # the daily grid's ends
        use, outside = [], []
        for k in merge_known_steps(by_station.get(s.station, [])):
            if first < k.epoch <= last and (not k.postseismic or k.epoch < last):
                use.append(k)
            elif _explicit(k):
                raise ValueError(
                    f"{k.origin}: the step of {s.station} at {iso_date(k.epoch)} is outside its series "
                    f"({iso_date(first)} .. {iso_date(last)})"
                )
            else:
                outside.append(k)
        fit = fit_station(
            s,
            steps=[k.epoch for k in use],
            detect=detect,
            kappa=kappa,
            random_walk=random_walk,
            reml=reml,
            screen=screen,
            sigma_factor=sigma_factor,
            residual_k=residual_k,
            periods_days=periods_days,
            warn_steps=True,
            poly_degree=poly_degree,
            postseismic=[(k.epoch, form, tau) for k in use for form, tau in k.postseismic],
        )
        for k in outside:
            fit.warnings.append(
                f"known step at {iso_date(k.epoch)} ({k.kind}, {k.origin}) is outside the series "
                f"({iso_date(first)} .. {iso_date(last)}): not in the model"
            )
        fig = out / f"{s.station}_fit.png"
        plot_station_fit(fit, fig)
        rec = station_record(fit, file=f, figure=fig, step_labels={float(k.epoch): (k.kind, k.origin) for k in use})
        rec["known_steps_outside_series"] = [_known_step_dict(k) for k in outside]
        llh = np.asarray(s.llh, float)
        ok = np.isfinite(llh[:, :2]).all(axis=1)
        rec["latitude_deg"] = float(np.degrees(np.median(llh[ok, 0]))) if ok.any() else None
        rec["longitude_deg"] = float(np.degrees(np.median(llh[ok, 1]))) if ok.any() else None
        rec["first_day"], rec["last_day"] = iso_date(fit.grid.t[0]), iso_date(fit.grid.t[fit.grid.n_days - 1])
        _log.debug("station %s fitted in %.1f s", s.station, time.perf_counter() - t_st)
        result["stations"][s.station] = rec
        for comp in COMPONENTS:
            n = rec["noise"][comp]
            no = sum(1 for d in rec["outliers"]["list"] if d["component"] == comp)
            lines.append(
                f"{s.station:<8}{comp:<6}{rec['velocity_mm_per_yr'][comp]:>15.2f}"
                f"{rec['velocity_sigma_mm_per_yr'][comp]:>10.2f}"
                f"{rec['velocity_sigma_white_noise_only_mm_per_yr'][comp]:>13.3f}{n['white_mm']:>9.2f}"
                f"{n['powerlaw_amplitude']:>14.2f}{n['spectral_index']:>7.2f}"
                f"{n['random_walk_mm_per_sqrt_yr']:>12.2f}{no:>9d}"
            )
        mv, ms = rec["midas_velocity_mm_per_yr"], rec["midas_velocity_sigma_mm_per_yr"]
        lines.append(
            f"{'':<8}MIDAS mm/yr: "
            + ", ".join(
                f"{k} {'n/a' if mv[k] is None else format(mv[k], '+.2f')} +- "
                f"{'n/a' if ms[k] is None else format(ms[k], '.2f')}"
                for k in COMPONENTS
            )
        )
        for st in rec["steps"]:
            lines.append(
                f"{'':<8}step {st['date']} ({st['source']}"
                + (f", {st['kind']}" if st["kind"] else "")
                + "): "
                + ", ".join(f"{k} {v:+.1f} +- {st['sigma_mm'][k]:.1f} mm" for k, v in st["size_mm"].items())
            )
        for ps in rec["postseismic"]:
            lo, hi = ps["tau_range_days"]
            lines.append(
                f"{'':<8}post-seismic {ps['form']} after {ps['date']}, tau {ps['tau_days']:.3g} d"
                + (f" (estimated, {lo:.3g} .. {hi:.3g})" if ps["tau_estimated"] else " (given)")
                + ": "
                + ", ".join(
                    f"{k} {v:+.1f} +- {ps['amplitude_sigma_mm'][k]:.1f} mm" for k, v in ps["amplitude_mm"].items()
                )
            )
        if "acceleration_mm_per_yr2" in rec["polynomial"]:
            acc, asd = rec["polynomial"]["acceleration_mm_per_yr2"], rec["polynomial"]["acceleration_sigma_mm_per_yr2"]
            lines.append(
                f"{'':<8}acceleration mm/yr^2 (rate at {rec['polynomial']['reference_epoch']}): "
                + ", ".join(f"{k} {acc[k]:+.3f} +- {asd[k]:.3f}" for k in COMPONENTS)
            )
        for w in rec["warnings"]:
            lines.append(f"{'':<8}warning: {w}")
        if s.n_masked:
            lines.append(f"{'':<8}{s.n_masked} position value(s) given as nan in {f}: masked")
    if s1:
        from jaxnav.experiments.s1 import run_monitor_files

        _log.info("S1 adaptive-filter forecasts of %d station(s)", len(files))
        r1 = run_monitor_files(files, out / "s1", period=period, robust=robust)
        for name, st in r1["stations"].items():
            if name in result["stations"]:
                result["stations"][name]["s1_adaptive_filter"] = st
        lines += [
            "",
            f"S1 adaptive filter (constant-velocity Kalman filter, white noise; written to {out / 's1'}):",
            r1["text"],
        ]
    if len(files) > 1:
        from jaxnav.plot import plot_velocity_map

        recs = result["stations"]
        write_velocity_table(out / "velocities.csv", recs, command=command)
        nan = float("nan")
        pts = [
            dict(
                name=n,
                lat_deg=nan if r["latitude_deg"] is None else r["latitude_deg"],
                lon_deg=nan if r["longitude_deg"] is None else r["longitude_deg"],
                ve=r["velocity_mm_per_yr"]["east"],
                vn=r["velocity_mm_per_yr"]["north"],
                se=r["velocity_sigma_mm_per_yr"]["east"],
                sn=r["velocity_sigma_mm_per_yr"]["north"],
            )
            for n, r in recs.items()
        ]
        missing = [p["name"] for p in pts if not np.isfinite(p["lat_deg"])]
        plot_velocity_map(
            pts,
            out / "velocity_map.png",
            title=f"Horizontal velocities of {len(pts) - len(missing)} of {len(pts)} stations "
            "(those with coordinates), frame as in the files",
        )
        lines.append(
            f"wrote {out / 'velocities.csv'} and {out / 'velocity_map.png'}"
            + (f" (no coordinates in the file, not on the map: {', '.join(missing)})" if missing else "")
        )
    result["wall_time_s"] = time.perf_counter() - t0
    result["text"] = "\n".join(lines)
    io.write_json(out / "monitor.json", result)
    return result
