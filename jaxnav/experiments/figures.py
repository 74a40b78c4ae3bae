"""Figures of single experiments: the S0 reproduction (:func:`plot_s0`), the filter-family
demonstration (:func:`plot_filter_family`) and the coordinated-turn filters on the real car drive
(:func:`plot_ct_drive`)."""

from __future__ import annotations

import pathlib

import matplotlib.pyplot as plt
import numpy as np

from jaxnav.geodesy import geodetic_to_enu
from jaxnav.plot import save_figure
from jaxnav.units import MM

AXES = ("E", "N", "U")


def plot_s0(outdir, *, truth, gidx, t, detail, sweep_b, sweep_rms, b_paper, sweep_per_seed=None, seed_label="seed 0"):
    """Write the S0 figures into ``outdir``; return their paths.

    Args:
      truth: :class:`jaxnav.sim.Trajectory`.  gidx: (M,) truth indices of the GPS epochs.  t: (M,) s.
      detail: {filter: {"pos_err", "vel_err", "sig_pos", "sig_vel" (M, 3), "factors" (M,)}} for one seed.
      sweep_b: (B,) b values.  sweep_rms: (B,) mean position RMS, m.  b_paper: the paper's b.
      sweep_per_seed: optional (B, S) position RMS of each Monte Carlo seed, m: drawn as min-max bars
        and +-1 std bars around the mean (the sweep's spread over seeds).
      seed_label: which Monte Carlo run ``detail`` is, named in the titles (e.g. "seed 0 of 32").
    """
    outdir = pathlib.Path(outdir)
    paths = []
    pos = np.asarray(truth.pos)
    e, n, _ = (np.asarray(a) for a in geodetic_to_enu(pos[:, 0], pos[:, 1], pos[:, 2], pos[0, 0], pos[0, 1], pos[0, 2]))
    fig, ax = plt.subplots(1, 2, figsize=(12, 5))
    ax[0].plot(e / 1e3, n / 1e3)
    ax[0].plot(e[0] / 1e3, n[0] / 1e3, "go", label="start")
    ax[0].set_xlabel("east, km")
    ax[0].set_ylabel("north, km")
    ax[0].axis("equal")
    ax[0].legend()
    lat0, lon0 = np.rad2deg(pos[0, 0]), np.rad2deg(pos[0, 1])  # the truth's start, not a fixed text
    ax[0].set_title(
        f"S0 true trajectory, start {abs(lon0):.2f} deg {'E' if lon0 >= 0 else 'W'}, "
        f"{abs(lat0):.2f} deg {'N' if lat0 >= 0 else 'S'}"
    )
    tt = np.asarray(truth.t)
    # ellipsoidal height, not the tangent-plane "up" (which drops ~d^2 / 2R, ~1 km over 115 km)
    ax[1].plot(tt, pos[:, 2] - pos[0, 2])
    ax[1].set_xlabel("time, s")
    ax[1].set_ylabel("ellipsoidal height - start height, m")
    ax[1].set_title("true height profile")
    for a in ax:
        a.grid(alpha=0.3)
    fig.tight_layout()
    paths.append(outdir / "trajectory.png")
    save_figure(fig, paths[-1], dpi=100)
    plt.close(fig)

    fig, ax = plt.subplots(3, 1, figsize=(10, 7), sharex=True)
    v = np.asarray(truth.v_n)
    for i in range(3):
        ax[i].plot(tt, v[:, i])
        ax[i].set_ylabel(f"V{AXES[i]}, m/s")
    ax[0].set_title("S0 true velocity (local east, north, up)")
    for a in ax:
        a.grid(alpha=0.3)
    ax[2].set_xlabel("time, s")
    fig.tight_layout()
    paths.append(outdir / "velocity.png")
    save_figure(fig, paths[-1], dpi=100)
    plt.close(fig)

    for name, d in detail.items():
        fig, ax = plt.subplots(3, 2, figsize=(13, 8), sharex=True)
        for i in range(3):
            for j, (err, sig, unit) in enumerate(
                ((d["pos_err"], d["sig_pos"], "m"), (d["vel_err"], d["sig_vel"], "m/s"))
            ):
                ax[i, j].fill_between(t, -3 * sig[:, i], 3 * sig[:, i], color="0.85", label="+-3 sigma")
                ax[i, j].plot(t, err[:, i], lw=0.8, label="error")
                ax[i, j].set_ylabel(f"{'pos' if j == 0 else 'vel'} {AXES[i]}, {unit}")
        ax[0, 0].set_title(f"{name}: position error")
        ax[0, 1].set_title(f"{name}: velocity error")
        ax[0, 0].legend(loc="upper right", fontsize=8)
        fig.suptitle(f"S0 {name} filter, Monte Carlo {seed_label}: error and +-3 sigma of the filter")
        ax[2, 0].set_xlabel("time, s")
        ax[2, 1].set_xlabel("time, s")
        fig.tight_layout()
        paths.append(outdir / f"errors_{name}.png")
        save_figure(fig, paths[-1], dpi=100)
        plt.close(fig)

    fig = plt.figure(figsize=(14, 6))
    gs = fig.add_gridspec(2, 2, width_ratios=[1.3, 1])
    fax = [fig.add_subplot(gs[0, 0])]
    fax.append(fig.add_subplot(gs[1, 0], sharex=fax[0]))
    sax = fig.add_subplot(gs[:, 1])
    # S_k and lambda_k in separate panels: on one axis the attenuated filter's S_k lay under lambda_k
    for a, (name, label, color) in zip(
        fax,
        (
            ("attenuated", "S_k (attenuated, S0 eq. 11)", "tab:orange"),
            ("fading", "lambda_k (fading, S0 eqs. 13-17)", "tab:blue"),
        ),
    ):
        if name in detail:
            f = np.asarray(detail[name]["factors"])
            a.plot(t, f, lw=0.8, color=color, label=label)
            if np.all(f > 0) and f.max() / f.min() > 20:
                a.set_yscale("log")
            a.set_ylabel("inflation factor")
            a.legend(loc="upper right", fontsize=8)
        else:
            a.text(0.5, 0.5, f"{name} filter not run", transform=a.transAxes, ha="center")
        a.grid(alpha=0.3)
    plt.setp(fax[0].get_xticklabels(), visible=False)
    fax[1].set_xlabel("time, s")
    fax[0].set_title(f"covariance inflation factors, {seed_label}")
    sweep_b, sweep_rms = np.asarray(sweep_b, float), np.asarray(sweep_rms, float)
    if sweep_per_seed is not None:
        ps = np.asarray(sweep_per_seed, float).reshape(len(sweep_b), -1)
        lo, hi, sd = ps.min(1), ps.max(1), ps.std(1)
        sax.errorbar(
            sweep_b,
            sweep_rms,
            yerr=[sweep_rms - lo, hi - sweep_rms],
            fmt="none",
            ecolor="0.6",
            elinewidth=1,
            capsize=5,
            label=f"min-max over {ps.shape[1]} seeds",
        )
        sax.errorbar(
            sweep_b, sweep_rms, yerr=sd, fmt="o-", color="tab:blue", elinewidth=2.5, capsize=0, label="mean +- 1 std"
        )
    else:
        sax.plot(sweep_b, sweep_rms, "o-", color="tab:blue", label="mean")
    i = int(np.argmin(np.abs(sweep_b - b_paper)))
    sax.plot(sweep_b[i], sweep_rms[i], "rs", ms=8, label=f"b = {b_paper} (paper)", zorder=5)
    k = int(np.argmin(sweep_rms))
    sax.plot(sweep_b[k], sweep_rms[k], "g*", ms=14, label=f"best mean: b = {sweep_b[k]:.3f}", zorder=6)
    sax.set_xlabel("attenuation factor b")
    sax.set_ylabel("position RMS (mean of E, N, U), m")
    sax.set_title("b sweep of the attenuated filter")
    sax.grid(alpha=0.3)
    sax.legend(fontsize=8)
    fig.tight_layout()
    paths.append(outdir / "factors_and_b_sweep.png")
    save_figure(fig, paths[-1], dpi=100)
    plt.close(fig)
    return paths


