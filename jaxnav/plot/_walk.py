"""Figure of the real-data walk experiment (``jaxnav walk``): track and error inside each GNSS outage."""

from __future__ import annotations

import pathlib


import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from jaxnav.plot._save import save_figure


def plot_walk(scores, extras: dict, path, *, title: str = "walk_0827") -> pathlib.Path:
    """Track with outage windows (left) and horizontal error inside each outage (right).

    Args:
      scores: :class:`jaxnav.experiments.walk.OutageScores` (windows (K, 2) s, t (M,) s, err_fwd/err_sm (M,) m,
        n_ref/fwd_max/sm_max (K,), fwd_rms_all/sm_rms_all m).
      extras: dict with "enu_ref", "enu_fwd", "enu_sm": (M, 3) local ENU, m.
      path: the PNG written (folders created).  title: name of the recording in the left title.
    Returns:
      The path written.
    """
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    ref, f, s = extras["enu_ref"], extras["enu_fwd"], extras["enu_sm"]
    t = scores.t
    fig, ax = plt.subplots(1, 2, figsize=(13, 5.5))
    a = ax[0]
    a.plot(ref[:, 0], ref[:, 1], ".", color="0.6", ms=3, label="RTK (.pos)")
    a.plot(f[:, 0], f[:, 1], "-", color="C0", lw=1, label="forward filter")
    a.plot(s[:, 0], s[:, 1], "-", color="C1", lw=1, label="RTS smoother")
    starts = []
    for k, (ta, tb) in enumerate(scores.windows):
        w = (t >= ta) & (t < tb)
        a.plot(ref[w, 0], ref[w, 1], "k.", ms=4,
               label="withheld (outage n, numbered at its start)" if k == 0 else None)
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
            a.annotate(str(n), xy, xytext=(3, 3), textcoords="offset points", fontsize=8,
                       bbox=dict(boxstyle="round,pad=0.15", fc="white", ec="0.5", lw=0.5, alpha=0.8))
    a.legend(fontsize=8)
    a.set_title(f"{title}: track, GNSS withheld on the outage windows")
    b = ax[1]
    scored = [k for k in range(len(scores.windows)) if scores.n_ref[k]]
    fwd_max = np.nanmax(np.asarray(scores.fwd_max, float)[scored]) if scored else np.nan
    sm_max = np.nanmax(np.asarray(scores.sm_max, float)[scored]) if scored else np.nan
    for j, k in enumerate(scored):  # one legend entry per solution, for all outages together
        ta, tb = scores.windows[k]
        w = (t >= ta) & (t < tb)
        b.plot(t[w] - ta, scores.err_fwd[w], "-", color="C0", lw=1, alpha=0.8,
               label=f"forward filter ({len(scored)} outages; max {fwd_max:.2f} m)" if j == 0 else None)
        b.plot(t[w] - ta, scores.err_sm[w], "--", color="C1", lw=1, alpha=0.8,
               label=f"RTS smoother (max {sm_max:.2f} m)" if j == 0 else None)
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
