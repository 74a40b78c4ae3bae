"""Earth model (ENU): normal gravity against published values, Earth rate, transport rate, position rate.

Published constants: NIMA TR8350.2 (WGS-84, 3rd ed., tables 3.4 and 3.5) and Moritz (1980),
"Geodetic Reference System 1980" (GRS80). The transport rate and the position rate are
checked against the geometry of :mod:`jaxnav.geodesy` (the ENU frame's own rotation and the
derivative of geodetic -> ECEF), not against their own formulas.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxnav import geodesy as g
from jaxnav.ins import earth as E
from jaxnav.ins import earth_params, normal_gravity, position_rate

# (gamma_e, gamma_p, k = b gamma_p / (a gamma_e) - 1, m = omega^2 a^2 b / GM), as published
PUBLISHED = {
    "WGS-84": (9.7803253359, 9.8321849378, 0.00193185265241, 0.00344978650684),  # TR8350.2
    "GRS80": (9.7803267715, 9.8321863685, 0.001931851353, 0.00344978600308),  # Moritz 1980
}
ELLS = {"WGS-84": g.WGS84, "GRS80": g.GRS80}


@pytest.mark.parametrize("name", list(PUBLISHED))
def test_normal_gravity_equator_and_pole_published(name):
    ell, (ge, gp, _, _) = ELLS[name], PUBLISHED[name]
    assert abs(float(normal_gravity(0.0, 0.0, ell)) - ge) < 1e-9
    assert abs(float(normal_gravity(np.pi / 2, 0.0, ell)) - gp) < 1e-9
    assert abs(float(normal_gravity(-np.pi / 2, 0.0, ell)) - gp) < 1e-9
    ce, cp = ell.normal_gravity_constants()  # the closed forms themselves
    assert abs(ce - ge) < 1e-9 and abs(cp - gp) < 1e-9


def test_grs80_normal_gravity_at_45_deg_published():
    # Moritz (1980): gamma_45 = 9.806 199 203 m/s^2 (printed to 1e-9; its rounding is 5e-10)
    assert abs(float(normal_gravity(np.pi / 4, 0.0, g.GRS80)) - 9.806199203) < 1e-9


@pytest.mark.parametrize("name", list(PUBLISHED))
def test_somigliana_with_published_k(name):
    """gamma_0 = gamma_e (1 + k sin^2) / sqrt(1 - e^2 sin^2) with the published gamma_e and k."""
    ell, (ge, _, k, _) = ELLS[name], PUBLISHED[name]
    lat = np.linspace(-np.pi / 2, np.pi / 2, 181)
    s2 = np.sin(lat) ** 2
    ref = ge * (1 + k * s2) / np.sqrt(1 - ell.e2 * s2)
    np.testing.assert_allclose(np.array(normal_gravity(lat, 0.0, ell)), ref, rtol=0, atol=1e-9)
    if name != "GRS80":
        return
    # GRS80 only: its International Gravity Formula 1980 series, good to ~1e-6 m/s^2 (0.1 mGal)
    igf = 9.780327 * (1 + 0.0053024 * s2 - 0.0000058 * np.sin(2 * lat) ** 2)
    np.testing.assert_allclose(np.array(normal_gravity(lat, 0.0, ell)), igf, rtol=0, atol=1e-6)


def _profile(ell):
    """normal_gravity at several heights and its h-derivatives: one compiled call per ellipsoid."""

    @jax.jit
    def run(lat, hs):
        gam = jax.vmap(lambda h: normal_gravity(lat, h, ell))(hs)
        d1 = jax.vmap(jax.grad(normal_gravity, argnums=1), in_axes=(0, None, None))(lat, 0.0, ell)
        d2 = jax.vmap(jax.grad(jax.grad(normal_gravity, argnums=1), argnums=1), in_axes=(0, None, None))(lat, 0.0, ell)
        return gam, d1, d2

    return run


@pytest.mark.parametrize("name", list(PUBLISHED))
def test_height_correction(name):
    """TR8350.2 eq. 4-3 with the published m; d gamma/dh ~ -3.086e-6 s^-2 (free-air gradient)."""
    ell, (_, _, _, m) = ELLS[name], PUBLISHED[name]
    a, f = ell.a, ell.f
    lat = np.r_[np.linspace(-np.pi / 2, np.pi / 2, 37), np.pi / 4]
    s2 = np.sin(lat) ** 2
    hs = np.array([0.0, -400.0, 1000.0, 2e4, 1e5])
    gam, dgdh, d2 = (np.array(x) for x in _profile(ell)(jnp.array(lat), jnp.array(hs)))
    g0 = gam[0]
    for h, gh in zip(hs[1:], gam[1:]):
        ref = g0 * (1 - 2 / a * (1 + f + m - 2 * f * s2) * h + 3 * h * h / a**2)
        np.testing.assert_allclose(gh, ref, rtol=0, atol=1e-12)
    # the gradient at the surface, by AD
    np.testing.assert_allclose(dgdh, -2 * g0 / a * (1 + f + m - 2 * f * s2), rtol=1e-12)
    assert np.all(np.abs(dgdh + 3.086e-6) < 3.5e-9)  # -3.0877e-6 (equator) .. -3.0834e-6 (pole)
    assert abs(dgdh[-1] + 3.086e-6) < 1e-9  # the textbook 0.3086 mGal/m holds at 45 deg
    np.testing.assert_allclose(d2, 6 * g0 / a**2, rtol=1e-12)
    # gravity decreases with height and increases towards the poles
    assert np.all(gam[3] < g0)
    g0 = g0[:37]
    assert np.all(np.diff(g0[18:]) > 0) and np.all(np.diff(g0[:19]) < 0)


def test_krassovsky_and_cgcs2000_use_their_own_geometry():
    # CGCS2000 = GRS80 geometry with the WGS-84 GM: gravity close to both, equal to neither
    gc, gg, gw = (float(normal_gravity(0.5, 0.0, e)) for e in (g.CGCS2000, g.GRS80, g.WGS84))
    assert abs(gc - gw) < 1e-8 and abs(gc - gg) > 1e-6
    gk = float(normal_gravity(0.5, 0.0, g.KRASSOVSKY))
    assert abs(gk - gw) > 1e-4 and abs(gk - gw) < 1e-3  # larger a: ~3e-4 m/s^2 weaker
    assert np.isfinite(gk)


def test_earth_rate():
    rng = np.random.default_rng(0)
    lat = rng.uniform(-np.pi / 2, np.pi / 2, 50)
    w = np.array(E.earth_rate_n(jnp.array(lat)))
    assert w.shape == (50, 3)
    np.testing.assert_allclose(np.linalg.norm(w, axis=-1), 7.292115e-5, rtol=1e-15)
    np.testing.assert_array_equal(w[:, 0], 0.0)
    np.testing.assert_allclose(w[:, 1], 7.292115e-5 * np.cos(lat), rtol=1e-15)
    np.testing.assert_allclose(w[:, 2], 7.292115e-5 * np.sin(lat), rtol=1e-15)
    assert np.all(w[:, 1] >= 0)  # the Earth rate points north, and up in the northern hemisphere
    assert np.all(np.sign(w[:, 2]) == np.sign(lat))
    # the ECEF rotation vector [0, 0, omega] rotated into ENU (geodesy's rotation), at any longitude
    lon = rng.uniform(-np.pi, np.pi, 50)
    ref = np.array(g.ecef_to_enu_vector(0.0, 0.0, g.WGS84.omega, lat, lon)).T
    np.testing.assert_allclose(w, ref, rtol=0, atol=1e-20)
    # earth_params: sign -1 negates it (reverse navigation), the rest unchanged
    pos = jnp.array([0.6, 1.9, 300.0])
    v = jnp.array([3.0, -4.0, 0.5])
    fwd, rev = earth_params(pos, v), earth_params(pos, v, earth_rate_sign=-1.0)
    np.testing.assert_allclose(rev.w_ie_n, -fwd.w_ie_n, rtol=0, atol=0)
    np.testing.assert_allclose(rev.w_en_n, fwd.w_en_n, rtol=0, atol=0)
    np.testing.assert_allclose(rev.g_n, fwd.g_n, rtol=0, atol=0)


def _C_ne(pos):
    """ENU -> ECEF rotation (columns e, n, u) from geodesy's vector rotation."""
    eye = jnp.eye(3)
    return jnp.stack([jnp.stack(g.enu_to_ecef_vector(*eye[i], pos[0], pos[1])) for i in range(3)], axis=1)


