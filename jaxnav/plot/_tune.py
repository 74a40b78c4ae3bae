"""Figures of ``jaxnav sweep`` and ``jaxnav tune``: loss landscapes, optimiser paths, Monte Carlo histograms."""

from __future__ import annotations

import pathlib

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.ticker import MaxNLocator

from jaxnav.plot._save import save_figure
from jaxnav.plot._style import readable_ticks as _readable_ticks


def plot_sweep(outdir, *, grid, axes, loss, loss_name, init):
    """Loss landscape of a sweep (1-D: mean and spread over runs; 2-D: contours) and the per-run histogram.

    Args:
      outdir: folder.  grid: dict name -> (G,) flattened grid.  axes: names of the swept axes.
      loss: (G, K) per-run loss.  loss_name: axis label.  init: dict of initial values (marked).
    Returns:
      List of written file paths.
    """
    out = pathlib.Path(outdir)
    mean = loss.mean(1)
    best = int(np.argmin(mean))
    files = []
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    if len(axes) == 1:
        x = grid[axes[0]]
        lo, hi = np.percentile(loss, [10, 90], axis=1)
        ax[0].fill_between(x, lo, hi, alpha=0.25, label="10-90 % of the runs")
        ax[0].plot(x, mean, "-", label="mean over runs")
        ax[0].plot(x[best], mean[best], "g*", ms=12, label=f"best {axes[0]} = {x[best]:.4g}")
        ax[0].set_xlabel(axes[0])
        ax[0].set_ylabel(loss_name)
        ax[0].legend()
    else:
        a, b = axes[:2]
        xa, xb = np.unique(grid[a]), np.unique(grid[b])
        Z = mean.reshape(len(xa), len(xb), -1).mean(-1)
        cs = ax[0].contourf(xb, xa, Z, 20)
        fig.colorbar(cs, ax=ax[0], label=loss_name)
        ax[0].plot(grid[b][best], grid[a][best], "w*", ms=12, label="best")
        ax[0].plot(init[b], init[a], "rs", label="init")
        if np.all(xa > 0) and np.all(xb > 0):
            ax[0].set_xscale("log")
            ax[0].set_yscale("log")
        ax[0].set_xlabel(b)
        ax[0].set_ylabel(a)
        ax[0].legend(fontsize=8, framealpha=0.6)
    ax[0].set_title(f"loss landscape (mean over {loss.shape[1]} runs)")
    ax[1].hist(loss[best], bins=min(20, max(5, loss.shape[1] // 2)), alpha=0.7, ec="white", lw=0.8, label="best point")
    ax[1].set_xlabel(loss_name)
    ax[1].set_ylabel("runs")
    ax[1].set_title("Monte Carlo distribution at the best grid point")
    _readable_ticks(ax[0])
    _readable_ticks(ax[1], "x")
    ax[1].yaxis.set_major_locator(MaxNLocator(nbins=5, integer=True))  # counts of runs: whole numbers
    for a in ax:
        plt.setp(a.get_xticklabels(), rotation=30, ha="right")
    fig.tight_layout()
    f = out / "sweep_landscape.png"
    save_figure(fig, f, dpi=110)
    plt.close(fig)
    files.append(f)
    return files


def plot_tune(outdir, *, path, losses, final, final_loss, landscape, loss_name, start_runs, final_runs):
    """Optimiser path (on the loss landscape when given), loss history and per-run histograms.

    Args:
      outdir: folder.  path: dict name -> (steps,) parameter values each step started from.
      losses: (steps,) loss history.  final, final_loss: tuned values and loss.
      landscape: None or dict(values (P,), loss (P,)) of a 1-D grid.  loss_name: label.
      start_runs, final_runs: (K,) per-run losses at the start and at the tuned values.
    Returns:
      List of written file paths.
    """
    out = pathlib.Path(outdir)
    fig, ax = plt.subplots(1, 3, figsize=(15, 4))
    names = list(path)
    if len(names) == 1:
        (n,) = names
        if landscape is not None:
            ax[0].plot(landscape["values"], landscape["loss"], "-", color="0.5", label="grid (mean over runs)")
        ax[0].plot(path[n], losses, "o-", ms=4, label="optimiser path")
        ax[0].plot(final[n], final_loss, "g*", ms=14, label=f"tuned {n} = {final[n]:.4g}")
        ax[0].set_xlabel(n)
        ax[0].set_ylabel(loss_name)
    else:
        a, b = names[:2]
        ax[0].plot(path[b], path[a], "o-", ms=4, label="optimiser path")
        ax[0].plot(final[b], final[a], "g*", ms=14, label="tuned")
        ax[0].set_xlabel(b)
        ax[0].set_ylabel(a)
        if np.all(path[a] > 0) and np.all(path[b] > 0):
            ax[0].set_xscale("log")
            ax[0].set_yscale("log")
    ax[0].legend()
    ax[0].set_title("optimiser path")
    # the loss itself (not "loss - min", which dips to ~0 by construction at the best step)
    losses = np.asarray(losses, float)
    steps = np.arange(len(losses))
    ax[1].plot(steps, losses, "o-" if len(losses) <= 40 else "-", ms=3, lw=1, label="loss at each step's start values")
    ax[1].axhline(float(final_loss), color="g", ls="--", lw=1, label=f"tuned: {float(final_loss):.4g}")
    finite = np.concatenate([losses[np.isfinite(losses)], [float(final_loss)]])
    if np.all(finite > 0) and finite.max() / finite.min() > 10:
        ax[1].set_yscale("log")
    _readable_ticks(ax[1], "y")
    ax[1].xaxis.set_major_locator(MaxNLocator(nbins=6, integer=True))
    ax[1].set_xlabel("optimiser step")
    ax[1].set_ylabel(f"loss: {loss_name}")
    ax[1].set_title("convergence")
    ax[1].grid(alpha=0.3, which="both")
    ax[1].legend(fontsize=8)
    bins = min(20, max(5, len(final_runs) // 2))
    ax[2].hist(start_runs, bins=bins, alpha=0.6, ec="white", lw=0.8, label="initial values")
    ax[2].hist(final_runs, bins=bins, alpha=0.6, ec="white", lw=0.8, label="tuned values")
    ax[2].set_xlabel(loss_name)
    ax[2].set_ylabel("runs")
    ax[2].legend()
    ax[2].set_title("Monte Carlo distribution")
    _readable_ticks(ax[0])
    _readable_ticks(ax[2], "x")
    ax[2].yaxis.set_major_locator(MaxNLocator(nbins=5, integer=True))  # counts of runs: whole numbers
    for a in ax:
        plt.setp(a.get_xticklabels(), rotation=30, ha="right")
    fig.tight_layout()
    f = out / "tune.png"
    save_figure(fig, f, dpi=110)
    plt.close(fig)
    return [f]
