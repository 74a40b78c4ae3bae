"""S1: deformation monitoring with standard vs adaptive (variance-compensation) forecasts, on
simulated 1 Hz stations or on daily station files (what ``jaxnav monitor`` runs).

S1 compares the standard and the variance-compensation filters on a two-station CORS network,
one hour (3600 epochs) a day for 30 days (60 station-hours), and reports Tables 1-6. Here each
period is a fresh simulation (:func:`jaxnav.sim.simulate_subsidence`) with a rapid subsidence
episode (Knothe time function) at a random time, of random size and speed, on every station;
periods are vmapped (:func:`run_s1_simulation`, scored by :func:`s1_tables`). On real daily
series (NGL ``.tenv3``, SIO ``.neu``, ``.col``), :func:`run_monitor_files` gives velocities and
one-day forecast statistics per station; :func:`run_monitor_simulation` writes the simulated
experiment's tables and figures.
"""

from __future__ import annotations

import pathlib
import time
from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxnav import io, status_words
from jaxnav.io import write_json
from jaxnav.monitoring import (
    S1_THRESHOLDS_XYH,
    daily_forecasts,
    forecast,
    forecast_summary,
    improvement,
    initial_state,
    internal_precision,
    network_model,
    period_statistics,
    rms,
    s1_filters,
    station_velocity,
    velocity_summary,
)
from jaxnav.sim import simulate_subsidence, subsidence_config
from jaxnav.tune import map_chunked
from jaxnav.units import MM, MM_PER_YEAR

#: S1's published numbers (Tables 3-6 and the text), mm and %
S1_PUBLISHED = {
    "X": {"standard": (3.21, 0.53, 57.67), "adaptive": (0.80, 0.18, 99.94)},
    "Y": {"standard": (1.83, 0.33, 67.81), "adaptive": (0.80, 0.18, 99.97)},
    "H": {"standard": (8.27, 1.45, 43.39), "adaptive": (1.29, 0.58, 99.94)},
    "internal": {
        "standard_plane": 5.4,
        "standard_height": 8.3,
        "adaptive_plane": 3.9,
        "adaptive_height": 6.6,
        "improvement_plane": 26.6,
        "improvement_height": 20.1,
    },
    "forecast_ratio": 2.0,
}


class S1Settings(NamedTuple):
    """Settings of :func:`run_s1_simulation` (host-side numbers).

    Attributes:
      n_stations: S.  n_periods: P.  period: epochs per period (1 Hz).
      sigma: (3,) measurement std assumed by the filters (E, N, U), m.
      accel_std: acceleration std per epoch assumed by the standard filter, m/s^2 (a quiet station).
      w_max: (lo, hi) range of the episode's subsidence, m.
      time_constant: (lo, hi) range of the Knothe time constant 1/c, s.
      onset: (lo, hi) range of the onset as a fraction of the period.
      gross_frac: share of measurement components with a gross error.  gross_size: in sigmas.
      window, horizon: variance-compensation window and largest prediction step.
      skip: epochs left out of the statistics at the start of each period (filter start-up).
    """

    n_stations: int = 2
    n_periods: int = 60
    period: int = 3600
    sigma: tuple = (1.9 * MM, 1.9 * MM, 3.7 * MM)
    accel_std: float = 1e-7
    w_max: tuple = (50 * MM, 150 * MM)
    time_constant: tuple = (60.0, 300.0)
    onset: tuple = (0.15, 0.65)
    gross_frac: float = 0.0
    gross_size: float = 10.0
    window: int = 30
    horizon: int = 10
    skip: int = 60


#: the settings passed as traced leaves (one compilation serves every value)
_TRACED = ("sigma", "accel_std", "w_max", "time_constant", "onset", "gross_frac", "gross_size")