def _unskew(W):
    return jnp.stack([W[2, 1], W[0, 2], W[1, 0]])


def _random_states(n, seed):
    rng = np.random.default_rng(seed)
    pos = np.c_[rng.uniform(-1.4, 1.4, n), rng.uniform(-np.pi, np.pi, n), rng.uniform(-1000.0, 1e5, n)]
    v = rng.normal(0.0, 300.0, (n, 3))
    return jnp.array(pos), jnp.array(v)


@jax.jit
def _geometric_rates(pos, v):
    """(w_en^n from d C_ne/dt, d r_e/dt from d ecef/dpos) along the position rate of jaxnav."""
    pdot = position_rate(pos, v)
    Cdot = jax.jvp(_C_ne, (pos,), (pdot,))[1]  # d C_ne / dt = C_ne [w_en^n x]
    w_en = _unskew(_C_ne(pos).T @ Cdot)
    rdot = jax.jvp(lambda p: jnp.stack(g.geodetic_to_ecef(p[0], p[1], p[2])), (pos,), (pdot,))[1]
    return w_en, rdot, _C_ne(pos) @ v


def test_position_rate_moves_the_ecef_point_by_the_velocity():
    """d/dt geodetic_to_ecef(pos) = C_ne v_n when pos moves at position_rate(pos, v_n)."""
    pos, v = _random_states(40, 1)
    _, rdot, ref = jax.vmap(_geometric_rates)(pos, v)
    np.testing.assert_allclose(np.array(rdot), np.array(ref), rtol=0, atol=1e-10)


