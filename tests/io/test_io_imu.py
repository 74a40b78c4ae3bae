"""RTKLIB-logged raw IMU reader (CSV + .tag) on the real walk file and on crafted bad input."""

import datetime as dt
import struct

import numpy as np
import pytest
from _paths import DATA_ROOT

from jaxnav.io._imu import GPS_EPOCH_UNIX, STANDARD_GRAVITY, read_rtklib_imu, read_rtklib_tag
from jaxnav.io._rtklib import GPS_EPOCH

DATA = DATA_ROOT / "rtklibexplorer-gnss-imu" / "walk_0827"
CSV, TAG, UPSTREAM = DATA / "imu_1730.csv", DATA / "imu_1730.csv.tag", DATA / "imu_1730_sf.csv"
T_START = (dt.datetime(2025, 8, 28, 17, 30, 40, 961000) - GPS_EPOCH).total_seconds()  # README: tag start, GPST


@pytest.fixture(scope="module")
def upstream():
    u = np.loadtxt(UPSTREAM, delimiter=",")
    return u[:, 0] - GPS_EPOCH_UNIX, u[:, 1:4], u[:, 4:7]  # GPST s since 1980, accel g, gyro rad/s


@pytest.fixture(scope="module")
def walk():
    return {m: read_rtklib_imu(CSV, TAG, timing=m) for m in ("counter", "arrival", "endpoints")}


def test_walk_tag_file_decodes_consistently():
    tags = read_rtklib_tag(TAG)
    assert tags.version == "EX" and tags.fpos_bytes == 4 and len(tags.tick) == 9560
    assert abs(tags.t_start - T_START) < 1e-6  # time_t 0x68b09240 = 1756402240 (GPST, Unix-style) + 0.961
    assert tags.tick_f == 0x2A05D895  # absolute PC tick; the records are already relative to it
    assert tags.tick[0] == 113 and tags.tick[-1] == 134271  # README: last tick 134 271 ms
    assert np.all(np.diff(tags.tick) >= 0) and np.all(np.diff(tags.fpos) > 0)
    # positions count the file as logged with CRLF; the stored copy has LF only: one byte per line less
    raw = CSV.read_bytes()
    assert b"\r" not in raw and tags.fpos[-1] == len(raw) + raw.count(b"\n")


def test_walk_file_reads(walk):
    log = walk["counter"]
    assert len(log.t) == 20455 and log.f_b.shape == (20455, 3) and log.w_b.shape == (20455, 3)
    assert log.n_skipped_lines == 2 and [k for k, _ in log.skipped] == [1, 20457]  # README: 20 457 lines
    assert "partial first line" in log.skipped[0][1] and "partial last line" in log.skipped[1][1]
    np.testing.assert_array_equal(log.lineno, np.arange(2, 20457))
    assert log.counter[0] == 3326345 and log.counter[-1] == 3460597
    assert set(np.unique(np.diff(log.counter))) == {6, 7, 8, 9}  # a millisecond counter, ~6.6 ms mean step
    assert log.t_start == pytest.approx(T_START, abs=1e-6)
    dt_ = np.diff(log.t)
    assert np.all(dt_ > 0) and abs(np.median(dt_) - 0.006) < 1e-4
    assert abs(log.t[-1] - log.t[0] - 134.3) < 0.1
    # at rest at the start: |f| about 1 g (the sensor reads 1.011 g), gyro about 0.2 deg/s
    assert 9.7 < np.linalg.norm(log.f_b[:100].mean(0)) < 10.1
    assert np.linalg.norm(log.w_b[:100].mean(0)) < np.radians(0.5)


def test_units_are_converted_exactly(walk):
    log = walk["counter"]
    line2 = CSV.read_text().splitlines()[1].split(",")  # -0.017,-0.007,1.011,0.038,-0.160,0.160,3326345
    np.testing.assert_array_equal(log.f_b[0], np.array([float(v) for v in line2[:3]]) * 9.80665)
    np.testing.assert_array_equal(log.w_b[0], np.array([float(v) for v in line2[3:6]]) * (np.pi / 180))
    assert STANDARD_GRAVITY == 9.80665


