"""S3 step 1: AR(p) identification (Yule-Walker, least squares, AIC/BIC) and the AR Kalman filter."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg

from jaxnav.survey import (
    ar_kalman,
    ar_state_space,
    autocovariance,
    fit_ar,
    select_ar_order,
    simulate_ar,
    white_noise_variance,
)
from jaxnav.survey._ar import ar_stationary_cov

PHI2 = jnp.array([0.6, -0.3])


@pytest.fixture(scope="module")
def ar2():
    return np.asarray(simulate_ar(jax.random.PRNGKey(7), PHI2, 1.0, 20000))


def test_autocovariance_matches_direct_sum(ar2):
    x = ar2[:3000]
    d = x - x.mean()
    ref = np.array([np.dot(d[: len(d) - k], d[k:]) / len(d) for k in range(6)])
    np.testing.assert_allclose(np.asarray(autocovariance(jnp.asarray(x), 5)), ref, rtol=1e-10, atol=1e-12)


def test_yule_walker_equals_scipy_toeplitz_solve(ar2):
    g = np.asarray(autocovariance(jnp.asarray(ar2), 4))
    for p in (2, 4):
        ref = scipy.linalg.solve_toeplitz(g[:p], g[1 : p + 1])
        f = fit_ar(jnp.asarray(ar2), p, "yule_walker")
        np.testing.assert_allclose(np.asarray(f.phi), ref, rtol=1e-10)
        np.testing.assert_allclose(float(f.sigma2), g[0] - ref @ g[1 : p + 1], rtol=1e-10)


def test_least_squares_equals_numpy_lstsq(ar2):
    x = ar2[:5000]
    d = x - x.mean()
    p = 3
    X = np.stack([d[p - i - 1 : len(d) - i - 1] for i in range(p)], 1)
    ref, *_ = np.linalg.lstsq(X, d[p:], rcond=None)
    f = fit_ar(jnp.asarray(x), p, "ls")
    np.testing.assert_allclose(np.asarray(f.phi), ref, rtol=1e-9)
    rss = np.sum((d[p:] - X @ ref) ** 2)
    cov = rss / (len(d) - 2 * p) * np.linalg.inv(X.T @ X)
    np.testing.assert_allclose(np.asarray(f.se), np.sqrt(np.diag(cov)), rtol=1e-8)


@pytest.mark.parametrize("method", ["yule_walker", "ls"])
def test_ar2_recovered_within_standard_errors(ar2, method):
    f = fit_ar(jnp.asarray(ar2), 2, method)
    z = np.abs(np.asarray(f.phi - PHI2) / np.asarray(f.se))
    assert np.all(z < 2.0), (np.asarray(f.phi), np.asarray(f.se))
    assert abs(float(f.sigma2) - 1.0) < 0.05


def test_standard_errors_are_calibrated():
    """Over 300 independent AR(2) series the true phi lies within 1 SE ~68 % and 2 SE ~95 % of the time."""
    keys = jax.random.split(jax.random.PRNGKey(3), 300)
    fits = jax.jit(jax.vmap(lambda k: fit_ar(simulate_ar(k, PHI2, 1.0, 2000), 2, "yule_walker")))(keys)
    z = np.abs(np.asarray(fits.phi - PHI2) / np.asarray(fits.se))
    # binomial 99.9 % bands for 600 coefficient draws (pairs are correlated: widened by sqrt(2))
    s1 = 3.3 * np.sqrt(0.6827 * 0.3173 / 300)
    s2 = 3.3 * np.sqrt(0.9545 * 0.0455 / 300)
    assert abs((z < 1).mean() - 0.6827) < s1
    assert abs((z < 2).mean() - 0.9545) < s2


def test_information_criteria_select_order_two(ar2):
    sel = select_ar_order(jnp.asarray(ar2), 6, criterion="bic")
    assert sel.order == 2
    assert select_ar_order(jnp.asarray(ar2), 6, criterion="aic").order >= 2  # same compiled criteria
    assert np.all(np.diff(sel.bic[1:]) > 0)  # orders above 2 only add the log(n) penalty
    x1 = simulate_ar(jax.random.PRNGKey(1), jnp.array([0.9]), 1.0, 20000)
    assert select_ar_order(x1, 6).order == 1


def test_state_space_stationary_covariance_closed_form():
    P = ar_stationary_cov(jnp.array([0.8]), 0.36)
    np.testing.assert_allclose(float(P[0, 0]), 0.36 / (1 - 0.64), rtol=1e-12)
    m = ar_state_space(PHI2, 1.0, 0.1)
    P2 = ar_stationary_cov(PHI2, 1.0)
    np.testing.assert_allclose(np.asarray(m.F @ P2 @ m.F.T + m.Q), np.asarray(P2), atol=1e-12)
    # AR(2) variance: (1 - phi2) / ((1 + phi2) ((1 - phi2)^2 - phi1^2))
    p1, p2 = 0.6, -0.3
    np.testing.assert_allclose(float(P2[0, 0]), (1 - p2) / ((1 + p2) * ((1 - p2) ** 2 - p1**2)), rtol=1e-12)


def test_ar_kalman_separates_correlated_error_from_white_noise():
    """y = x + v with x AR(1): the filter/smoother estimate of x is closer to x than y is."""
    k1, k2 = jax.random.split(jax.random.PRNGKey(11))
    x = simulate_ar(k1, jnp.array([0.98]), 0.2, 20000)
    v = 1.0 * jax.random.normal(k2, x.shape)
    y = x + v
    R = white_noise_variance(y)
    assert abs(float(R) - 1.0) < 0.1
    fit = fit_ar(y, 1)
    kf = ar_kalman(y, fit.phi, fit.sigma2, R)
    raw = float(jnp.var(y - x))
    est = float(jnp.var(kf.error - x))
    assert est < 0.5 * raw
    # the exact model (true phi, q, R) does better still, and the filter alone is worse than the smoother
    exact = ar_kalman(y, jnp.array([0.98]), 0.04, 1.0)
    filt = ar_kalman(y, jnp.array([0.98]), 0.04, 1.0, smooth=False)
    assert float(jnp.var(exact.error - x)) <= est
    assert float(jnp.var(exact.error - x)) < float(jnp.var(filt.error - x))
    np.testing.assert_allclose(np.asarray(kf.noise + kf.error), np.asarray(y), atol=1e-12)


def test_bad_input():
    with pytest.raises(ValueError, match="1-D"):
        fit_ar(jnp.zeros((10, 2)), 1)
    with pytest.raises(ValueError, match="N > 2p"):
        fit_ar(jnp.zeros(4), 2)
    with pytest.raises(ValueError, match="method"):
        fit_ar(jnp.ones(50), 1, "burg")
    with pytest.raises(ValueError, match="criterion"):
        select_ar_order(jnp.ones(50), 2, criterion="hqc")