def test_transport_rate_is_the_rotation_rate_of_the_enu_frame():
    pos, v = _random_states(40, 2)
    w_geo, _, _ = jax.vmap(_geometric_rates)(pos, v)
    w = E.transport_rate_n(pos[:, 0], pos[:, 2], v)
    np.testing.assert_allclose(np.array(w), np.array(w_geo), rtol=0, atol=1e-16)
    ep = earth_params(pos, v)
    np.testing.assert_allclose(np.array(ep.w_en_n), np.array(w), rtol=1e-15, atol=0)
    np.testing.assert_allclose(np.array(ep.w_in_n), np.array(ep.w_ie_n + ep.w_en_n), rtol=0, atol=0)
    np.testing.assert_allclose(np.array(ep.R_M), np.array(g.meridian_radius(pos[:, 0])), rtol=0, atol=0)
    np.testing.assert_allclose(np.array(ep.R_N), np.array(g.prime_vertical_radius(pos[:, 0])), rtol=0, atol=0)
    np.testing.assert_allclose(np.array(ep.g_n[:, :2]), 0.0, rtol=0, atol=0)
    np.testing.assert_allclose(np.array(ep.g_n[:, 2]), -np.array(normal_gravity(pos[:, 0], pos[:, 2])), rtol=0, atol=0)


