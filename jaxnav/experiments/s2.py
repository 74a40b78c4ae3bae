"""S2: the RTK point-series pipeline on files (epoch logs, RTKLIB .pos) and the simulated 45-point survey.

:func:`run_rtk` is what ``jaxnav rtk`` runs: read the files (:mod:`jaxnav.io`), cut static ``.pos``
files into occupations, filter every point in one vmapped call (:func:`jaxnav.survey.process_points`,
S2 eqs. (9)-(19)), compare with levelling (S2 Table 3), and write the per-point CSV, a JSON summary
and the figure. :func:`write_simulated_survey` writes the simulated survey's files.
"""

from __future__ import annotations

import logging
import math
import pathlib

import jax
import jax.numpy as jnp
import numpy as np

from jaxnav.io import (
    gpst_iso,
    read_control_points,
    read_levelling,
    read_rtk_epochs,
    write_control_points,
    write_epoch_log,
    write_json,
    write_levelling,
    write_rtk_results,
)
from jaxnav.plot import plot_rtk
from jaxnav.sim import RtkPointsConfig, simulate_rtk_points
from jaxnav.survey.rtk import (
    MotionParams,
    central_meridians,
    connection_models,
    connection_summary,
    levelling_summary,
    pack_points,
    point_records,
    point_sigmas,
    precision_summary,
    process_points,
    sampling_grid,
    sigma_summary,
    unusable_epochs,
)
from jaxnav.units import MM, rad_to_deg

_log = logging.getLogger(__name__)


