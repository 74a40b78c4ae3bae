"""Gauss-Krüger against PROJ's own regression vectors (GRS80 tmerc/etmerc blocks, 50 nm)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _paths import DATA_ROOT
from reference.proj_run import proj_available, proj_transform

from jaxnav import geodesy as g

GIE = DATA_ROOT / "proj_reference_values" / "tmerc_etmerc_utm_builtins_excerpt.gie"


def _grs80_cases():
    """(direction, accept, expect, tolerance m) of the blocks '+proj=(e)tmerc +ellps=GRS80' only."""
    cases, op, direction, tol, accept = [], None, "forward", None, None
    for line in GIE.read_text().splitlines():
        words = line.split()
        if not words or words[0].startswith("#"):
            continue
        if words[0] == "operation":
            op, direction, tol = " ".join(words[1:]), "forward", None
        elif words[0] == "direction":
            direction = words[1]
        elif words[0] == "tolerance":
            val, unit = float(words[1]), words[2]
            tol = val * {"nm": 1e-9, "mm": 1e-3, "m": 1.0}[unit]
        elif words[0] == "accept":
            accept = [float(w) for w in words[1:3]]
        elif words[0] == "expect" and op in ("+proj=etmerc +ellps=GRS80", "+proj=tmerc +ellps=GRS80"):
            cases.append((op, direction, accept, [float(w) for w in words[1:3]], tol))
    return cases


CASES = _grs80_cases()


def test_vectors_found():
    assert len(CASES) >= 20


@pytest.mark.parametrize("case", CASES, ids=lambda c: f"{c[0].split()[0][6:]}-{c[1]}-{c[2]}")
def test_against_proj_vectors(case):
    op, direction, acc, exp, tol = case
    kw = dict(lon0=0.0, ellipsoid=g.GRS80, false_easting=0.0)
    if direction == "forward":
        x, y = g.gauss_kruger(np.radians(acc[1]), np.radians(acc[0]), **kw)
        assert abs(float(y) - exp[0]) <= tol and abs(float(x) - exp[1]) <= tol
    else:
        lat, lon = g.gauss_kruger_inverse(np.float64(acc[1]), np.float64(acc[0]), **kw)
        # 50 nm on the ground is ~4.5e-13 deg; the vectors print 12-14 significant digits
        assert abs(np.degrees(float(lon)) - exp[0]) <= 1e-11
        assert abs(np.degrees(float(lat)) - exp[1]) <= 1e-11


def test_round_trip_zone_prefix_and_extras():
    lat = jnp.radians(jnp.linspace(18.0, 53.0, 50))
    lon0, zone = g.zone_central_meridian(jnp.radians(jnp.float64(117.2)), 3)
    assert int(zone) == 39 and abs(float(jnp.degrees(lon0)) - 117.0) < 1e-12
    lon = lon0 + jnp.radians(jnp.linspace(-1.5, 1.5, 50))
    x, y, ex = g.gauss_kruger(lat, lon, lon0=lon0, ellipsoid=g.CGCS2000, zone=39, with_extras=True)
    assert float(jnp.min(y)) > 39e6
    la, lo = g.gauss_kruger_inverse(x, y, lon0=lon0, ellipsoid=g.CGCS2000, zone=39)
    assert float(jnp.max(jnp.abs(la - lat))) < 1e-14 and float(jnp.max(jnp.abs(lo - lon))) < 1e-14
    # convergence ~ dlon sin(lat) and scale ~ 1 + (y - 500 km)^2 / (2 R^2) to first order
    dl = lon - lon0
    np.testing.assert_allclose(ex.convergence, dl * jnp.sin(lat), atol=2e-6)
    np.testing.assert_allclose(ex.scale, 1 + (y - 39.5e6) ** 2 / (2 * 6.38e6**2), atol=2e-6)
    # the scale is the derivative of the projection (conformal): compare with jacfwd
    J = jax.jacfwd(lambda p: jnp.stack(g.gauss_kruger(p[0], p[1], lon0=lon0, ellipsoid=g.CGCS2000)))(
        jnp.array([lat[10], lon[10]])
    )
    RM, RN = g.meridian_radius(lat[10], g.CGCS2000), g.prime_vertical_radius(lat[10], g.CGCS2000)
    k_num = float(jnp.hypot(J[0, 0], J[1, 0]) / RM)
    assert abs(k_num - float(ex.scale[10])) < 1e-12
    assert abs(float(jnp.hypot(J[0, 1], J[1, 1]) / (RN * jnp.cos(lat[10]))) - k_num) < 1e-12


def test_float32_plane_coordinates_rejected():
    with pytest.raises(ValueError, match="enable_x64"):
        g.gauss_kruger_inverse(jnp.float32(4e6), jnp.float32(5e5), lon0=0.0)


# --- against pyproj at 1000 random points (issue 6) -------------------------------------------

if not proj_available():
    pytest.skip("pyproj is not installed", allow_module_level=True)


def _pyproj_tmerc(ellipsoid, lon0_deg):
    # PROJ's exact (Poder/Engsager) transverse Mercator on the same ellipsoid; x east, y north
    crs = (
        f"+proj=tmerc +algo=poder_engsager +lat_0=0 +lon_0={lon0_deg!r} +k=1 +x_0=500000 +y_0=0 "
        f"+a={ellipsoid.a!r} +rf={1.0 / ellipsoid.f!r} +units=m +no_defs"
    )
    return f"+proj=pipeline +step +proj=unitconvert +xy_in=deg +xy_out=rad +step {crs}"


def _tmerc_per_meridian(ell, cm, u, v, direction):
    """PROJ's tmerc of (u, v) with one pipeline per central meridian in cm (n,), in one subprocess."""
    cms = np.unique(cm)
    res = proj_transform([(_pyproj_tmerc(ell, float(c)), (u[cm == c], v[cm == c]), direction) for c in cms])
    a, b = np.empty(len(u)), np.empty(len(u))
    for c, r in zip(cms, res):
        a[cm == c], b[cm == c] = r
    return a, b


