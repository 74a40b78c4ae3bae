"""Figures of the S2 RTK pipeline: height differences against levelling (the form of S2 Fig. 1) and the
precision of the point means (eq. (19), reported sigmas, and with time-correlated epochs)."""

from __future__ import annotations

import pathlib

import matplotlib.pyplot as plt
import numpy as np

from jaxnav.plot._save import save_figure
from jaxnav.plot._style import legend_outside, readable_ticks
from jaxnav.units import CM, MM


def plot_rtk(result, path, *, h_level=None, names=None, thresholds=(0.007, 0.015), sigma=None, title=None):
    """S2 Fig. 1 (RTK height - levelling per point, conventional vs filtered) and internal precision.

    Top panel (only with ``h_level``): differences in cm per point number for the conventional RTK
    heights (the terminal's fitted h, averaged) and the filtered pipeline (ellipsoidal H + fitted
    height anomaly), with +-``thresholds`` bands. Bottom panels: internal precision of each point's
    mean, plane sqrt(m_x^2 + m_y^2) and height, in mm, conventional averaging vs filtered. The
    points are separate marks (no lines between them: neighbouring points are not a series).

    Args:
      result: :class:`jaxnav.survey.rtk.RtkResult` (P points).
      path: PNG file to write.
      h_level: optional (P,) levelled heights, m (NaN where a point was not levelled).
      names: optional (P,) point names for the x tick labels (shown when P <= 30).
      thresholds: |difference| bands to draw, m.
      sigma: optional (P, 3) precision of the means with time-correlated epochs
        (:func:`jaxnav.survey.point_sigmas`), m, drawn beside the eq. (19) values.
      title: figure title (e.g. naming the input files); default "RTK point means: P points".
        The points named in it are appended: "(first .. last)" when ``names`` is given.
    Returns:
      The matplotlib figure.
    """
    xyh = np.asarray(result.xyh)
    P = xyh.shape[0]
    k = np.arange(1, P + 1)
    rows = 3 if h_level is not None else 2
    fig, ax = plt.subplots(rows, 1, figsize=(12, 3.2 * rows), sharex=True)
    a = 0
    if h_level is not None:
        hl = np.asarray(h_level, float)
        d_f = (xyh[:, 2] - hl) / CM
        d_t = (np.asarray(result.terminal_xyh)[:, 2] - hl) / CM
        if np.any(np.isfinite(d_t)):
            ax[0].plot(k, d_t, "s", ms=4, color="tab:gray", label="conventional RTK (terminal h)")
        ax[0].plot(k, d_f, "o", ms=4, color="tab:blue", label="filtered (H - fitted anomaly)")
        for th, ls in zip(thresholds, (":", "--")):
            ax[0].axhspan(-th / CM, th / CM, color="tab:green", alpha=0.07, lw=0)
            ax[0].axhline(th / CM, color="tab:green", ls=ls, lw=0.8)
            ax[0].axhline(-th / CM, color="tab:green", ls=ls, lw=0.8, label=f"+-{th / CM:g} cm")
        ax[0].axhline(0.0, color="k", lw=0.5)
        ax[0].set_ylabel("RTK - levelling, cm")
        ax[0].set_title("Height differences against levelling (form of S2 Fig. 1)")
        legend_outside(ax[0])
        a = 1
    mp_raw = np.hypot(*np.asarray(result.raw_precision)[:, :2].T) / MM
    mp_f = np.hypot(*np.asarray(result.precision)[:, :2].T) / MM
    ax[a].plot(k, mp_raw, "s", ms=4, color="tab:gray", label="conventional mean, eq. (19)")
    ax[a].plot(k, mp_f, "o", ms=4, color="tab:blue", label="filtered mean, eq. (19)")
    fp = np.asarray(result.formal_precision)
    ax[a].plot(k, np.hypot(fp[:, 0], fp[:, 1]) / MM, "_", ms=10, mew=1.5, color="tab:red", label="from reported sigmas")
    if sigma is not None:
        sg = np.asarray(sigma, float)
        ax[a].plot(
            k,
            np.hypot(sg[:, 0], sg[:, 1]) / MM,
            "^",
            ms=4,
            color="tab:orange",
            label="correlated epochs (acf_ess_segment)",
        )
    ax[a].set_title("Precision of each point's mean (log scale)")
    ax[a].set_ylabel("plane precision, mm")
    legend_outside(ax[a])
    ax[a + 1].plot(k, np.asarray(result.raw_precision)[:, 2] / MM, "s", ms=4, color="tab:gray", label="conventional")
    ax[a + 1].plot(k, np.asarray(result.precision)[:, 2] / MM, "o", ms=4, color="tab:blue", label="filtered")
    ax[a + 1].plot(k, fp[:, 2] / MM, "_", ms=10, mew=1.5, color="tab:red", label="from reported sigmas")
    if sigma is not None:  # after the others: the same legend order as the plane panel
        ax[a + 1].plot(
            k,
            np.asarray(sigma, float)[:, 2] / MM,
            "^",
            ms=4,
            color="tab:orange",
            label="correlated epochs (acf_ess_segment)",
        )
    ax[a].set_yscale("log")
    ax[a + 1].set_yscale("log")
    ax[a + 1].set_ylabel("height precision, mm")
    legend_outside(ax[a + 1])
    readable_ticks(ax[a], "y")
    readable_ticks(ax[a + 1], "y")
    if names is not None and P <= 30:
        ax[-1].set_xticks(k)
        ax[-1].set_xticklabels([str(n) for n in names], rotation=60, fontsize=7)
        ax[-1].set_xlabel("point name (in order of occupation)")
    else:
        ax[-1].set_xlabel(f"point number 1..{P} (in order of occupation)")
        ax[-1].xaxis.get_major_locator().set_params(integer=True)
    for axis in ax:
        axis.grid(alpha=0.3)
    head = title if title else f"RTK point means: {P} point{'s' if P != 1 else ''}"
    if names is not None and P > 0:
        nm = [str(n) for n in names]
        head += f" ({nm[0]})" if P == 1 else f" ({nm[0]} .. {nm[-1]})"
    fig.suptitle(head, fontsize=10)
    fig.tight_layout()
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    save_figure(fig, path, dpi=120)
    return fig
