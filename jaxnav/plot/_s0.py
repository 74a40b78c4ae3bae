"""Figures of the S0 reproduction (trajectory, velocity, error curves with 3-sigma bands, factors, b sweep)."""

from __future__ import annotations

import pathlib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from jaxnav.geodesy import geodetic_to_enu  # noqa: E402
from jaxnav.plot._save import save_figure

AXES = ("E", "N", "U")


def plot_s0(outdir, *, truth, gidx, t, detail, sweep_b, sweep_rms, b_paper):
    """Write the S0 figures into ``outdir``; return their paths.

    Args:
      truth: :class:`jaxnav.sim.Trajectory`.  gidx: (M,) truth indices of the GPS epochs.  t: (M,) s.
      detail: {filter: {"pos_err", "vel_err", "sig_pos", "sig_vel" (M, 3), "factors" (M,)}} for one seed.
      sweep_b: (B,) b values.  sweep_rms: (B,) mean position RMS, m.  b_paper: the paper's b.
    """
    outdir = pathlib.Path(outdir)
    paths = []
    pos = np.asarray(truth.pos)
    e, n, u = (np.asarray(a) for a in geodetic_to_enu(pos[:, 0], pos[:, 1], pos[:, 2], pos[0, 0], pos[0, 1], pos[0, 2]))
    fig, ax = plt.subplots(1, 2, figsize=(12, 5))
    ax[0].plot(e / 1e3, n / 1e3)
    ax[0].plot(e[0] / 1e3, n[0] / 1e3, "go", label="start")
    ax[0].set_xlabel("east, km")
    ax[0].set_ylabel("north, km")
    ax[0].axis("equal")
    ax[0].legend()
    ax[0].set_title("S0 trajectory (108E 39N, heading 30 deg)")
    tt = np.asarray(truth.t)
    ax[1].plot(tt, u)
    ax[1].set_xlabel("time, s")
    ax[1].set_ylabel("up, m")
    fig.tight_layout()
    paths.append(outdir / "trajectory.png")
    save_figure(fig, paths[-1], dpi=100)
    plt.close(fig)

    fig, ax = plt.subplots(3, 1, figsize=(10, 7), sharex=True)
    v = np.asarray(truth.v_n)
    for i in range(3):
        ax[i].plot(tt, v[:, i])
        ax[i].set_ylabel(f"V{AXES[i]}, m/s")
    ax[0].set_title("true velocity")
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
        ax[2, 0].set_xlabel("time, s")
        ax[2, 1].set_xlabel("time, s")
        fig.tight_layout()
        paths.append(outdir / f"errors_{name}.png")
        save_figure(fig, paths[-1], dpi=100)
        plt.close(fig)

    fig, ax = plt.subplots(1, 2, figsize=(13, 4.5))
    for name, label in (("attenuated", "S_k (attenuated)"), ("fading", "lambda_k (fading)")):
        if name in detail:
            ax[0].semilogy(t, detail[name]["factors"], lw=0.8, label=label)
    ax[0].set_xlabel("time, s")
    ax[0].set_ylabel("inflation factor")
    ax[0].legend()
    ax[1].plot(sweep_b, sweep_rms, "o-")
    i = int(np.argmin(np.abs(np.asarray(sweep_b) - b_paper)))
    ax[1].plot(sweep_b[i], sweep_rms[i], "rs", label=f"b = {b_paper} (paper)")
    k = int(np.argmin(sweep_rms))
    ax[1].plot(sweep_b[k], sweep_rms[k], "g*", ms=12, label=f"best b = {sweep_b[k]:.3f}")
    ax[1].set_xlabel("attenuation factor b")
    ax[1].set_ylabel("mean position RMS, m")
    ax[1].legend()
    fig.tight_layout()
    paths.append(outdir / "factors_and_b_sweep.png")
    save_figure(fig, paths[-1], dpi=100)
    plt.close(fig)
    return paths
