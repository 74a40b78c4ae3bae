"""Figures of the filter-family demonstration."""

from __future__ import annotations

import pathlib

import matplotlib

matplotlib.use("Agg")
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
    fig, ax = plt.subplots(4, 1, figsize=(10, 12), sharex=True)
    t = np.asarray(t)
    for a in ax:
        a.axvspan(t[change[0]], t[min(change[1], len(t) - 1)], color="red", alpha=0.08, lw=0)
    for name, r in runs.items():
        c = COLORS.get(name)
        label = f"{name} (b={b})" if name == "attenuated" and b is not None else name
        ax[0].plot(t, r["err"][:, 2] / MM, color=c, lw=0.8, label=label)
        ax[1].plot(t, np.hypot(r["err"][:, 0], r["err"][:, 1]) / MM, color=c, lw=0.8, label=label)
        if name in ("attenuated", "fading"):
            ax[2].plot(t, r["factors"], color=c, lw=0.8, label=("S_k" if name == "attenuated" else "lambda_k"))
        if name == "variance_compensation":
            ax[3].semilogy(t, np.sqrt(np.maximum(r["q"], 1e-30)), lw=0.8)
    ax[0].set_ylabel("up error, mm")
    ax[1].set_ylabel("horizontal error, mm")
    ax[2].set_ylabel("inflation factor")
    ax[3].set_ylabel("VC sqrt(diag D_Omega), m/s^2")
    ax[3].legend(["x", "y", "h"], loc="upper right", fontsize=8)
    ax[3].set_xlabel("time, s")
    ax[0].legend(loc="upper right", fontsize=8)
    ax[2].legend(loc="upper right", fontsize=8)
    ax[0].set_title("Filter family on a constant-velocity series with an unmodelled acceleration burst (shaded)")
    fig.tight_layout()
    path = pathlib.Path(path)
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return fig
