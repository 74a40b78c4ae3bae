"""Figures of S1 deformation monitoring: a forecast period, per-period statistics, daily velocities."""

from __future__ import annotations

import pathlib

import matplotlib.pyplot as plt
import numpy as np

from jaxnav.plot._save import save_figure
from jaxnav.plot._style import legend_outside, readable_ticks
from jaxnav.units import DAY, MM, MM_PER_YEAR, YEAR

COLORS = {
    "standard": "tab:gray",
    "adaptive": "tab:green",
    "standard_robust": "tab:red",
    "adaptive_robust": "tab:blue",
    "yang_robust": "tab:purple",
}
AXES = ("east", "north", "up")


def _save(fig, path):
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return fig


def plot_s1_period(series: dict, path, *, station: int = 0, skip: int = 60):
    """One simulated period: truth, measurements and forecasts (up), forecast errors per axis.

    Args:
      series: one entry of ``run_s1_simulation(...)["series"]`` ({"filters": {name: {"forecast",
        "error", ...}}, "pos", "zs", "episode"}), numpy, SI.
      path: PNG file.  station: which station.  skip: start-up epochs not drawn.
    Returns:
      The figure (closed after saving).
    """
    fig, ax = plt.subplots(4, 1, figsize=(11, 12), sharex=True)
    t = np.arange(series["pos"].shape[0])[skip:]
    ep = series["episode"][skip:, station]
    for a in ax:
        if ep.any():
            a.axvspan(t[ep][0], t[ep][-1], color="orange", alpha=0.12, lw=0, label="subsidence episode")
    ax[0].plot(t, series["zs"][skip:, station, 2] / MM, ".", ms=1, color="0.7", label="measured")
    ax[0].plot(t, series["pos"][skip:, station, 2] / MM, "k-", lw=1, label="truth")
    for name, o in series["filters"].items():
        c = COLORS.get(name)
        ax[0].plot(t, o["forecast"][skip:, station, 2] / MM, lw=0.8, color=c, label=f"{name} forecast")
        for i in range(3):
            ax[i + 1].plot(t, o["error"][skip:, station, i] / MM, lw=0.6, color=c, label=name)
    ax[0].set_ylabel("up, mm")
    legend_outside(ax[0], fontsize=7, markerscale=6)
    for i, name in enumerate(AXES):
        ax[i + 1].set_ylabel(f"{name} forecast - truth, mm")
    legend_outside(ax[1], fontsize=7)
    ax[-1].set_xlabel("epoch (1 Hz), s from the period start")
    ax[0].set_title(
        f"S1 on simulated station {station + 1}: Knothe subsidence episode (shaded), one-step forecasts X(k/k-1)",
        fontsize=10,
    )
    fig.tight_layout()
    return _save(fig, path)


def plot_s1_statistics(result: dict, path):
    """Per-period plane and height forecast RMS (m_P, m_H) of every filter (S1 Tables 1-2 as a figure).

    Args:
      result: output of :func:`jaxnav.experiments.s1.run_s1_simulation`.
      path: PNG file.
    Returns:
      The figure.
    """
    fig, ax = plt.subplots(3, 1, figsize=(11, 10), sharex=True)
    names = list(result["stats"])
    width = 0.8 / max(len(names), 1)  # periods are independent: markers side by side per period, no lines
    _STATION_MARKERS = ("o", "s", "^", "D", "v")
    S = 1
    for j, name in enumerate(names):
        st = result["stats"][name]
        c = COLORS.get(name, f"C{j}")
        for a, arr in ((ax[0], st.m_P), (ax[1], st.m_H), (ax[2], result["forecast_rms"][name])):
            v = np.asarray(arr, float)
            v = (v.reshape(v.shape[0], -1) if v.ndim >= 2 else v.reshape(-1, 1)) / MM  # (periods, stations)
            P, S = v.shape
            x = np.arange(1, P + 1) - 0.4 + (j + 0.5) * width
            for s_ in range(S):
                m = _STATION_MARKERS[s_] if S <= len(_STATION_MARKERS) else "o"
                a.plot(
                    x,
                    v[:, s_],
                    m,
                    ls="none",
                    ms=4,
                    color=c,
                    mec="k",
                    mew=0.3,
                    alpha=0.9,
                    label=name if s_ == 0 else None,
                )
    if 1 < S <= len(_STATION_MARKERS):  # station key: grey markers
        for s_ in range(S):
            ax[0].plot([], [], _STATION_MARKERS[s_], ls="none", color="0.5", label=f"station {s_ + 1}")
    ax[0].set_ylabel("m_P plane, mm")
    ax[1].set_ylabel("m_H height, mm")
    ax[2].set_ylabel("forecast - truth RMS, mm")
    ax[2].set_xlabel("period (independent simulated periods; filters side by side)")
    n_per = ax[2].get_xlim()
    P = int(round(n_per[1]))
    for a in ax:
        a.set_yscale("log")
        a.grid(alpha=0.3, which="major", axis="y")
        if P <= 60:  # thin separators between the periods
            for k in range(1, P):
                a.axvline(k + 0.5, color="0.85", lw=0.6, zorder=0)
        a.set_xlim(n_per)
        readable_ticks(a, "y")
    legend_outside(ax[0], fontsize=7)
    ax[2].xaxis.get_major_locator().set_params(integer=True)
    ax[0].set_title(
        "Forecast precision per period: m_P, m_H (forecast - measurement, S1 Tables 1-2)\n"
        "and forecast - simulated truth (bottom)",
        fontsize=10,
    )
    fig.tight_layout()
    return _save(fig, path)


