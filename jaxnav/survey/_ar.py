"""AR(p) error-model identification and the Kalman filter on it (S3 step 1: "model-structure
selection, model parameter estimation, error model", "a Kalman filter on that error model").

The sensor-error series x_k (a static IMU record, mean removed) is modelled as

    x_k = phi_1 x_{k-1} + ... + phi_p x_{k-p} + w_k,    w_k ~ N(0, sigma_w^2),

identified by Yule-Walker (biased autocovariances, Cholesky solve of the Toeplitz system) or
conditional least squares, with the order chosen by AIC or BIC. The state-space form (companion
matrix) then runs through :func:`jaxnav.filters.kalman_filter` (and optionally
:func:`jaxnav.filters.rts_smoother`) with the measurement y_k = x_k + v_k, v_k white with
variance R: the filter separates the correlated error process from the white noise.
"""

from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxnav._numerics import cho_solve, cholesky
from jaxnav.filters import LinearGaussian, kalman_filter, rts_smoother


class ARFit(NamedTuple):
    """An identified AR(p) model.

    Attributes:
      phi: (p,) coefficients phi_1..phi_p.
      sigma2: () driving-noise variance sigma_w^2 (unit^2 of the series).
      se: (p,) standard errors of phi (asymptotic for Yule-Walker, OLS for least squares).
      cov: (p, p) covariance of phi.
      mean: () the sample mean that was removed.
      aic, bic: () information criteria n_eff log(sigma2) + 2p / + p log(n_eff).
      n_eff: () number of equations (N - p for least squares, N for Yule-Walker).
    """

    phi: jax.Array
    sigma2: jax.Array
    se: jax.Array
    cov: jax.Array
    mean: jax.Array
    aic: jax.Array
    bic: jax.Array
    n_eff: jax.Array


def autocovariance(x, max_lag: int):
    """Biased sample autocovariance gamma(0..max_lag) = 1/N sum (x_t - m)(x_{t+k} - m).

    Args:
      x: (N,) series.  max_lag: static int < N.
    Returns:
      (max_lag + 1,) autocovariances.
    """
    x = jnp.asarray(x)
    if x.ndim != 1 or x.shape[0] <= max_lag:
        raise ValueError(f"autocovariance needs a 1-D series longer than max_lag={max_lag}, got shape {x.shape}")
    N = x.shape[0]
    d = x - jnp.mean(x)
    # FFT with zero padding: O(N log N), exact up to rounding
    nfft = int(2 ** np.ceil(np.log2(2 * N)))
    f = jnp.fft.rfft(d, nfft)
    ac = jnp.fft.irfft(f * jnp.conj(f), nfft)[: max_lag + 1]
    return ac / N


def _toeplitz(g, p):
    i = np.arange(p)
    return g[np.abs(i[:, None] - i[None, :])]


