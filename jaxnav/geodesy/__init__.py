"""Ellipsoids and coordinate conversions: geodetic <-> ECEF <-> local ENU (radians, metres).

Small geodetic differences <-> local ENU metres: :func:`curvilinear_to_enu`, :func:`enu_to_curvilinear`.

Every function takes an ``ellipsoid=`` keyword (default WGS-84) and works under
``jit``/``vmap``/``grad``. Absolute coordinates must be float64 (a float32 ECEF or geodetic
input raises ``ValueError`` naming the fix, :func:`jaxnav.enable_x64`).
"""

from jaxnav.geodesy._ellipsoid import CGCS2000, ELLIPSOIDS, GRS80, KRASSOVSKY, WGS84, Ellipsoid
from jaxnav.geodesy._frames import (
    check_float64,
    ecef_to_enu,
    ecef_to_enu_vector,
    ecef_to_geodetic,
    enu_to_ecef,
    enu_to_ecef_vector,
    enu_to_geodetic,
    geodetic_to_ecef,
    geodetic_to_enu,
    meridian_radius,
    prime_vertical_radius,
)
from jaxnav.geodesy._gauss_kruger import (
    FALSE_EASTING,
    GaussKrugerExtras,
    gauss_kruger,
    gauss_kruger_inverse,
    zone_central_meridian,
)
from jaxnav.geodesy._height import (
    HeightAnomalyModel,
    choose_surface,
    fit_height_anomaly,
    height_anomaly,
    height_anomaly_std,
    normal_height,
)
from jaxnav.geodesy._helmert import (
    CONVENTIONS,
    Helmert7,
    HelmertFit,
    Similarity2D,
    estimate_helmert7,
    estimate_similarity2d,
    helmert7,
    helmert7_inverse,
    rotation_matrix,
    similarity2d,
    similarity2d_inverse,
)
from jaxnav.geodesy._local import curvilinear_to_enu, enu_to_curvilinear

__all__ = [
    "CGCS2000",
    "ELLIPSOIDS",
    "Ellipsoid",
    "GRS80",
    "KRASSOVSKY",
    "WGS84",
    "check_float64",
    "ecef_to_enu",
    "ecef_to_enu_vector",
    "ecef_to_geodetic",
    "enu_to_ecef",
    "enu_to_ecef_vector",
    "enu_to_geodetic",
    "geodetic_to_ecef",
    "geodetic_to_enu",
    "meridian_radius",
    "prime_vertical_radius",
    "FALSE_EASTING",
    "GaussKrugerExtras",
    "gauss_kruger",
    "gauss_kruger_inverse",
    "zone_central_meridian",
    "CONVENTIONS",
    "Helmert7",
    "HelmertFit",
    "Similarity2D",
    "estimate_helmert7",
    "estimate_similarity2d",
    "helmert7",
    "helmert7_inverse",
    "rotation_matrix",
    "similarity2d",
    "similarity2d_inverse",
    "HeightAnomalyModel",
    "choose_surface",
    "fit_height_anomaly",
    "height_anomaly",
    "height_anomaly_std",
    "normal_height",
    "curvilinear_to_enu",
    "enu_to_curvilinear",
]
