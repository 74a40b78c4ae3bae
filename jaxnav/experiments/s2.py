"""S2: the RTK point-series pipeline on files (epoch logs, RTKLIB .pos) and the simulated 45-point survey.

:func:`run_rtk` is what ``jaxnav rtk`` runs: read the files (:mod:`jaxnav.io`), cut static ``.pos``
files into occupations, filter every point in one vmapped call (:func:`jaxnav.survey.process_points`,
S2 eqs. (9)-(19)), compare with levelling (S2 Table 3), and write the per-point CSV, a JSON summary
and the figure. :func:`write_simulated_survey` writes the simulated survey's files.
"""

from __future__ import annotations

import math
import pathlib

import jax
import jax.numpy as jnp
import numpy as np

from jaxnav.io import write_json
from jaxnav.geodesy import zone_central_meridian
from jaxnav.io import (
    read_control_points,
    read_epoch_log,
    read_levelling,
    read_pos,
    write_control_points,
    write_epoch_log,
    write_levelling,
    write_rtk_results,
)
from jaxnav.plot import plot_rtk
from jaxnav.sim import RtkPointsConfig, simulate_rtk_points
from jaxnav.survey.rtk import compare_levelling, connection_models, pack_points, process_points, windows_from_pos
from jaxnav.units import CM, MM, rad_to_deg