def plot_daily_velocity(series, velocity, path, *, forecasts=None):
    """A daily series: positions with the constant-velocity fit, smoothed velocity with +-2 sigma bands.

    Args:
      series: :class:`jaxnav.io.DailySeries`.  velocity: :class:`jaxnav.monitoring.StationVelocity`.
      path: PNG file.  forecasts: optional {name: Forecast} of one-day forecasts (drawn as lines).
    Returns:
      The figure.
    """
    fig, ax = plt.subplots(3, 2, figsize=(13, 9), sharex=True)
    yr = series.year
    for i, name in enumerate(AXES):
        a = ax[i, 0]
        a.plot(yr, series.enu[:, i] / MM, ".", ms=1.5, color="0.6", label="daily position")
        fit = series.enu[:, i] - velocity.residuals[:, i]
        a.plot(
            yr,
            fit / MM,
            "k-",
            lw=1,
            label=f"CV filter: {velocity.velocity[i] / MM_PER_YEAR:+.2f} +- "
            f"{velocity.sigma_ar1[i] / MM_PER_YEAR:.2f} mm/yr",
        )
        if forecasts:
            for fname, f in forecasts.items():
                a.plot(
                    yr, np.asarray(f.forecast)[:, 0, i] / MM, lw=0.6, color=COLORS.get(fname), label=f"{fname} forecast"
                )
        a.set_ylabel(f"{name}, mm")
        a.legend(fontsize=7, loc="best")
        b = ax[i, 1]
        b.set_ylabel(f"{name} velocity, mm/yr")
        if velocity.smoothed_velocity is None:  # long-term velocity only: residuals instead
            b.plot(yr, velocity.residuals[:, i] / MM, ".", ms=1.5, color="0.5", label="residual to the CV fit")
            b.set_ylabel(f"{name} residual, mm")
            b.legend(fontsize=7, loc="best")
            continue
        v = velocity.smoothed_velocity[:, i] / MM_PER_YEAR
        s = velocity.smoothed_sigma[:, i] / MM_PER_YEAR
        b.fill_between(yr, v - 2 * s, v + 2 * s, color="tab:blue", alpha=0.2, lw=0)
        rw = np.sqrt(velocity.accel_psd[i] * YEAR) / MM_PER_YEAR
        b.plot(yr, v, color="tab:blue", lw=1, label=f"RTS velocity, ML random walk {rw:.2g} mm/yr/sqrt(yr)")
        b.axhline(velocity.velocity[i] / MM_PER_YEAR, color="k", lw=1, ls="--", label="constant-velocity estimate")
        if velocity.reference_velocity is not None:
            b.axhline(
                velocity.reference_velocity[i] / MM_PER_YEAR,
                color="tab:red",
                lw=1,
                ls=":",
                label="published (file header)",
            )
        b.legend(fontsize=7, loc="best")
    ax[-1, 0].set_xlabel("year")
    ax[-1, 1].set_xlabel("year")
    fig.suptitle(f"{series.station}: daily positions ({series.fmt}), velocity estimates")
    fig.tight_layout()
    return _save(fig, path)


def _model_psd(f_cpy, fit, c):
    """One-sided PSD (mm^2/cpy) of the fitted noise of component c at frequencies f (cycles/yr)."""
    dt = 1.0 / 365.25  # yr
    th = np.asarray(fit.noise.theta[c])
    sw, spl, srw, kappa = np.exp(th[0]) / MM, np.exp(th[1]) / MM, np.exp(th[2]) / MM, th[3]
    d = -0.5 * kappa
    phi = 1.0 - 6.9e-6
    z = np.abs(1.0 - phi * np.exp(-2j * np.pi * f_cpy * dt)) ** 2
    pl = 2.0 * spl**2 * dt / z**d
    rw = 2.0 * srw**2 * dt / np.abs(1.0 - np.exp(-2j * np.pi * f_cpy * dt)) ** 2 if np.any(fit.random_walk) else 0.0
    return 2.0 * sw**2 * dt + pl + rw


