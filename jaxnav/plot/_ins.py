"""Figures of ``jaxnav ins``: the track and errors inside simulated outages, differences to GNSS with 3-sigma
bands, attitude, sensor-bias estimates."""

from __future__ import annotations

import pathlib

import matplotlib.pyplot as plt
import numpy as np

from jaxnav.plot._save import save_figure
from jaxnav.plot._style import legend_below, readable_ticks, symlog_ticks


def _shade_outages(ax, windows, t0):
    for k, (a, b) in enumerate(windows):
        ax.axvspan(a - t0, b - t0, color="0.85", zorder=0, label="simulated GNSS outage" if k == 0 else None)


def _unwrap_deg(x):
    """Angles in degrees made continuous (multiples of 360 added at the jumps), NaN kept where they are."""
    out = np.array(x, float)
    ok = np.isfinite(out)
    if ok.any():
        out[ok] = np.degrees(np.unwrap(np.radians(out[ok])))
    return out


def plot_ins_differences(t, d_pos, sig_pos, d_vel, sig_vel, windows, path, *, title: str) -> pathlib.Path:
    """Forward-filter minus GNSS position (E, N, U, m) and velocity (m/s) with the filter's +-3 sigma.

    Inside the outage windows GNSS was withheld from the filter, so the difference there is the
    free-inertial drift; the y axes are symmetric-log (linear within the median 3 sigma).

    Args:
      t: (M,) epoch times, s.  d_pos, sig_pos: (M, 3) antenna position difference and 1-sigma, m.
      d_vel, sig_vel: (M, 3) velocity difference and 1-sigma, m/s (NaN where GNSS has no velocity).
      windows: (K, 2) outage windows, s.  path: file written.  title: figure title.
    """
    path = pathlib.Path(path)
    t0 = float(t[0])
    fig, ax = plt.subplots(2, 3, figsize=(14, 6.5), sharex=True)
    for row, (d, s, unit, what) in enumerate(((d_pos, sig_pos, "m", "position"), (d_vel, sig_vel, "m/s", "velocity"))):
        for c, comp in enumerate("ENU"):
            a = ax[row, c]
            _shade_outages(a, windows, t0)
            a.fill_between(t - t0, -3 * s[:, c], 3 * s[:, c], color="C1", alpha=0.25, lw=0, label="filter +-3 sigma")
            a.plot(t - t0, d[:, c], ".", ms=2, color="C0", label="filter - GNSS")
            a.set_title(f"{what} {comp}")
            a.grid(alpha=0.3)
            # symmetric log scale: cm-level agreement with GNSS and metre-level drift in outages both visible
            lin = float(np.nanmedian(3 * s[:, c])) if np.any(np.isfinite(s[:, c])) else 0.1
            lin = 10.0 ** np.ceil(np.log10(max(lin, 1e-3)))  # a power of ten: ticks 0, +-lin, +-10 lin
            a.set_yscale("symlog", linthresh=lin)
            symlog_ticks(a, lin)  # plain numbers, not -10^0
            a.set_ylabel(f"difference, {unit}\n(log beyond +-{lin:g})")
    for a in ax[1]:
        a.set_xlabel("time since start, s")
    fig.suptitle(title)
    legend_below(fig, ax[0, 0], ncol=3, height=0.05)  # below the panels: inside one it covered data
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return path


