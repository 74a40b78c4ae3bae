"""Daily station series readers: NGL tenv3, SIO .neu, .col tables (real files and bad input)."""

import numpy as np
import pytest
from _paths import DATA_ROOT

from jaxnav import io
from jaxnav.units import CM, DEG, MM_PER_YEAR, YEAR

DATA = DATA_ROOT / "gnss_daily_timeseries"


def test_tenv3_lhas():
    s = io.read_daily(DATA / "LHAS.tenv3")
    assert s.station == "LHAS" and s.fmt == "tenv3" and len(s.t) == 3631
    # first record: 385 + 0.888603 E, 3282129 + 0.602585 N, 3624 + 0.707878 U (m); sig 2.231, 1.932, 8.643 mm
    np.testing.assert_allclose(s.origin, [385.888603, 3282129.602585, 3624.707878], rtol=0, atol=1e-9)
    np.testing.assert_allclose(s.enu[1], [0.024531, -0.005243, 0.013874], atol=1e-9)
    np.testing.assert_allclose(np.sqrt(np.diagonal(s.cov[0])), [0.002231, 0.001932, 0.008643], rtol=1e-12)
    np.testing.assert_allclose(s.cov[0, 0, 1], -0.009728 * 0.002231 * 0.001932, rtol=1e-12)
    np.testing.assert_allclose(s.cov[0, 1, 2], -0.198749 * 0.001932 * 0.008643, rtol=1e-12)
    assert np.all(np.linalg.eigvalsh(s.cov) > 0)
    # MJD 49856 = 1995-05-19 00:00; -268.896 deg longitude wraps to 91.104 E
    np.testing.assert_allclose(s.t[0], (49856 - 51544.5) * 86400.0)
    np.testing.assert_allclose(s.llh[0], [29.6573392384 * DEG, (360 - 268.8960142076) * DEG, 3624.70788], rtol=1e-12)
    np.testing.assert_allclose(s.year[0], 1995.3785)
    # the decimal-year column agrees with the MJD time to within half a day
    assert np.max(np.abs(io.year_to_seconds(s.year) - s.t)) < 0.6 * 86400
    assert np.all(np.diff(s.t) > 0)


def test_neu_bjfs_header_slopes():
    s = io.read_daily(DATA / "bjfsCleanUnf.neu")
    assert s.station == "BJFS" and s.fmt == "neu"
    np.testing.assert_allclose(s.enu[0], [-0.1458, 0.0537, -0.0204])  # dE, dN, dU of the first line
    np.testing.assert_allclose(np.sqrt(np.diagonal(s.cov[0])), [0.0051, 0.0054, 0.0056])
    np.testing.assert_allclose(s.reference_velocity / MM_PER_YEAR, [30.4, -10.5, 2.4], rtol=1e-12)
    np.testing.assert_allclose(s.reference_velocity_sigma * YEAR, [0.0003, 0.0002, 0.0006], rtol=1e-12)


@pytest.mark.parametrize("name", ["MRHK", "UH01", "UHCR"])
def test_col_houston_in_cm(name):
    s = io.read_daily(DATA / f"{name}_GOM20_neu_cm.col")
    assert s.station == name and s.fmt == "col" and len(s.t) > 2500
    raw = np.loadtxt(DATA / f"{name}_GOM20_neu_cm.col", skiprows=1)
    np.testing.assert_allclose(s.enu, raw[:, [2, 1, 3]] * CM, rtol=1e-12)  # EW, NS, UD columns -> E, N, U
    np.testing.assert_allclose(np.sqrt(np.diagonal(s.cov, axis1=1, axis2=2)), raw[:, [5, 4, 6]] * CM, rtol=1e-12)
    if name == "MRHK":  # subsides about 12.7 cm in about 7 years
        assert -0.14 < s.enu[-30:, 2].mean() - s.enu[:30, 2].mean() < -0.11


def _write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


TENV3_HDR = (
    "site YYMMMDD yyyy.yyyy __MJD week d reflon _e0(m) __east(m) ____n0(m) _north(m) u0(m) ____up(m) _ant(m) "
    "sig_e(m) sig_n(m) sig_u(m) __corr_en __corr_eu __corr_nu _latitude(deg) _longitude(deg) __height(m)\n"
)
TENV3_1 = (
    "LHAS 95MAY19 1995.3785 49856  801 5   91.1    385  0.888603   3282129  0.602585  3624  0.707878  0.0000 "
    "0.002231 0.001932 0.008643 -0.009728 -0.044382 -0.198749  29.6573392384 -268.8960142076  3624.70788\n"
)
TENV3_2 = TENV3_1.replace("95MAY19 1995.3785 49856  801 5", "95MAY20 1995.3812 49857  801 6")


