"""KF-GINS text readers and the generic CSV readers (issue 18): round trips against known numbers,
units, missing values (masked and counted), errors naming FILE:LINE."""

import math

import numpy as np
import pytest

from jaxnav import ins, io
from jaxnav.io import ReaderError

WEEK, SOW0 = 2202, 456250.0


def _kf_imu(tmp_path, n=400, rate=200.0, seed=0):
    rng = np.random.default_rng(seed)
    t = SOW0 + np.arange(1, n + 1) / rate
    dth = rng.normal(0, 1e-3, (n, 3)) + [0, 0, 2e-4]
    dv = rng.normal(0, 1e-3, (n, 3)) + [0, 0, -9.8 / rate]  # FRD: an up force reads negative on z (down)
    p = tmp_path / "imu.txt"
    p.write_text(
        "".join(
            f"{t[k]:.4f}  {dth[k, 0]: .12e} {dth[k, 1]: .12e} {dth[k, 2]: .12e}  "
            f"{dv[k, 0]: .12e} {dv[k, 1]: .12e} {dv[k, 2]: .12e}\n"
            for k in range(n)
        )
    )
    return p, t, dth, dv


def test_kfgins_imu_round_trip(tmp_path):
    p, t, dth, dv = _kf_imu(tmp_path)
    log = io.read_kfgins_imu(p, gps_week=WEEK)
    np.testing.assert_allclose(log.t, WEEK * 604800.0 + t, rtol=0, atol=1e-6)
    assert log.timing == "increments" and log.n_skipped_lines == 0 and log.lineno[0] == 1
    # imu_increments (identity mounting) gives the file's increments back
    _, th, v, dt = io.imu_increments(log, np.eye(3))
    np.testing.assert_allclose(th, dth, rtol=1e-9, atol=1e-18)
    np.testing.assert_allclose(v, dv, rtol=1e-9, atol=1e-18)
    # FRD file axes -> jaxnav RFU body: the vertical force shows +g on up
    _, _, vb, dt = io.imu_increments(log, ins.sensor_to_body(np.eye(3)))
    assert np.mean(vb[:, 2] / dt) == pytest.approx(9.8, abs=0.05)
    # seconds of week without a week
    assert io.read_kfgins_imu(p).t[0] == pytest.approx(t[0])
    # a week rollover inside the file: seconds of week restart at 0, the times keep increasing
    q = tmp_path / "roll.txt"
    q.write_text("".join(f"{sow:.3f} 1e-4 0 0 0 0 -0.049\n" for sow in (604799.990, 604799.995, 0.0, 0.005)))
    log = io.read_kfgins_imu(q, gps_week=WEEK)
    np.testing.assert_allclose(np.diff(log.t), 0.005, atol=1e-6)
    assert log.t[2] == pytest.approx((WEEK + 1) * 604800.0)
    q.write_text("".join(f"{sow:.3f} 1e-4 0 0 0 0 -0.049\n" for sow in (456250.0, 456250.005, 0.0, 456250.015)))
    with pytest.raises(ReaderError, match=r"roll\.txt:3: time 0 s is not after"):  # a corrupted time, not a rollover
        io.read_kfgins_imu(q)


def test_kfgins_imu_missing_and_errors(tmp_path):
    p, *_ = _kf_imu(tmp_path, n=30)
    lines = p.read_text().splitlines()
    w = lines[9].split()
    w[3] = "nan"
    lines[9] = " ".join(w)
    p.write_text("\n".join(lines) + "\n")
    log = io.read_kfgins_imu(p)
    assert log.n_skipped_lines == 1 and log.skipped[0][0] == 10 and len(log.t) == 29
    bad = tmp_path / "bad.txt"
    for text, match in (
        (lines[0] + "\n" + lines[1] + " 1.0\n", r"bad\.txt:2: 8 fields, expected 7"),
        (lines[1] + "\n" + lines[0] + "\n", r"bad\.txt:2: time .* is not after"),
        (lines[0].replace(lines[0].split()[2], "inf", 1) + "\n", r"bad\.txt:1: column 'dthy'.*inf"),
        (lines[0].replace(lines[0].split()[4], "x1", 1) + "\n", r"bad\.txt:1: column 'dvx'.*'x1'"),
        (
            lines[0] + "\n" + lines[1].replace(lines[1].split()[1], "9", 1) + "\n",
            r"bad\.txt:2: angular rate .* exceeds 200",
        ),
        ("", r"bad\.txt: no data records"),
    ):
        bad.write_text(text)
        with pytest.raises(ReaderError, match=match):
            io.read_kfgins_imu(bad)