@partial(jax.jit, static_argnames=("p", "method"))
def fit_ar(x, p: int, method: str = "yule_walker") -> ARFit:
    """Identify an AR(p) model of a series (S3 step 1, model parameter estimation).

    Yule-Walker: Gamma_p phi = gamma_{1..p} with the biased autocovariances, sigma_w^2 =
    gamma_0 - phi . gamma_{1..p}, Cov(phi) = sigma_w^2 Gamma_p^{-1} / N (asymptotic).
    Least squares: regress x_t on (x_{t-1}, ..., x_{t-p}), t = p..N-1 (mean removed),
    sigma_w^2 = RSS / (N - 2p), Cov(phi) = sigma_w^2 (X^T X)^{-1}.
    Both criteria use the maximum-likelihood variance RSS / n_eff (Yule-Walker: sigma_w^2).

    Args:
      x: (N,) series (unit u).  p: static order >= 1.  method: "yule_walker" or "ls".
    Returns:
      :class:`ARFit`.
    Raises:
      ValueError: for a non-1-D series, p < 1, N <= 2p, or an unknown method.
    """
    x = jnp.asarray(x)
    if x.ndim != 1:
        raise ValueError(f"fit_ar needs a 1-D series, got shape {x.shape}")
    N = x.shape[0]
    if p < 1 or N <= 2 * p:
        raise ValueError(f"fit_ar needs p >= 1 and N > 2p, got p={p}, N={N}")
    m = jnp.mean(x)
    if method == "yule_walker":
        g = autocovariance(x, p)
        G = _toeplitz(g, p)
        L = cholesky(G)
        phi = cho_solve(L, g[1:, None])[:, 0]
        s2 = g[0] - phi @ g[1:]
        cov = s2 * cho_solve(L, jnp.eye(p, dtype=x.dtype)) / N
        n_eff = jnp.asarray(N, x.dtype)
        s2_ml = s2
    elif method == "ls":
        d = x - m
        X = jnp.stack([d[p - i - 1 : N - i - 1] for i in range(p)], axis=1)  # (N-p, p): lags 1..p
        y = d[p:]
        A = X.T @ X
        L = cholesky(A)
        phi = cho_solve(L, (X.T @ y)[:, None])[:, 0]
        r = y - X @ phi
        rss = r @ r
        s2 = rss / (N - 2 * p)
        cov = s2 * cho_solve(L, jnp.eye(p, dtype=x.dtype))
        n_eff = jnp.asarray(N - p, x.dtype)
        s2_ml = rss / n_eff
    else:
        raise ValueError(f"method must be 'yule_walker' or 'ls', got {method!r}")
    se = jnp.sqrt(jnp.diagonal(cov))
    aic = n_eff * jnp.log(s2_ml) + 2.0 * p
    bic = n_eff * jnp.log(s2_ml) + p * jnp.log(n_eff)
    return ARFit(phi=phi, sigma2=s2, se=se, cov=cov, mean=m, aic=aic, bic=bic, n_eff=n_eff)


class OrderSelection(NamedTuple):
    """Result of :func:`select_ar_order`.

    Attributes:
      order: the selected p.  fit: its :class:`ARFit`.  orders: (P,) candidate orders.
      aic, bic: (P,) criteria per order.  criterion: "aic" or "bic".
    """

    order: int
    fit: ARFit
    orders: jax.Array
    aic: jax.Array
    bic: jax.Array
    criterion: str


def select_ar_order(x, max_order: int = 6, *, criterion: str = "bic", method: str = "yule_walker") -> OrderSelection:
    """Choose the AR order by an information criterion (S3 step 1, model-structure selection).

    Every order 1..max_order is fitted on the same series (a host loop over orders: each has its
    own static shape) and the smallest AIC or BIC wins. For least squares the criteria are
    compared on a common sample (the first ``max_order`` points dropped) so they are comparable.

    Args:
      x: (N,) series.  max_order: largest order tried.  criterion: "aic" or "bic".
      method: "yule_walker" or "ls".
    Returns:
      :class:`OrderSelection`.
    """
    if criterion not in ("aic", "bic"):
        raise ValueError(f"criterion must be 'aic' or 'bic', got {criterion!r}")
    x = jnp.asarray(x)
    aic, bic = (np.asarray(a) for a in _criteria(x, max_order, method))
    k = int(np.argmin(aic if criterion == "aic" else bic))
    best = fit_ar(x, k + 1, method)
    return OrderSelection(
        order=k + 1, fit=best, orders=np.arange(1, max_order + 1), aic=aic, bic=bic, criterion=criterion
    )


@partial(jax.jit, static_argnames=("max_order", "method"))
def _criteria(x, max_order, method):
    """AIC and BIC of every order 1..max_order in one compiled call (orders unrolled)."""
    if method == "ls":
        # a common estimation sample (the first max_order points dropped) keeps the likelihoods comparable
        fits = [fit_ar.__wrapped__(x[max_order - p :], p, "ls") for p in range(1, max_order + 1)]
    elif method == "yule_walker":
        fits = [fit_ar.__wrapped__(x, p, method) for p in range(1, max_order + 1)]
    else:
        raise ValueError(f"method must be 'yule_walker' or 'ls', got {method!r}")
    return jnp.stack([f.aic for f in fits]), jnp.stack([f.bic for f in fits])


