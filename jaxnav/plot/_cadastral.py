"""Figures of the S3 cadastral survey: route and stops, target errors per stage, stop detection."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np

from jaxnav.plot._save import save_figure
from jaxnav.plot._style import readable_ticks

_KIND_STYLE = {
    0: ("s", "tab:red", "known coordinate"),
    1: ("D", "tab:orange", "known position"),
    2: ("^", "tab:purple", "levelling"),
    3: ("o", "tab:gray", "ZUPT"),
    4: ("*", "tab:green", "target"),
}
_STAGE_COLOR = {
    "forward": "tab:red",
    "preprocessed": "tab:orange",
    "smoothed": "tab:blue",
    "fused": "tab:green",
    "filtered": "tab:gray",
    "rts": "tab:purple",
}


def plot_cadastral_route(
    path, route_enu, stops_enu, kinds, names, *, estimates=None, target_errors=None, title="S3 cadastral survey"
):
    """Route (true and estimated, E/N metres), stops by kind, and target errors per stage.

    Args:
      path: output file.  route_enu: (N, 2) true E, N, m.  stops_enu: (K, 2).  kinds: (K,) codes.
      names: K point names.  estimates: optional dict label -> (N, 2) estimated routes.
      target_errors: optional dict stage -> (T, 3) E/N/U errors of one run, m (right panel).
    Returns:
      the matplotlib figure (also saved to ``path``).
    """
    fig, axes = plt.subplots(1, 2, figsize=(13, 6), gridspec_kw={"width_ratios": [1.4, 1]})
    ax = axes[0]
    ax.plot(route_enu[:, 0], route_enu[:, 1], "k-", lw=1.5, label="true route")
    for lab, r in (estimates or {}).items():
        ax.plot(r[:, 0], r[:, 1], lw=0.8, alpha=0.8, label=lab)
    seen = set()
    for p, k, nm in zip(stops_enu, kinds, names):
        m, c, lab = _KIND_STYLE[int(k)]
        ax.plot(p[0], p[1], m, color=c, ms=11 if k == 4 else 8, mec="k", label=None if k in seen else lab)
        seen.add(int(k))
        ax.annotate(nm, p, textcoords="offset points", xytext=(6, 6), fontsize=8)
    ax.set_xlabel("East, m")
    ax.set_ylabel("North, m")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(fontsize=8, loc="best")
    ax.set_title(title)
    ax = axes[1]
    if target_errors:
        stages = list(target_errors)
        T = np.asarray(target_errors[stages[0]]).shape[0]
        x = np.arange(T)
        wdt = 0.8 / len(stages)
        for i, s in enumerate(stages):
            e = np.asarray(target_errors[s])
            ax.bar(x + i * wdt, np.hypot(e[:, 0], e[:, 1]), wdt, color=_STAGE_COLOR.get(s), label=s)
        ax.set_yscale("log")
        ax.set_xticks(x + 0.4 - wdt / 2)
        tnames = [nm for nm, k in zip(names, kinds) if k == 4]
        ax.set_xticklabels(tnames[:T])
        ax.set_ylabel("horizontal target error, m")
        ax.set_xlabel("target point")
        ax.set_title("horizontal error at each target, per processing stage (this run)", fontsize=10)
        ax.legend(fontsize=8)
        ax.grid(True, which="major", alpha=0.3)
        readable_ticks(ax, "y")
    fig.tight_layout()
    save_figure(fig, path, dpi=120)
    plt.close(fig)
    return fig


def plot_cadastral_errors(path, errors, *, title="target errors over Monte Carlo seeds"):
    """Box plots of horizontal and vertical target errors per stage (all seeds and targets).

    Args:
      path: output file.  errors: dict stage -> (S, T, 3) E/N/U errors, m.
    Returns:
      the figure.
    """
    stages = list(errors)
    hz = [np.hypot(np.asarray(errors[s])[..., 0], np.asarray(errors[s])[..., 1]).ravel() for s in stages]
    vt = [np.abs(np.asarray(errors[s])[..., 2]).ravel() for s in stages]
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    for ax, data, lab in ((axes[0], hz, "horizontal"), (axes[1], vt, "vertical")):
        bp = ax.boxplot(data, showfliers=True, patch_artist=True)
        ax.set_xticks(np.arange(1, len(stages) + 1))
        ax.set_xticklabels(stages)
        for patch, s in zip(bp["boxes"], stages):
            patch.set_facecolor(_STAGE_COLOR.get(s, "white"))
            patch.set_alpha(0.6)
        rms = [np.sqrt(np.mean(d**2)) for d in data]
        ax.plot(np.arange(1, len(stages) + 1), rms, "kx", ms=9, label="RMS")
        ax.set_yscale("log")
        ax.set_ylabel(f"{lab} error, m")
        ax.set_xlabel("processing stage")
        ax.grid(True, which="major", alpha=0.3)
        readable_ticks(ax, "y")
        ax.legend(fontsize=8)
        ax.tick_params(axis="x", labelrotation=20)
    fig.suptitle(title)
    fig.tight_layout()
    save_figure(fig, path, dpi=120)
    plt.close(fig)
    return fig


def plot_stop_detection(
    path, t, statistic, threshold, detected, true=None, *, title="stop detection", extra=None, true_label="true stop"
):
    """The detector's GLRT statistic over time, its threshold, the detected (and true) stop spans.

    The statistic T_k of :func:`jaxnav.survey.stance_statistic` (dimensionless, ~1 when static) is
    drawn on a log axis when it spans more than two decades; samples below ``threshold`` are static.
    Detected stops are shaded, true stops are bars along the top; the legend sits outside the axes.

    Args:
      path: output file.  t: (N,) s.  statistic: (N,) detector statistic (not a 0/1 mask).
      threshold: scalar, the detector's threshold on ``statistic``.
      detected: (K, 2) spans, s.  true: optional (J, 2) spans.  extra: optional (t, y, label) trace
        on a second axis (e.g. GNSS speed).  true_label: legend entry of the ``true`` spans (e.g. what
        they come from on real data).
    Returns:
      the figure.
    Raises:
      ValueError: ``t`` and ``statistic`` of different lengths.
    """
    t = np.asarray(t, float).reshape(-1)
    stat = np.asarray(statistic, float).reshape(-1)
    if t.shape != stat.shape:
        raise ValueError(f"t {t.shape} and statistic {stat.shape} must have the same length")
    fig, ax = plt.subplots(figsize=(13, 4.2))
    for i, (a, b) in enumerate(np.asarray(detected, float).reshape(-1, 2)):
        ax.axvspan(a, b, color="tab:green", alpha=0.22, lw=0, label="detected stop" if i == 0 else None)
    ax.plot(t, stat, lw=0.6, color="tab:blue", label="GLRT statistic T_k")
    ax.axhline(threshold, color="k", ls="--", lw=1, label=f"threshold = {threshold:g} (static below)")
    pos = stat[np.isfinite(stat) & (stat > 0)]
    if pos.size and (pos.max() / max(pos.min(), 1e-300) > 100 or pos.max() / threshold > 100):
        ax.set_yscale("log")
        lo = max(np.percentile(pos, 0.5), threshold * 1e-3)
        ax.set_ylim(lo / 2, max(pos.max(), threshold) * 3)
    if true is not None:
        for i, (a, b) in enumerate(np.asarray(true, float).reshape(-1, 2)):  # along the top, in axes y units
            ax.plot(
                [a, b],
                [0.97, 0.97],
                color="tab:red",
                lw=5,
                solid_capstyle="butt",
                transform=ax.get_xaxis_transform(),
                label=true_label if i == 0 else None,
            )
    handles, labels = ax.get_legend_handles_labels()
    if extra is not None:
        ax2 = ax.twinx()
        ax2.plot(extra[0], extra[1], color="tab:orange", lw=1, label=extra[2])
        ax2.set_ylabel(extra[2], color="tab:orange")
        h2, l2 = ax2.get_legend_handles_labels()
        handles, labels = handles + h2, labels + l2
    ax.set_xlabel("time, s")
    ax.set_ylabel("GLRT statistic T_k (dimensionless)")
    if t.size > 1:
        ax.set_xlim(t[0], t[-1])
    ax.grid(alpha=0.3, which="major")
    ax.set_title(title, fontsize=10)
    # outside the data, so that the legend hides no stop
    ax.legend(
        handles,
        labels,
        fontsize=8,
        loc="upper left",
        bbox_to_anchor=(1.08 if extra is not None else 1.01, 1.0),
        borderaxespad=0.0,
    )
    fig.tight_layout()
    save_figure(fig, path, dpi=120)
    plt.close(fig)
    return fig