def test_times_match_upstream_converter(walk, upstream):
    tu = upstream[0]
    assert len(tu) == len(walk["counter"].t)
    # 'endpoints' is the upstream rule; its t column has 7 decimals on ~1.7e9 s (float64 ulp 2.4e-7 s)
    assert np.max(np.abs(walk["endpoints"].t - tu)) < 1e-6
    # 'counter': the same sample clock, but rate and offset fitted to all tag records instead of pinning
    # the first line to the file-open time (it arrived 113 ms later in a backlog burst) and the last line
    # to its arrival tick. Measured: max 11.6 ms, median 4.4 ms; bound: one 16 ms USB polling period.
    d = np.abs(walk["counter"].t - tu)
    assert d.max() < 0.016 and np.median(d) < 0.006
    # 'arrival': tag time of each line's last byte; the backlog at the start is 113 ms late
    a = walk["arrival"].t
    d = np.abs(a - tu)
    assert abs(d[0] - 0.113) < 1e-3 and np.median(d) < 0.010
    assert np.all(np.diff(a) >= 0) and np.sum(np.diff(a) == 0) == 15  # equal-tick records give ties


def test_counter_times_respect_read_times(walk):
    # read time of a line = tick of the first record covering its last byte (logged with CRLF)
    tags = read_rtklib_tag(TAG)
    ends = np.cumsum([len(s) + 2 for s in CSV.read_bytes().split(b"\n")])
    ends[-1] -= 2  # no newline after the last line
    log = walk["counter"]
    read = tags.t_start + tags.tick[np.searchsorted(tags.fpos, ends[log.lineno - 1])] * 1e-3
    lat = read - log.t
    assert lat.min() == pytest.approx(0.0, abs=1e-6)  # no sample dated after it was read, one at the bound
    assert np.median(lat) < 0.016  # and typically within one USB polling period of it
    rate = (log.t[-1] - log.t[0]) / ((log.counter[-1] - log.counter[0]) * 1e-3)
    assert abs(rate - 1) < 20e-6  # the IMU counter runs 9.5 ppm slow against the PC clock


def test_values_match_upstream_converter(walk, upstream):
    # the upstream file is low-pass filtered (zero phase): compare 1 s means (167 samples)
    _, acc_g, gyr = upstream
    log = walk["counter"]
    k = len(gyr) // 167

    def means(x):
        return x[: k * 167].reshape(k, 167, 3).mean(axis=1)

    assert np.max(np.abs(means(log.f_b / STANDARD_GRAVITY) - means(acc_g))) < 3e-3  # g; measured 1.4e-3
    assert np.max(np.abs(means(log.w_b) - means(gyr))) < 2e-3  # rad/s; measured 8.2e-4
    for j in range(3):  # column order: same axes
        assert np.corrcoef(log.w_b[:, j], gyr[:, j])[0, 1] > 0.99
        assert np.corrcoef(log.f_b[:, j], acc_g[:, j])[0, 1] > 0.9


# ---------------------------------------------------------------- crafted files


def _lines(n, c0=1000, step=6):
    return [f"{0.01 * i:.3f},-0.020,1.001,0.100,-0.200,{0.3 + i:.3f},{c0 + step * i}" for i in range(n)]


def _tag_bytes(
    text_bytes, *, every=3, dtick=16, header=b"TIMETAG RTKLIB EX", fpos_bytes=4, crlf=None, t_unix=1756402240, frac=0.5
):
    """A tag file for a data file written `every` lines per write, `dtick` ms apart."""
    logged = text_bytes if crlf is None else text_bytes.replace(b"\n", b"\r\n")
    ends = [i + 1 for i, ch in enumerate(logged) if ch == 0x0A]
    if not logged.endswith(b"\n"):
        ends.append(len(logged))
    fpos = ends[every - 1 :: every]
    if fpos[-1] != len(logged):
        fpos.append(len(logged))
    fmt = "<II" if fpos_bytes == 4 else "<IQ"
    recs = b"".join(struct.pack(fmt, dtick * (k + 1), p) for k, p in enumerate(fpos))
    return header.ljust(60, b"\0") + struct.pack("<IId", 123456, t_unix, frac) + recs


def _write(tmp_path, lines, name="x.csv", **tag_kw):
    f = tmp_path / name
    data = ("\n".join(lines) + "\n").encode()
    f.write_bytes(data)
    g = tmp_path / (name + ".tag")
    g.write_bytes(_tag_bytes(data, **tag_kw))
    return f, g