def _kf_gnss_rows(n=20, vel=False):
    rows = []
    for k in range(n):
        r = [SOW0 + k, 30.4447858 + 1e-6 * k, 114.4718661 + 2e-6 * k, 21.09 + 0.01 * k]
        if vel:
            r += [0.1 * k, 0.2, -0.05]
        r += [0.010, 0.009, 0.019]
        if vel:
            r += [0.02, 0.03, 0.04]
        rows.append(r)
    return rows


def test_kfgins_gnss_7_and_13_columns(tmp_path):
    p = tmp_path / "gnss.txt"
    p.write_text("".join("  ".join(f"{x:.10f}" for x in r) + "\n" for r in _kf_gnss_rows()))
    s = io.read_kfgins_gnss(p, gps_week=WEEK)
    assert s.t[0] == WEEK * 604800.0 + SOW0 and s.n_masked == 0
    assert math.degrees(s.lat[0]) == pytest.approx(30.4447858) and math.degrees(s.lon[1]) == pytest.approx(114.4718681)
    np.testing.assert_allclose(np.diagonal(s.cov_enu[0]), [0.009**2, 0.010**2, 0.019**2])  # east, north, up
    assert np.all(np.isnan(s.v_enu)) and np.all(s.q == 1)
    p.write_text("".join(",".join(f"{x:.10f}" for x in r) + "\n" for r in _kf_gnss_rows(vel=True)))
    s = io.read_kfgins_gnss(p, quality=2)
    np.testing.assert_allclose(s.v_enu[3], [0.2, 0.3, 0.05])  # N, E, D -> E, N, U
    np.testing.assert_allclose(np.diagonal(s.vcov_enu[3]), [0.03**2, 0.02**2, 0.04**2])
    np.testing.assert_allclose(np.diagonal(s.cov_enu[3]), [0.009**2, 0.010**2, 0.019**2])
    assert np.all(s.q == 2)


def test_kfgins_gnss_missing_and_errors(tmp_path):
    rows = _kf_gnss_rows(vel=True)
    text = ["  ".join(f"{x:.10f}" for x in r) for r in rows]
    w = text[4].split()
    w[1] = "nan"  # latitude missing: epoch dropped
    text[4] = " ".join(w)
    w = text[6].split()
    w[5] = "NaN"  # a velocity missing: NaN row
    text[6] = " ".join(w)
    p = tmp_path / "g.txt"
    p.write_text("\n".join(text) + "\n")
    s = io.read_kfgins_gnss(p)
    assert s.n_masked == 2 and len(s.t) == 19
    assert np.isnan(s.v_enu[5]).all() and np.isfinite(np.delete(s.v_enu, 5, 0)).all()
    # a bad value in the third row, written as the file's second line
    for i, val, match in (
        (1, "95.0", r"g\.txt:2: latitude 95"),
        (8, "-0.01", r"g\.txt:2: position standard dev"),
        (0, "1e5", r"g\.txt:2: time .* is not after"),
    ):
        t2 = list(text)
        w = t2[2].split()
        w[i] = val
        t2[2] = " ".join(w)
        p.write_text("\n".join(t2[1:]) + "\n")
        with pytest.raises(ReaderError, match=match):
            io.read_kfgins_gnss(p)
    p.write_text("1 2 3 4 5\n")
    with pytest.raises(ReaderError, match=r"g\.txt:1: 5 fields; a KF-GINS GNSS file has 7 or 13"):
        io.read_kfgins_gnss(p)


