"""Figure of the coordinated-turn filters on the real car drive."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np

from jaxnav.plot._save import save_figure

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
        ax[0].semilogy(t, e, "-" if st == "filtered" else "--", color=COLOR.get(k), lw=0.8 if st == "filtered" else 1.2,
                       alpha=0.85, label=f"{k} classic, {st}")
    ax[0].set_ylabel("horizontal error, m")
    ax[0].set_title("Coordinated-turn model on the real 1 Hz RTK drive (mostly float): "
                    "horizontal error against the reference")
    _shade(ax[1], t, result["turns"], "red", "turning (reference > 5 deg/s)")
    for (k, p, st), e in result["manoeuvre_errors"].items():
        if st == "filtered":
            ax[1].plot(t, e, STYLE.get(p, "-"), color="tab:gray" if p == "classic" else "tab:blue", lw=0.9,
                       label=f"{k} {p} (stiff model)")
    ax[1].set_ylabel("horizontal error, m")
    ax[1].set_ylim(0, 60)
    ax[1].set_title("Manoeuvres: a stiff model (turns unmodelled), classic vs fading (filtered)")
    _shade(ax[2], t, result["fixed_runs"], "green", "runs of fixed solutions")
    for (k, p, st), e in result["outlier_errors"].items():
        if st == "filtered":
            ax[2].semilogy(t, e, STYLE.get(p, "-"), color="tab:gray" if p == "classic" else "tab:purple", lw=0.9,
                           label=f"{k} {NAME.get(p, p)} (filtered)")
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
