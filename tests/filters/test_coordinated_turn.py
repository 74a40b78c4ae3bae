"""The coordinated-turn model of jaxnav.filters: its transition, noise and measurement, and the EKF on a
simulated circle."""

import jax.numpy as jnp
import numpy as np
import pytest

from jaxnav import filters as jf


def test_transition_noise_and_cached_functions():
    m = jf.coordinated_turn(2.0, np.eye(2), accel_std=0.5, turn_std=0.1, pos_std=0.2)
    x = jnp.array([1.0, 2.0, 3.0, np.pi / 2, 0.1])
    np.testing.assert_allclose(m.f(x, 0), [1.0, 8.0, 3.0, np.pi / 2 + 0.2, 0.1], atol=1e-12)
    np.testing.assert_allclose(m.h(x, 0), [1.0, 2.0])
    np.testing.assert_allclose(jnp.diag(m.Q), [0.04, 0.04, 1.0, 0.04, 0.04], rtol=1e-12)
    assert jf.coordinated_turn(2.0, np.eye(2)).f is m.f  # same functions per step: jit caches hold
    with pytest.raises(ValueError, match=r"R has shape \(3, 3\)"):
        jf.coordinated_turn(1.0, np.eye(3))


def test_ekf_follows_a_circle():
    T, v, om = 120, 5.0, 0.05
    th = om * np.arange(T)
    truth = np.stack([v / om * np.sin(th), v / om * (1 - np.cos(th))], -1)
    zs = truth + np.random.default_rng(0).normal(0.0, 0.3, truth.shape)
    m = jf.coordinated_turn(1.0, 0.09 * np.eye(2), accel_std=0.1, turn_std=0.01, pos_std=0.05)
    r = jf.extended_kalman_filter(
        m, jnp.array([0.0, 0.0, v, 0.0, 0.0]), jnp.diag(jnp.array([1.0, 1.0, 1.0, 0.1, 0.01])), jnp.asarray(zs)
    )
    assert abs(float(r.means[-1, 4]) - om) < 0.02
    rms = lambda p: np.sqrt(np.mean(np.sum((p[20:, :2] - truth[20:]) ** 2, -1)))
    assert rms(np.asarray(r.means)) < 0.85 * rms(zs)  # better than the fixes it filters
