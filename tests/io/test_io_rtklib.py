"""RTKLIB .pos reader on the real files in ../shared/data and on crafted bad input."""

import datetime as dt

import numpy as np
import pytest
from _paths import DATA_ROOT

from jaxnav.io import GPS_EPOCH, read_pos

DATA = DATA_ROOT
WALK = DATA / "rtklibexplorer-gnss-imu" / "walk_0827" / "gnss_1730_sf.pos"

HEADER = (
    "%  GPST                  latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m)   sde(m)   sdu(m)"
    "  sdne(m)  sdeu(m)  sdun(m) age(s)  ratio\n"
)


def test_walk_file_matches_its_readme():
    s = read_pos(WALK)
    assert len(s.t) == 536
    assert np.sum(s.q == 1) == 349 and np.sum(s.q == 2) == 187
    t0 = (dt.datetime(2025, 8, 28, 17, 30, 39, 749000) - GPS_EPOCH).total_seconds()
    assert abs(s.t[0] - t0) < 1e-6
    np.testing.assert_allclose(np.diff(s.t), 0.25, atol=1e-6)  # 4 Hz
    assert abs(np.degrees(s.lat[0]) - 40.0966916) < 1e-12 and abs(np.degrees(s.lon[0]) + 105.1471665) < 1e-12
    assert abs(s.h[0] - 1601.435) < 1e-9
    # sdn = sde = 0.0098995 m, sdu = 0.01 m; velocities ve = -0.002, vn = 0.001, vu = 0.027 m/s
    np.testing.assert_allclose(np.diag(s.cov_enu[0]), [0.0098995**2, 0.0098995**2, 0.01**2], rtol=1e-12)
    np.testing.assert_allclose(s.v_enu[0], [-0.002, 0.001, 0.027], rtol=1e-12)


@pytest.mark.parametrize("path", sorted(DATA.rglob("*.pos")), ids=lambda p: p.name)
def test_every_shared_pos_file_reads(path):
    s = read_pos(path)
    assert len(s.t) > 100 and np.all(np.diff(s.t) > 0)
    assert np.all(np.isfinite(s.lat)) and np.all(np.abs(s.lat) < np.pi / 2)
    np.testing.assert_array_equal(s.cov_enu, np.swapaxes(s.cov_enu, 1, 2))
    assert set(np.unique(s.q)) <= {1, 2, 3, 4, 5, 6}


def test_signed_square_root_covariances_and_week_tow(tmp_path):
    f = tmp_path / "a.pos"
    f.write_text(
        "% program : test\n"
        + HEADER.replace("GPST                 ", "GPST")
        + "2100 345600.000  35.0  136.0  41.0  1  19  0.0040  0.0030  0.0100  -0.0020  0.0010  -0.0050  0.03  5.9\n"
    )
    s = read_pos(f)
    assert s.t[0] == 2100 * 604800 + 345600
    c = s.cov_enu[0]  # E, N, U order
    np.testing.assert_allclose(np.diag(c), [0.003**2, 0.004**2, 0.01**2])
    assert c[0, 1] == pytest.approx(-(0.002**2)) and c[0, 2] == pytest.approx(0.001**2)
    assert c[1, 2] == pytest.approx(-(0.005**2))
    assert np.all(np.isnan(s.v_enu))  # no velocity columns in this file


def test_bad_files_name_file_and_line(tmp_path):
    f = tmp_path / "bad.pos"
    good = (
        "2023/07/11 06:04:32.000   35.1   136.8   41.4   1  19   0.0045 0.0045 0.0097 0.0027 0.0011 -0.0030 0.03 5.9\n"
    )
    f.write_text(HEADER + good + good.replace("41.4", "4x.4"))
    with pytest.raises(ValueError, match=r"bad.pos:3: could not convert"):
        read_pos(f)
    f.write_text(HEADER + good + good.rsplit(" ", 1)[0] + "\n")
    with pytest.raises(ValueError, match=r"bad.pos:3: expected 13 values after the time, found 12"):
        read_pos(f)
    f.write_text(HEADER + "2023/13/11 06:04:32.000 " + good.split(None, 2)[2])
    with pytest.raises(ValueError, match=r"bad.pos:2: cannot read the GPST time"):
        read_pos(f)
    f.write_text(good)
    with pytest.raises(ValueError, match=r"bad.pos:1: data before the"):
        read_pos(f)
    f.write_text("%  GPST  x-ecef(m) y-ecef(m) z-ecef(m) Q ns\n")
    with pytest.raises(ValueError, match="ECEF"):
        read_pos(f)
    with pytest.raises(FileNotFoundError):
        read_pos(tmp_path / "missing.pos")


def test_non_increasing_time_and_missing_columns_name_the_line(tmp_path):
    f = tmp_path / "t.pos"
    good = (
        "2023/07/11 06:04:32.000   35.1   136.8   41.4   1  19   0.0045 0.0045 0.0097 0.0027 0.0011 -0.0030 0.03 5.9\n"
    )
    f.write_text(HEADER + good + good.replace("32.000", "33.000") + good.replace("32.000", "32.500"))
    with pytest.raises(
        ValueError,
        match=r"t.pos:4: time 2023/07/11 06:04:32.500 is not after the previous record's "
        r"\(line 3\)",
    ):
        read_pos(f)
    f.write_text(HEADER + good + good)
    with pytest.raises(ValueError, match=r"t.pos:3: time .* is not after"):
        read_pos(f)
    f.write_text(HEADER.replace("height(m)", "hgt") + good)
    with pytest.raises(ValueError, match=r"t.pos:1: the header line lacks the column\(s\) \['height\(m\)'\]"):
        read_pos(f)


def test_signed_square_root_covariances_of_a_real_file():
    """The off-diagonal columns sdne/sdeu/sdun of the MatRTKLIB static file are signed roots."""
    path = DATA / "rtk_pos_matrtklib" / "static" / "rover_rtk.pos"
    s = read_pos(path)
    line = [ln for ln in path.read_text().splitlines() if ln and not ln.startswith("%")][0].split()
    sdn, sde, sdu, sdne, sdeu, sdun = (float(v) for v in line[7:13])
    c = s.cov_enu[0]
    np.testing.assert_allclose([c[1, 1], c[0, 0], c[2, 2]], [sdn**2, sde**2, sdu**2], rtol=1e-12)
    np.testing.assert_allclose(
        [c[0, 1], c[0, 2], c[1, 2]],
        [np.sign(sdne) * sdne**2, np.sign(sdeu) * sdeu**2, np.sign(sdun) * sdun**2],
        rtol=1e-12,
    )
    assert np.all(np.linalg.eigvalsh(s.cov_enu) > 0)  # every epoch's covariance is positive definite


def test_take_selects_epochs_of_every_per_epoch_field():
    s = read_pos(WALK)
    sel = np.asarray(s.q) == 1
    sub = s.take(sel)
    assert sub.path == s.path and sub.n_masked == s.n_masked and len(sub.t) == int(sel.sum()) < len(s.t)
    for f in ("t", "lat", "lon", "h", "q", "ns", "cov_enu", "age", "ratio", "v_enu", "vcov_enu"):
        np.testing.assert_array_equal(getattr(sub, f), np.asarray(getattr(s, f))[sel], err_msg=f)
    np.testing.assert_array_equal(s.take(np.array([3, 1])).t, np.asarray(s.t)[[3, 1]])