def _period_run(key, num: dict, S: int, T: int, filters: dict):
    """One period: simulate, add gross errors, run every filter (pure; vmapped over keys)."""
    ko, kt, kw, ks, kg = jax.random.split(key, 5)
    cfg = subsidence_config(S)
    u = lambda k, lo_hi: jax.random.uniform(k, (S,), minval=lo_hi[0], maxval=lo_hi[1])
    cfg = cfg._replace(onset=u(ko, num["onset"]) * T, rate=1.0 / u(kt, num["time_constant"]), w_max=u(kw, num["w_max"]))
    simu = simulate_subsidence(ks, cfg, T)
    sig = jnp.tile(num["sigma"], S)
    k1, k2 = jax.random.split(kg)
    hit = jax.random.uniform(k1, simu.zs.shape) < num["gross_frac"]
    sign = jnp.where(jax.random.uniform(k2, simu.zs.shape) < 0.5, -1.0, 1.0)
    zs = simu.zs + jnp.where(hit, num["gross_size"] * sig * sign, 0.0)
    model = network_model(S, 1.0, sigma=num["sigma"], accel_var=num["accel_std"] ** 2)
    x0, P0 = initial_state(zs[0], sigma_pos=sig, sigma_vel=1e-4)
    out = {}
    for name, kw_ in filters.items():
        f = forecast(model, x0, P0, zs, uncertainty=False, **kw_)
        out[name] = dict(
            deviation=f.deviation, error=f.forecast - simu.pos, forecast=f.forecast, factors=f.factors, status=f.status
        )
    t = jnp.arange(T)[:, None]
    episode = (t >= cfg.onset) & (t < cfg.onset + 3.0 / cfg.rate)  # (T, S)
    return out, dict(episode=episode, pos=simu.pos, zs=zs.reshape(T, S, 3), hit=hit.reshape(T, S, 3))


@partial(jax.jit, static_argnames=("static",))
def _chunk(keys, num: dict, static):
    """Statistics (and full series) of a chunk of periods, vmapped; one compilation per ``static``."""
    S, T, window, horizon, skip, robust = static
    filters = s1_filters(window=window, horizon=horizon, robust=robust)

    def one(k):
        out, extra = _period_run(k, num, S, T, filters)
        res = {}
        for name, o in out.items():
            dev = o["deviation"][skip:]
            err = o["error"][skip:]
            ep = extra["episode"][skip:]
            res[name] = dict(
                stats=period_statistics(dev[:, :, [1, 0, 2]], T - skip, S1_THRESHOLDS_XYH),
                internal=internal_precision(o["forecast"][skip:][:, :, [1, 0, 2]], T - skip),
                forecast_rms=rms(err, axis=(0, 2)),
                episode_rms=rms(jnp.where(ep[..., None], err, jnp.nan), axis=(0, 2)),
                status=o["status"],
                max_factor=jnp.max(o["factors"]),
            )
        return res, dict(
            filters={n: {k_: o[k_] for k_ in ("forecast", "error", "deviation", "factors")} for n, o in out.items()},
            **extra,
        )

    return jax.vmap(one)(keys)


def run_s1_simulation(
    key,
    settings: S1Settings = S1Settings(),
    *,
    robust: bool = False,
    chunk: int = 4,
    progress: bool = False,
    keep_series: int = 1,
) -> dict:
    """Simulate ``n_periods`` periods of an S-station network and compare the S1 filters.

    Periods run in vmapped chunks of one compiled function; the numeric settings are traced, so
    a second call with other numbers (e.g. gross errors) reuses the compilation.

    Args:
      key: PRNG key.
      settings: :class:`S1Settings`.
      robust: also run the robust variants of :func:`s1_filters`.
      chunk: periods per compiled vmapped call (memory bound).
      progress: show a progress bar.
      keep_series: how many periods' full series to return for figures (at most ``chunk``).
    Returns:
      dict with "stats" {filter: :class:`PeriodStatistics` (P, S, ...) numpy}, "internal"
      {filter: :class:`InternalPrecision`}, "forecast_rms" {filter: (P, S) RMS of forecast minus
      truth over the 3 axes, m}, "episode_rms" {filter: (P, S) the same inside the episodes},
      "status" {filter: OR of the flags}, "series" (the first ``keep_series`` periods), "settings".
    """
    st = settings
    static = (int(st.n_stations), int(st.period), int(st.window), int(st.horizon), int(st.skip), bool(robust))
    num = {k: jnp.asarray(getattr(st, k), float) for k in _TRACED}
    P = int(st.n_periods)
    keys = jax.random.split(key, P)
    series = []

    def call(idx):
        """Statistics of the periods ``idx``; keeps the first ``keep_series`` periods' full series."""
        res, ser = _chunk(keys[idx], num, static)
        n_keep = min(keep_series - len(series), len(idx), P - int(idx[0]))
        if n_keep > 0:
            ser = jax.tree_util.tree_map(np.asarray, ser)
            series.extend(jax.tree_util.tree_map(lambda a, j=j: a[j], ser) for j in range(n_keep))
        return res

    res = map_chunked(call, P, chunk=min(int(chunk), P), desc="S1 periods", progress=progress, unit="period")
    squeeze = lambda a: a[:, 0] if a.ndim >= 2 and a.shape[1] == 1 else a
    out = {"stats": {}, "internal": {}, "forecast_rms": {}, "episode_rms": {}, "status": {}}
    for name, r in res.items():
        out["stats"][name] = jax.tree_util.tree_map(squeeze, r["stats"])
        out["internal"][name] = jax.tree_util.tree_map(squeeze, r["internal"])
        out["forecast_rms"][name] = r["forecast_rms"]
        out["episode_rms"][name] = r["episode_rms"]
        out["status"][name] = int(np.bitwise_or.reduce(r["status"].ravel()))
    out["series"] = series
    out["settings"] = st._asdict()
    return out