def plot_ins_attitude(t, fwd, sm, sig, windows, path, *, title: str) -> pathlib.Path:
    """Roll, pitch, heading (deg) of the forward and smoothed solutions, and their 1-sigma (deg).

    Args:
      t: (M,) s.  fwd, sm: (M, 3) roll, pitch, heading, deg.  sig: (M, 3) smoothed 1-sigma misalignment
        about east, north, up, deg.  windows: (K, 2) s.
    """
    path = pathlib.Path(path)
    t0 = float(t[0])
    fig, ax = plt.subplots(2, 3, figsize=(14, 6.5), sharex=True)
    for c, name in enumerate(("roll", "pitch", "heading")):
        a = ax[0, c]
        _shade_outages(a, windows, t0)
        f_c, s_c = fwd[:, c].astype(float), sm[:, c].astype(float)
        label = f"{name}, deg"
        if name == "heading":  # unwrapped: no 0/360 jumps; the forward heading on the smoothed one's turn
            s_c = _unwrap_deg(s_c)
            f_c = s_c + (f_c - s_c + 180.0) % 360.0 - 180.0
            label = "heading (unwrapped), deg"
        a.plot(t - t0, f_c, "-", lw=1, color="C0", label="forward")
        a.plot(t - t0, s_c, "-", lw=1, color="C1", label="RTS smoothed")
        a.set_title(name)
        a.set_ylabel(label)
        a.grid(alpha=0.3)
        b = ax[1, c]
        _shade_outages(b, windows, t0)
        b.semilogy(t - t0, sig[:, c], "--", lw=1.2, color="C3", label="RTS smoothed 1-sigma")
        b.set_ylabel(f"1-sigma {('tilt about east', 'tilt about north', 'heading')[c]}, deg")
        b.set_xlabel("time since start, s")
        b.grid(alpha=0.3, which="both")
        readable_ticks(b, "y")
    h0, l0 = ax[0, 0].get_legend_handles_labels()
    h1, l1 = ax[1, 0].get_legend_handles_labels()
    fig.suptitle(title)
    fig.tight_layout(rect=(0.0, 0.05, 1.0, 1.0))
    fig.legend(h0 + h1[1:], l0 + l1[1:], loc="lower center", ncol=4, fontsize=8, frameon=False)
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return path


def plot_ins_biases(
    t, gyro, gyro_sig, accel, accel_sig, windows, path, *, title: str, gyro_sm=None, accel_sm=None
) -> pathlib.Path:
    """Estimated gyro (deg/h) and accelerometer (mg) biases, body axes x/y/z (right, forward, up), +-1 sigma.

    Args:
      t: (M,) s.  gyro, gyro_sig: (M, 3) forward estimate and 1-sigma, deg/h.  accel, accel_sig: (M, 3) mg.
      windows: (K, 2) s.  gyro_sm, accel_sm: optional (M, 3) smoothed estimates (dashed).
    """
    path = pathlib.Path(path)
    t0 = float(t[0])
    fig, ax = plt.subplots(1, 2, figsize=(13, 4.8), sharex=True)
    for a, val, sig, sm, unit, what in (
        (ax[0], gyro, gyro_sig, gyro_sm, "deg/h", "gyro bias"),
        (ax[1], accel, accel_sig, accel_sm, "mg", "accelerometer bias"),
    ):
        _shade_outages(a, windows, t0)
        for c, axis in enumerate(("x (right)", "y (forward)", "z (up)")):
            a.plot(t - t0, val[:, c], color=f"C{c}", lw=1, label=f"{axis}, forward +-1 sigma")
            a.fill_between(t - t0, val[:, c] - sig[:, c], val[:, c] + sig[:, c], color=f"C{c}", alpha=0.15, lw=0)
            if sm is not None:
                a.plot(t - t0, sm[:, c], "--", color=f"C{c}", lw=1, label=f"{axis}, RTS smoothed")
        a.set_title(what)
        a.set_ylabel(f"{what}, {unit}")
        a.set_xlabel("time since start, s")
        a.grid(alpha=0.3)
    fig.suptitle(title)
    legend_below(fig, ax[0], ncol=4, height=0.11)  # one legend for both panels, below them
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return path


