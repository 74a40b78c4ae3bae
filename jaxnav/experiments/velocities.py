"""Station velocities with coloured noise on daily files (``jaxnav monitor FILES``).

:func:`run_monitor_velocities` reads each file, screens outliers, fits the trajectory model with
white + power-law (+ random-walk) noise by maximum likelihood (:func:`jaxnav.monitoring.fit_stations`,
all stations' fits batched),
writes ``monitor.json`` (labelled east/north/up values, mm and mm/yr) and one figure per station.
With ``s1=True`` the S1 adaptive-filter analysis of the same files
(:func:`jaxnav.experiments.s1.run_monitor_files`) runs as well, into ``OUT/s1``, and its per-station
results are copied under ``s1_adaptive_filter``.
"""

from __future__ import annotations

import logging
import pathlib
import time

import numpy as np

from jaxnav import io
from jaxnav.io import explicit_step
from jaxnav.monitoring import COMPONENTS, decimal_year, fit_stations, iso_date, median_position, series_span
from jaxnav.units import DAY

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


def _known_step_dict(k) -> dict:
    return dict(
        station=k.station,
        date=iso_date(k.epoch),
        decimal_year=float(decimal_year(k.epoch)),
        kind=k.kind,
        postseismic=[dict(form=f, tau_days=None if tau is None else float(tau) / DAY) for f, tau in k.postseismic],
        given_by=k.origin,
    )


def _station_lines(station: str, rec: dict) -> list[str]:
    """The text table's lines of one station record (velocities, MIDAS, steps, post-seismic terms, warnings)."""
    lines = []
    for comp in COMPONENTS:
        n = rec["noise"][comp]
        no = sum(1 for d in rec["outliers"]["list"] if d["component"] == comp)
        lines.append(
            f"{station:<8}{comp:<6}{rec['velocity_mm_per_yr'][comp]:>15.2f}"
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
            + ", ".join(f"{k} {v:+.1f} +- {ps['amplitude_sigma_mm'][k]:.1f} mm" for k, v in ps["amplitude_mm"].items())
        )
    if "acceleration_mm_per_yr2" in rec["polynomial"]:
        acc, asd = rec["polynomial"]["acceleration_mm_per_yr2"], rec["polynomial"]["acceleration_sigma_mm_per_yr2"]
        lines.append(
            f"{'':<8}acceleration mm/yr^2 (rate at {rec['polynomial']['reference_epoch']}): "
            + ", ".join(f"{k} {acc[k]:+.3f} +- {asd[k]:.3f}" for k in COMPONENTS)
        )
    for w in rec["warnings"]:
        lines.append(f"{'':<8}warning: {w}")
    return lines


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
        if explicit_step(k) and k.station not in names:
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
    uses, outsides = [], []
    for s in series:
        first, last = series_span(s)
        use, outside = [], []
        for k in io.merge_known_steps(by_station.get(s.station, [])):
            if first < k.epoch <= last and (not k.postseismic or k.epoch < last):
                use.append(k)
            elif explicit_step(k):
                raise ValueError(
                    f"{k.origin}: the step of {s.station} at {iso_date(k.epoch)} is outside its series "
                    f"({iso_date(first)} .. {iso_date(last)})"
                )
            else:
                outside.append(k)
        uses.append(use)
        outsides.append(outside)
    _log.info(
        "fitting %d station(s): trajectory model and %s noise (%s), batched",
        len(series),
        "white + power-law" + (" + random-walk" if random_walk else ""),
        "REML" if reml else "ML",
    )
    fits = fit_stations(
        series,
        steps=[[k.epoch for k in use] for use in uses],
        postseismic=[[(k.epoch, form, tau) for k in use for form, tau in k.postseismic] for use in uses],
        progress=True,
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
    )
    for f, s, fit, use, outside in zip(files, series, fits, uses, outsides):
        first_day, last_day = iso_date(fit.grid.t[0]), iso_date(fit.grid.t[fit.grid.n_days - 1])
        for k in outside:
            fit.warnings.append(
                f"known step at {iso_date(k.epoch)} ({k.kind}, {k.origin}) is outside the series "
                f"({first_day} .. {last_day}): not in the model"
            )
        fig = out / f"{s.station}_fit.png"
        plot_station_fit(fit, fig)
        rec = io.station_fit_record(
            fit, file=f, figure=fig, step_labels={float(k.epoch): (k.kind, k.origin) for k in use}
        )
        rec["known_steps_outside_series"] = [_known_step_dict(k) for k in outside]
        pos = median_position(s)
        rec["latitude_deg"], rec["longitude_deg"] = (None, None) if pos is None else map(float, np.degrees(pos))
        rec["first_day"], rec["last_day"] = first_day, last_day
        result["stations"][s.station] = rec
        lines += _station_lines(s.station, rec)
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
        io.write_velocity_table(out / "velocities.csv", recs, command=command)
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