def test_transport_rate_signs():
    lat, h = 0.7, 100.0
    east = np.array(E.transport_rate_n(lat, h, jnp.array([10.0, 0.0, 0.0])))
    assert east[0] == 0.0 and east[1] > 0.0 and east[2] > 0.0  # east at lat > 0: n turns about north and up
    assert np.array(E.transport_rate_n(-lat, h, jnp.array([10.0, 0.0, 0.0])))[2] < 0.0
    north = np.array(E.transport_rate_n(lat, h, jnp.array([0.0, 10.0, 0.0])))
    assert north[0] < 0.0 and north[1] == 0.0 and north[2] == 0.0  # north: about -east
    up = np.array(E.transport_rate_n(lat, h, jnp.array([0.0, 0.0, 10.0])))
    np.testing.assert_array_equal(up, 0.0)
    # magnitudes: V / (R + h)
    np.testing.assert_allclose(east[1], 10.0 / (g.prime_vertical_radius(lat) + h), rtol=1e-15)
    np.testing.assert_allclose(-north[0], 10.0 / (g.meridian_radius(lat) + h), rtol=1e-15)
    # position rate signs and units: north -> lat increases, east -> lon increases, up -> h
    pr = np.array(position_rate(jnp.array([lat, 0.2, h]), jnp.array([1.0, 2.0, 3.0])))
    np.testing.assert_allclose(
        pr,
        [2.0 / (g.meridian_radius(lat) + h), 1.0 / ((g.prime_vertical_radius(lat) + h) * np.cos(lat)), 3.0],
        rtol=1e-15,
    )


def test_earth_params_batched_jit_and_grad():
    pos, v = _random_states(8, 3)
    eager = jax.jit(earth_params)(pos, v)  # leading batch dimension, no vmap
    jitted = jax.jit(jax.vmap(earth_params))(pos, v)
    single = jax.jit(earth_params)  # compiled once for shape (3,)
    loop = [single(p, u) for p, u in zip(pos, v)]
    for name in eager._fields:
        np.testing.assert_allclose(np.array(getattr(jitted, name)), np.array(getattr(eager, name)), rtol=1e-14, atol=0)
        np.testing.assert_allclose(
            np.array([getattr(e, name) for e in loop]), np.array(getattr(eager, name)), rtol=1e-14, atol=0
        )
    # gravity and its gradient are finite at the poles
    grad = jax.jit(jax.vmap(jax.grad(normal_gravity, argnums=(0, 1))))
    gr = grad(jnp.array([np.pi / 2, -np.pi / 2]), jnp.zeros(2))
    assert all(bool(jnp.all(jnp.isfinite(x))) for x in gr)


def test_gravity_minus_coriolis_eotvos():
    """Up component: -gamma + 2 w V_E cos L + V_E^2 / (R_N + h) + V_N^2 / (R_M + h) (Eotvos and curvature terms)."""
    lat, h = 0.7, 300.0
    pos = jnp.array([lat, 2.0, h])
    assert np.array_equal(
        E.gravity_minus_coriolis(earth_params(pos, jnp.zeros(3)), jnp.zeros(3)), earth_params(pos, jnp.zeros(3)).g_n
    )
    v = jnp.array([80.0, -30.0, 2.0])
    e = earth_params(pos, v)
    G = np.array(E.gravity_minus_coriolis(e, v))
    w = g.WGS84.omega
    RMh, RNh = g.meridian_radius(lat) + h, g.prime_vertical_radius(lat) + h
    up = -normal_gravity(lat, h) + 2 * w * v[0] * np.cos(lat) + v[0] ** 2 / RNh + v[1] ** 2 / RMh
    np.testing.assert_allclose(G[2], up, rtol=1e-14)
    # horizontal: -(2 w_ie + w_en) x v, east and north rows written out
    wsum = 2 * np.array(e.w_ie_n) + np.array(e.w_en_n)
    np.testing.assert_allclose(G[:2], -np.cross(wsum, np.array(v))[:2], rtol=1e-14)
    # batched: (B, 3) points
    pb, vb = jnp.stack([pos, pos]), jnp.stack([v, -v])
    assert E.gravity_minus_coriolis(earth_params(pb, vb), vb).shape == (2, 3)
