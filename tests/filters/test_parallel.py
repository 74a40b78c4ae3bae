"""Parallel-in-time filter and smoother (associative scan) = the sequential ones.

Reduction identity of the design's test pyramid (level 3): ``parallel_filter`` /
``parallel_smoother`` against ``kalman_filter`` / ``rts_smoother`` on the same data, to 1e-9,
including NaN and user masks, time-varying models with a noise input matrix, both scan
schedules, and gradients. Every test runs under a timeout: associative scans with LAPACK
solves inside hung on this machine (DESIGN.md), so a hang must fail fast.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxnav import filters as jf
from jaxnav._numerics import solve_small
from jaxnav.filters._parallel import parallel_filter, parallel_smoother

pytestmark = pytest.mark.timeout(120)

T_LONG = 2000
FIELDS = (
    "means",
    "covs",
    "pred_means",
    "pred_covs",
    "innovations",
    "innov_covs",
    "nis",
    "logliks",
    "valid",
    "loglik",
    "n_nonfinite",
    "n_skipped",
    "status",
    "x_final",
    "P_final",
)


def _random_model(rng, n, m, T=None, p=None):
    """A random stable linear Gaussian model with PD noises (time-varying when T is given)."""

    def spd(k, scale):
        B = rng.standard_normal((k, k))
        return scale * (B @ B.T / k + 0.2 * np.eye(k))

    def trans():
        Q, _ = np.linalg.qr(rng.standard_normal((n, n)))
        return 0.97 * Q + 0.05 * rng.standard_normal((n, n))

    if T is None:
        F, H, R = trans(), rng.standard_normal((m, n)), spd(m, 0.5)
        Q = spd(n if p is None else p, 0.1)
        G = None if p is None else rng.standard_normal((n, p))
    else:
        F = np.stack([trans() for _ in range(T)])
        H = rng.standard_normal((T, m, n))
        R = np.stack([spd(m, 0.5) for _ in range(T)])
        Q = spd(n if p is None else p, 0.1)
        G = None if p is None else rng.standard_normal((T, n, p))
    return jf.LinearGaussian(
        F=jnp.asarray(F), H=jnp.asarray(H), Q=jnp.asarray(Q), R=jnp.asarray(R), G=None if G is None else jnp.asarray(G)
    )


def _simulate(rng, model, x0, T):
    n = x0.shape[0]
    F = np.broadcast_to(np.asarray(model.F), (T, n, n))
    m = np.asarray(model.H).shape[-2]
    H = np.broadcast_to(np.asarray(model.H), (T, m, n))
    x, zs = np.asarray(x0), []
    for t in range(T):
        x = F[t] @ x + 0.1 * rng.standard_normal(n)
        zs.append(H[t] @ x + 0.5 * rng.standard_normal(m))
    return jnp.asarray(np.array(zs))


def _assert_equal(seq, par, atol=1e-9, rtol=1e-9):
    for name in FIELDS:
        a, b = getattr(seq, name), getattr(par, name)
        np.testing.assert_allclose(np.asarray(b, float), np.asarray(a, float), rtol=rtol, atol=atol, err_msg=name)


@pytest.fixture(scope="module")
def cv_long():
    """The benchmark's constant-velocity problem, T = 2000, with NaN epochs and a user mask."""
    rng = np.random.default_rng(7)
    model = jf.constant_velocity(1.0, sigma=0.003, q=1e-6)
    x0 = jnp.zeros(6)
    P0 = jnp.diag(jnp.array([1.0] * 3 + [0.01] * 3))
    zs = _simulate(rng, model, x0, T_LONG) * 0.01
    zs = zs.at[17, 1].set(jnp.nan).at[400].set(jnp.inf).at[401:405].set(jnp.nan)
    mask = jnp.ones((T_LONG, 3), bool).at[900, 0].set(False).at[1500:1510].set(False)
    seq = jf.kalman_filter(model, x0, P0, zs, mask=mask)
    par = parallel_filter(model, x0, P0, zs, mask=mask)
    return model, x0, P0, zs, mask, seq, par


def test_filter_equals_sequential_long_with_nan_and_mask(cv_long):
    model, x0, P0, zs, mask, seq, par = cv_long
    _assert_equal(seq, par)
    assert int(par.n_nonfinite) == 1 + 3 + 12 and int(par.n_skipped) == 1 + 4 + 10
    assert int(par.status) == int(seq.status) != 0  # NONFINITE_MEASUREMENT, information only


def test_smoother_equals_rts_long(cv_long):
    model, x0, P0, zs, mask, seq, par = cv_long
    ref = jf.rts_smoother(model, seq)
    got = parallel_smoother(model, par)
    for name in ("means", "covs", "gains"):
        np.testing.assert_allclose(
            np.asarray(getattr(got, name)), np.asarray(getattr(ref, name)), rtol=1e-9, atol=1e-9, err_msg=name
        )
    assert int(got.status) == int(ref.status) == 0
    means_only = parallel_smoother(model, par, save=("means",))
    assert means_only.covs is None and means_only.gains is None
    np.testing.assert_allclose(np.asarray(means_only.means), np.asarray(ref.means), rtol=0, atol=1e-9)