def test_csv_imu_units_header_and_increments(tmp_path):
    rng = np.random.default_rng(3)
    n = 50
    t_ms = 1.4e12 + 10.0 * np.arange(n)
    g_dps = rng.normal(0, 5, (n, 3))
    a_g = rng.normal(0, 0.1, (n, 3)) + [0, 0, 1]
    p = tmp_path / "imu.csv"
    p.write_text(
        "# my logger\ntime_ms,gx,gy,gz,ax,ay,az,temp\n"
        + "".join(
            f"{t_ms[k]:.1f},{g_dps[k, 0]:.9f},{g_dps[k, 1]:.9f},{g_dps[k, 2]:.9f},{a_g[k, 0]:.9f},{a_g[k, 1]:.9f},"
            f"{a_g[k, 2]:.9f},25.0\n"
            for k in range(n)
        )
    )
    cols = {"t": "time_ms", "gx": "gx", "gy": "gy", "gz": "gz", "ax": "ax", "ay": "ay", "az": "az"}
    log = io.read_csv_imu(p, cols, {"t": "ms", "gyro": "deg/s", "accel": "g"})
    np.testing.assert_allclose(log.t, t_ms * 1e-3)
    np.testing.assert_allclose(log.w_b, np.radians(g_dps), atol=1e-10)  # 9 decimals written
    np.testing.assert_allclose(log.f_b, a_g * 9.80665, atol=1e-8)
    assert log.lineno[0] == 3
    # the same by index, no header line: the header is recognised as text and skipped
    cols_i = {"t": 0, "gx": 1, "gy": 2, "gz": 3, "ax": 4, "ay": 5, "az": 6}
    log2 = io.read_csv_imu(p, cols_i, {"t": "ms", "gyro": "deg/s", "accel": "g"})
    np.testing.assert_array_equal(log2.w_b, log.w_b)
    # increments, blank-separated, week + tow
    q = tmp_path / "inc.txt"
    q.write_text("".join(f"{WEEK} {SOW0 + 0.01 * k:.2f} {1e-3 * k} 0 0 0 0 -0.098\n" for k in range(1, 6)))
    cols = {"week": 0, "tow": 1, "dthx": 2, "dthy": 3, "dthz": 4, "dvx": 5, "dvy": 6, "dvz": 7}
    log3 = io.read_csv_imu(q, cols, {"gyro": "rad", "accel": "m/s"}, delimiter=None)
    assert log3.t[0] == pytest.approx(WEEK * 604800 + SOW0 + 0.01)
    # (float64 GPST seconds resolve 0.24 us: a 10 ms interval to 2.4e-5 relative)
    np.testing.assert_allclose(log3.w_b[:, 0], 1e-3 * np.arange(1, 6) / 0.01, rtol=3e-5)
    np.testing.assert_allclose(log3.f_b[:, 2], -9.8, rtol=3e-5)


def test_csv_imu_bad_maps_and_lines(tmp_path):
    p = tmp_path / "i.csv"
    p.write_text("0.00,1,2,3,4,5,6\n0.01,1,2,nan,4,5,6\n0.02,1,2,3,4,5,6\n")
    cols = {"t": 0, "gx": 1, "gy": 2, "gz": 3, "ax": 4, "ay": 5, "az": 6}
    log = io.read_csv_imu(p, cols)
    assert log.n_skipped_lines == 1 and log.skipped == ((2, "missing value (nan)"),)
    with pytest.raises(ValueError, match="not a mix"):
        io.read_csv_imu(p, {"t": 0, "gx": 1, "gy": 2, "gz": 3, "dvx": 4, "dvy": 5, "dvz": 6})
    with pytest.raises(ValueError, match="unit gyro='dps'"):
        io.read_csv_imu(p, cols, {"gyro": "dps"})
    with pytest.raises(ValueError, match="unknown column key 'gyro_x'"):
        io.read_csv_imu(p, {**cols, "gyro_x": 1})
    with pytest.raises(ValueError, match="needs 't'"):
        io.read_csv_imu(p, {k: v for k, v in cols.items() if k != "t"})
    p.write_text("0.00,1,2,3,4,5,6\n0.01,1,2,3,4,5\n")
    with pytest.raises(ReaderError, match=r"i\.csv:2: 6 fields, the column map needs 7"):
        io.read_csv_imu(p, cols)
    p.write_text("t,gx\n0.00,1,2,3,4,5,6\n")
    with pytest.raises(ReaderError, match=r"i\.csv:1: the header has no column 'gy'"):
        io.read_csv_imu(p, {"t": "t", "gx": "gx", "gy": "gy", "gz": "gz", "ax": 4, "ay": 5, "az": 6})