def simulate_ar(key, phi, sigma, n: int, *, burn: int = 500):
    """Draw n samples of a stationary AR(p) process (burn-in discarded) with ``lax.scan``.

    Args:
      key: PRNG key.  phi: (p,) coefficients.  sigma: driving-noise std.  n, burn: static lengths.
    Returns:
      (n,) series.
    """
    phi = jnp.asarray(phi, jnp.result_type(float))
    p = phi.shape[0]
    w = sigma * jax.random.normal(key, (n + burn,), phi.dtype)

    def step(state, wk):
        x = phi @ state + wk
        return jnp.concatenate([x[None], state[:-1]]), x

    _, xs = jax.lax.scan(step, jnp.zeros(p, phi.dtype), w)
    return xs[burn:]


def ar_state_space(phi, sigma2, R) -> LinearGaussian:
    """Companion-form state space of AR(p) plus white measurement noise.

    X_k = [x_k, ..., x_{k-p+1}],  X_k = F X_{k-1} + e_1 w_k,  y_k = e_1^T X_k + v_k,
    F = [[phi_1 ... phi_p], [I_{p-1} 0]], Q = sigma_w^2 e_1 e_1^T, R = [[R]].
    """
    phi = jnp.asarray(phi)
    p = phi.shape[0]
    dtype = phi.dtype
    F = jnp.zeros((p, p), dtype).at[0].set(phi)
    if p > 1:
        F = F.at[1:, :-1].set(jnp.eye(p - 1, dtype=dtype))
    H = jnp.zeros((1, p), dtype).at[0, 0].set(1.0)
    Q = jnp.zeros((p, p), dtype).at[0, 0].set(sigma2)
    return LinearGaussian(F=F, H=H, Q=Q, R=jnp.reshape(jnp.asarray(R, dtype), (1, 1)))


@jax.jit
def ar_stationary_cov(phi, sigma2):
    """Stationary covariance of the companion state: solves P = F P F^T + Q (vectorised, p^2 x p^2)."""
    m = ar_state_space(phi, sigma2, 1.0)
    p = m.F.shape[0]
    A = jnp.eye(p * p, dtype=m.F.dtype) - jnp.kron(m.F, m.F)
    P = jnp.linalg.solve(A, m.Q.reshape(-1)).reshape(p, p)
    return 0.5 * (P + P.T)


class ARKalmanResult(NamedTuple):
    """Output of :func:`ar_kalman`.

    Attributes:
      error: (N,) estimated correlated error process x_k (mean added back).
      noise: (N,) the removed white part y_k - error_k.
      variance: (N,) posterior variance of x_k.
    """

    error: jax.Array
    noise: jax.Array
    variance: jax.Array


def white_noise_variance(y):
    """Robust white-noise variance from first differences: (1.4826 MAD(diff y))^2 / 2.

    Var(v_k - v_{k-1}) = 2 R for white v; a slowly varying correlated part adds little at a high
    sampling rate. The median absolute deviation keeps wild values out.
    """
    d = jnp.diff(jnp.asarray(y))
    mad = jnp.median(jnp.abs(d - jnp.median(d)))
    return (1.4826 * mad) ** 2 / 2.0


