"""Power-law noise of daily GNSS series as a sum of first-order Gauss-Markov processes (host side).

The power-law noise of GNSS position series is modelled, as in Hector (Bos et al. 2013,
J. Geod. 87(4) 351-360), by the generalised Gauss-Markov (GGM) process
w = (1 - phi B)^(-d) eps with d = -kappa/2 (kappa the spectral index: -1 flicker, -2 random
walk) and 1 - phi tiny (Hector's default 6.9e-6): stationary, and within a few decades of
years indistinguishable from the pure power law. Its impulse response is
g_k = phi^k Gamma(k + d) / (Gamma(d) k!) and its autocovariance per unit driving variance
gamma(k) = sum_j g_j g_(j+k).

For 0 < d < 1, g_k is a completely monotone sequence (a mixture of geometric sequences with
positive weights, from the Beta integral of Gamma(k + d) / k!), and so is gamma(k). Hence
gamma(k) ~= sum_j w_j r_j^|k| with w_j >= 0: the covariance of K independent stationary
first-order Gauss-Markov (AR(1)) processes x_j with x_j(k+1) = r_j x_j(k) + n_j,
var n_j = w_j (1 - r_j^2). The r_j are fixed (time constants log-spaced from 0.2 day to ten
times the series length), the w_j are fitted by non-negative least squares on the relative
error over lags 0 .. N-1 (the only lags a series of N days sees). With the default 1.5 terms
per decade (about 8 processes for 10 years) the largest relative error of gamma over the
series is 0.1-0.2 % (tests/monitoring/test_trajectory.py checks it), far below what the
rate uncertainty can tell.

Everything here is numpy (computed once per spectral index and series length, cached); the
Kalman filter that uses the result is in :mod:`jaxnav.monitoring._trajectory`.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import numpy as np

#: Hector's default 1 - phi of the GGM process (its ``GGM_1mphi``)
GGM_ONE_MINUS_PHI = 6.9e-6
#: longest lag (days) the cached autocovariances cover (about 90 years of daily data)
MAX_LAGS = 1 << 15


class GaussMarkovSum(NamedTuple):
    """K first-order Gauss-Markov processes whose summed covariance approximates a power law.

    Attributes:
      r: (K,) one-day AR(1) coefficients exp(-1 day / tau_j).
      w: (K,) stationary variances per unit driving variance of the power law (>= 0).
      d: fractional difference parameter (-kappa / 2).
      n: series length (days) the fit covers.
      max_rel_error: largest |approximation / gamma - 1| over lags 0 .. n-1.
    """

    r: np.ndarray
    w: np.ndarray
    d: float
    n: int
    max_rel_error: float


@functools.lru_cache(maxsize=64)
def ggm_autocovariance(d: float, one_minus_phi: float = GGM_ONE_MINUS_PHI) -> np.ndarray:
    """Autocovariance gamma(k), k = 0 .. MAX_LAGS-1, of the GGM process per unit driving variance.

    gamma(k) = sum_j g_j g_(j+k), g_j = phi^j Gamma(j + d) / (Gamma(d) j!) (Bos et al. 2013,
    eq. (9)-(10)); the sum is a correlation computed by FFT over j < 25 / (1 - phi) (phi^j < 1e-10
    beyond, capped at 2^23 terms).

    Args:
      d: fractional difference parameter, 0 < d < 1 (0.5 flicker).
      one_minus_phi: 1 - phi, > 0.
    Returns:
      (MAX_LAGS,) float64, dimensionless (variance per unit driving variance).
    """
    if not 0.0 < d < 1.0:
        raise ValueError(f"d = {d!r} must lie in (0, 1) (spectral index kappa = -2 d in (-2, 0))")
    if not 0.0 < one_minus_phi < 1.0:
        raise ValueError(f"1 - phi = {one_minus_phi!r} must lie in (0, 1)")
    phi = 1.0 - one_minus_phi
    m = int(min(1 << 23, 25.0 / one_minus_phi + MAX_LAGS))
    j = np.arange(1, m, dtype=np.float64)
    g = np.concatenate([[1.0], np.cumprod((j - 1.0 + d) / j * phi)])
    size = 1 << int(np.ceil(np.log2(m + MAX_LAGS)))
    f = np.fft.rfft(g, size)
    return np.fft.irfft(f * np.conj(f), size)[:MAX_LAGS].copy()


def _nnls(A, b, max_iter: int = 500):
    """Non-negative least squares min |A x - b|, x >= 0 (Lawson & Hanson 1974, ch. 23 active set)."""
    n = A.shape[1]
    passive = np.zeros(n, bool)
    x = np.zeros(n)
    w = A.T @ (b - A @ x)
    for _ in range(max_iter):
        if passive.all() or np.max(np.where(passive, -np.inf, w)) <= 1e-12 * np.max(np.abs(w)):
            break
        passive[int(np.argmax(np.where(passive, -np.inf, w)))] = True
        while True:
            z = np.zeros(n)
            z[passive] = np.linalg.lstsq(A[:, passive], b, rcond=None)[0]
            if np.all(z[passive] > 0):
                x = z
                break
            neg = passive & (z <= 0)
            alpha = np.min(x[neg] / (x[neg] - z[neg]))
            x = x + alpha * (z - x)
            passive &= x > 1e-15
            x[~passive] = 0.0
        w = A.T @ (b - A @ x)
    return x


@functools.lru_cache(maxsize=256)
def _fit(d: float, n: int, per_decade: float, one_minus_phi: float):
    gamma = ggm_autocovariance(d, one_minus_phi)[:n]
    tau_max = 10.0 * n
    taus = np.geomspace(0.2, tau_max, int(np.log10(tau_max / 0.2) * per_decade) + 1)
    r = np.exp(-1.0 / taus)
    lags = np.unique(np.concatenate([np.arange(min(n, 20)), np.geomspace(1, n - 1, 300).astype(int)]))
    A = r[None, :] ** lags[:, None] / gamma[lags][:, None]
    w = _nnls(A, np.ones(lags.size))
    keep = w > 0
    r, w = r[keep], w[keep]
    k = np.arange(n)
    approx = (r[None, :] ** k[:, None]) @ w
    return r, w, float(np.max(np.abs(approx / gamma - 1.0)))


def gauss_markov_sum(
    d: float, n: int, *, per_decade: float = 1.5, one_minus_phi: float = GGM_ONE_MINUS_PHI
) -> GaussMarkovSum:
    """Approximate the GGM power-law autocovariance over ``n`` daily lags by a sum of AR(1) processes.

    Args:
      d: fractional difference parameter, 0 < d < 1 (-kappa / 2; 0.5 is flicker noise).
      n: series length, days (2 .. MAX_LAGS).
      per_decade: time constants per decade (1.5: ~0.2 % error; 1: ~1.5 %; 2: ~0.02 %).
      one_minus_phi: 1 - phi of the GGM (Hector's ``GGM_1mphi``).
    Returns:
      :class:`GaussMarkovSum` (the processes with zero weight are dropped).
    Raises:
      ValueError: d outside (0, 1), n outside [2, MAX_LAGS].
    """
    if not 2 <= int(n) <= MAX_LAGS:
        raise ValueError(f"series length n = {n} days must lie in [2, {MAX_LAGS}]")
    r, w, err = _fit(round(float(d), 12), int(n), float(per_decade), float(one_minus_phi))
    return GaussMarkovSum(r=r.copy(), w=w.copy(), d=float(d), n=int(n), max_rel_error=err)


def gauss_markov_table(d_grid, n: int, *, per_decade: float = 1.5, one_minus_phi: float = GGM_ONE_MINUS_PHI):
    """One set of time constants with weights for each d of ``d_grid`` (for an estimated spectral index).

    The time constants are shared (those of the finest fit), the weights of each d are refitted
    by NNLS on that common set, so the covariance is linear in the weights and a weight vector
    interpolated linearly in d is again a valid (non-negative) covariance.

    Returns:
      (r (K,), W (len(d_grid), K), max relative error over the grid).
    """
    tau_max = 10.0 * n
    taus = np.geomspace(0.2, tau_max, int(np.log10(tau_max / 0.2) * per_decade) + 1)
    r = np.exp(-1.0 / taus)
    lags = np.unique(np.concatenate([np.arange(min(n, 20)), np.geomspace(1, n - 1, 300).astype(int)]))
    k = np.arange(n)
    W, err = [], 0.0
    for d in np.asarray(d_grid, float):
        gamma = ggm_autocovariance(round(float(d), 12), one_minus_phi)[:n]
        w = _nnls(r[None, :] ** lags[:, None] / gamma[lags][:, None], np.ones(lags.size))
        W.append(w)
        err = max(err, float(np.max(np.abs((r[None, :] ** k[:, None]) @ w / gamma - 1.0))))
    return r, np.asarray(W), err
