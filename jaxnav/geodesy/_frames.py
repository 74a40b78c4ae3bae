"""Geodetic <-> ECEF <-> local ENU conversions (radians, metres), jit/vmap/grad ready."""

from __future__ import annotations

import jax.numpy as jnp

from jaxnav._numerics import check_float64  # the package's one float64 guard, re-exported here
from jaxnav.geodesy._ellipsoid import WGS84, Ellipsoid

_BOWRING_ITERATIONS = 4


def _f(x):
    return jnp.asarray(x, dtype=jnp.result_type(x, float))


def prime_vertical_radius(lat, ellipsoid: Ellipsoid = WGS84):
    """R_N = a / sqrt(1 - e^2 sin^2 lat), m; lat in rad."""
    s = jnp.sin(lat)
    return ellipsoid.a / jnp.sqrt(1.0 - ellipsoid.e2 * s * s)


def meridian_radius(lat, ellipsoid: Ellipsoid = WGS84):
    """R_M = a (1 - e^2) / (1 - e^2 sin^2 lat)^{3/2}, m; lat in rad."""
    s = jnp.sin(lat)
    w = 1.0 - ellipsoid.e2 * s * s
    return ellipsoid.a * (1.0 - ellipsoid.e2) / (w * jnp.sqrt(w))


def geodetic_to_ecef(lat, lon, h, *, ellipsoid: Ellipsoid = WGS84):
    """Geodetic latitude, longitude (rad) and ellipsoidal height (m) -> ECEF x, y, z (m).

    Args broadcast together; any shape. Returns a tuple (x, y, z).

    Raises:
      ValueError: absolute coordinates in float32.
    """
    check_float64(lat, lon, h)
    lat, lon, h = _f(lat), _f(lon), _f(h)
    N = prime_vertical_radius(lat, ellipsoid)
    cl = jnp.cos(lat)
    x = (N + h) * cl * jnp.cos(lon)
    y = (N + h) * cl * jnp.sin(lon)
    z = (N * (1.0 - ellipsoid.e2) + h) * jnp.sin(lat)
    return x, y, z


def ecef_to_geodetic(x, y, z, *, ellipsoid: Ellipsoid = WGS84):
    """ECEF x, y, z (m) -> geodetic latitude, longitude (rad), ellipsoidal height (m).

    Bowring's iteration on the parametric latitude (4 fixed iterations: below 1e-15 rad for
    any point above -a/2 and far above that for points deep inside the ellipsoid, where the
    nearest-surface solution is still returned). Points on the polar axis give lon = 0 and
    lat = +-pi/2 exactly; gradients stay finite there (double-where).

    Raises:
      ValueError: absolute coordinates given in float32.
    """
    check_float64(x, y, z)
    x, y, z = _f(x), _f(y), _f(z)
    a, b, e2, ep2 = ellipsoid.a, ellipsoid.b, ellipsoid.e2, ellipsoid.ep2
    p2 = x * x + y * y
    on_axis = p2 == 0.0
    p = jnp.sqrt(jnp.where(on_axis, 1.0, p2))
    p = jnp.where(on_axis, 0.0, p)
    lon = jnp.arctan2(jnp.where(on_axis, 0.0, y), jnp.where(on_axis, 1.0, x))
    beta = jnp.arctan2(a * z, b * p)
    lat = beta
    for _ in range(_BOWRING_ITERATIONS):
        sb, cb = jnp.sin(beta), jnp.cos(beta)
        lat = jnp.arctan2(z + ep2 * b * sb**3, p - e2 * a * cb**3)
        beta = jnp.arctan2((1.0 - ellipsoid.f) * jnp.sin(lat), jnp.cos(lat))
    lat = jnp.where(on_axis, jnp.where(z >= 0, jnp.pi / 2, -jnp.pi / 2), lat)
    sl, cl = jnp.sin(lat), jnp.cos(lat)
    N = prime_vertical_radius(lat, ellipsoid)
    h = p * cl + (z + e2 * N * sl) * sl - N
    return lat, lon, h


def _rot_enu(lat0, lon0):
    """Rows e, n, u of the ECEF -> ENU rotation at (lat0, lon0)."""
    sl, cl = jnp.sin(lat0), jnp.cos(lat0)
    so, co = jnp.sin(lon0), jnp.cos(lon0)
    e = (-so, co, jnp.zeros_like(so))
    n = (-sl * co, -sl * so, cl)
    u = (cl * co, cl * so, sl)
    return e, n, u


def ecef_to_enu_vector(dx, dy, dz, lat0, lon0):
    """Rotate an ECEF vector (e.g. a velocity) into local east, north, up at (lat0, lon0) rad."""
    e, n, u = _rot_enu(_f(lat0), _f(lon0))
    dot = lambda r: r[0] * dx + r[1] * dy + r[2] * dz
    return dot(e), dot(n), dot(u)


def enu_to_ecef_vector(de, dn, du, lat0, lon0):
    """Rotate a local east, north, up vector at (lat0, lon0) rad into ECEF."""
    e, n, u = _rot_enu(_f(lat0), _f(lon0))
    return tuple(e[i] * de + n[i] * dn + u[i] * du for i in range(3))


def ecef_to_enu(x, y, z, lat0, lon0, h0, *, ellipsoid: Ellipsoid = WGS84):
    """ECEF point (m) -> local east, north, up (m) about the origin (lat0, lon0 rad, h0 m)."""
    check_float64(x, y, z, lat0, lon0, h0)
    x0, y0, z0 = geodetic_to_ecef(lat0, lon0, h0, ellipsoid=ellipsoid)
    return ecef_to_enu_vector(x - x0, y - y0, z - z0, lat0, lon0)


def enu_to_ecef(e, n, u, lat0, lon0, h0, *, ellipsoid: Ellipsoid = WGS84):
    """Local east, north, up (m) about (lat0, lon0 rad, h0 m) -> ECEF point (m).

    The offsets may be float32 (local); the origin must be float64.
    """
    check_float64(lat0, lon0, h0, what="the ENU origin (absolute coordinates)")
    x0, y0, z0 = geodetic_to_ecef(lat0, lon0, h0, ellipsoid=ellipsoid)
    dx, dy, dz = enu_to_ecef_vector(e, n, u, lat0, lon0)
    return x0 + dx, y0 + dy, z0 + dz


def geodetic_to_enu(lat, lon, h, lat0, lon0, h0, *, ellipsoid: Ellipsoid = WGS84):
    """Geodetic point -> local ENU (m) about a geodetic origin; angles in rad."""
    x, y, z = geodetic_to_ecef(lat, lon, h, ellipsoid=ellipsoid)
    return ecef_to_enu(x, y, z, lat0, lon0, h0, ellipsoid=ellipsoid)


def enu_to_geodetic(e, n, u, lat0, lon0, h0, *, ellipsoid: Ellipsoid = WGS84):
    """Local ENU (m) about a geodetic origin -> geodetic point; angles in rad."""
    x, y, z = enu_to_ecef(e, n, u, lat0, lon0, h0, ellipsoid=ellipsoid)
    return ecef_to_geodetic(x, y, z, ellipsoid=ellipsoid)