def plot_standstill(
    t, stat, threshold, detected, vetoed, t_gnss, speed, speed_sigma, windows, path, *, title: str, unconfirmed=None
) -> pathlib.Path:
    """SHOE statistic with its threshold and the accepted standstills (top), GNSS speed with its sigma
    and the samples the GNSS check vetoed (bottom).

    Args:
      t: (N,) IMU times, s.  stat: (N,) T_n.  threshold: gamma.  detected, vetoed: (N,) bool.
      t_gnss, speed, speed_sigma: (M,) s, m/s, m/s (or None).  windows: (K, 2) outage windows, s.
      unconfirmed: optional (N,) bool, standstills dropped for want of a GNSS-static sample.
    """
    path = pathlib.Path(path)
    t0 = float(t[0])
    x = np.asarray(t) - t0
    fig, ax = plt.subplots(2, 1, figsize=(13, 6.5), sharex=True)

    def spans(a, flag, color, label):
        d = np.diff(np.concatenate([[0], np.asarray(flag, np.int8), [0]]))
        for k, (i, j) in enumerate(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1)):
            a.axvspan(x[i], x[j], color=color, alpha=0.3, lw=0, label=label if k == 0 else None)

    for a in ax:
        _shade_outages(a, windows, t0)
    spans(ax[0], detected, "C2", "accepted standstill (ZUPT)")
    spans(ax[0], vetoed, "C3", "vetoed: GNSS says moving")
    if unconfirmed is not None:
        spans(ax[0], unconfirmed, "C1", "dropped: no GNSS-static epoch")
    ax[0].semilogy(x, np.maximum(np.asarray(stat, float), 1e-6), color="C0", lw=0.8, label="SHOE statistic T_n")
    ax[0].axhline(threshold, color="k", ls="--", lw=1, label=f"threshold {threshold:.3g}")
    ax[0].set_ylabel("T_n (dimensionless)")
    ax[0].grid(alpha=0.3)
    ax[0].legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    if t_gnss is not None and speed is not None:
        tg = np.asarray(t_gnss) - t0
        ax[1].plot(tg, speed, ".", ms=2, color="C1", label="GNSS speed")
        ax[1].plot(tg, 3 * np.asarray(speed_sigma), color="0.4", lw=0.8, label="3 x its sigma")
        ax[1].set_yscale("symlog", linthresh=0.1)
    spans(ax[1], vetoed, "C3", "vetoed: GNSS says moving")
    spans(ax[1], detected, "C2", "accepted standstill (ZUPT)")
    ax[1].set_ylabel("speed, m/s")
    ax[1].set_xlabel("time since start, s")
    ax[1].grid(alpha=0.3)
    ax[1].legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return path


def plot_time_offset_likelihood(offsets, loglik, best, sigma, path, *, title: str) -> pathlib.Path:
    """Innovation log-likelihood against the trial IMU-GNSS time offset, with the estimate and its 1-sigma.

    Args:
      offsets: (K,) trial offsets added to the IMU times, s.  loglik: (K,) their log-likelihoods.
      best: the estimate, s.  sigma: its 1-sigma, s (NaN: not drawn).  path: file written.
    """
    path = pathlib.Path(path)
    x, y = np.asarray(offsets, float), np.asarray(loglik, float)
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    for a, near in zip(ax, (None, 0.06)):
        s = np.ones(x.size, bool) if near is None else np.abs(x - best) <= near
        a.plot(1e3 * x[s], y[s], "o-", ms=3, lw=1, color="C0", label="trial offsets")
        if np.isfinite(sigma):
            a.axvspan(
                1e3 * (best - sigma),
                1e3 * (best + sigma),
                color="C1",
                alpha=0.25,
                lw=0,
                label=f"estimate +-1 sigma ({1e3 * best:+.1f} +- {1e3 * sigma:.1f} ms)",
            )
        a.axvline(1e3 * best, color="C1", lw=1, label=None if np.isfinite(sigma) else f"estimate {1e3 * best:+.1f} ms")
        a.set_xlabel("time offset added to the IMU times, ms")
        a.set_ylabel("GNSS innovation log-likelihood")
        a.set_title("whole search" if near is None else "around the estimate")
        a.grid(alpha=0.3)
    fig.suptitle(title)
    legend_below(fig, ax[0], ncol=2, height=0.08)
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return path