#: line colour of each filter in :func:`plot_filter_family`
COLORS = {"classic": "tab:gray", "attenuated": "tab:orange", "fading": "tab:blue", "variance_compensation": "tab:green"}


def plot_filter_family(runs: dict, t, change, path, *, b=None):
    """Plot one seed of the demonstration: up error, horizontal error, factors, VC noise estimate.

    Args:
      runs: {filter name: {"err": (T, 3) m, "factors": (T,), "q": (T, 3) m^2/s^4}}.
      t: (T,) s.  change: (start, end) epoch indices of the change of dynamics.
      path: PNG file to write.  b: attenuation factor for the legend.
    Returns:
      The matplotlib figure.
    """
    fig, ax = plt.subplots(4, 1, figsize=(12, 12), sharex=True)
    t = np.asarray(t)
    t0, t1 = t[change[0]], t[min(change[1], len(t) - 1)]
    for a in ax:
        a.axvspan(t0, t1, color="red", alpha=0.08, lw=0, label="unmodelled acceleration burst")
        a.grid(alpha=0.3)
    for name, r in runs.items():
        c = COLORS.get(name)
        label = f"{name} (b={b})" if name == "attenuated" and b is not None else name
        ax[0].plot(t, r["err"][:, 2] / MM, color=c, lw=0.8, label=label)
        ax[1].plot(t, np.hypot(r["err"][:, 0], r["err"][:, 1]) / MM, color=c, lw=0.8, label=label)
        if name == "attenuated":
            ax[2].plot(t, r["factors"], color=c, lw=0.8, label="S_k, attenuated (S0 eq. 11)")
        elif name == "fading":
            ax[2].plot(t, r["factors"], color=c, lw=0.8, ls="--", label="lambda_k, fading (S0 eqs. 13-17)")
        if name == "variance_compensation":
            q = np.sqrt(np.maximum(np.asarray(r["q"]), 1e-30))
            for i, (comp, ls) in enumerate((("x (horizontal)", "-"), ("y (horizontal)", "--"), ("h (up)", ":"))):
                ax[3].semilogy(t, q[:, i], color=c, ls=ls, lw=0.9, label=comp)
    ax[0].set_ylabel("up error, mm")
    ax[1].set_ylabel("horizontal error, mm")
    ax[2].set_ylabel("inflation factor (dimensionless)")
    ax[3].set_ylabel("VC sqrt(diag D_Omega), m/s^2")
    ax[3].set_xlabel("time, s")
    for a, title in zip(ax, ("", "", "", "variance compensation: estimated process-noise std per axis")):
        # legends beside the axes, never over the curves
        a.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, borderaxespad=0.0)
        if title:
            a.set_title(title, fontsize=9)
    ax[1].set_title("horizontal position error (same filters)", fontsize=9)
    ax[2].set_title("inflation factors of the predicted covariance", fontsize=9)
    ax[0].set_title(
        "Filter family on a constant-velocity series with an unmodelled acceleration burst (shaded)\n"
        "up position error, one Monte Carlo seed",
        fontsize=10,
    )
    fig.tight_layout()
    path = pathlib.Path(path)
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return fig


