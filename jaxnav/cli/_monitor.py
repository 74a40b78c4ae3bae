"""``jaxnav monitor``: S1 deformation monitoring on daily station files or on simulated 1 Hz stations.

* ``jaxnav monitor FILES... --out DIR``: each file (NGL ``.tenv3``, SIO ``.neu``, ``.col`` table)
  is a station. Velocities with uncertainties (constant-velocity filter, checked against the
  weighted least-squares slope and any published slope), one-day forecasts of the standard and
  adaptive (variance-compensation) filters with the S1 statistics over periods of ``--period``
  epochs, and a figure per station.
* ``jaxnav monitor --simulate --out DIR``: the S1 experiment on simulated 1 Hz stations
  (Knothe subsidence episodes, correlated noise), S1's Tables 1-6 for the standard and adaptive
  filters, forecast RMS against the truth, robust variants with ``--robust`` / ``--gross``.

Both write ``monitor.json`` (statistics) and PNG figures to ``--out``.
"""

from __future__ import annotations

import json
import pathlib
import time

import jax
import numpy as np

import jaxnav
from jaxnav import io
from jaxnav.monitoring import (
    S1_PUBLISHED,
    S1Settings,
    daily_forecasts,
    format_s1_tables,
    outlier_flags,
    period_statistics,
    run_s1_simulation,
    s1_filters,
    s1_tables,
    station_velocity,
)
from jaxnav.units import MM, MM_PER_YEAR


def _tolist(a):
    if a is None:
        return None
    return np.asarray(a).tolist()


def run_monitor_files(files, out, *, period: int = 365, robust: bool = False, window: int = 30,
                      horizon: int = 10) -> dict:
    """Velocities, forecasts and S1 statistics of daily station files; writes JSON and figures.

    Args:
      files: paths of daily series (.tenv3, .neu, .col).
      out: output folder.
      period: epochs per statistics period (365: about a year of daily solutions).
      robust: add the robust filters (IGG-III; variance compensation + IGG-III; IGG-III + Yang).
      window, horizon: variance-compensation settings.
    Returns:
      The dictionary written to ``monitor.json``.
    """
    from jaxnav.plot import plot_daily_velocity

    out = pathlib.Path(out)
    out.mkdir(parents=True, exist_ok=True)
    filters = s1_filters(window=window, horizon=horizon, robust=robust)
    result = {"stations": {}, "settings": dict(period=period, robust=robust, window=window, horizon=horizon)}
    lines = [f"{'station':<8}{'axis':<6}{'CV filter mm/yr':>18}{'+-formal':>10}{'+-AR(1)':>9}{'LS slope':>10}"
             f"{'published':>16}"]
    for f in files:
        s = io.read_daily(f)
        v = station_velocity(s)
        fc = daily_forecasts(s, accel_psd=v.accel_psd, filters=filters)
        st = {}
        for name, r in fc.items():
            P = max(1, min(period, len(s.t) - 1))
            ps = period_statistics(np.asarray(r.deviation), P, thresholds=(3 * MM, 3 * MM, 10 * MM))
            st[name] = dict(
                m_P_mm=_tolist(np.asarray(ps.m_P)[:, 0] / MM), m_H_mm=_tolist(np.asarray(ps.m_H)[:, 0] / MM),
                max_abs_mm=_tolist(np.asarray(ps.max_abs)[:, 0] / MM),
                mean_abs_mm=_tolist(np.asarray(ps.mean_abs)[:, 0] / MM),
                share_under_3_3_10mm=_tolist(np.asarray(ps.share_under)[:, 0]),
                status=int(r.status),
            )
            flags = outlier_flags(r.noise)
            if flags is not None:
                st[name]["outliers_flagged"] = int(np.sum(np.asarray(flags)))
        fig = out / f"velocity_{s.station}.png"
        plot_daily_velocity(s, v, fig)
        ref = v.reference_velocity
        result["stations"][s.station] = dict(
            file=str(f), format=s.fmt, epochs=v.n, span_years=v.span_years,
            velocity_mm_per_yr=_tolist(v.velocity / MM_PER_YEAR), sigma_formal_mm_per_yr=_tolist(v.sigma / MM_PER_YEAR),
            sigma_ar1_mm_per_yr=_tolist(v.sigma_ar1 / MM_PER_YEAR),
            ls_slope_mm_per_yr=_tolist(v.ls_velocity / MM_PER_YEAR),
            published_mm_per_yr=None if ref is None else _tolist(ref / MM_PER_YEAR),
            published_sigma_mm_per_yr=None if ref is None else _tolist(v.reference_sigma / MM_PER_YEAR),
            random_walk_psd_m2_per_s3=_tolist(v.accel_psd), forecast_statistics=st, figure=str(fig),
        )
        for i, ax in enumerate("ENU"):
            pub = "" if ref is None else f"{ref[i] / MM_PER_YEAR:+.2f}+-{v.reference_sigma[i] / MM_PER_YEAR:.2f}"
            lines.append(f"{s.station:<8}{ax:<6}{v.velocity[i] / MM_PER_YEAR:>18.2f}{v.sigma[i] / MM_PER_YEAR:>10.3f}"
                         f"{v.sigma_ar1[i] / MM_PER_YEAR:>9.3f}{v.ls_velocity[i] / MM_PER_YEAR:>10.2f}{pub:>16}")
        fl = "  ".join(f"{n}: m_P {np.mean(d['m_P_mm']):.2f} m_H {np.mean(d['m_H_mm']):.2f} mm" for n, d in st.items())
        lines.append(f"{'':<8}one-day forecasts (mean over periods of {period} epochs): {fl}")
    text = "\n".join(lines)
    print(text)
    result["text"] = text
    (out / "monitor.json").write_text(json.dumps(result, indent=1))
    print(f"wrote {out / 'monitor.json'} and {len(files)} figure(s) in {out}")
    return result