def test_tree_schedule_equals_sequential():
    """The lax.associative_scan schedule (method="tree")."""
    rng = np.random.default_rng(1)
    model = _random_model(rng, 3, 2)
    x0, P0 = jnp.zeros(3), jnp.eye(3)
    zs = _simulate(rng, model, x0, 13)
    seq = jf.kalman_filter(model, x0, P0, zs)
    # (the blocked schedule's padding, T not a multiple of the chunk, is exercised by cv_long:
    # T = 2000, chunk 45)
    par = parallel_filter(model, x0, P0, zs, save=("means", "covs"), method="tree")
    np.testing.assert_allclose(np.asarray(par.means), np.asarray(seq.means), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(np.asarray(par.covs), np.asarray(seq.covs), rtol=1e-9, atol=1e-9)
    sm = parallel_smoother(model, seq, method="tree", save=("means",))
    np.testing.assert_allclose(
        np.asarray(sm.means), np.asarray(jf.rts_smoother(model, seq).means), rtol=1e-9, atol=1e-9
    )


@settings(max_examples=8, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**31 - 1), nan_rate=st.sampled_from([0.0, 0.1, 0.5]))
def test_random_time_varying_models_with_noise_input(seed, nan_rate):
    """Random time-varying (F, H, R, G) with p < n process-noise inputs and random NaNs."""
    rng = np.random.default_rng(seed)
    T, n, m, p = 60, 4, 2, 2
    model = _random_model(rng, n, m, T=T, p=p)
    x0 = jnp.asarray(rng.standard_normal(n))
    P0 = jnp.asarray(np.diag(rng.uniform(0.5, 2.0, n)))
    zs = np.array(_simulate(rng, model, x0, T))
    zs[rng.random((T, m)) < nan_rate] = np.nan
    zs = jnp.asarray(zs)
    seq = jf.kalman_filter(model, x0, P0, zs)
    par = parallel_filter(model, x0, P0, zs)
    _assert_equal(seq, par, atol=1e-9, rtol=1e-8)
    ref = jf.rts_smoother(model, seq)
    got = parallel_smoother(model, par)
    np.testing.assert_allclose(np.asarray(got.means), np.asarray(ref.means), rtol=1e-8, atol=1e-9)
    np.testing.assert_allclose(np.asarray(got.covs), np.asarray(ref.covs), rtol=1e-8, atol=1e-9)


def test_gradient_of_loglik_equals_sequential():
    """d loglik / d (R scale, Q scale) through the associative scan = through the sequential scan."""
    rng = np.random.default_rng(3)
    model = _random_model(rng, 2, 1)
    x0, P0 = jnp.zeros(2), jnp.eye(2)
    zs = _simulate(rng, model, x0, 50)

    def nll(theta, fn):
        mod = model._replace(R=model.R * jnp.exp(theta[0]), Q=model.Q * jnp.exp(theta[1]))
        return -fn(mod, x0, P0, zs, save=()).loglik

    th = jnp.array([0.1, -0.2])
    v1, g1 = jax.value_and_grad(nll)(th, jf.kalman_filter)
    v2, g2 = jax.value_and_grad(nll)(th, parallel_filter)
    np.testing.assert_allclose(float(v2), float(v1), rtol=1e-10)
    np.testing.assert_allclose(np.asarray(g2), np.asarray(g1), rtol=1e-7, atol=1e-9)


def test_solve_small_pivots():
    """Gauss-Jordan with partial pivoting on a matrix whose leading element is zero."""
    A = jnp.array([[0.0, 2.0, 1.0], [1.0, 1.0, 0.0], [3.0, 0.0, 1.0]])
    B = jnp.arange(6.0).reshape(3, 2)
    solve = jax.jit(solve_small)
    np.testing.assert_allclose(
        np.asarray(solve(A, B)), np.linalg.solve(np.asarray(A), np.asarray(B)), rtol=1e-13, atol=1e-13
    )
    rng = np.random.default_rng(0)
    As = rng.standard_normal((5, 6, 6))
    bs = rng.standard_normal((5, 6))
    np.testing.assert_allclose(
        np.asarray(solve(jnp.asarray(As), jnp.asarray(bs))),
        np.linalg.solve(As, bs[..., None])[..., 0],
        rtol=1e-10,
        atol=1e-10,
    )


def test_bad_shapes_raise():
    model = jf.constant_velocity(1.0, sigma=0.003, q=1e-6)
    with pytest.raises(ValueError, match="P0 has shape"):
        parallel_filter(model, jnp.zeros(6), jnp.eye(5), jnp.zeros((10, 3)))
    with pytest.raises(ValueError, match="method"):
        parallel_filter(model, jnp.zeros(6), jnp.eye(6), jnp.zeros((10, 3)), method="nope")
    seq = jf.KalmanResult(means=jnp.zeros((10, 6)), covs=jnp.zeros((10, 6, 6)))
    with pytest.raises(ValueError, match="pred_means"):
        parallel_smoother(model, seq)