def plot_truth_errors(err_fwd, err_sm, windows, path, *, title: str) -> pathlib.Path:
    """Solution minus reference over time: position E/N/U (m), velocity E/N/U (m/s), roll/pitch/heading
    (deg), forward and smoothed, each with its own +-3 sigma band; outages shaded.

    Args:
      err_fwd, err_sm: :class:`jaxnav.ins.TrajectoryErrors` (SI) of the forward and smoothed solutions.
      windows: (K, 2) outage windows, s.  path: file written.  title: figure title.
    """
    path = pathlib.Path(path)
    t0 = float(min(err_fwd.t[0], err_sm.t[0]))
    fig, ax = plt.subplots(3, 3, figsize=(15, 9), sharex=True)
    rows = (
        ("pos_enu", "sig_pos_enu", 1.0, "m", ("east", "north", "up"), "position"),
        ("vel_enu", "sig_vel", 1.0, "m/s", ("east", "north", "up"), "velocity"),
        ("att", "sig_att", 180.0 / np.pi, "deg", ("roll", "pitch", "heading"), ""),
    )
    for r, (field, sfield, scale, unit, comps, what) in enumerate(rows):
        for c in range(3):
            a = ax[r, c]
            _shade_outages(a, windows, t0)
            for e, col, name in ((err_fwd, "C0", "forward"), (err_sm, "C1", "RTS smoothed")):
                x = np.asarray(e.t) - t0
                y = np.asarray(getattr(e, field))[:, c] * scale
                s = np.asarray(getattr(e, sfield))[:, c] * scale
                if np.any(np.isfinite(s)):
                    a.fill_between(x, -3 * s, 3 * s, color=col, alpha=0.15, lw=0, label=f"{name} +-3 sigma")
                a.plot(x, y, "-", lw=0.9, color=col, label=f"{name} - reference")
            a.set_title(f"{what} {comps[c]}".strip())
            a.set_ylabel(f"error, {unit}")
            a.grid(alpha=0.3)
            y_all = np.concatenate([np.asarray(getattr(e, field))[:, c] * scale for e in (err_fwd, err_sm)])
            y_all = y_all[np.isfinite(y_all)]
            if y_all.size:  # the band can be much wider than the error (a converging heading): zoom on the errors
                m = float(np.max(np.abs(y_all)))
                a.set_ylim(-1.3 * m if m > 0 else -1, 1.3 * m if m > 0 else 1)
    for a in ax[2]:
        a.set_xlabel("time since start, s")
    fig.suptitle(title)
    legend_below(fig, ax[0, 0], ncol=5, height=0.05)
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return path


def plot_shifted_outages(
    start, shift, drift_fwd, drift_sm, path, *, title: str, what: str, pooled=None
) -> pathlib.Path:
    """Largest drift per simulated outage against the outage's start, one marker per shifted schedule.

    Outages without a scored epoch (NaN drift) are marked at zero in grey.

    Args:
      start: (K,) start of each outage since the start of the run, s.  shift: (K,) int, the schedule
        (shift) of each outage.  drift_fwd, drift_sm: (K,) the forward and smoothed solutions' largest
        drift in each outage, m (NaN: not scored).  path: file written.  title: figure title.
      what: the drift plotted, for the y labels (e.g. "largest horizontal drift").
      pooled: optional (RMS forward, RMS smoothed) over all outages, m, drawn as dashed lines.
    """
    path = pathlib.Path(path)
    start, shift = np.asarray(start, float), np.asarray(shift, int)
    markers = "osD^vP*Xph<>"
    fig, ax = plt.subplots(2, 1, figsize=(10, 7), sharex=True)
    for i, (a, d, name) in enumerate(
        ((ax[0], np.asarray(drift_fwd, float), "forward filter"), (ax[1], np.asarray(drift_sm, float), "RTS smoothed"))
    ):
        ok = np.isfinite(d)
        for k in np.unique(shift):
            s = (shift == k) & ok
            a.plot(start[s], d[s], markers[k % len(markers)], ms=7, color=f"C{k % 10}", label=f"shift {k}")
        if (~ok).any():
            a.plot(
                start[~ok], np.zeros(int((~ok).sum())), "x", ms=7, color="0.5", label="not scored (no reference epoch)"
            )
        rms = None if pooled is None else pooled[i]
        if rms is not None and np.isfinite(rms):
            a.axhline(rms, ls="--", color="0.3", lw=1, label="RMS over all scored outages")
        a.set_title(f"{name}" + (f": RMS {rms:.3g} m over {int(ok.sum())} outages" if rms is not None else ""))
        a.set_ylabel(f"{what}, m")
        top = float(np.max(d[ok])) if ok.any() else 1.0
        a.set_ylim(-0.04 * top, 1.12 * top)
        a.grid(alpha=0.3)
    ax[1].set_xlabel("outage start since the start of the run, s")
    fig.suptitle(title)
    legend_below(fig, ax[0], ncol=4, height=0.08)
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return path


