"""Figures of the S0 reproduction (trajectory, velocity, error curves with 3-sigma bands, factors, b sweep)."""

from __future__ import annotations

import pathlib


import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from jaxnav.geodesy import geodetic_to_enu  # noqa: E402
from jaxnav.plot._save import save_figure

AXES = ("E", "N", "U")


def plot_s0(outdir, *, truth, gidx, t, detail, sweep_b, sweep_rms, b_paper, sweep_per_seed=None,
            seed_label="seed 0"):
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
    ax[0].set_title(f"S0 true trajectory, start {abs(lon0):.2f} deg {'E' if lon0 >= 0 else 'W'}, "
                    f"{abs(lat0):.2f} deg {'N' if lat0 >= 0 else 'S'}")
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
            for j, (err, sig, unit) in enumerate(((d["pos_err"], d["sig_pos"], "m"), (d["vel_err"], d["sig_vel"], "m/s"))):
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
    for a, (name, label, color) in zip(fax, (("attenuated", "S_k (attenuated, S0 eq. 11)", "tab:orange"),
                                             ("fading", "lambda_k (fading, S0 eqs. 13-17)", "tab:blue"))):
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
        sax.errorbar(sweep_b, sweep_rms, yerr=[sweep_rms - lo, hi - sweep_rms], fmt="none", ecolor="0.6",
                     elinewidth=1, capsize=5, label=f"min-max over {ps.shape[1]} seeds")
        sax.errorbar(sweep_b, sweep_rms, yerr=sd, fmt="o-", color="tab:blue", elinewidth=2.5, capsize=0,
                     label="mean +- 1 std")
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
