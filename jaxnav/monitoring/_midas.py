"""MIDAS robust trend estimator (Blewitt, Kreemer, Hammond and Gazeaux, JGR 121, 2016).

Median Interannual Difference Adjusted for Skewness: the median of the slopes of data pairs one
year apart (so annual terms cancel), pairs straddling a step left out, the slopes trimmed beyond
2 sigma of their scaled median absolute deviation and the median taken again.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

#: 1.4826 x MAD is the standard deviation of a Gaussian
MAD_TO_SIGMA = 1.4826
#: sqrt(pi / 2): the standard error of a median is this x the standard error of a mean
MEDIAN_EFFICIENCY = 1.2533


class MidasVelocity(NamedTuple):
    """MIDAS rates per column (units of x per unit of t, e.g. m/yr).

    Attributes:
      velocity: (C,) median of the trimmed pair slopes.  sigma: (C,) its uncertainty.
      pairs: (C,) pairs selected (forward + backward).  pairs_kept: (C,) after the 2-sigma trim.
      slope_sigma: (C,) 1.4826 x MAD of the kept slopes about ``velocity``.
    """

    velocity: np.ndarray
    sigma: np.ndarray
    pairs: np.ndarray
    pairs_kept: np.ndarray
    slope_sigma: np.ndarray


def midas_pairs(t_years, steps=(), *, tolerance: float = 0.001):
    """Index pairs (i, j), t_j - t_i = 1 yr +- ``tolerance``, not straddling a step (Blewitt et al. 2016, 2.2).

    Forward pass: each epoch i in time order is paired with the epoch closest to t_i + 1 yr;
    backward pass: each epoch j in reverse order with the epoch closest to t_j - 1 yr; a pair is
    kept when its separation is within ``tolerance`` of one year and no step s has t_i < s <= t_j.
    Both passes are returned together (a pair found by both appears twice, as in the paper).

    Args:
      t_years: (N,) increasing epochs, years.  steps: step epochs, years.  tolerance: years.
    Returns:
      (i, j): two (P,) int arrays, t_i < t_j.
    """
    t = np.asarray(t_years, float)
    if t.ndim != 1:
        raise ValueError(f"t_years must be 1-D, got shape {t.shape}")
    if t.size < 2:
        return np.zeros(0, int), np.zeros(0, int)
    if np.any(np.diff(t) <= 0):
        raise ValueError("t_years must be strictly increasing")
    s = np.sort(np.asarray(steps, float).ravel())

    def nearest(target):
        k = np.clip(np.searchsorted(t, target), 1, t.size - 1)
        return np.where(np.abs(t[k - 1] - target) <= np.abs(t[k] - target), k - 1, k)

    idx = np.arange(t.size)
    fj = nearest(t + 1.0)
    bi = nearest(t - 1.0)
    i = np.concatenate([idx, bi])
    j = np.concatenate([fj, idx])
    ok = (j > i) & (np.abs(t[j] - t[i] - 1.0) <= tolerance)
    # steps in (t_i, t_j]: the count of steps < t_j (strictly, s <= t_j) minus those <= t_i
    ok &= np.searchsorted(s, t[j], side="right") == np.searchsorted(s, t[i], side="right")
    return i[ok], j[ok]


def midas_velocity(t_years, x, steps=(), *, tolerance: float = 0.001, empirical_factor: float = 3.0) -> MidasVelocity:
    """MIDAS trend of each column of ``x`` (Blewitt et al. 2016, eqs. 11-17).

    For each column (NaN values left out): the slopes v = (x_j - x_i) / (t_j - t_i) of the
    :func:`midas_pairs`; their median m and sigma = 1.4826 median|v - m|; the slopes with
    |v - m| < 2 sigma kept; the median of those is the velocity, sigma recomputed about it, and the
    uncertainty ``empirical_factor`` x 1.2533 x sigma / sqrt(N / 4) with N the kept slopes
    (N / 4 independent pairs: every datum enters up to two pairs and each pair both passes;
    the factor 3 is the paper's scaling to match the real scatter of rates).

    Args:
      t_years: (N,) increasing epochs, years.  x: (N,) or (N, C) positions (NaN = missing).
      steps: step epochs, years.  tolerance: pair separation tolerance about one year, years.
      empirical_factor: the paper's 3; 1 gives the formal median uncertainty.
    Returns:
      :class:`MidasVelocity`, (C,) arrays (NaN where a column has no pair).
    """
    t = np.asarray(t_years, float)
    xx = np.asarray(x, float)
    one = xx.ndim == 1
    if one:
        xx = xx[:, None]
    if xx.ndim != 2 or xx.shape[0] != t.shape[0]:
        raise ValueError(f"x must be (N,) or (N, C) with N = len(t_years); got t {t.shape}, x {np.shape(x)}")
    out = np.full((5, xx.shape[1]), np.nan)
    for c in range(xx.shape[1]):  # components, not time steps
        k = np.isfinite(xx[:, c]) & np.isfinite(t)
        tc, xc = t[k], xx[k, c]
        i, j = midas_pairs(tc, steps, tolerance=tolerance)
        if i.size == 0:
            out[2:4, c] = 0
            continue
        v = (xc[j] - xc[i]) / (tc[j] - tc[i])
        m = np.median(v)
        sig = MAD_TO_SIGMA * np.median(np.abs(v - m))
        kept = v[np.abs(v - m) < 2.0 * sig] if sig > 0 else v
        vel = np.median(kept)
        sig2 = MAD_TO_SIGMA * np.median(np.abs(kept - vel))
        out[:, c] = (
            vel,
            empirical_factor * MEDIAN_EFFICIENCY * sig2 / np.sqrt(kept.size / 4.0),
            v.size,
            kept.size,
            sig2,
        )
    res = MidasVelocity(
        velocity=out[0], sigma=out[1], pairs=out[2].astype(int), pairs_kept=out[3].astype(int), slope_sigma=out[4]
    )
    return MidasVelocity(*(a[0] for a in res)) if one else res