def s1_tables(result: dict, *, longitudinal=(0, 0), compare=("standard", "adaptive")) -> dict:
    """S1's Tables 1-6 from :func:`run_s1_simulation` (or a real-data run) as numbers, mm and %.

    Args:
      result: with "stats" and "internal" as returned by :func:`run_s1_simulation`.
      longitudinal: (period, station) of Tables 3-5 (S1: CORS1, 2017-06-18 1:00-2:00).
      compare: the two filters compared (standard, adaptive).
    Returns:
      {"table1_plane": {filter: {min, max, mean} of m_P}, "table2_height": ... of m_H,
       "table3_5": {axis X/Y/H: {filter: (max, mean, share %)}}, "table6": {filter: plane/height
       internal precision per period (up to 8) and their mean, plus the improvement %},
       "forecast_ratio": mean m_P and m_H of standard / adaptive}.
    """
    p, s = longitudinal
    t = {"table1_plane": {}, "table2_height": {}, "table3_5": {"X": {}, "Y": {}, "H": {}}, "table6": {}}
    for name in compare:
        sts = result["stats"][name]
        for key, arr in (("table1_plane", sts.m_P), ("table2_height", sts.m_H)):
            a = np.asarray(arr) / MM
            t[key][name] = dict(min=float(a.min()), max=float(a.max()), mean=float(a.mean()))
        for i, ax in enumerate("XYH"):
            t["table3_5"][ax][name] = (
                float(sts.max_abs[p, s, i] / MM),
                float(sts.mean_abs[p, s, i] / MM),
                float(100 * sts.share_under[p, s, i]),
            )
        ip = result["internal"][name]
        n8 = min(8, np.asarray(ip.plane).shape[0])
        t["table6"][name] = dict(
            plane=(np.asarray(ip.plane)[:n8, s] / MM).tolist(), height=(np.asarray(ip.height)[:n8, s] / MM).tolist()
        )
    a, b = compare
    ipa, ipb = result["internal"][a], result["internal"][b]
    n8 = len(t["table6"][a]["plane"])
    t["table6"]["improvement_plane"] = np.asarray(improvement(ipa.plane[:n8, s], ipb.plane[:n8, s])).tolist()
    t["table6"]["improvement_height"] = np.asarray(improvement(ipa.height[:n8, s], ipb.height[:n8, s])).tolist()
    t["forecast_ratio"] = dict(
        plane=t["table1_plane"][a]["mean"] / t["table1_plane"][b]["mean"],
        height=t["table2_height"][a]["mean"] / t["table2_height"][b]["mean"],
    )
    return t