def test_csv_gnss(tmp_path):
    p = tmp_path / "g.csv"
    rows = ["t,lat_rad,lon_rad,h,se,sn,su,vn,ve,vd,fix"]
    for k in range(10):
        rows.append(
            f"{100 + k},{0.53 + 1e-7 * k:.12f},{1.99:.12f},{50 + k},0.02,0.03,0.05,1.0,2.0,-0.1,{1 if k % 2 else 2}"
        )
    p.write_text("\n".join(rows) + "\n")
    cols = {
        "t": "t",
        "lat": "lat_rad",
        "lon": "lon_rad",
        "h": "h",
        "sd_e": "se",
        "sd_n": "sn",
        "sd_u": "su",
        "vn": "vn",
        "ve": "ve",
        "vd": "vd",
        "q": "fix",
    }
    s = io.read_csv_gnss(p, cols, {"angle": "rad"})
    assert s.lat[0] == pytest.approx(0.53, abs=1e-12) and list(s.q[:2]) == [2, 1]
    np.testing.assert_allclose(s.v_enu[0], [2.0, 1.0, 0.1])
    np.testing.assert_allclose(np.diagonal(s.cov_enu[0]), [0.02**2, 0.03**2, 0.05**2])
    assert np.all(np.isnan(s.vcov_enu))  # no velocity sigmas given
    s2 = io.read_csv_gnss(p, {"t": 0, "lat": 1, "lon": 2, "h": 3}, {"angle": "rad"}, sigma_m=(1.0, 1.0, 2.0))
    np.testing.assert_allclose(np.diagonal(s2.cov_enu[4]), [1.0, 1.0, 4.0])
    assert np.all(s2.q == 1)
    with pytest.raises(ValueError, match="sigma_m"):
        io.read_csv_gnss(p, {"t": 0, "lat": 1, "lon": 2, "h": 3})
    with pytest.raises(ValueError, match="all three position sigmas"):
        io.read_csv_gnss(p, {"t": 0, "lat": 1, "lon": 2, "h": 3, "sd_e": 4})
    p.write_text("\n".join(rows[:3] + [rows[3].replace(",50.02,", ",-1e6,").replace(",52,", ",-1e6,")]) + "\n")
    with pytest.raises(ReaderError, match=r"g\.csv:4: height -1e\+06 is outside"):
        io.read_csv_gnss(p, cols, {"angle": "rad"})


def test_kfgins_odometer_column_and_csv_series(tmp_path):
    """The 8th column of a KF-GINS IMU file (wheel speed) read with its tags, the IMU part read with the column
    count detected; aiding series from a CSV with units (km/h, deg), a missing reading kept as NaN."""
    p, t, dth, dv = _kf_imu(tmp_path, n=50)
    sp = np.linspace(0.0, 12.0, 50)
    sp[7] = np.nan
    lines = p.read_text().splitlines()
    p.write_text("".join(f"{ln} {s:.4f}\n" for ln, s in zip(lines, sp)))
    to, so = io.read_kfgins_odometer(p, gps_week=WEEK)
    np.testing.assert_allclose(to, WEEK * 604800.0 + t, atol=1e-6)
    np.testing.assert_allclose(so, sp, atol=1e-4)
    assert np.isnan(so[7])
    log = io.read_kfgins_imu(p, gps_week=WEEK, n_columns=None)
    np.testing.assert_allclose(log.t, to, atol=0)
    with pytest.raises(ReaderError, match=r"imu\.txt:1: 8 fields, expected 7"):
        io.read_kfgins_imu(p)
    c = tmp_path / "wheel.csv"
    c.write_text("time,kmh\n1.0,36.0\n2.0,nan\n3.0,72.0\n")
    d = io.read_csv_series(c, {"t": "time", "speed": "kmh"}, {"speed": "km/h"})
    np.testing.assert_allclose(d["speed"], [10.0, np.nan, 20.0])
    h = tmp_path / "hdg.csv"
    h.write_text("1.0,90.0,0.5\n2.0,180.0,0.5\n")
    d = io.read_csv_series(h, {"t": 0, "heading": 1, "sigma": 2}, kind="heading")
    np.testing.assert_allclose(d["heading"], [math.pi / 2, math.pi])
    np.testing.assert_allclose(d["sigma"], np.radians([0.5, 0.5]))
    h.write_text("1.0,90.0\n1.0,91.0\n")
    with pytest.raises(ReaderError, match=r"hdg\.csv:2: the time does not increase"):
        io.read_csv_series(h, {"t": 0, "heading": 1}, kind="heading")