def run_rtk(
    files,
    out,
    *,
    control=None,
    levelling=None,
    lon0_deg=None,
    zone_width=3,
    step=2.0,
    window=60,
    min_epochs=30,
    fixed_only=True,
    smoother=False,
    surface="auto",
    quiet=False,
    motion: MotionParams | None = MotionParams(),
):
    """Run the S2 pipeline on files and write ``rtk_results.csv``, ``rtk_results.json`` and ``rtk.png``.

    Args:
      files: RTKLIB .pos files (split into static segments and moving epochs first, see ``motion``;
        each static segment cut into occupations of ``window`` epochs at ``step`` s) and/or CSV
        epoch logs (:func:`jaxnav.io.read_epoch_log`; one point a name, no motion test).
      out: output folder (created).
      control: optional control-point file (:func:`jaxnav.io.read_control_points`): gives the datum
        transformation and the height-anomaly surface; without it the results stay in WGS-84
        Gauss-Krüger coordinates and ellipsoidal heights.
      levelling: optional levelling file (:func:`jaxnav.io.read_levelling`) for the Table 3 comparison.
      lon0_deg: central meridian, deg (default: the ``zone_width`` zone of the mean longitude).
      step, window, min_epochs, fixed_only: see :func:`jaxnav.survey.rtk.windows_from_pos`.
      smoother: add the RTS pass.  surface: height-anomaly surface ("auto", "plane", "quadratic").
      quiet: do not print the summary.
      motion: static/moving test of the .pos files (:class:`jaxnav.survey.MotionParams`; None: none):
        moving epochs are excluded before points are formed, counted in ``excluded_moving_epochs``.
    Returns:
      dict summary (also written as JSON): besides the S2 figures, ``crs``, ``zone``,
      ``height_system``, ``time_system``, ``sigma_method``, ``excluded_moving_epochs`` and
      ``points`` (``name``, ``n_epochs``, ``t_start``, ``t_end``, ``x_m``, ``y_m``, ``h_m``,
      ``sigma_x_m``, ``sigma_y_m``, ``sigma_h_m``, ``sigma_method``, ...): the precision of each
      point's mean with time-correlated epochs (:func:`jaxnav.survey.point_sigmas`, computed on the
      WGS-84 Gauss-Krüger x, y, H epochs; the datum transformation's own uncertainty and the
      height-anomaly fit are not in it).
    """
    out = pathlib.Path(out)
    out.mkdir(parents=True, exist_ok=True)
    files = [pathlib.Path(f) for f in files]
    if not files:
        raise ValueError("jaxnav rtk: give at least one .pos or CSV epoch-log file")
    _log.info("reading %d file(s): %s", len(files), ", ".join(f.name for f in files))
    ep, motion_counts = read_rtk_epochs(
        files, step=step, window=window, min_epochs=min_epochs, fixed_only=fixed_only, motion=motion
    )
    if not len(ep["t"]):
        raise ValueError(
            f"{', '.join(map(str, files))}: no epochs left to process (a .pos file needs occupations of "
            f"at least min_epochs={min_epochs} {'fixed ' if fixed_only else ''}epochs)"
        )
    cp = read_control_points(control) if control is not None else None  # all files read before any work
    lev = read_levelling(levelling) if levelling is not None else None
    _, counts = np.unique(ep["point"], return_counts=True)
    length = int(-(-counts.max() // 20) * 20)  # padded to a multiple of 20: fewer compilations
    names, series = pack_points(
        ep["point"],
        ep["t"],
        ep["lat"],
        ep["lon"],
        ep["H"],
        ep["sigma"],
        h_terminal=ep["h_terminal"],
        xy_terminal=ep["xy_terminal"],
        mask=ep["mask"],
        length=length,
    )
    first = {n: i for i, n in reversed(list(enumerate(ep["point"])))}
    point_segment = np.array([ep["segment"][first[n]] for n in names])
    if lon0_deg is None:  # each point in its own zone
        lon0 = central_meridians(series, zone_width)
    else:
        lon0 = np.full(len(names), math.radians(lon0_deg))
    zones = sorted({round(float(v), 9) for v in rad_to_deg(lon0)})
    if control is not None and len(zones) > 1:
        raise ValueError(
            f"points fall in zones with central meridians {zones} deg; one control set needs one "
            "projection: give --lon0"
        )
    summary = dict(
        files=[str(f) for f in files],
        n_points=len(names),
        lon0_deg=zones,
        smoother=smoother,
        excluded_moving_epochs=sum(c["n_moving"] for c in motion_counts),
        excluded_short_static_epochs=sum(c["n_short_static"] for c in motion_counts),
        motion_test=None if motion is None else dict(motion._asdict(), files=motion_counts),
        masked_epochs=unusable_epochs(ep["mask"], ep["lat"], ep["lon"], ep["H"], ep["sigma"]),
    )
    transform = anomaly = None
    if control is not None:
        con = connection_models(
            cp.lat, cp.lon, cp.H, np.stack([cp.x, cp.y], -1), cp.h, lon0=float(lon0[0]), surface=surface
        )
        transform = None if con.transform is None else con.transform.params
        anomaly = con.anomaly
        summary.update(connection_summary(con))
    _log.info(
        "filtering %d point(s) (%d epochs, %s)",
        len(names),
        int(np.size(ep["t"])),
        "forward filter + RTS" if smoother else "forward filter",
    )
    res = process_points(series, lon0=jnp.asarray(lon0), transform=transform, anomaly=anomaly, smoother=smoother)
    res = type(res)(*[np.asarray(a) if not isinstance(a, tuple) else a for a in res])
    grid = sampling_grid(np.asarray(series.t), np.asarray(series.mask), names, ep["point"], ep["grid"])
    # precision with time-correlated epochs, on the filter's measurements (WGS-84 GK x, y, H)
    ps = point_sigmas(res.gk, np.asarray(series.mask) & (res.n[:, None] > 0), grid, point_segment)
    crs = (
        "reference grid of the control survey (4-parameter similarity from WGS-84 Gauss-Krueger; x north, y east, m)"
        if transform is not None
        else "WGS-84 Gauss-Krueger (transverse Mercator, scale 1, no false easting; x north, y east, m)"
    )
    summary["crs"] = crs
    summary["zone"] = dict(central_meridian_deg=zones, zone_width_deg=None if lon0_deg is not None else zone_width)
    summary["height_system"] = (
        "normal height: ellipsoidal H - fitted height anomaly (m)"
        if anomaly is not None
        else "WGS-84 ellipsoidal height (m)"
    )
    summary["time_system"] = "GPST"
    summary["sigma_method"] = ps.method
    summary["sigma_method_description"] = (
        "standard deviation of each point's mean from the sample autocovariance of its static segment "
        "(effective sample size; errors slower than the segment and errors common to the session not included)"
    )
    h_level = np.full(len(names), np.nan)
    if levelling is not None:
        table = dict(zip(lev.point, lev.height))
        h_level = np.array([table.get(n, np.nan) for n in names])
    summary["internal_precision_mean"] = precision_summary(res)
    summary.update({f"levelling_{k}": v for k, v in levelling_summary(res, h_level).items()})
    _log.info("writing rtk_results.csv, rtk_results.json and rtk.png into %s", out)
    proj = "; ".join(f"+proj=tmerc +lat_0=0 +lon_0={z:g} +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m" for z in zones)
    csv_crs = (
        f"{crs}; no EPSG code: a local grid fitted to {summary['datum_transformation']['n_control']} control "
        f"points from WGS-84 Gauss-Krueger ({proj})"
        if transform is not None
        else f"{crs}; no EPSG code, PROJ definition: {proj}"
    )
    if anomaly is not None:
        csv_height = (
            f"normal height h = ellipsoidal H - height anomaly, the anomaly a {anomaly.kind} surface fitted "
            f"to {int(anomaly.residuals.shape[0])} control points (sigma0 "
            f"{float(anomaly.sigma0) / MM:.1f} mm); H_ellipsoidal_m is WGS-84 ellipsoidal"
        )
    else:
        csv_height = "WGS-84 ellipsoidal height (no control points, no height anomaly): h = H"
    width = "" if lon0_deg is not None else f", {zone_width} deg zones"
    write_rtk_results(
        out / "rtk_results.csv",
        names,
        res,
        h_level,
        sigma=ps.sigma,
        sigma_method=ps.method,
        crs=csv_crs,
        zone=f"central meridian {', '.join(f'{z:g}' for z in zones)} deg{width}",
        height_system=csv_height,
    )
    fnames = [pathlib.Path(f).name for f in files]
    plot_rtk(
        res,
        out / "rtk.png",
        h_level=h_level if np.any(np.isfinite(h_level)) else None,
        names=names,
        sigma=ps.sigma,
        title=f"RTK {len(names)} point{'s' if len(names) != 1 else ''} from "
        f"{', '.join(fnames[:3])}{f' and {len(fnames) - 3} more' if len(fnames) > 3 else ''}",
    )
    pts = point_records(names, res, ps, series.t, series.mask, point_segment)
    for q in pts:  # GPST s -> ISO time
        for k in ("t_start", "t_end"):
            q[k] = None if q[k] is None else gpst_iso(q[k])
    summary["points"] = pts
    summary["sigma_mean_mm"] = sigma_summary(ps)
    summary["outputs"] = [str(out / "rtk_results.csv"), str(out / "rtk_results.json"), str(out / "rtk.png")]
    write_json(out / "rtk_results.json", summary)
    if not quiet:
        print(format_rtk(summary))
    return summary


def format_rtk(summary: dict) -> str:
    """The summary of :func:`run_rtk` as text: internal precisions (mm, S2 eq. (19)) and levelling (cm, Table 3)."""
    p = summary["internal_precision_mean"]
    lines = [
        f"S2 pipeline: {summary['n_points']} points, central meridian(s) {summary['lon0_deg']} deg, "
        f"{'forward filter + RTS' if summary['smoother'] else 'forward filter'}"
    ]
    mt = summary.get("motion_test")
    if mt is not None and mt["files"]:
        n_all = sum(c["n_epochs"] for c in mt["files"])
        moving, short = summary["excluded_moving_epochs"], summary["excluded_short_static_epochs"]
        lines.append(
            f"  static/moving test (.pos files): {n_all - moving - short} of {n_all} epochs kept as static "
            f"in {sum(c['n_segments'] for c in mt['files'])} segment(s); left out: {moving} moving "
            f"(speed > {mt['v_max']:g} m/s or > {mt['d_max']:g} m in {mt['window_s']:g} s), {short} in "
            f"static runs < {mt['min_static_s']:g} s"
        )
    sm = summary.get("sigma_mean_mm", {})
    if sm.get("corrected") is not None:
        c, nv = sm["corrected"], sm["naive"]
        lines.append(
            f"  precision of a point mean, x / y / h mm (rms over points): {c[0]:.2f} / {c[1]:.2f} / "
            f"{c[2]:.2f} [{summary['sigma_method']}: correlated epochs]; epochs taken as independent: "
            f"{nv[0]:.2f} / {nv[1]:.2f} / {nv[2]:.2f} ({c[0] / nv[0]:.1f} / {c[1] / nv[1]:.1f} / "
            f"{c[2] / nv[2]:.1f}x optimistic)"
        )
    lines += [
        "  S2 internal precision of the mean, eq. (19) (epochs taken as independent), plane / height mm:",
        f"    conventional averaging, eq. (19): {p['conventional']['plane_mm']:.2f} / "
        f"{p['conventional']['height_mm']:.2f}",
        f"    from the reported sigmas        : {p['formal']['plane_mm']:.2f} / {p['formal']['height_mm']:.2f}",
        f"    filtered, eq. (19)              : {p['filtered']['plane_mm']:.2f} / {p['filtered']['height_mm']:.2f}",
    ]
    for key in ("levelling_conventional_terminal", "levelling_conventional_H_anomaly", "levelling_filtered"):
        if key in summary:
            c = summary[key]
            shares = ", ".join(
                f"{s * 100:.1f} % within {th:g} cm" for s, th in zip(c["share_within"], c["thresholds_cm"])
            )
            lines.append(
                f"  {key[10:]:>24}: max {c['max_abs_cm']:.2f} cm, mean {c['mean_cm']:.2f} cm, "
                f"std {c['std_cm']:.2f} cm; {shares}"
            )
    pts = summary.get("points") or []
    if pts:
        h = "h (normal)" if str(summary.get("height_system", "")).startswith("normal") else "h (ellipsoidal)"
        lines.append(
            f"  points ({summary.get('crs', 'grid').split(' (')[0]}; x north, y east, {h}; sigma with "
            f"correlated epochs):"
        )
        for q in pts[:POINTS_PRINTED]:
            lines.append(
                f"    {q['name']}: x {q['x_m']:.4f} m, y {q['y_m']:.4f} m, h {q['h_m']:.4f} m; sigma x/y/h "
                f"{q['sigma_x_m'] / MM:.2f}/{q['sigma_y_m'] / MM:.2f}/{q['sigma_h_m'] / MM:.2f} mm "
                f"({q['n_epochs']} epochs)"
            )
        if len(pts) > POINTS_PRINTED:
            lines.append(f"    ... and {len(pts) - POINTS_PRINTED} more points in rtk_results.csv")
    lines.append(f"wrote {', '.join(summary['outputs'])}")
    return "\n".join(lines)


#: points whose coordinates the summary prints (the rest are in rtk_results.csv)
POINTS_PRINTED = 20


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
    f_ep = write_epoch_log(
        out / "sim_epochs.csv",
        pts,
        sim.t[m],
        sim.xy_terminal[m][:, 0],
        sim.xy_terminal[m][:, 1],
        sim.h_terminal[m],
        sim.lat[m],
        sim.lon[m],
        sim.H[m],
        sim.sigma[m],
    )
    C = sim.control_h.shape[0]
    f_cp = write_control_points(
        out / "sim_control.csv",
        [f"K{i + 1}" for i in range(C)],
        sim.control_lat,
        sim.control_lon,
        sim.control_H,
        sim.control_xy[:, 0],
        sim.control_xy[:, 1],
        sim.control_h,
    )
    f_lv = write_levelling(out / "sim_levelling.csv", names, sim.h_level)
    return f_ep, f_cp, f_lv, sim