def plot_outage_track(scores, enu_ref, enu_fwd, enu_sm, path, *, title: str) -> pathlib.Path:
    """Track with simulated GNSS outage windows (left) and the horizontal error inside each outage (right).

    Args:
      scores: :class:`jaxnav.ins.OutageScores` (windows (K, 2) s, t (M,) s, err_fwd/err_sm (M,) m,
        n_ref/fwd_max/sm_max (K,), fwd_rms_all/sm_rms_all m).
      enu_ref, enu_fwd, enu_sm: (M, 3) local ENU, m, at ``scores.t``: the GNSS reference, the forward
        filter and the smoother.
      path: the PNG written (folders created).  title: name of the recording in the left title.
    Returns:
      The path written.
    """
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    ref, f, s = (np.asarray(a, float) for a in (enu_ref, enu_fwd, enu_sm))
    t = scores.t
    fig, ax = plt.subplots(1, 2, figsize=(13, 5.5))
    a = ax[0]
    a.plot(ref[:, 0], ref[:, 1], ".", color="0.6", ms=3, label="RTK (.pos)")
    a.plot(f[:, 0], f[:, 1], "-", color="C0", lw=1, label="forward filter")
    a.plot(s[:, 0], s[:, 1], "-", color="C1", lw=1, label="RTS smoother")
    starts = []
    for k, (ta, tb) in enumerate(scores.windows):
        w = (t >= ta) & (t < tb)
        a.plot(ref[w, 0], ref[w, 1], "k.", ms=4, label="withheld (outage n, numbered at its start)" if k == 0 else None)
        if w.any():
            starts.append((k + 1, ref[np.nonzero(w)[0][0], :2]))
    a.plot(ref[0, 0], ref[0, 1], "g^", label="start")
    a.set_xlabel("east, m")
    a.set_ylabel("north, m")
    a.axis("equal")
    # outage numbers at their starts; one that would land on a label already placed is left out
    span = max(np.ptp(ref[:, 0]), np.ptp(ref[:, 1]), 1e-9) if len(ref) else 1.0
    placed = []
    for n, xy in starts:
        if all(np.hypot(*(xy - q)) > 0.04 * span for q in placed):
            placed.append(xy)
            a.annotate(
                str(n),
                xy,
                xytext=(3, 3),
                textcoords="offset points",
                fontsize=8,
                bbox=dict(boxstyle="round,pad=0.15", fc="white", ec="0.5", lw=0.5, alpha=0.8),
            )
    a.legend(fontsize=8)
    a.set_title(f"{title}: track, GNSS withheld on the outage windows")
    b = ax[1]
    scored = [k for k in range(len(scores.windows)) if scores.n_ref[k]]
    fwd_max = np.nanmax(np.asarray(scores.fwd_max, float)[scored]) if scored else np.nan
    sm_max = np.nanmax(np.asarray(scores.sm_max, float)[scored]) if scored else np.nan
    for j, k in enumerate(scored):  # one legend entry per solution, for all outages together
        ta, tb = scores.windows[k]
        w = (t >= ta) & (t < tb)
        b.plot(
            t[w] - ta,
            scores.err_fwd[w],
            "-",
            color="C0",
            lw=1,
            alpha=0.8,
            label=f"forward filter ({len(scored)} outages; max {fwd_max:.2f} m)" if j == 0 else None,
        )
        b.plot(
            t[w] - ta,
            scores.err_sm[w],
            "--",
            color="C1",
            lw=1,
            alpha=0.8,
            label=f"RTS smoother (max {sm_max:.2f} m)" if j == 0 else None,
        )
    skipped = len(scores.windows) - len(scored)
    if skipped:
        b.plot([], [], " ", label=f"{skipped} outage(s) without an RTK-fixed epoch inside (not scored)")
    b.set_xlabel("time since outage start, s")
    b.set_ylabel("horizontal error vs RTK fix, m")
    b.set_title(f"RMS over outages: forward {scores.fwd_rms_all:.2f} m, RTS {scores.sm_rms_all:.2f} m")
    b.grid(alpha=0.3)
    b.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return path