@partial(jax.jit, static_argnames=("smooth",))
def ar_kalman(y, phi, sigma2, R, *, smooth: bool = True) -> ARKalmanResult:
    """Kalman filter (and RTS smoother) on an identified AR(p) error model (S3 step 1).

    y_k - mean = x_k + v_k with x_k the AR(p) process of :func:`ar_state_space`; the filter
    starts from the stationary covariance. Post-processing is allowed (S3), so by default the
    fixed-interval smoother output is returned.

    Args:
      y: (N,) series (unit u).  phi: (p,) AR coefficients.  sigma2: driving-noise variance, u^2.
      R: white measurement-noise variance, u^2 (e.g. :func:`white_noise_variance`).
      smooth: static; RTS-smooth the filter output.
    Returns:
      :class:`ARKalmanResult`.
    """
    y = jnp.asarray(y)
    m = jnp.mean(y)
    model = ar_state_space(phi, sigma2, R)
    p = model.F.shape[0]
    P0 = ar_stationary_cov(phi, sigma2)
    res = kalman_filter(
        model, jnp.zeros(p, y.dtype), P0, (y - m)[:, None], save=("means", "covs", "pred_means", "pred_covs")
    )
    if smooth:
        sm = rts_smoother(model, res)
        x, P = sm.means, sm.covs
    else:
        x, P = res.means, res.covs
    err = x[:, 0] + m
    return ARKalmanResult(error=err, noise=y - err, variance=P[:, 0, 0])


def autocovariance_masked(x, mask, max_lag: int):
    """Biased sample autocovariance of a regularly sampled series with gaps.

    gamma(k) = 1/n sum_t m_t m_{t+k} (x_t - xbar)(x_{t+k} - xbar), xbar and n = sum m_t over the
    valid samples (m_t = 1) only: the estimator of :func:`autocovariance` with missing samples
    left out of every product (Box, Jenkins & Reinsel, Time Series Analysis, sec. 2.1.4, with the
    usual treatment of missing values). Computed by FFT with zero padding.

    Args:
      x: (N,) series on a regular grid (values at masked samples are ignored).
      mask: (N,) bool, True where a sample exists.  max_lag: static int < N.
    Returns:
      (max_lag + 1,) autocovariances, unit^2 of x.
    """
    x = jnp.asarray(x)
    mask = jnp.asarray(mask, bool)
    if x.ndim != 1 or x.shape != mask.shape or x.shape[0] <= max_lag:
        raise ValueError(
            f"autocovariance_masked needs a 1-D series and mask of one shape, longer than "
            f"max_lag={max_lag}; got {x.shape} and {mask.shape}"
        )
    N = x.shape[0]
    m = mask.astype(x.dtype)
    n = jnp.maximum(jnp.sum(m), 1.0)
    d = jnp.where(mask, x - jnp.sum(jnp.where(mask, x, 0.0)) / n, 0.0)
    nfft = int(2 ** np.ceil(np.log2(2 * N)))
    f = jnp.fft.rfft(d, nfft)
    return jnp.fft.irfft(f * jnp.conj(f), nfft)[: max_lag + 1] / n


def mean_variance_from_acov(gamma, lag_index, weights):
    """Variance of a weighted mean of correlated samples from their autocovariance function.

    Var(sum_i w_i x_i) = sum_i sum_j w_i w_j gamma(|k_i - k_j|) for samples at grid indices k_i
    of a stationary series (the effective-sample-size correction of the mean: with equal weights
    1/n it is gamma(0)/n [1 + 2 sum_{k>=1} (1 - k/n) rho_k] for n consecutive samples;
    e.g. Bayley & Hammersley 1946, von Storch & Zwiers, Statistical Analysis in Climate Research,
    sec. 6.6). Lags beyond the end of ``gamma`` count as uncorrelated (gamma = 0).

    Args:
      gamma: (L + 1,) autocovariances for lags 0..L (unit^2).
      lag_index: (n,) int grid indices of the samples.  weights: (n,) weights (0 for absent samples).
    Returns:
      () variance, unit^2.
    """
    gamma = jnp.asarray(gamma)
    k = jnp.asarray(lag_index)
    lag = jnp.abs(k[:, None] - k[None, :])
    L = gamma.shape[0]
    G = jnp.where(lag < L, gamma[jnp.minimum(lag, L - 1)], 0.0)
    w = jnp.asarray(weights, gamma.dtype)
    return w @ G @ w
