"""Shared figure styling: readable tick labels and legends placed outside the data."""

from __future__ import annotations

import numpy as np
from matplotlib.ticker import FixedLocator, FuncFormatter, MaxNLocator, NullFormatter


def _fmt(v, _pos=None):
    """Tick label: 3 significant digits, no offset text ("0.0025", "1e-05", "120")."""
    return f"{v:.3g}"


def _log_ticks(lo, hi, most: int = 6):
    """Up to ``most`` tick values in [lo, hi] (0 < lo < hi), spread evenly on a log axis.

    Candidates by preference: 1 x 10^k, then 2 and 5 x 10^k, then 3, 4, 6, 7, 8, 9 x 10^k (a group
    is only tried while fewer than 3 ticks are taken); one is taken when it is at least
    1/(most + 1) of the span (in decades) from every tick already taken.
    """
    ks = range(int(np.floor(np.log10(lo))) - 1, int(np.ceil(np.log10(hi))) + 1)
    gap = np.log10(hi / lo) / (most + 1)
    chosen = []
    for subs in ((1,), (2, 5), (3, 4, 6, 7, 8, 9)):
        if len(chosen) >= 3:  # three decades or more: decades only
            break
        for k in ks:
            for m in subs:
                v = float(f"{m * 10.0**k:.12g}")
                if lo * (1 - 1e-9) <= v <= hi * (1 + 1e-9) and all(
                    abs(np.log10(v / c)) >= gap * (1 - 1e-9) for c in chosen
                ):
                    chosen.append(v)
    if len(chosen) < 2:  # under a factor ~1.1: three values at 3 significant digits
        chosen = [float(f"{v:.3g}") for v in np.geomspace(lo, hi, 3)]
    return sorted(chosen)


def readable_ticks(ax, which="both"):
    """Few, short tick labels on ``ax`` (call after the data and limits are set).

    Log axes: decades, or 1-2-5 x 10^k (or 1..9 x 10^k) on a narrow range, at most 6, minor labels
    off (matplotlib labels every minor tick of a narrow log axis, and they overlap); linear axes:
    at most 5 ticks. Labels use 3 significant digits, no offset text.
    """
    for name in ("x", "y") if which == "both" else (which,):
        axis = getattr(ax, f"{name}axis")
        if axis.get_scale() == "log":
            lo, hi = sorted(getattr(ax, f"get_{name}lim")())
            if lo > 0:
                axis.set_major_locator(FixedLocator(_log_ticks(lo, hi)))
            axis.set_minor_formatter(NullFormatter())
        else:
            axis.set_major_locator(MaxNLocator(nbins=5))
        axis.set_major_formatter(FuncFormatter(_fmt))


def symlog_ticks(ax, linthresh: float, which: str = "y", most: int = 7):
    """Plain-number ticks on a symmetric-log axis: 0 and +-linthresh x 10^k ("-1", "0", "0.1", "10").

    matplotlib labels symlog ticks as powers ("-10^0", "10^-1"), hard to read as numbers. Call after
    the data and limits are set; at most ``most`` ticks (every other decade when there are more).
    """
    axis = getattr(ax, f"{which}axis")
    lo, hi = sorted(getattr(ax, f"get_{which}lim")())
    pos = [linthresh * 10.0**k for k in range(0, 12) if linthresh * 10.0**k <= max(hi, -lo) * (1 + 1e-9)]
    step = 1
    while 1 + 2 * len(pos[::step]) > most and step < len(pos):
        step += 1
    pos = pos[::step]
    ticks = sorted([0.0] + [v for v in pos if v <= hi] + [-v for v in pos if -v >= lo])
    if len(ticks) < 3:  # the data stay inside the linear part: linear ticks there
        ticks = [float(f"{v:.6g}") for v in MaxNLocator(nbins=4).tick_values(lo, hi) if lo <= v <= hi]
    axis.set_major_locator(FixedLocator(ticks))
    axis.set_major_formatter(FuncFormatter(_fmt))
    axis.set_minor_formatter(NullFormatter())


def legend_outside(ax, handles=None, labels=None, *, fontsize=8, x=1.01, **kw):
    """Legend beside ``ax`` (upper left corner at axes x = ``x``, top aligned): it never covers data.

    Call ``fig.tight_layout()`` afterwards so the figure makes room for it; ``kw`` go to
    ``ax.legend``. Returns the legend.
    """
    args = () if handles is None else (handles, labels)
    return ax.legend(*args, fontsize=fontsize, loc="upper left", bbox_to_anchor=(x, 1.0), borderaxespad=0.0, **kw)


def legend_below(fig, ax, *, ncol=3, fontsize=8, height=0.07):
    """One legend for the whole figure (the entries of ``ax``), centred below the axes grid.

    Lays the figure out with ``tight_layout`` leaving ``height`` (figure fraction) at the bottom for
    it; use when every panel shares the same entries and a legend inside a panel would cover data.
    """
    handles, labels = ax.get_legend_handles_labels()
    fig.tight_layout(rect=(0.0, height, 1.0, 1.0))
    return fig.legend(handles, labels, loc="lower center", ncol=ncol, fontsize=fontsize, frameon=False)
