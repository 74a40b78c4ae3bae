"""Earth model for strapdown navigation in the ENU frame (S3 class 2, step 6).

Radii of curvature, normal gravity (Somigliana with a second-order height correction), Earth
rate and transport rate, all in the local-level east-north-up navigation frame.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxnav.geodesy import WGS84, Ellipsoid, meridian_radius, prime_vertical_radius


class EarthParams(NamedTuple):
    """Earth quantities at a point (ENU frame; all SI).

    Attributes:
      R_M: meridian radius of curvature, m.  R_N: prime-vertical radius, m.
      w_ie_n: (3,) Earth rate in n, rad/s.  w_en_n: (3,) transport rate in n, rad/s.
      w_in_n: (3,) w_ie_n + w_en_n.  g_n: (3,) normal gravity vector in n, m/s^2.
    """

    R_M: jax.Array
    R_N: jax.Array
    w_ie_n: jax.Array
    w_en_n: jax.Array
    w_in_n: jax.Array
    g_n: jax.Array


def normal_gravity(lat, h, ellipsoid: Ellipsoid = WGS84):
    """Normal gravity magnitude, m/s^2: Somigliana's formula with a height correction.

    gamma_0 = (a gamma_e cos^2 lat + b gamma_p sin^2 lat) / sqrt(a^2 cos^2 lat + b^2 sin^2 lat)
    gamma_h = gamma_0 [1 - 2/a (1 + f + m - 2 f sin^2 lat) h + 3 h^2 / a^2]
    (NIMA TR8350.2 eqs. 4-1 and 4-3), m = omega^2 a^2 b / GM.

    Args:
      lat: geodetic latitude, rad.  h: ellipsoidal height, m.
    """
    ge, gp = ellipsoid.normal_gravity_constants()
    a, b, f = ellipsoid.a, ellipsoid.b, ellipsoid.f
    m = ellipsoid.omega**2 * a * a * b / ellipsoid.GM
    s2 = jnp.sin(lat) ** 2
    c2 = 1.0 - s2
    g0 = (a * ge * c2 + b * gp * s2) / jnp.sqrt(a * a * c2 + b * b * s2)
    return g0 * (1.0 - 2.0 / a * (1.0 + f + m - 2.0 * f * s2) * h + 3.0 * h * h / (a * a))


def earth_rate_n(lat, ellipsoid: Ellipsoid = WGS84):
    """Earth rate in ENU, w_ie^n = [0, w cos L, w sin L] rad/s (S3 step 6)."""
    w = ellipsoid.omega
    return jnp.stack([jnp.zeros_like(lat), w * jnp.cos(lat), w * jnp.sin(lat)], axis=-1)


def transport_rate_n(lat, h, v_n, ellipsoid: Ellipsoid = WGS84):
    """Transport rate in ENU, w_en^n = [-V_N/(R_M+h), V_E/(R_N+h), V_E tan L/(R_N+h)] (S3 step 6).

    Args:
      lat: rad.  h: m.  v_n: (..., 3) ENU velocity, m/s.
    """
    RMh = meridian_radius(lat, ellipsoid) + h
    RNh = prime_vertical_radius(lat, ellipsoid) + h
    ve, vn = v_n[..., 0], v_n[..., 1]
    return jnp.stack([-vn / RMh, ve / RNh, ve * jnp.tan(lat) / RNh], axis=-1)


def earth_params(pos, v_n, ellipsoid: Ellipsoid = WGS84, earth_rate_sign=1.0) -> EarthParams:
    """All Earth quantities at pos = [lat rad, lon rad, h m] with ENU velocity v_n (m/s).

    ``earth_rate_sign = -1`` negates the Earth rate, as reverse navigation requires (S3 class 3).
    """
    lat, h = pos[..., 0], pos[..., 2]
    RM = meridian_radius(lat, ellipsoid)
    RN = prime_vertical_radius(lat, ellipsoid)
    wie = earth_rate_sign * earth_rate_n(lat, ellipsoid)
    wen = transport_rate_n(lat, h, v_n, ellipsoid)
    g = normal_gravity(lat, h, ellipsoid)
    g_n = jnp.stack([jnp.zeros_like(g), jnp.zeros_like(g), -g], axis=-1)
    return EarthParams(R_M=RM, R_N=RN, w_ie_n=wie, w_en_n=wen, w_in_n=wie + wen, g_n=g_n)


def gravity_minus_coriolis(e: EarthParams, v_n):
    """Gravity minus the Coriolis and centripetal-transport terms, g_n - (2 w_ie + w_en) x v_n.

    The ENU velocity equation (S3 class 2) is v_dot = C_bn f_b + this term; conversely the
    specific force of a trajectory is f_n = a_n - this term.

    Args:
      e: :class:`EarthParams` at the point (its ``w_ie_n``, ``w_en_n``, ``g_n``).
      v_n: (..., 3) ENU velocity, m/s (the one ``e.w_en_n`` was computed with).
    Returns:
      (..., 3) m/s^2 in n.
    """
    return e.g_n - jnp.cross(2.0 * e.w_ie_n + e.w_en_n, v_n)


def position_rate(pos, v_n, ellipsoid: Ellipsoid = WGS84):
    """d[lat, lon, h]/dt = [V_N/(R_M+h), V_E/((R_N+h) cos L), V_U] for pos = [lat, lon, h]."""
    lat, h = pos[..., 0], pos[..., 2]
    RMh = meridian_radius(lat, ellipsoid) + h
    RNh = prime_vertical_radius(lat, ellipsoid) + h
    return jnp.stack([v_n[..., 1] / RMh, v_n[..., 0] / (RNh * jnp.cos(lat)), v_n[..., 2]], axis=-1)