def _residual_psd(res_mm, valid, segments: int = 4):
    """Welch periodogram (mm^2/cpy, one-sided; Hann, 50 % overlap) of daily residuals with gaps set to
    zero and the power divided by the share of days present (an approximation for gappy series)."""
    x = np.where(valid, res_mm, 0.0)
    n = len(x)
    L = min(n, max(64, 2 * n // (segments + 1)))  # ``segments`` half-overlapping windows
    step = max(1, L // 2)
    win = np.hanning(L)
    acc, k = 0.0, 0
    for s in range(0, n - L + 1, step):
        seg = (
            x[s : s + L] - np.mean(x[s : s + L][valid[s : s + L]]) * valid[s : s + L]
            if valid[s : s + L].any()
            else x[s : s + L]
        )
        share = max(valid[s : s + L].mean(), 1e-3)
        F = np.fft.rfft(seg * win)
        acc = acc + np.abs(F) ** 2 / (np.sum(win**2) * share)
        k += 1
    dt = 1.0 / 365.25
    psd = 2.0 * dt * acc / max(k, 1)
    f = np.fft.rfftfreq(L, d=dt)
    return f[1:], psd[1:]


def plot_station_fit(fit, path):
    """Daily series with the fitted trajectory, residuals, and residual spectrum against the fitted noise.

    Args:
      fit: :class:`jaxnav.monitoring.StationFit`.
      path: PNG file.
    Returns:
      The figure (closed after saving).
    """
    g = fit.grid
    n = g.n_days
    yr = 2000.0 + g.t[:n] / YEAR
    model = fit.A[:n] @ np.asarray(fit.noise.beta).T  # (n, 3)
    fig, ax = plt.subplots(3, 3, figsize=(15, 10))
    for c, name in enumerate(AXES):
        v = g.valid[:n, c]
        y = np.where(v, g.y[:n, c], np.nan)
        off = np.nanmedian(y)
        ax[0, c].plot(yr, (y - off) / MM, ".", ms=1.5, color="0.55", label="daily position")
        ax[0, c].plot(yr, (model[:, c] - off) / MM, "-", lw=1.0, color="tab:red", label="trajectory model")
        rej = [d for d in fit.screening.records if d["component"] == name]
        if rej:
            ry = np.array([d["decimal_year"] for d in rej])
            rv = np.array([d["value_m"] for d in rej])
            ax[0, c].plot(ry, (rv - off) / MM, "x", ms=3, color="tab:orange", label=f"rejected ({len(rej)})")
        for ts in fit.steps:
            for a in ax[:2, c]:
                a.axvline(2000.0 + ts / YEAR, color="tab:purple", lw=0.8, ls="--")
        vel, sd = fit.velocity[c] / MM_PER_YEAR, fit.velocity_sigma[c] / MM_PER_YEAR
        ax[0, c].set_title(f"{fit.station} {name}: {vel:+.2f} +- {sd:.2f} mm/yr (95 %: +-{1.96 * sd:.2f})", fontsize=9)
        ax[0, c].set_ylabel(f"{name}, mm")
        leg = ax[0, c].legend(fontsize=7, loc="best")
        for h in leg.legend_handles:  # legible markers in the key (the daily dots are 1.5 pt)
            if hasattr(h, "set_markersize"):
                h.set_markersize(6)
        res = np.where(v, g.y[:n, c] - model[:, c], np.nan) / MM
        ax[1, c].plot(yr, res, ".", ms=1.5, color="0.4")
        ax[1, c].axhline(0.0, color="k", lw=0.5)
        ax[1, c].set_ylabel(f"{name} residual, mm")
        ax[1, c].set_xlabel("year")
        f, p = _residual_psd(np.nan_to_num(res), v)
        ax[2, c].loglog(f, p, "-", lw=0.7, color="0.4", label="residuals (Welch)")
        ax[2, c].loglog(f, _model_psd(f, fit, c), "-", lw=1.5, color="tab:red", label="fitted noise model")
        kap = float(fit.kappa[c])
        amp = fit.powerlaw_amplitude[c] * YEAR ** (-kap / 4) / MM
        rw = fit.random_walk[c] * np.sqrt(YEAR) / MM
        ax[2, c].set_title(
            f"white {fit.white_sigma[c] / MM:.2f} mm, power law {amp:.2f} mm/yr^{-kap / 4:.2f}\n"
            f"(kappa {kap:.2f}), random walk {rw:.2f} mm/sqrt(yr)",
            fontsize=8,
        )
        ax[2, c].set_xlabel("frequency, cycles/yr")
        ax[2, c].set_ylabel("PSD, mm^2/(cycle/yr)")
        ax[2, c].legend(fontsize=7)
    terms = "offset, rate, annual, semi-annual, steps"
    if getattr(fit, "poly_degree", 1) > 1:
        terms += f", polynomial of degree {fit.poly_degree}"
    if getattr(fit, "postseismic", ()):
        terms += ", post-seismic " + ", ".join(f"{p.form} (tau {p.tau / DAY:.3g} d)" for p in fit.postseismic)
    fig.suptitle(f"{fit.station}: trajectory ({terms}) with {fit.model}", fontsize=10)
    fig.tight_layout()
    return _save(fig, path)


#: 95 % of a 2-D Gaussian lies within this many sigmas (sqrt of the chi-square 2-dof 95 % point, 5.991)
ELLIPSE_95 = 2.4477


def plot_velocity_map(stations: list, path, *, title: str = "Station velocities"):
    """Horizontal velocity arrows with 95 % error ellipses, a scale arrow and names on a lat/lon grid.

    Args:
      stations: dicts with name, lat_deg, lon_deg, ve, vn (mm/yr), se, sn (mm/yr, 1 sigma) and
        optional corr_en (default 0); stations without coordinates (NaN) are left out.
      path: output file.  title: figure title.
    """
    st = [s for s in stations if np.isfinite(s["lat_deg"]) and np.isfinite(s["lon_deg"])]
    fig, ax = plt.subplots(figsize=(7.5, 6.5))
    if not st:
        ax.text(0.5, 0.5, "no station with coordinates in its file", ha="center", va="center", transform=ax.transAxes)
        ax.set_axis_off()
        return _save(fig, path)
    lat = np.array([s["lat_deg"] for s in st])
    lon = np.array([s["lon_deg"] for s in st])
    vmax = max(max(np.hypot(s["ve"], s["vn"]) for s in st), 1e-3)
    span = max(np.ptp(lat), np.ptp(lon) * np.cos(np.radians(lat.mean())), 1.0)
    k = 0.3 * span / vmax  # degrees of latitude per mm/yr: the longest arrow is 30 % of the map
    coslat = np.cos(np.radians(lat.mean()))
    for s in st:
        dx, dy = s["ve"] * k / coslat, s["vn"] * k
        ax.annotate(
            "",
            xy=(s["lon_deg"] + dx, s["lat_deg"] + dy),
            xytext=(s["lon_deg"], s["lat_deg"]),
            arrowprops=dict(arrowstyle="-|>", color="tab:red", lw=1.5, shrinkA=0, shrinkB=0),
        )
        c = s.get("corr_en", 0.0) or 0.0
        cov = np.array([[s["se"] ** 2, c * s["se"] * s["sn"]], [c * s["se"] * s["sn"], s["sn"] ** 2]])
        L = np.linalg.cholesky(cov + 1e-12 * np.eye(2))
        th = np.linspace(0.0, 2.0 * np.pi, 73)
        e, n = ELLIPSE_95 * (L @ np.stack([np.cos(th), np.sin(th)]))  # mm/yr, around the arrow tip
        ax.plot(s["lon_deg"] + dx + e * k / coslat, s["lat_deg"] + dy + n * k, color="tab:red", lw=0.8)
        ax.plot(s["lon_deg"], s["lat_deg"], "k^", ms=6)
        ax.annotate(s["name"], (s["lon_deg"], s["lat_deg"]), xytext=(4, -12), textcoords="offset points", fontsize=9)
    pad = 0.45 * span + 0.5
    ax.set_xlim(lon.min() - pad / coslat, lon.max() + pad / coslat)
    ax.set_ylim(lat.min() - pad, lat.max() + pad)
    ax.set_aspect(1.0 / coslat)
    ref = float(f"{vmax / 2:.0g}") if vmax >= 2 else round(vmax, 1) or 1.0
    x0, y0 = ax.get_xlim()[0] + 0.05 * np.ptp(ax.get_xlim()), ax.get_ylim()[0] + 0.06 * np.ptp(ax.get_ylim())
    ax.annotate(
        "",
        xy=(x0 + ref * k / coslat, y0),
        xytext=(x0, y0),
        arrowprops=dict(arrowstyle="-|>", color="k", lw=1.5, shrinkA=0, shrinkB=0),
    )
    ax.text(x0, y0 + 0.02 * np.ptp(ax.get_ylim()), f"{ref:g} mm/yr (ellipses: 95 %)", fontsize=9)
    ax.grid(True, lw=0.4, alpha=0.6)
    ax.set_xlabel("longitude (deg)")
    ax.set_ylabel("latitude (deg)")
    ax.set_title(title)
    return _save(fig, path)