def test_crafted_log_times(tmp_path):
    # GPST since 1980 is ~1.44e9 s: float64 resolves 2.4e-7 s, hence atol=1e-6 on absolute times
    f, g = _write(tmp_path, _lines(30), dtick=18)  # 3 lines of 6 ms per write, writes 18 ms apart
    t_start = 1756402240 - GPS_EPOCH_UNIX + 0.5
    a = read_rtklib_imu(f, g, timing="arrival")
    assert a.n_skipped_lines == 0 and a.t_start == t_start
    np.testing.assert_allclose(a.t[2::3] - t_start, 0.018 * np.arange(1, 11), atol=1e-6)  # each write's last line
    np.testing.assert_allclose(np.diff(a.t[2:6]), 0.006, atol=1e-4)  # lines of one write spread by byte position
    assert a.t[0] == a.t[2]  # before the first record: nothing earlier is known, all get its tick
    c = read_rtklib_imu(f, g)
    np.testing.assert_allclose(np.diff(c.t), 0.006, atol=1e-6)
    np.testing.assert_allclose(c.t[2::3], a.t[2::3], atol=1e-6)  # last line of each write: read at once
    e = read_rtklib_imu(f, g, timing="endpoints")
    assert e.t[0] == t_start and e.t[-1] == pytest.approx(t_start + 0.180, abs=1e-6)
    n = read_rtklib_imu(f, t_start=1000.0)  # no tag: counter ms from the given start
    np.testing.assert_allclose(n.t, 1000.0 + 0.006 * np.arange(30), atol=1e-12)
    np.testing.assert_allclose(n.w_b[1], np.radians([0.1, -0.2, 1.3]))
    with pytest.raises(ValueError, match="t_start"):
        read_rtklib_imu(f)
    with pytest.raises(ValueError, match="needs the tag file"):
        read_rtklib_imu(f, t_start=0.0, timing="arrival")


def test_counter_clock_fit_on_realistic_arrivals(tmp_path):
    # 6 ms samples, counter 40 ppm slow against the PC, 16 ms reads with 5..15 ms latency
    rng = np.random.default_rng(0)
    n = 2000
    lines = _lines(n)
    data = ("\n".join(lines) + "\n").encode()
    ends = np.cumsum([len(s) + 1 for s in lines])
    t_true = 0.050 + 0.006 * np.arange(n) * (1 + 40e-6)
    read_at = np.ceil((t_true + rng.uniform(0.005, 0.015, n)) / 0.016) * 0.016
    ticks, idx = np.unique(np.round(read_at * 1000).astype(int), return_index=True)
    last = np.r_[idx[1:] - 1, n - 1]
    recs = b"".join(struct.pack("<II", k, int(ends[j])) for k, j in zip(ticks, last))
    (tmp_path / "r.csv").write_bytes(data)
    start = struct.pack("<IId", 1, int(GPS_EPOCH_UNIX), 0.0)  # the GPS epoch (Unix time 0 is refused)
    (tmp_path / "r.csv.tag").write_bytes(b"TIMETAG RTKLIB EX".ljust(60, b"\0") + start + recs)
    log = read_rtklib_imu(tmp_path / "r.csv", tmp_path / "r.csv.tag")
    err = log.t - t_true
    assert np.all(err > 0) and err.max() - err.min() < 2e-3  # a constant latency, no rate error
    assert err.mean() < 0.012


def test_crlf_logged_then_converted_to_lf(tmp_path):
    lines = _lines(20)
    f, g = _write(tmp_path, lines, crlf=True)  # tag counts CRLF bytes; the CSV holds LF
    a = read_rtklib_imu(f, g, timing="arrival")
    h = tmp_path / "y.csv"
    h.write_bytes(("\r\n".join(lines) + "\r\n").encode())
    (tmp_path / "y.csv.tag").write_bytes(g.read_bytes())
    b = read_rtklib_imu(h, tmp_path / "y.csv.tag", timing="arrival")
    np.testing.assert_array_equal(a.t, b.t)
    np.testing.assert_array_equal(a.f_b, b.f_b)


def test_eight_byte_positions_are_detected(tmp_path):
    f, g = _write(tmp_path, _lines(25), fpos_bytes=8)
    assert read_rtklib_tag(g).fpos_bytes == 8
    a = read_rtklib_imu(f, g, timing="arrival")
    f4, g4 = _write(tmp_path, _lines(25), name="z.csv")
    np.testing.assert_array_equal(a.t, read_rtklib_imu(f4, g4, timing="arrival").t)