def run_monitor_simulation(out, *, periods: int = 60, stations: int = 2, epochs: int = 3600, robust: bool = False,
                           gross: float = 0.0, seed: int = 2017, progress: bool = True) -> dict:
    """The S1 experiment on simulated 1 Hz stations; prints S1's tables, writes JSON and figures.

    Args:
      out: output folder.  periods: number of periods (S1: 60 station-hours = 30 periods x 2).
      stations: network size.  epochs: epochs per period (3600 = an hour at 1 Hz).
      robust: add the robust filters.  gross: share of components with 10-sigma gross errors.
      seed: PRNG seed.  progress: progress bar.
    Returns:
      The dictionary written to ``monitor.json``.
    """
    from jaxnav.plot import plot_s1_period, plot_s1_statistics

    out = pathlib.Path(out)
    out.mkdir(parents=True, exist_ok=True)
    st = S1Settings(n_stations=stations, n_periods=periods, period=epochs, gross_frac=gross)
    t0 = time.perf_counter()
    res = run_s1_simulation(jax.random.PRNGKey(seed), st, robust=robust or gross > 0, progress=progress)
    wall = time.perf_counter() - t0
    tables = s1_tables(res)
    text = format_s1_tables(tables)
    L = [f"S1 on simulated stations: {periods} periods x {stations} stations x {epochs} epochs at 1 Hz, "
         f"gross errors {100 * gross:.1f} %", "", text, "",
         "Forecast minus truth, RMS over all periods and stations (mm): whole periods / inside the episodes"]
    for name in res["forecast_rms"]:
        whole, ep = np.mean(res["forecast_rms"][name]) / MM, np.mean(res["episode_rms"][name]) / MM
        L.append(f"  {name:<18}{whole:>8.2f}{ep:>10.2f}   status {res['status'][name]}")
    ratio = np.mean(res["forecast_rms"]["standard"]) / np.mean(res["forecast_rms"]["adaptive"])
    ratio_ep = np.mean(res["episode_rms"]["standard"]) / np.mean(res["episode_rms"]["adaptive"])
    L.append(f"standard / adaptive forecast RMS: {ratio:.2f} (whole periods), {ratio_ep:.2f} (episodes)")
    text = "\n".join(L)
    print(text)
    plot_s1_statistics(res, out / "s1_statistics.png")
    plot_s1_period(res["series"][0], out / "s1_period.png")
    result = dict(
        settings=st._asdict(), tables=tables, published=S1_PUBLISHED, text=text,
        forecast_rms_mm={k: float(np.mean(v) / MM) for k, v in res["forecast_rms"].items()},
        episode_rms_mm={k: float(np.mean(v) / MM) for k, v in res["episode_rms"].items()},
        ratio_standard_adaptive=float(ratio), ratio_standard_adaptive_episodes=float(ratio_ep),
        status=res["status"], wall_time_s=wall, jax_version=jax.__version__,
        figures=[str(out / "s1_statistics.png"), str(out / "s1_period.png")],
    )
    (out / "monitor.json").write_text(json.dumps(result, indent=1, default=float))
    print(f"\nwrote {out / 'monitor.json'}, {out / 's1_statistics.png'}, {out / 's1_period.png'} ({wall:.1f} s)")
    return result


def run_monitor(files, out="out/monitor", *, simulate=False, period=365, robust=False, periods=60, stations=2,
                epochs=3600, gross=0.0, seed=2017, progress=True) -> dict:
    """Dispatch of ``jaxnav monitor`` (files, or ``--simulate``).

    Raises:
      ValueError: neither files nor ``simulate``.
    """
    jaxnav.enable_x64()
    if simulate:
        return run_monitor_simulation(out, periods=periods, stations=stations, epochs=epochs, robust=robust,
                                      gross=gross, seed=seed, progress=progress)
    if not files:
        raise ValueError("jaxnav monitor: give daily series files (.tenv3, .neu, .col) or --simulate")
    return run_monitor_files(files, out, period=period, robust=robust)