def format_s1_tables(tables: dict, *, compare=("standard", "adaptive")) -> str:
    """Text of :func:`s1_tables` in the form of S1's tables, with the published values beside."""
    a, b = compare
    L = []
    L.append("Tables 1-2: forecast precision per period (m_P plane, m_H height), mm, over all periods")
    L.append(f"{'filter':<18}{'m_P min':>9}{'m_P max':>9}{'m_P mean':>10}{'m_H min':>9}{'m_H max':>9}{'m_H mean':>10}")
    for name in compare:
        p1, p2 = tables["table1_plane"][name], tables["table2_height"][name]
        L.append(
            f"{name:<18}{p1['min']:>9.2f}{p1['max']:>9.2f}{p1['mean']:>10.2f}"
            f"{p2['min']:>9.2f}{p2['max']:>9.2f}{p2['mean']:>10.2f}"
        )
    fr = tables["forecast_ratio"]
    L.append(f"ratio {a}/{b}: plane {fr['plane']:.2f}, height {fr['height']:.2f} (published: about 2)")
    L.append("")
    L.append("Tables 3-5: forecast deviation (forecast - measurement) of one period and station")
    L.append(f"{'series':<16}{'filter':<18}{'max mm':>8}{'mean mm':>9}{'share %':>9}   published max / mean / share")
    thr = {"X": "(N) < 0.5 mm", "Y": "(E) < 0.4 mm", "H": "(U) < 1 mm"}
    for ax in "XYH":
        for name in compare:
            mx, mn, sh = tables["table3_5"][ax][name]
            pub = S1_PUBLISHED[ax].get(name if name in ("standard", "adaptive") else "", None)
            pubs = f"{pub[0]:.2f} / {pub[1]:.2f} / {pub[2]:.2f} %" if pub else ""
            L.append(f"{ax + ' ' + thr[ax]:<16}{name:<18}{mx:>8.2f}{mn:>9.2f}{sh:>9.2f}   {pubs}")
    L.append("")
    L.append("Table 6: internal precision of the forecasts per period, mm, and improvement %")
    t6 = tables["table6"]
    L.append(
        f"{'period':<8}{a + ' plane':>16}{a + ' height':>17}{b + ' plane':>16}{b + ' height':>17}"
        f"{'impr. plane':>13}{'impr. height':>14}"
    )
    for i in range(len(t6[a]["plane"])):
        L.append(
            f"{i + 1:<8}{t6[a]['plane'][i]:>16.2f}{t6[a]['height'][i]:>17.2f}{t6[b]['plane'][i]:>16.2f}"
            f"{t6[b]['height'][i]:>17.2f}{t6['improvement_plane'][i]:>13.1f}{t6['improvement_height'][i]:>14.1f}"
        )
    mean = lambda x: float(np.mean(x))
    L.append(
        f"{'mean':<8}{mean(t6[a]['plane']):>16.2f}{mean(t6[a]['height']):>17.2f}{mean(t6[b]['plane']):>16.2f}"
        f"{mean(t6[b]['height']):>17.2f}{mean(t6['improvement_plane']):>13.1f}"
        f"{mean(t6['improvement_height']):>14.1f}"
    )
    P = S1_PUBLISHED["internal"]
    L.append(
        f"{'publ.':<8}{P['standard_plane']:>16.1f}{P['standard_height']:>17.1f}{P['adaptive_plane']:>16.1f}"
        f"{P['adaptive_height']:>17.1f}{P['improvement_plane']:>13.1f}{P['improvement_height']:>14.1f}"
    )
    return "\n".join(L)


def _enu_dict(a):
    """A (3,) east/north/up array as {"east": ., "north": ., "up": .} (None stays None)."""
    if a is None:
        return None
    return dict(zip(("east", "north", "up"), (float(v) for v in np.asarray(a, float).reshape(3))))


#: the share threshold of each axis in S1's Tables 3-5, mm
_S1_SHARE_THRESHOLD_MM = {"X": 0.5, "Y": 0.4, "H": 1.0}


def _labelled_table3_5(t3: dict) -> dict:
    """S1 Tables 3-5 ({axis: {filter: (max, mean, share %)}}) with labelled fields for the JSON file."""
    return {
        ax: {
            name: dict(
                max_abs_mm=v[0],
                mean_abs_mm=v[1],
                share_below_threshold_percent=v[2],
                threshold_mm=_S1_SHARE_THRESHOLD_MM.get(ax),
            )
            for name, v in per.items()
        }
        for ax, per in t3.items()
    }


def run_monitor_files(
    files, out, *, period: int = 365, robust: bool = False, window: int = 30, horizon: int = 10
) -> dict:
    """Velocities, forecasts and S1 statistics of daily station files; writes JSON and figures.

    Writes ``monitor.json`` and ``velocity_STATION.png`` per file into ``out``.

    Args:
      files: paths of daily series (.tenv3, .neu, .col).
      out: output folder.
      period: epochs per statistics period (365: about a year of daily solutions).
      robust: add the robust filters (IGG-III; variance compensation + IGG-III; IGG-III + Yang).
      window, horizon: variance-compensation settings.
    Returns:
      The dictionary written to ``monitor.json`` ("text": the tables as printed by ``jaxnav monitor``).
    """
    from jaxnav.plot import plot_daily_velocity

    out = pathlib.Path(out)
    out.mkdir(parents=True, exist_ok=True)
    filters = s1_filters(window=window, horizon=horizon, robust=robust)
    result = {"stations": {}, "settings": dict(period=period, robust=robust, window=window, horizon=horizon)}
    lines = [
        f"{'station':<8}{'axis':<6}{'CV filter mm/yr':>18}{'+-formal':>10}{'+-AR(1)':>9}{'LS slope':>10}"
        f"{'published':>16}"
    ]
    all_series = [io.read_daily(f) for f in files]  # every file read (and checked) before any work
    for f, s in zip(files, all_series):
        v = station_velocity(s)
        st = forecast_summary(daily_forecasts(s, accel_psd=v.accel_psd, filters=filters), period)
        fig = out / f"velocity_{s.station}.png"
        plot_daily_velocity(s, v, fig)
        ref = v.reference_velocity
        result["stations"][s.station] = dict(
            file=str(f),
            format=s.fmt,
            **velocity_summary(v, n_masked=s.n_masked),
            forecast_statistics=st,
            figure=str(fig),
        )
        for i, ax in enumerate("ENU"):
            pub = "" if ref is None else f"{ref[i] / MM_PER_YEAR:+.2f}+-{v.reference_sigma[i] / MM_PER_YEAR:.2f}"
            lines.append(
                f"{s.station:<8}{ax:<6}{v.velocity[i] / MM_PER_YEAR:>18.2f}{v.sigma[i] / MM_PER_YEAR:>10.3f}"
                f"{v.sigma_ar1[i] / MM_PER_YEAR:>9.3f}{v.ls_velocity[i] / MM_PER_YEAR:>10.2f}{pub:>16}"
            )
        fl = "  ".join(f"{n}: m_P {np.mean(d['m_P_mm']):.2f} m_H {np.mean(d['m_H_mm']):.2f} mm" for n, d in st.items())
        lines.append(f"{'':<8}one-day forecasts (mean over periods of {period} epochs): {fl}")
        if s.n_masked:
            lines.append(
                f"{'':<8}{s.n_masked} position value(s) given as nan in {f}: masked (left out of the "
                f"filters and the LS slope)"
            )
    result["text"] = "\n".join(lines)
    write_json(out / "monitor.json", result)
    return result