@pytest.mark.parametrize("zone_width", [3, 6])
@pytest.mark.parametrize("ell", [g.CGCS2000, g.KRASSOVSKY, g.WGS84], ids=lambda e: e.name)
def test_against_pyproj_1000_random_points(zone_width, ell):
    rng = np.random.default_rng(zone_width * 7 + len(ell.name))
    n = 1000
    lat = rng.uniform(18.0, 54.0, n)
    zone = rng.integers(25 if zone_width == 3 else 13, 45 if zone_width == 3 else 23, n)  # China's zones
    cm = 3.0 * zone if zone_width == 3 else 6.0 * zone - 3.0
    lon = cm + rng.uniform(-zone_width / 2, zone_width / 2, n)
    x, y = g.gauss_kruger(jnp.radians(lat), jnp.radians(lon), lon0=jnp.radians(cm), ellipsoid=ell, zone=zone)
    x, y = np.asarray(x), np.asarray(y)
    E, N = _tmerc_per_meridian(ell, cm, lon, lat, "FORWARD")
    assert np.max(np.abs(x - N)) <= 1e-4  # 0.1 mm
    assert np.max(np.abs(y - zone * 1e6 - E)) <= 1e-4
    la, lo = g.gauss_kruger_inverse(jnp.asarray(x), jnp.asarray(y), lon0=jnp.radians(cm), ellipsoid=ell, zone=zone)
    lo_p, la_p = _tmerc_per_meridian(ell, cm, E, N, "INVERSE")
    assert np.max(np.abs(np.degrees(np.asarray(la)) - la_p)) <= 1e-9
    assert np.max(np.abs(np.degrees(np.asarray(lo)) - lo_p)) <= 1e-9
    # and both return to the generating coordinates
    assert np.max(np.abs(la_p - lat)) <= 1e-9 and np.max(np.abs(lo_p - lon)) <= 1e-9