#: line style per plug-in, colour per filter and plug-in labels of :func:`plot_ct_drive`
STYLE = {"classic": "-", "fading": "--", "igg3": ":"}
COLOR = {"EKF": "tab:blue", "UKF": "tab:orange"}
NAME = {"classic": "classic", "fading": "fading", "igg3": "IGG-III"}


def _shade(ax, t, where, color, label):
    """Shade the runs of ``where`` (T,) bool on ax."""
    w = np.r_[False, np.asarray(where, bool), False]
    starts, ends = np.flatnonzero(~w[:-1] & w[1:]), np.flatnonzero(w[:-1] & ~w[1:])
    for i, (a, b) in enumerate(zip(starts, ends)):
        ax.axvspan(t[a], t[b - 1] + 1.0, color=color, alpha=0.12, lw=0, label=label if i == 0 else None)


def plot_ct_drive(result: dict, path):
    """Horizontal errors against the reference over time: all variants, manoeuvres, gross errors.

    Args:
      result: the dict of :func:`jaxnav.experiments.ct_drive.run_ct_drive` (errors (T,) m, "drive"
        with t (T,) s, "raw", "measured", "turns", "fixed_runs", "outlier_epochs").
      path: PNG file to write.
    Returns:
      The matplotlib figure.
    """
    d = result["drive"]
    t = np.asarray(d.t) - d.t[0]
    fig, ax = plt.subplots(3, 1, figsize=(12, 11), sharex=True)
    meas = result["measured"]
    for a in ax:
        _shade(a, t, ~meas, "gray", "no RTK epoch (masked)")
        a.grid(alpha=0.3)
    ax[0].semilogy(t[meas], result["raw"][meas], ".", color="k", ms=2.5, label="rover RTK itself")
    for (k, p, st), e in result["errors"].items():
        if p != "classic":  # the plug-ins are in the tables; here the filters and the smoother
            continue
        ax[0].semilogy(
            t,
            e,
            "-" if st == "filtered" else "--",
            color=COLOR.get(k),
            lw=0.8 if st == "filtered" else 1.2,
            alpha=0.85,
            label=f"{k} classic, {st}",
        )
    ax[0].set_ylabel("horizontal error, m")
    ax[0].set_title(
        "Coordinated-turn model on the real 1 Hz RTK drive (mostly float): horizontal error against the reference"
    )
    _shade(ax[1], t, result["turns"], "red", "turning (reference > 5 deg/s)")
    for (k, p, st), e in result["manoeuvre_errors"].items():
        if st == "filtered":
            ax[1].plot(
                t,
                e,
                STYLE.get(p, "-"),
                color="tab:gray" if p == "classic" else "tab:blue",
                lw=0.9,
                label=f"{k} {p} (stiff model)",
            )
    ax[1].set_ylabel("horizontal error, m")
    ax[1].set_ylim(0, 60)
    ax[1].set_title("Manoeuvres: a stiff model (turns unmodelled), classic vs fading (filtered)")
    _shade(ax[2], t, result["fixed_runs"], "green", "runs of fixed solutions")
    for (k, p, st), e in result["outlier_errors"].items():
        if st == "filtered":
            ax[2].semilogy(
                t,
                e,
                STYLE.get(p, "-"),
                color="tab:gray" if p == "classic" else "tab:purple",
                lw=0.9,
                label=f"{k} {NAME.get(p, p)} (filtered)",
            )
    for i, k in enumerate(result["outlier_epochs"]):
        ax[2].axvline(t[k], color="red", lw=0.6, alpha=0.6, label="injected 20-50 m outlier" if i == 0 else None)
    ax[2].set_ylabel("horizontal error, m")
    ax[2].set_xlabel("time since the first rover epoch, s")
    ax[2].set_title("Gross errors injected into the fixed runs: classic vs IGG-III")
    for a in ax:
        a.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, borderaxespad=0.0)
    fig.tight_layout()
    save_figure(fig, path)
    return fig