def test_bad_tenv3(tmp_path):
    p = _write(tmp_path, "a.tenv3", TENV3_HDR + TENV3_1 + TENV3_2.replace("0.002231", "x.002231"))
    with pytest.raises(ValueError, match=r"a\.tenv3:3: cannot read"):
        io.read_tenv3(p)
    p = _write(tmp_path, "b.tenv3", TENV3_HDR + TENV3_1 + " ".join(TENV3_2.split()[:12]) + "\n")
    with pytest.raises(ValueError, match=r"b\.tenv3:3: expected 20 or 23 fields"):
        io.read_tenv3(p)
    p = _write(tmp_path, "c.tenv3", TENV3_HDR + TENV3_2 + TENV3_1)
    with pytest.raises(ValueError, match=r"c\.tenv3:3: time .* does not increase"):
        io.read_tenv3(p)
    p = _write(tmp_path, "d.tenv3", TENV3_HDR + TENV3_1 + TENV3_2.replace("-0.198749", "-1.198749"))
    with pytest.raises(ValueError, match=r"d\.tenv3:3: correlations"):
        io.read_tenv3(p)
    p = _write(tmp_path, "e.tenv3", TENV3_HDR)
    with pytest.raises(ValueError, match=r"e\.tenv3: no data records"):
        io.read_tenv3(p)


NEU = (
    "# header\n1999.8068 1999 295  0.0537 -0.1458 -0.0204  0.0054  0.0051  0.0056\n"
    "1999.8096 1999 296  0.0530 -0.1429 -0.0073  0.0062  0.0057  0.0063\n"
)


def test_bad_neu(tmp_path):
    p = _write(tmp_path, "x.neu", NEU + "1999.8123 1999 297  0.0543 -0.1477\n")
    with pytest.raises(ValueError, match=r"x\.neu:4: expected 9 fields"):
        io.read_neu(p)
    p = _write(tmp_path, "y.neu", NEU + "1999.8000 1999 292  0.0543 -0.1477 -0.0274  0.0060  0.0054  0.0061\n")
    with pytest.raises(ValueError, match=r"y\.neu:4: time .* does not increase"):
        io.read_neu(p)
    p = _write(tmp_path, "z.neu", NEU + "1999.8200 1999 300  0.0543 -0.1477 -0.0274  0.0060  -0.0054  0.0061\n")
    with pytest.raises(ValueError, match=r"z\.neu:4: sigmas must be positive"):
        io.read_neu(p)


COL = (
    "Decimal-Year       NS(cm)       EW(cm)       UD(cm) sigma-NS(cm) sigma-EW(cm) sigma-UD(cm)\n"
    "   2014.3956       0.2037       0.0395      -0.0516       0.0548       0.0255       0.0605\n"
)


def test_bad_col(tmp_path):
    p = _write(tmp_path, "A_x.col", COL.replace(" sigma-UD(cm)", "").replace("       0.0605", ""))
    with pytest.raises(ValueError, match=r"A_x\.col:1: header lacks the column\(s\) \['sigma-UD\(unit\)'\]"):
        io.read_col(p)
    p = _write(tmp_path, "B_x.col", COL + "   2014.3984       0.1714       0.0465      -0.7940       0.0542\n")
    with pytest.raises(ValueError, match=r"B_x\.col:3: expected 7 columns"):
        io.read_col(p)
    p = _write(tmp_path, "C_x.col", COL + "   2014.3956   0.1714   0.0465  -0.7940   0.0542  0.02  0.05\n")
    with pytest.raises(ValueError, match=r"C_x\.col:3: time .* does not increase"):
        io.read_col(p)
    p = _write(tmp_path, "D_x.col", COL + "   2014.3984       0.1714       abc      -0.7940       0.0542  0.02  0.05\n")
    with pytest.raises(ValueError, match=r"D_x\.col:3: cannot read"):
        io.read_col(p)
    p = _write(tmp_path, "E_x.col", "   2014.3956       0.2037\n")
    with pytest.raises(ValueError, match=r"E_x\.col:1: expected a header"):
        io.read_col(p)
    s = io.read_col(_write(tmp_path, "F_x.col", COL.replace("(cm)", "(mm)")))
    np.testing.assert_allclose(s.enu[0], [0.0395e-3, 0.2037e-3, -0.0516e-3])
    with pytest.raises(ValueError, match=r"unknown daily-series format"):
        io.read_daily(_write(tmp_path, "G.txt", COL))
