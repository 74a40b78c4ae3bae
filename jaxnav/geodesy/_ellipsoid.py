"""Reference ellipsoids and their normal-gravity constants."""

from __future__ import annotations

import math
from typing import NamedTuple


class Ellipsoid(NamedTuple):
    """A reference ellipsoid with the constants of its normal gravity field.

    Attributes:
      name: label.  a: semi-major axis, m.  f: flattening.
      GM: geocentric gravitational constant, m^3/s^2.  omega: rotation rate, rad/s.
    """

    name: str
    a: float
    f: float
    GM: float = 3.986004418e14
    omega: float = 7.292115e-5

    @property
    def b(self) -> float:
        """Semi-minor axis, m."""
        return self.a * (1.0 - self.f)

    @property
    def e2(self) -> float:
        """First eccentricity squared."""
        return self.f * (2.0 - self.f)

    @property
    def ep2(self) -> float:
        """Second eccentricity squared."""
        return self.e2 / (1.0 - self.e2)

    def normal_gravity_constants(self) -> tuple[float, float]:
        """Normal gravity at the equator and the pole, m/s^2 (closed forms of Heiskanen & Moritz 2-7x).

        gamma_e = GM/(ab) (1 - m - m e' q0'/(6 q0)), gamma_p = GM/a^2 (1 + m e' q0'/(3 q0)),
        m = omega^2 a^2 b / GM; for WGS-84 they give 9.7803253359 and 9.8321849378 m/s^2.
        """
        a, b = self.a, self.b
        ep = math.sqrt(a * a - b * b) / b
        q0 = 0.5 * ((1.0 + 3.0 / ep**2) * math.atan(ep) - 3.0 / ep)
        q0p = 3.0 * (1.0 + 1.0 / ep**2) * (1.0 - math.atan(ep) / ep) - 1.0
        m = self.omega**2 * a * a * b / self.GM
        ge = self.GM / (a * b) * (1.0 - m - m * ep * q0p / (6.0 * q0))
        gp = self.GM / (a * a) * (1.0 + m * ep * q0p / (3.0 * q0))
        return ge, gp


#: WGS-84 (NIMA TR8350.2)
WGS84 = Ellipsoid("WGS-84", 6378137.0, 1.0 / 298.257223563, 3.986004418e14, 7.292115e-5)
#: GRS 80 (Moritz 1980)
GRS80 = Ellipsoid("GRS80", 6378137.0, 1.0 / 298.257222101, 3.986005e14, 7.292115e-5)
#: China Geodetic Coordinate System 2000
CGCS2000 = Ellipsoid("CGCS2000", 6378137.0, 1.0 / 298.257222101, 3.986004418e14, 7.292115e-5)
#: Krassovsky 1940, the ellipsoid of Beijing 1954 (it defines no gravity field: WGS-84's GM and
#: omega are used for its normal gravity)
KRASSOVSKY = Ellipsoid("Krassovsky", 6378245.0, 1.0 / 298.3, 3.986004418e14, 7.292115e-5)

ELLIPSOIDS = {e.name: e for e in (WGS84, GRS80, CGCS2000, KRASSOVSKY)}
