"""Figures of the filter-family demonstration."""

from __future__ import annotations

import pathlib


import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from jaxnav.units import MM  # noqa: E402
from jaxnav.plot._save import save_figure

COLORS = {"classic": "tab:gray", "attenuated": "tab:orange", "fading": "tab:blue",
          "variance_compensation": "tab:green"}


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
    ax[0].set_title("Filter family on a constant-velocity series with an unmodelled acceleration burst (shaded)\n"
                    "up position error, one Monte Carlo seed", fontsize=10)
    fig.tight_layout()
    path = pathlib.Path(path)
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return fig