def run_monitor_simulation(
    out,
    *,
    periods: int = 60,
    stations: int = 2,
    epochs: int = 3600,
    robust: bool = False,
    gross: float = 0.0,
    seed: int = 2017,
    progress: bool = True,
) -> dict:
    """The S1 experiment on simulated 1 Hz stations; writes S1's tables (JSON, text) and figures.

    Writes ``monitor.json``, ``s1_statistics.png`` and ``s1_period.png`` into ``out``.

    Args:
      out: output folder.  periods: number of periods (S1: 60 station-hours = 30 periods x 2).
      stations: network size.  epochs: epochs per period (3600 = an hour at 1 Hz).
      robust: add the robust filters.  gross: share of components with 10-sigma gross errors.
      seed: PRNG seed.  progress: progress bar.
    Returns:
      The dictionary written to ``monitor.json`` ("text": the tables as printed by ``jaxnav monitor``).
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
    L = [
        f"S1 on simulated stations: {periods} periods x {stations} stations x {epochs} epochs at 1 Hz, "
        f"gross errors {100 * gross:.1f} %",
        "",
        text,
        "",
        "Forecast minus truth, RMS over all periods and stations (mm): whole periods / inside the episodes",
    ]
    rms_mm = {key: {k: float(np.mean(v) / MM) for k, v in res[key].items()} for key in ("forecast_rms", "episode_rms")}
    for name, whole in rms_mm["forecast_rms"].items():
        ep = rms_mm["episode_rms"][name]
        L.append(f"  {name:<18}{whole:>8.2f}{ep:>10.2f}   status {status_words(res['status'][name])}")
    ratio = np.mean(res["forecast_rms"]["standard"]) / np.mean(res["forecast_rms"]["adaptive"])
    ratio_ep = np.mean(res["episode_rms"]["standard"]) / np.mean(res["episode_rms"]["adaptive"])
    L.append(f"standard / adaptive forecast RMS: {ratio:.2f} (whole periods), {ratio_ep:.2f} (episodes)")
    text = "\n".join(L)
    plot_s1_statistics(res, out / "s1_statistics.png")
    plot_s1_period(res["series"][0], out / "s1_period.png")
    result = dict(
        settings={**{k: v for k, v in st._asdict().items() if k != "sigma"}, "sigma_m": _enu_dict(st.sigma)},
        tables={**tables, "table3_5": _labelled_table3_5(tables["table3_5"])},
        published={**S1_PUBLISHED, **_labelled_table3_5({ax: S1_PUBLISHED[ax] for ax in ("X", "Y", "H")})},
        text=text,
        forecast_rms_mm=rms_mm["forecast_rms"],
        episode_rms_mm=rms_mm["episode_rms"],
        ratio_standard_adaptive=float(ratio),
        ratio_standard_adaptive_episodes=float(ratio_ep),
        status=res["status"],
        wall_time_s=wall,
        jax_version=jax.__version__,
        figures=[str(out / "s1_statistics.png"), str(out / "s1_period.png")],
    )
    write_json(out / "monitor.json", result)
    return result
