"""Height-anomaly surface fitting (plane / quadratic, chosen by the number of control points)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxnav import geodesy as g


def _controls(n, seed=0):
    rng = np.random.default_rng(seed)
    x = 3.6315e6 + rng.uniform(-2000, 2000, n)
    y = 39.486e6 + rng.uniform(-2000, 2000, n)  # zone-prefixed easting: conditioning must cope
    return jnp.asarray(x), jnp.asarray(y)


def _quadratic(x, y):
    dx, dy = x - 3.6315e6, y - 39.486e6
    return -3.45 + 1.8e-5 * dx - 2.6e-5 * dy + 2e-10 * dx * dx - 1e-10 * dx * dy + 1.5e-10 * dy * dy


def test_quadratic_surface_is_recovered_exactly():
    x, y = _controls(9)
    m = g.fit_height_anomaly(x, y, _quadratic(x, y))
    assert m.kind == "quadratic" and m.dof == 3
    assert float(jnp.max(jnp.abs(m.residuals))) < 1e-10
    xe, ye = _controls(50, seed=1)
    np.testing.assert_allclose(g.height_anomaly(m, xe, ye), _quadratic(xe, ye), atol=1e-9)
    H = 25.0 + _quadratic(xe, ye)
    np.testing.assert_allclose(g.normal_height(H, xe, ye, m), 25.0, atol=1e-9)


def test_auto_choice_by_number_of_control_points():
    assert g.choose_surface(3) == "plane" and g.choose_surface(6) == "plane"
    assert g.choose_surface(7) == "quadratic" and g.choose_surface(40) == "quadratic"
    x, y = _controls(5)
    m = g.fit_height_anomaly(x, y, _quadratic(x, y))
    assert m.kind == "plane" and m.coef.shape == (3,) and m.dof == 2
    # the plane cannot follow the curvature: non-zero residuals and sigma0 reported
    assert float(m.sigma0) > 0 and m.residuals.shape == (5,)


def test_plane_noise_precision_and_grad():
    rng = np.random.default_rng(3)
    x, y = _controls(12)
    zeta = -3.45 + 1.8e-5 * (x - 3.6315e6) + rng.normal(0, 0.004, 12)
    m = g.fit_height_anomaly(x, y, zeta, kind="plane")
    assert 0.002 < float(m.sigma0) < 0.007
    s = g.height_anomaly_std(m, x.mean(), y.mean())
    assert float(s) == pytest.approx(float(m.sigma0) / np.sqrt(12), rel=1e-6)  # centroid: sigma0 / sqrt(n)
    # differentiable with respect to the heights (e.g. for tuning): d zeta(centroid) / d zeta_i = 1 / n
    gr = jax.grad(lambda z: g.height_anomaly(g.fit_height_anomaly(x, y, z, kind="plane"), x.mean(), y.mean()))(zeta)
    np.testing.assert_allclose(gr, 1.0 / 12, atol=1e-12)


def test_too_few_control_points_is_a_clear_error():
    x, y = _controls(5)
    with pytest.raises(ValueError, match="quadratic height-anomaly surface has 6 parameters and needs at least 6"):
        g.fit_height_anomaly(x, y, _quadratic(x, y), kind="quadratic")
    with pytest.raises(ValueError, match="at least 3 control points"):
        g.fit_height_anomaly(x[:2], y[:2], _quadratic(x, y)[:2])
    with pytest.raises(ValueError, match="kind must be"):
        g.fit_height_anomaly(x, y, _quadratic(x, y), kind="cubic")
    with pytest.raises(ValueError, match=r"\(5,\), \(5,\), \(4,\)"):
        g.fit_height_anomaly(x, y, _quadratic(x, y)[:4])
