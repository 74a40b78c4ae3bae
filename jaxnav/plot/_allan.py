"""Figure of ``jaxnav allan``: Allan deviation per axis with the fitted noise terms (log-log)."""

from __future__ import annotations

import math
import pathlib

import matplotlib.pyplot as plt
import numpy as np

from jaxnav.plot._save import save_figure


def plot_allan(
    taus,
    adev,
    adev_sigma,
    fitted,
    white,
    bias_instability,
    rate_rw,
    path,
    *,
    title: str,
    adev_unit: str,
    white_label,
    bi_label,
    rrw_label,
    resolved=None,
    bounds=None,
) -> pathlib.Path:
    """Overlapping Allan deviation of three axes with error bars and the fitted slope lines.

    One panel per axis: the measured deviation (+-1 sigma, taus outside the fit hollow), white noise
    N / sqrt(tau) (slope -1/2, marked at tau = 1 s), the bias-instability floor 0.664 B, the rate
    random walk K sqrt(tau / 3) (slope +1/2, marked at tau = 3 s), and their sum.

    Args:
      taus: (k,) s.  adev, adev_sigma: (3, k) in the plotted unit.  fitted: (k,) bool.
      white, bias_instability, rate_rw: (3,) N, B, K in the plotted unit (times sqrt(s), -, / sqrt(s)).
      path: file written.  title: figure title.  adev_unit: e.g. "deg/h".
      white_label, bi_label, rrw_label: (3,) legend texts with the values in datasheet units.
      resolved: optional (3, 3) bool per axis for (white, bias instability, rate random walk); a term not
        resolved is drawn dotted, at its 2-sigma upper bound from ``bounds`` when given.
      bounds: optional (3, 3) upper bounds of (N, B, K) per axis, in the plotted units.
    """
    path = pathlib.Path(path)
    taus = np.asarray(taus, float)
    fig, ax = plt.subplots(1, 3, figsize=(15, 5.2), sharey=True)
    tt = np.geomspace(taus[0], taus[-1], 200)
    finite = np.asarray(adev, float)[np.isfinite(adev) & (np.asarray(adev) > 0)]
    lo = float(np.min(finite)) / 3 if finite.size else 1e-6
    hi = float(np.max(finite)) * 3 if finite.size else 1.0
    for c, a in enumerate(ax):
        d, s = np.asarray(adev[c], float), np.asarray(adev_sigma[c], float)
        a.errorbar(
            taus[fitted],
            d[fitted],
            yerr=np.minimum(s[fitted], 0.999 * d[fitted]),
            fmt="o",
            ms=3,
            color="k",
            lw=0.8,
            capsize=2,
            label="Allan deviation +-1 sigma (fitted)",
        )
        if np.any(~fitted):
            a.plot(taus[~fitted], d[~fitted], "o", ms=3, mfc="none", color="0.4", label="not fitted")
        fit = [float(white[c]), float(bias_instability[c]), float(rate_rw[c])]
        ls = ["--" if resolved is None or resolved[c][j] else ":" for j in range(3)]
        n, b, k = (fit[j] if ls[j] == "--" or bounds is None else float(bounds[c][j]) for j in range(3))
        if n > 0:
            a.plot(tt, n / np.sqrt(tt), ls[0], color="C0", label=f"white (slope -1/2): {white_label[c]}")
            if tt[0] <= 1.0 <= tt[-1]:
                a.plot([1.0], [n], "s", color="C0", ms=6)
        if b > 0:
            a.plot(
                tt,
                np.full_like(tt, math.sqrt(2 * math.log(2) / math.pi) * b),
                ls[1],
                color="C2",
                label=f"bias instability (0.664 B): {bi_label[c]}",
            )
        if k > 0:
            a.plot(tt, k * np.sqrt(tt / 3.0), ls[2], color="C3", label=f"rate random walk (slope +1/2): {rrw_label[c]}")
            if tt[0] <= 3.0 <= tt[-1]:
                a.plot([3.0], [k], "s", color="C3", ms=6)
        a.plot(
            tt,
            np.sqrt(fit[0] ** 2 / tt + 2 * math.log(2) / math.pi * fit[1] ** 2 + fit[2] ** 2 * tt / 3),
            "-",
            color="C1",
            lw=1.5,
            label="sum of the fitted terms",
        )
        a.set_xscale("log")
        a.set_yscale("log")
        a.set_ylim(lo, hi)
        a.set_xlabel("averaging time tau, s")
        a.set_title(f"axis {'xyz'[c]}")
        a.grid(alpha=0.3, which="both")
        a.legend(fontsize=7, loc="best")
    ax[0].set_ylabel(f"Allan deviation, {adev_unit}")
    fig.suptitle(title)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return path