def test_partial_first_and_last_lines_are_skipped_and_reported(tmp_path):
    lines = _lines(10)
    f = tmp_path / "p.csv"
    f.write_bytes(("\n".join([lines[0][9:]] + lines[1:] + ["", lines[0][:12]])).encode())  # + blank line
    log = read_rtklib_imu(f, t_start=0.0)
    assert len(log.t) == 9 and log.n_skipped_lines == 3
    assert [k for k, _ in log.skipped] == [1, 11, 12]
    assert "partial first" in log.skipped[0][1] and "blank" in log.skipped[1][1] and "partial last" in log.skipped[2][1]


def test_malformed_middle_line_names_file_and_line(tmp_path):
    lines = _lines(10)
    lines[4] = lines[4].replace("1.001", "1.0x1")
    f, g = _write(tmp_path, lines, name="bad.csv")
    with pytest.raises(ValueError, match=r"bad\.csv:5: malformed IMU line"):
        read_rtklib_imu(f, g)
    lines[4] = lines[4].rsplit(",", 1)[0]
    f, g = _write(tmp_path, lines, name="bad.csv")
    with pytest.raises(ValueError, match=r"bad\.csv:5: .*6 comma-separated fields, expected 7"):
        read_rtklib_imu(f, g)
    log = read_rtklib_imu(f, g, bad_lines="skip")
    assert len(log.t) == 9 and log.skipped[0][0] == 5


def test_counter_checks(tmp_path):
    lines = _lines(10)
    lines[6] = lines[6].rsplit(",", 1)[0] + ",1000"  # counter jumps back
    f, g = _write(tmp_path, lines, name="c.csv")
    with pytest.raises(ValueError, match=r"c\.csv:7: counter 1000 does not increase"):
        read_rtklib_imu(f, g)
    assert len(read_rtklib_imu(f, g, timing="arrival").t) == 10  # tag times still work
    wrap = _lines(5, c0=2**32 - 12)
    wrap = [s.rsplit(",", 1)[0] + f",{(2**32 - 12 + 6 * i) % 2**32}" for i, s in enumerate(wrap)]
    f = tmp_path / "w.csv"
    f.write_text("\n".join(wrap) + "\n")
    np.testing.assert_allclose(read_rtklib_imu(f, t_start=0.0).t, 0.006 * np.arange(5), atol=1e-12)
    # a counter in microseconds read as milliseconds disagrees with the tags by 1000x
    f, g = _write(tmp_path, _lines(300, step=6000), name="us.csv", every=1, dtick=6)
    with pytest.raises(ValueError, match="wrong counter_unit"):
        read_rtklib_imu(f, g)
    assert read_rtklib_imu(f, g, counter_unit=1e-6).t[-1] > 0


def test_bad_tag_files_name_the_file(tmp_path):
    f, g = _write(tmp_path, _lines(12), header=b"TIMETAG RTKLOB EX")
    with pytest.raises(ValueError, match=r"x\.csv\.tag: not an RTKLIB time-tag file"):
        read_rtklib_imu(f, g)
    f, g = _write(tmp_path, _lines(12))
    g.write_bytes(g.read_bytes()[:-3])  # partial last record
    with pytest.raises(ValueError, match=r"x\.csv\.tag: .*not a whole number"):
        read_rtklib_imu(f, g)
    g.write_bytes(g.read_bytes()[:50])
    with pytest.raises(ValueError, match=r"x\.csv\.tag"):
        read_rtklib_imu(f, g)
    # the tag of a longer file: positions beyond the CSV
    _, g_long = _write(tmp_path, _lines(40), name="long.csv")
    with pytest.raises(ValueError, match=r"long\.csv\.tag: the tag file ends at byte \d+ but .*x\.csv has \d+ bytes"):
        read_rtklib_imu(f, g_long)
    # decreasing ticks
    b = bytearray(_tag_bytes(f.read_bytes()))
    b[76:80] = struct.pack("<I", 10_000)
    g.write_bytes(bytes(b))
    with pytest.raises(ValueError, match=r"x\.csv\.tag: record 1 .*tick 32 is smaller"):
        read_rtklib_imu(f, g)
    with pytest.raises(FileNotFoundError):
        read_rtklib_imu(f, tmp_path / "missing.tag")
    with pytest.raises(ValueError, match="either tag_path or t_start"):
        read_rtklib_imu(f, g, t_start=0.0)