def _read_inputs(files, *, step, window, min_epochs, fixed_only):
    """Flat epoch arrays (S2 input) from .pos files (cut into occupations) and/or CSV epoch logs.

    Returns:
      dict of N epochs: point (N,) names, t (N,) s, lat, lon (N,) rad, H (N,) m, sigma (N, 3) m,
      mask (N,) bool, h_terminal (N,) m and xy_terminal (N, 2) m (NaN for .pos files).
    """
    parts = []
    for f in files:
        f = pathlib.Path(f)
        if f.suffix.lower() == ".pos":
            w = windows_from_pos(read_pos(f), step=step, window=window, min_epochs=min_epochs,
                                 fixed_only=fixed_only)
            n = len(w["t"])
            w["h_terminal"] = np.full(n, np.nan)
            w["xy_terminal"] = np.full((n, 2), np.nan)
            parts.append(w)
        else:
            log = read_epoch_log(f)
            parts.append(dict(point=log.point, t=log.t, lat=log.lat, lon=log.lon, H=log.H, sigma=log.sigma,
                              mask=np.ones(len(log.t), bool), h_terminal=log.h,
                              xy_terminal=np.stack([log.x, log.y], -1)))
    names_seen = {}
    for f, p in zip(files, parts):
        for name in dict.fromkeys(p["point"]):
            if name in names_seen:
                raise ValueError(f"{f}: point {name!r} also appears in {names_seen[name]}")
            names_seen[name] = f
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def run_rtk(files, out, *, control=None, levelling=None, lon0_deg=None, zone_width=3, step=2.0, window=60,
            min_epochs=30, fixed_only=True, smoother=False, surface="auto", quiet=False):
    """Run the S2 pipeline on files and write ``rtk_results.csv``, ``rtk_results.json`` and ``rtk.png``.

    Args:
      files: RTKLIB .pos files (static; each cut into occupations of ``window`` epochs at ``step``
        s) and/or CSV epoch logs (:func:`jaxnav.io.read_epoch_log`).
      out: output folder (created).
      control: optional control-point file (:func:`jaxnav.io.read_control_points`): gives the datum
        transformation and the height-anomaly surface; without it the results stay in WGS-84
        Gauss-Krüger coordinates and ellipsoidal heights.
      levelling: optional levelling file (:func:`jaxnav.io.read_levelling`) for the Table 3 comparison.
      lon0_deg: central meridian, deg (default: the ``zone_width`` zone of the mean longitude).
      step, window, min_epochs, fixed_only: see :func:`jaxnav.survey.rtk.windows_from_pos`.
      smoother: add the RTS pass.  surface: height-anomaly surface ("auto", "plane", "quadratic").
      quiet: do not print the summary.
    Returns:
      dict summary (also written as JSON).
    """
    out = pathlib.Path(out)
    out.mkdir(parents=True, exist_ok=True)
    files = [pathlib.Path(f) for f in files]
    if not files:
        raise ValueError("jaxnav rtk: give at least one .pos or CSV epoch-log file")
    ep = _read_inputs(files, step=step, window=window, min_epochs=min_epochs, fixed_only=fixed_only)
    if not len(ep["t"]):
        raise ValueError(f"{', '.join(map(str, files))}: no epochs left to process (a .pos file needs occupations of "
                         f"at least min_epochs={min_epochs} {'fixed ' if fixed_only else ''}epochs)")
    cp = read_control_points(control) if control is not None else None  # all files read before any work
    lev = read_levelling(levelling) if levelling is not None else None
    _, counts = np.unique(ep["point"], return_counts=True)
    length = int(-(-counts.max() // 20) * 20)  # padded to a multiple of 20: fewer compilations
    names, series = pack_points(ep["point"], ep["t"], ep["lat"], ep["lon"], ep["H"], ep["sigma"],
                                h_terminal=ep["h_terminal"], xy_terminal=ep["xy_terminal"], mask=ep["mask"],
                                length=length)
    if lon0_deg is None:  # each point in its own zone
        lon_pt = np.array([np.nanmean(np.where(m, lo, np.nan)) for lo, m in zip(series.lon, series.mask)])
        lon0 = np.asarray(zone_central_meridian(jnp.asarray(lon_pt), zone_width)[0])
    else:
        lon0 = np.full(len(names), math.radians(lon0_deg))
    zones = sorted({round(float(v), 9) for v in rad_to_deg(lon0)})
    if control is not None and len(zones) > 1:
        raise ValueError(f"points fall in zones with central meridians {zones} deg; one control set needs one "
                         "projection: give --lon0")
    summary = dict(files=[str(f) for f in files], n_points=len(names), lon0_deg=zones, smoother=smoother,
                   masked_epochs=int(np.sum(~np.asarray(ep["mask"]) | ~np.all(np.isfinite(ep["sigma"]), axis=1)
                                        | ~np.isfinite(ep["lat"]) | ~np.isfinite(ep["lon"]) | ~np.isfinite(ep["H"]))))
    transform = anomaly = None
    if control is not None:
        con = connection_models(cp.lat, cp.lon, cp.H, np.stack([cp.x, cp.y], -1), cp.h, lon0=float(lon0[0]),
                                surface=surface)
        if con.transform is not None:
            transform = con.transform.params
            tp = con.transform
            summary["datum_transformation"] = dict(
                model="4-parameter plane similarity (x' = t + (1+m) R(theta) x)", tx=float(tp.params.t[0]),
                ty=float(tp.params.t[1]), theta_arcsec=float(tp.params.theta) / (math.pi / 648000),
                m_ppm=float(tp.params.m) * 1e6, sigma0_mm=float(tp.sigma0) / MM,
                residual_rms_mm=[float(v) / MM for v in tp.rms], n_control=int(tp.residuals.shape[0]))
        if con.anomaly is not None:
            anomaly = con.anomaly
            summary["height_anomaly"] = dict(surface=anomaly.kind, sigma0_mm=float(anomaly.sigma0) / MM,
                                             n_control=int(anomaly.residuals.shape[0]),
                                             residuals_mm=[float(v) / MM for v in anomaly.residuals])
    res = process_points(series, lon0=jnp.asarray(lon0), transform=transform, anomaly=anomaly,
                         smoother=smoother)
    res = type(res)(*[np.asarray(a) if not isinstance(a, tuple) else a for a in res])
    h_level = np.full(len(names), np.nan)
    if levelling is not None:
        table = dict(zip(lev.point, lev.height))
        h_level = np.array([table.get(n, np.nan) for n in names])
    prec = {key: dict(plane_mm=float(np.nanmean(np.hypot(p[:, 0], p[:, 1]))) / MM,
                      height_mm=float(np.nanmean(p[:, 2])) / MM)
            for key, p in (("filtered", res.precision), ("conventional", res.raw_precision),
                           ("formal", res.formal_precision))}
    for key in ("conventional", "formal"):
        prec[f"factor_{key}_over_filtered"] = dict(
            plane=prec[key]["plane_mm"] / prec["filtered"]["plane_mm"],
            height=prec[key]["height_mm"] / prec["filtered"]["height_mm"])
    summary["internal_precision_mean"] = prec
    if np.any(np.isfinite(h_level)):
        for key, h in (("filtered", res.xyh[:, 2]), ("conventional_terminal", res.terminal_xyh[:, 2]),
                       ("conventional_H_anomaly", res.raw_xyh[:, 2])):
            if np.any(np.isfinite(h - h_level)):
                c = compare_levelling(h, h_level)
                summary[f"levelling_{key}"] = dict(
                    max_abs_cm=c.max_abs / CM, mean_cm=c.mean / CM, std_cm=c.std / CM, rms_cm=c.rms / CM,
                    thresholds_cm=[float(v) / CM for v in c.thresholds], count_within=[int(v) for v in c.count_within],
                    share_within=[float(v) for v in c.share_within])
    write_rtk_results(out / "rtk_results.csv", names, res, h_level)
    plot_rtk(res, out / "rtk.png", h_level=h_level if np.any(np.isfinite(h_level)) else None, names=names)
    summary["points"] = [dict(point=str(n), n=int(res.n[i]), x=float(res.xyh[i, 0]), y=float(res.xyh[i, 1]),
                              h=float(res.xyh[i, 2]), precision_mm=[float(v) / MM for v in res.precision[i]],
                              raw_precision_mm=[float(v) / MM for v in res.raw_precision[i]],
                              formal_precision_mm=[float(v) / MM for v in res.formal_precision[i]])
                         for i, n in enumerate(names)]
    summary["outputs"] = [str(out / "rtk_results.csv"), str(out / "rtk_results.json"), str(out / "rtk.png")]
    write_json(out / "rtk_results.json", summary)
    if not quiet:
        print(format_rtk(summary))
    return summary


def format_rtk(summary: dict) -> str:
    """The summary of :func:`run_rtk` as text: internal precisions (mm, S2 eq. (19)) and levelling (cm, Table 3)."""
    p = summary["internal_precision_mean"]
    lines = [f"S2 pipeline: {summary['n_points']} points, central meridian(s) {summary['lon0_deg']} deg, "
             f"{'forward filter + RTS' if summary['smoother'] else 'forward filter'}",
             "  internal precision of the mean (average over points): plane / height mm",
             f"    conventional averaging, eq. (19): {p['conventional']['plane_mm']:.2f} / "
             f"{p['conventional']['height_mm']:.2f}",
             f"    from the reported sigmas        : {p['formal']['plane_mm']:.2f} / {p['formal']['height_mm']:.2f}",
             f"    filtered, eq. (19)              : {p['filtered']['plane_mm']:.2f} / "
             f"{p['filtered']['height_mm']:.2f}"]
    for key in ("levelling_conventional_terminal", "levelling_conventional_H_anomaly", "levelling_filtered"):
        if key in summary:
            c = summary[key]
            shares = ", ".join(f"{s * 100:.1f} % within {th:g} cm"
                               for s, th in zip(c["share_within"], c["thresholds_cm"]))
            lines.append(f"  {key[10:]:>24}: max {c['max_abs_cm']:.2f} cm, mean {c['mean_cm']:.2f} cm, "
                         f"std {c['std_cm']:.2f} cm; {shares}")
    lines.append(f"wrote {', '.join(summary['outputs'])}")
    return "\n".join(lines)


def write_simulated_survey(out, seed: int = 0):
    """Simulate the 45-point S2 survey (:func:`jaxnav.sim.simulate_rtk_points`) and write its files.

    Returns:
      (epoch-log path, control path, levelling path, the simulation).
    """
    out = pathlib.Path(out)
    out.mkdir(parents=True, exist_ok=True)
    sim = simulate_rtk_points(jax.random.PRNGKey(seed), RtkPointsConfig())
    sim = type(sim)(*[np.asarray(a) for a in sim])
    P = sim.t.shape[0]
    names = np.array([f"P{i + 1:02d}" for i in range(P)])
    m = sim.mask
    pts = np.repeat(names[:, None], sim.t.shape[1], axis=1)[m]
    f_ep = write_epoch_log(out / "sim_epochs.csv", pts, sim.t[m], sim.xy_terminal[m][:, 0], sim.xy_terminal[m][:, 1],
                           sim.h_terminal[m], sim.lat[m], sim.lon[m], sim.H[m], sim.sigma[m])
    C = sim.control_h.shape[0]
    f_cp = write_control_points(out / "sim_control.csv", [f"K{i + 1}" for i in range(C)], sim.control_lat,
                                sim.control_lon, sim.control_H, sim.control_xy[:, 0], sim.control_xy[:, 1],
                                sim.control_h)
    f_lv = write_levelling(out / "sim_levelling.csv", names, sim.h_level)
    return f_ep, f_cp, f_lv, sim
