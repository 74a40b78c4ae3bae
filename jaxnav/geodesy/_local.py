"""Small geodetic differences <-> local east, north, up metres through the radii of curvature."""

from __future__ import annotations

import jax.numpy as jnp

from jaxnav.geodesy._ellipsoid import WGS84, Ellipsoid
from jaxnav.geodesy._frames import _f, meridian_radius, prime_vertical_radius


def _radii_h(pos, ellipsoid: Ellipsoid):
    """(lat, R_M + h, R_N + h) at pos (..., 3)."""
    lat, h = pos[..., 0], pos[..., 2]
    return lat, meridian_radius(lat, ellipsoid) + h, prime_vertical_radius(lat, ellipsoid) + h


def curvilinear_to_enu(pos, dpos, ellipsoid: Ellipsoid = WGS84):
    """Small geodetic differences at ``pos`` -> local east, north, up metres (first order).

    dE = dlon (R_N + h) cos lat,  dN = dlat (R_M + h),  dU = dh,
    with the meridian and prime-vertical radii R_M, R_N taken at pos (the D matrix of the INS
    position measurement, :func:`jaxnav.ins.predict_gnss_pv`).
    The neglected terms are of relative size |d| / R (about 1.6e-7 per metre of offset).

    Args:
      pos: (..., 3) [lat rad, lon rad, h m], the point where the radii are taken.
      dpos: (..., 3) [dlat rad, dlon rad, dh m]; broadcasts against ``pos``.
      ellipsoid: static reference ellipsoid (default WGS-84).
    Returns:
      (..., 3) [dE, dN, dU], m.
    """
    lat, RMh, RNh = _radii_h(_f(pos), ellipsoid)
    dpos = _f(dpos)
    dE, dN = dpos[..., 1] * RNh * jnp.cos(lat), dpos[..., 0] * RMh
    return jnp.stack([dE, dN, jnp.broadcast_to(dpos[..., 2], dE.shape)], axis=-1)


def enu_to_curvilinear(pos, d_enu, ellipsoid: Ellipsoid = WGS84):
    """Local east, north, up metres at ``pos`` -> small geodetic differences (inverse of :func:`curvilinear_to_enu`).

    dlat = dN / (R_M + h),  dlon = dE / ((R_N + h) cos lat),  dh = dU.

    Args:
      pos: (..., 3) [lat rad, lon rad, h m], the point where the radii are taken.
      d_enu: (..., 3) [dE, dN, dU], m; broadcasts against ``pos``.
      ellipsoid: static reference ellipsoid (default WGS-84).
    Returns:
      (..., 3) [dlat rad, dlon rad, dh m].

    Notes:
      Singular at the poles (cos lat = 0), like any longitude difference.
    """
    lat, RMh, RNh = _radii_h(_f(pos), ellipsoid)
    d_enu = _f(d_enu)
    dlat, dlon = d_enu[..., 1] / RMh, d_enu[..., 0] / (RNh * jnp.cos(lat))
    return jnp.stack([dlat, dlon, jnp.broadcast_to(d_enu[..., 2], dlat.shape)], axis=-1)
