"""Local ENU metres <-> small geodetic differences (jaxnav.geodesy.curvilinear_to_enu and its inverse).

Outside reference: pymap3d's exact geodetic2enu for offsets of a few metres (the first-order
formula agrees to |d|^2 / R); then the exact inverse, broadcasting, and jit / vmap / grad.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pymap3d as pm
import pytest

from jaxnav.geodesy import GRS80, KRASSOVSKY, WGS84, curvilinear_to_enu, enu_to_curvilinear


@pytest.mark.parametrize("ell, pm_name", [(WGS84, "wgs84"), (KRASSOVSKY, "krassovsky1940")])
def test_matches_pymap3d_for_small_offsets(ell, pm_name):
    rng = np.random.default_rng(3)
    pos = np.stack([rng.uniform(-1.3, 1.3, 200), rng.uniform(-3.0, 3.0, 200), rng.uniform(-100, 3000, 200)], -1)
    d_enu = rng.normal(0.0, 5.0, (200, 3))  # m
    dpos = np.asarray(enu_to_curvilinear(pos, d_enu, ell))
    q = pos + dpos
    e, n, u = pm.geodetic2enu(
        q[:, 0], q[:, 1], q[:, 2], pos[:, 0], pos[:, 1], pos[:, 2], ell=pm.Ellipsoid.from_name(pm_name), deg=False
    )
    exact = np.stack([e, n, u], -1)
    # second-order terms: |d|^2 / R (~4e-6 m for 5 m offsets; tan(lat) up to 3.6 at 1.3 rad)
    assert np.max(np.abs(exact - d_enu)) < 5e-5
    assert np.max(np.abs(np.asarray(curvilinear_to_enu(pos, dpos, ell)) - d_enu)) < 1e-9


def test_formula_and_inverse():
    pos = np.array([0.57, 2.04, 35.0])
    dpos = np.array([1e-7, -2e-7, 0.3])
    RM = WGS84.a * (1 - WGS84.e2) / (1 - WGS84.e2 * np.sin(pos[0]) ** 2) ** 1.5
    RN = WGS84.a / np.sqrt(1 - WGS84.e2 * np.sin(pos[0]) ** 2)
    want = [dpos[1] * (RN + pos[2]) * np.cos(pos[0]), dpos[0] * (RM + pos[2]), dpos[2]]
    np.testing.assert_allclose(curvilinear_to_enu(pos, dpos), want, rtol=1e-14)
    np.testing.assert_allclose(enu_to_curvilinear(pos, curvilinear_to_enu(pos, dpos, GRS80), GRS80), dpos, rtol=1e-14)


def test_broadcast_jit_vmap_grad():
    rng = np.random.default_rng(0)
    pos = np.stack([rng.uniform(0.1, 1.0, 6), rng.uniform(0, 2, 6), rng.uniform(0, 100, 6)], -1)
    d = rng.normal(0, 1, (4, 6, 3))
    out = curvilinear_to_enu(pos, d * 1e-6)  # (6, 3) against (4, 6, 3)
    assert out.shape == (4, 6, 3)
    assert enu_to_curvilinear(pos[0], d).shape == (4, 6, 3)
    loop = np.stack([np.asarray(enu_to_curvilinear(pos[i], d[0, i])) for i in range(6)])
    np.testing.assert_allclose(jax.jit(jax.vmap(enu_to_curvilinear))(pos, d[0]), loop, rtol=1e-14)
    # d dE / d h = dlon cos(lat), d dN / d h = dlat
    g = jax.jacfwd(lambda p: curvilinear_to_enu(p, jnp.array([1e-6, 2e-6, 0.0])))(jnp.asarray(pos[0]))
    np.testing.assert_allclose(g[:, 2], [2e-6 * np.cos(pos[0, 0]), 1e-6, 0.0], rtol=1e-12)
