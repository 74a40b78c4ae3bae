"""S2 survey files: RTK epoch log, levelling, control points; round trips and bad input."""

import numpy as np
import pytest

from jaxnav import io

HEAD = "point,time,x,y,h,B,L,H,sigma_x,sigma_y,sigma_h\n"
ROW = "P01,{t},3631500.1234,39486000.5678,22.1234,32.8100000000,116.8500000000,18.6700,0.0080,0.0080,0.0150\n"


def test_epoch_log_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    n = 7
    point = np.array(["A"] * 3 + ["B"] * 4)
    t = np.array([0.0, 2.0, 4.0, 100.0, 102.0, 104.0, 106.0])
    lat, lon = np.radians(32.8 + rng.uniform(0, 0.01, n)), np.radians(116.8 + rng.uniform(0, 0.01, n))
    x, y = (rng.uniform(0, 1e6, n) for _ in range(2))
    h, H = (rng.uniform(0, 3e3, n) for _ in range(2))  # heights on Earth: the reader refuses impossible ones
    sig = rng.uniform(0.005, 0.02, (n, 3))
    f = io.write_epoch_log(tmp_path / "e.csv", point, t, x, y, h, lat, lon, H, sig)
    log = io.read_epoch_log(f)
    assert list(log.point) == list(point) and log.line[0] == 3  # comment line, header, then data
    np.testing.assert_allclose(log.t, t)
    np.testing.assert_allclose(log.lat, lat, atol=1e-12)
    np.testing.assert_allclose(log.lon, lon, atol=1e-12)
    np.testing.assert_allclose(np.stack([log.x, log.y, log.h, log.H], 1), np.stack([x, y, h, H], 1), atol=1e-4)
    np.testing.assert_allclose(log.sigma, sig, atol=1e-4)


def test_epoch_log_iso_time_sigma_plane_and_nan(tmp_path):
    f = tmp_path / "e.csv"
    f.write_text(
        "point,time,x,y,h,B,L,H,sigma_plane,sigma_h,extra\n"
        "Q1,2014-11-17T09:30:00,1,2,3,32.8,116.8,nan,0.010,0.02,z\n"
        "Q1,2014-11-17T09:30:02,1,2,3,32.8,116.8,18.1,0.010,0.02,z\n"
    )
    log = io.read_epoch_log(f)
    assert log.t[1] - log.t[0] == 2.0
    np.testing.assert_allclose(log.sigma[0], [0.01 / np.sqrt(2), 0.01 / np.sqrt(2), 0.02])
    assert np.isnan(log.H[0])  # kept; the filter masks it


@pytest.mark.parametrize(
    "text, match",
    [
        (HEAD + ROW.format(t=0) + ROW.format(t=2).replace("22.1234", "22.1x34"), r"e.csv:3: column 'h': cannot read"),
        (HEAD + ROW.format(t=0) + ROW.format(t=2) + ROW.format(t=2), r"e.csv:4: time 2 of point 'P01' is not after"),
        (HEAD + ROW.format(t=4) + ROW.format(t=2), r"e.csv:3: time 2 of point 'P01' is not after"),
        (HEAD.replace(",H,", ",") + ROW.format(t=0), r"e.csv:1: header lacks column\(s\) \['H'\]"),
        (HEAD + ROW.format(t=0).rsplit(",", 1)[0] + "\n", r"e.csv:2: 10 fields, the header has 11"),
        (
            HEAD + ROW.format(t=0) + ROW.format(t=2).replace("P01", "P02") + ROW.format(t=4),
            r"e.csv:4: point 'P01' continues after other points",
        ),
        (HEAD + ROW.format(t="yesterday"), r"e.csv:2: column 'time'"),
        (
            HEAD + ROW.format(t=0).replace("0.0150", "-0.01"),
            r"e.csv:2: column 'sigma_h': -0.01 is outside \[0, 10000\]",
        ),
        (HEAD + ROW.format(t=0).replace("32.81", "132.81"), r"e.csv:2: column 'B': 132.81 is outside \[-90, 90\]"),
        ("# only a comment\n", r"e.csv: empty file"),
        (HEAD, r"e.csv: no epochs"),
    ],
)
def test_epoch_log_errors_name_file_and_line(tmp_path, text, match):
    f = tmp_path / "e.csv"
    f.write_text(text)
    with pytest.raises(ValueError, match=match):
        io.read_epoch_log(f)


def test_levelling_and_control_round_trip_and_errors(tmp_path):
    f = io.write_levelling(tmp_path / "lev.csv", ["P01", "P02"], [21.5, 22.25])
    lev = io.read_levelling(f)
    assert list(lev.point) == ["P01", "P02"] and lev.height[1] == 22.25
    c = io.write_control_points(
        tmp_path / "cp.csv",
        ["K1", "K2", "K3"],
        np.radians([32.8, 32.81, 32.82]),
        np.radians([116.8, 116.81, 116.82]),
        [18.0, 19.0, 20.0],
        [3.6e6, np.nan, 3.61e6],
        [4.8e5, np.nan, 4.81e5],
        [21.4, 22.4, np.nan],
    )
    cp = io.read_control_points(c)
    np.testing.assert_allclose(np.degrees(cp.lat), [32.8, 32.81, 32.82], atol=1e-10)
    assert np.isnan(cp.x[1]) and np.isnan(cp.h[2]) and cp.h[0] == 21.4
    (tmp_path / "l2.csv").write_text("point,height\nP01,21.5\nP01,21.6\n")
    with pytest.raises(ValueError, match=r"l2.csv:3: point 'P01' repeats line 2"):
        io.read_levelling(tmp_path / "l2.csv")
    (tmp_path / "l3.csv").write_text("point,h\nP01,21.5\n")
    with pytest.raises(ValueError, match=r"l3.csv:1: header lacks column\(s\) \['height'\]"):
        io.read_levelling(tmp_path / "l3.csv")
    (tmp_path / "c2.csv").write_text("point,B,L,H,x,y,h\nK1,32.8,116.8,18.0,3600000,,21.0\n")
    with pytest.raises(ValueError, match=r"c2.csv:2: give both x and y"):
        io.read_control_points(tmp_path / "c2.csv")
    (tmp_path / "c3.csv").write_text("point,B,L,H,x,y,h\nK1,32.8,,18.0,,,21.0\n")
    with pytest.raises(ValueError, match=r"c3.csv:2: column 'L'"):
        io.read_control_points(tmp_path / "c3.csv")
    with pytest.raises(FileNotFoundError):
        io.read_levelling(tmp_path / "missing.csv")
