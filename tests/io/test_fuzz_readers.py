"""Seeded fuzzing of every file reader: mutated real files (a few hundred lines copied from the
shared data at run time) and small self-made fixtures.

For each reader a few hundred mutations (byte flips, non-UTF-8 and NUL bytes, truncation, line
deletion/duplication/swaps, field swaps, nan/inf/1e308/-1/9e99/huge numbers in a field, an
over-long field, empty and header-only files) must each end in one of three ways:

* a :class:`jaxnav.io.ReaderError` (a ValueError) whose message starts with the file name and
  names the line when a line is at fault -- never another exception type;
* a clean read whose arrays are finite;
* a read whose non-finite values are exactly the ones the reader counts (``n_masked``, skipped
  IMU lines), i.e. a missing value the format allows.

The counts per reader are printed (``pytest -s``) and kept in ``COUNTS``.
"""

from __future__ import annotations

import math
import pathlib
import random
import struct

import numpy as np
import pytest
from _paths import DATA_ROOT

from jaxnav import io
from jaxnav.io import ReaderError

SEED = 20
N_MUTATIONS = 240
BAD_TOKENS = [
    "nan",
    "NaN",
    "inf",
    "-inf",
    "1e308",
    "-1e308",
    "1e999",
    "-1",
    "9e99",
    "0",
    "99999999999999999999999999",
    "",
    "x",
    "--",
    "1,5",
    "0x10",
    "-0",
]
COUNTS: dict = {}


# ----------------------------------------------------------------------------- sources


def _head(rel, n_lines, *, keep_comments=True):
    """The first ``n_lines`` lines of a shared-data file (bytes), or skip the test if absent."""
    p = DATA_ROOT / rel
    if not p.exists():
        pytest.skip(f"shared data {rel} not present")
    lines = p.read_bytes().split(b"\n")
    return b"\n".join(lines[:n_lines]) + b"\n"


def _epoch_log_fixture():
    rng = np.random.default_rng(1)
    rows = ["# RTK epoch log (fixture)", "point,time,x,y,h,B,L,H,sigma_x,sigma_y,sigma_h"]
    for p in range(3):
        for k in range(25):
            rows.append(
                f"P{p:02d},{100 * p + 2 * k},{3631500 + p + rng.normal(0, 0.01):.4f},"
                f"{39486000 + p + rng.normal(0, 0.01):.4f},{22.1 + rng.normal(0, 0.02):.4f},"
                f"{32.81 + p * 1e-4:.10f},{116.85 + p * 1e-4:.10f},{18.67 + rng.normal(0, 0.02):.4f},"
                f"0.0080,0.0080,0.0150"
            )
    return ("\n".join(rows) + "\n").encode()


def _control_fixture():
    rows = ["point,B,L,H,x,y,h"]
    for i in range(8):
        xy = "" if i == 7 else f"{3631000 + 100 * i:.4f},{39486000 + 90 * i:.4f}"
        rows.append(
            f"K{i},{32.80 + 0.001 * i:.10f},{116.84 + 0.001 * i:.10f},{18 + i:.4f},"
            + (xy if xy else ",")
            + f",{21.5 + i:.4f}"
        )
    return ("\n".join(rows) + "\n").encode()


def _levelling_fixture():
    return ("point,height\n" + "".join(f"P{i:02d},{20 + 0.37 * i:.4f}\n" for i in range(20))).encode()


def _stop_fixture():
    rows = [
        "# name, kind, t_start_s, t_end_s, lat_deg, lon_deg, h_m, sigma_e_m, sigma_n_m, sigma_u_m",
        "K0, known_coordinate, 0, 10, 32.0, 118.0, 10.0",
    ]
    t = 20.0
    for i in range(12):
        kind = ("zupt", "target", "levelling")[i % 3]
        h = "12.5" if kind == "levelling" else "nan"
        rows.append(f"S{i}, {kind}, {t:.1f}, {t + 8:.1f}, nan, nan, {h}, 0.01, 0.01, 0.01")
        t += 30
    rows.append(f"K1, known_coordinate, {t:.1f}, {t + 10:.1f}, 32.001, 118.001, 11.0")
    return ("\n".join(rows) + "\n").encode()


def _kfgins_imu_fixture():
    rng = np.random.default_rng(4)
    return "".join(
        f"{456250.0 + 0.005 * k:.3f} "
        + " ".join(f"{x: .9e}" for x in rng.normal(0, 1e-3, 3))
        + " "
        + " ".join(f"{x: .9e}" for x in rng.normal(0, 1e-3, 2))
        + f" {-0.049 + rng.normal(0, 1e-4): .9e}\n"
        for k in range(1, 121)
    ).encode()


def _kfgins_gnss_fixture():
    rng = np.random.default_rng(5)
    rows = []
    for k in range(80):
        rows.append(
            f"{456250 + k:.3f} {30.4447858 + 1e-6 * k:.10f} {114.4718661 + 1e-6 * k:.10f} "
            f"{21.09 + rng.normal(0, 0.01):.3f} {0.1 * k:.3f} {0.2:.3f} {-0.01:.3f} 0.010 0.009 0.019 "
            "0.020 0.020 0.030"
        )
    return ("\n".join(rows) + "\n").encode()


def _csv_imu_fixture():
    rng = np.random.default_rng(6)
    rows = ["# generic IMU log", "time_ms,gx,gy,gz,ax,ay,az"]
    for k in range(120):
        g = rng.normal(0, 2, 3)
        a = rng.normal(0, 0.05, 3) + [0, 0, 1]
        rows.append(f"{1.4e12 + 10 * k:.1f},{g[0]:.6f},{g[1]:.6f},{g[2]:.6f},{a[0]:.6f},{a[1]:.6f},{a[2]:.6f}")
    return ("\n".join(rows) + "\n").encode()


def _csv_gnss_fixture():
    rows = ["t,lat,lon,h,sd_e,sd_n,sd_u,ve,vn,vu,q"]
    for k in range(80):
        rows.append(
            f"{1.4e9 + 0.2 * k:.1f},{52.1 + 1e-7 * k:.10f},{13.4 + 1e-7 * k:.10f},{40 + 0.01 * k:.3f},"
            f"0.02,0.02,0.04,{0.5:.3f},{0.4:.3f},0.0,{1 + k % 2}"
        )
    return ("\n".join(rows) + "\n").encode()


# ----------------------------------------------------------------------------- output checks


def _finite(*arrays):
    return all(np.all(np.isfinite(np.asarray(a, float))) for a in arrays)


def _check_pos(s):
    assert _finite(s.t, s.lat, s.lon, s.h, s.cov_enu, s.q, s.ns)
    for a in (s.v_enu, s.age, s.ratio):  # NaN only where the column is absent (the whole column)
        a = np.asarray(a, float).reshape(len(s.t), -1)
        for j in range(a.shape[1]):
            assert np.all(np.isfinite(a[:, j])) or np.all(np.isnan(a[:, j]))
    return 0


def _check_imu(s):
    assert _finite(s.t, s.f_b, s.w_b, s.counter)
    assert np.all(np.abs(s.f_b) <= 1000.0) and np.all(np.diff(s.t) > 0)
    assert s.n_skipped_lines == len(s.skipped)
    return s.n_skipped_lines


def _check_pos_masked(s):
    """KF-GINS / CSV GNSS: positions finite; NaN velocity rows only as counted missing values."""
    assert _finite(s.t, s.lat, s.lon, s.h, s.cov_enu, s.q, s.ns) and np.all(np.diff(s.t) > 0)
    v = np.asarray(s.v_enu, float)
    assert not np.any(np.isinf(v))
    nan_rows = int(np.any(np.isnan(v), axis=1).sum())
    assert nan_rows == len(s.t) or nan_rows <= s.n_masked  # no velocity columns, or masked ones
    return s.n_masked


def _read_csv_imu(p):
    cols = {"t": "time_ms", "gx": "gx", "gy": "gy", "gz": "gz", "ax": "ax", "ay": "ay", "az": "az"}
    return io.read_csv_imu(p, cols, {"t": "ms", "gyro": "deg/s", "accel": "g"})


def _read_csv_gnss(p):
    cols = {k: k for k in ("t", "lat", "lon", "h", "sd_e", "sd_n", "sd_u", "ve", "vn", "vu", "q")}
    return io.read_csv_gnss(p, cols)


def _check_tag(s):
    assert math.isfinite(s.t_start) and len(s.tick) > 0
    assert np.all(np.diff(s.tick) >= 0) and np.all(np.diff(s.fpos) >= 0)
    return 0


def _check_daily(s):
    assert _finite(s.t, s.year, s.cov, s.origin) and np.all(np.diff(s.t) > 0)
    assert not np.any(np.isinf(s.enu))
    assert int(np.isnan(s.enu).sum()) == s.n_masked  # every NaN is a counted missing value
    return s.n_masked


def _check_epoch_log(s):
    a = np.stack([s.x, s.y, s.h, s.lat, s.lon, s.H, *s.sigma.T], 1)
    assert _finite(s.t) and not np.any(np.isinf(a))
    assert int(np.any(np.isnan(a), axis=1).sum()) == s.n_masked
    return s.n_masked


def _check_levelling(s):
    assert _finite(s.height)
    return 0


def _check_control(s):
    assert _finite(s.lat, s.lon, s.H)
    assert not np.any(np.isinf(np.stack([s.x, s.y, s.h])))
    return int(np.isnan(np.stack([s.x, s.y, s.h])).sum())  # "not given": allowed by the format


def _check_stops(s):
    assert _finite(s.t_start, s.t_end, s.sigma) and not np.any(np.isinf(s.pos))
    return 0


def _read_imu(p):
    return io.read_rtklib_imu(p, t_start=1.4e9)


def _read_experiment(p):
    from jaxnav.experiments.s0 import load_experiment

    return load_experiment(p)


def _check_experiment(d):
    f = d["filter"]
    assert 0.0 <= f["b"] < 1.0 and f["q_scale"] > 0 and f["r_scale"] > 0 and d["monte_carlo"]["seeds"] >= 1
    return 0


def _experiment_source():
    from jaxnav.experiments.s0 import EXPERIMENT

    return pathlib.Path(EXPERIMENT).read_bytes()


#: name -> (source bytes factory, file suffix, reader, output check, field delimiter or None for binary)
READERS = {
    "pos": (lambda: _head("rtk_pos_matrtklib/static/rover_rtk.pos", 330), ".pos", io.read_pos, _check_pos, None),
    "imu_csv": (
        lambda: _head("rtklibexplorer-gnss-imu/walk_0827/imu_1730.csv", 300),
        ".csv",
        _read_imu,
        _check_imu,
        b",",
    ),
    "imu_tag": (
        lambda: _head_bytes("rtklibexplorer-gnss-imu/walk_0827/imu_1730.csv.tag", 76 + 8 * 200),
        ".tag",
        io.read_rtklib_tag,
        _check_tag,
        "binary",
    ),
    "tenv3": (lambda: _head("gnss_daily_timeseries/LHAS.tenv3", 300), ".tenv3", io.read_daily, _check_daily, None),
    "neu": (lambda: _head("gnss_daily_timeseries/bjfsCleanUnf.neu", 320), ".neu", io.read_daily, _check_daily, None),
    "pbo": (lambda: _pbo_fixture(), ".pos", io.read_daily, _check_daily, None),
    "col": (
        lambda: _head("gnss_daily_timeseries/UH01_GOM20_neu_cm.col", 300),
        ".col",
        io.read_daily,
        _check_daily,
        None,
    ),
    "epoch_log": (_epoch_log_fixture, ".csv", io.read_epoch_log, _check_epoch_log, b","),
    "control": (_control_fixture, ".csv", io.read_control_points, _check_control, b","),
    "levelling": (_levelling_fixture, ".csv", io.read_levelling, _check_levelling, b","),
    "stop_list": (_stop_fixture, ".csv", io.read_stop_list, _check_stops, b","),
    "s0_experiment_toml": (_experiment_source, ".toml", _read_experiment, _check_experiment, b"="),
    "kfgins_imu": (_kfgins_imu_fixture, ".txt", io.read_kfgins_imu, _check_imu, None),
    "kfgins_gnss": (_kfgins_gnss_fixture, ".txt", io.read_kfgins_gnss, _check_pos_masked, None),
    "csv_imu": (_csv_imu_fixture, ".csv", _read_csv_imu, _check_imu, b","),
    "csv_gnss": (_csv_gnss_fixture, ".csv", _read_csv_gnss, _check_pos_masked, b","),
}


def _head_bytes(rel, n):
    p = DATA_ROOT / rel
    if not p.exists():
        pytest.skip(f"shared data {rel} not present")
    return p.read_bytes()[:n]


# ----------------------------------------------------------------------------- mutations


def _split_fields(line, delim):
    return line.split(delim) if delim not in (None, b"=") else line.split()


def _join_fields(fields, delim):
    return (delim if delim not in (None, b"=") else b" ").join(fields)


def _text_mutation(rng: random.Random, data: bytes, delim):
    """One mutation of a text file; returns (bytes, kind, 1-based line at fault or None)."""
    lines = data.split(b"\n")
    if lines and lines[-1] == b"":
        lines = lines[:-1]
    n = len(lines)
    data_idx = [i for i, l in enumerate(lines) if l.strip() and not l.lstrip().startswith((b"#", b"%"))]
    kind = rng.choice(
        [
            "flip",
            "non_utf8",
            "nul",
            "truncate",
            "delete",
            "duplicate",
            "swap_lines",
            "swap_fields",
            "bad_token",
            "bad_token",
            "bad_token",
            "long_field",
            "empty",
            "header_only",
            "crlf",
        ]
    )
    i = rng.choice(data_idx) if data_idx else 0
    line_at_fault = None
    if kind == "flip":
        pos = rng.randrange(len(data)) if data else 0
        out = data[:pos] + bytes([rng.randrange(256)]) + data[pos + 1 :]
    elif kind == "non_utf8":
        pos = rng.randrange(len(lines[i]) + 1)
        lines[i] = lines[i][:pos] + rng.choice([b"\xe9", b"\xff", b"\xc3"]) + lines[i][pos:]
        out, line_at_fault = b"\n".join(lines) + b"\n", i + 1
    elif kind == "nul":
        lines[i] = lines[i] + b"\x00"
        out, line_at_fault = b"\n".join(lines) + b"\n", i + 1
    elif kind == "truncate":
        out = data[: rng.randrange(len(data) + 1)]
    elif kind == "delete":
        out = b"\n".join(lines[:i] + lines[i + 1 :]) + b"\n"
    elif kind == "duplicate":
        out = b"\n".join(lines[: i + 1] + [lines[i]] + lines[i + 1 :]) + b"\n"
    elif kind == "swap_lines":
        j = min(i + 1, n - 1)
        lines[i], lines[j] = lines[j], lines[i]
        out = b"\n".join(lines) + b"\n"
    elif kind == "swap_fields":
        f = _split_fields(lines[i], delim)
        if len(f) > 1:
            a, b = rng.sample(range(len(f)), 2)
            f[a], f[b] = f[b], f[a]
        lines[i] = _join_fields(f, delim)
        out = b"\n".join(lines) + b"\n"
    elif kind == "bad_token":
        if delim == b"=":  # TOML: a value after '='
            cands = [k for k, l in enumerate(lines) if b"=" in l and not l.lstrip().startswith(b"#")]
            i = rng.choice(cands)
            key = lines[i].split(b"=", 1)[0]
            lines[i] = (
                key
                + b"= "
                + rng.choice([b"nan", b"inf", b"-1", b"1.5", b"1e308", b"0", b'"x"', b"true", b"[]", b"-0.1", b"2e9"])
            )
        else:
            f = _split_fields(lines[i], delim)
            f[rng.randrange(len(f))] = rng.choice(BAD_TOKENS).encode()
            lines[i] = _join_fields(f, delim)
            line_at_fault = i + 1
        out = b"\n".join(lines) + b"\n"
    elif kind == "long_field":
        lines[i] = lines[i] + (delim if delim not in (None, b"=") else b" ") + b"9" * 200_000
        out, line_at_fault = b"\n".join(lines) + b"\n", i + 1
    elif kind == "empty":
        out = b""
    elif kind == "header_only":
        out = b"\n".join(lines[: (data_idx[0] if data_idx else n)]) + b"\n"
    else:  # crlf: harmless, must still read
        out = b"\r\n".join(lines) + b"\r\n"
    return out, kind, line_at_fault


def _binary_mutation(rng: random.Random, data: bytes):
    """One mutation of a binary RTKLIB tag file; returns (bytes, kind, None)."""
    kind = rng.choice(
        [
            "flip",
            "flip",
            "truncate",
            "header_only",
            "empty",
            "start_time",
            "fraction",
            "reverse",
            "partial_record",
            "append_garbage",
        ]
    )
    b = bytearray(data)
    if kind == "flip":
        for _ in range(rng.randint(1, 4)):
            b[rng.randrange(len(b))] = rng.randrange(256)
    elif kind == "truncate":
        b = b[: rng.randrange(len(b))]
    elif kind == "header_only":
        b = b[:76]
    elif kind == "empty":
        b = bytearray()
    elif kind == "start_time":
        struct.pack_into("<I", b, 64, rng.choice([0, 1, 2**32 - 1, 315964799]))
    elif kind == "fraction":
        struct.pack_into("<d", b, 68, rng.choice([math.nan, math.inf, -0.5, 1.0, 1e308]))
    elif kind == "reverse":
        recs = [bytes(b[k : k + 8]) for k in range(76, len(b), 8)]
        b = b[:76] + b"".join(recs[::-1])
    elif kind == "partial_record":
        b = b + b"\x01\x02\x03"
    else:
        b = b + bytes(rng.randrange(256) for _ in range(8 * rng.randint(1, 5)))
    return bytes(b), kind, None


# ----------------------------------------------------------------------------- the test


@pytest.mark.parametrize("name", list(READERS))
def test_reader_fuzz(name, tmp_path):
    source, suffix, reader, check, delim = READERS[name]
    data = source()
    rng = random.Random(f"{SEED}-{name}")
    counts = {"error_file_and_line": 0, "error_file_only": 0, "masked_counted": 0, "clean": 0}
    clean = reader(_write(tmp_path / f"orig{suffix}", data))  # the unmutated source reads cleanly
    baseline = check(clean)  # e.g. the real IMU log's cut-off first line, skipped and counted
    file_only = {}
    for k in range(N_MUTATIONS):
        if delim == "binary":
            mutated, kind, line_at_fault = _binary_mutation(rng, data)
        else:
            mutated, kind, line_at_fault = _text_mutation(rng, data, delim)
        path = _write(tmp_path / f"m{k:03d}{suffix}", mutated)
        try:
            out = reader(path)
        except ReaderError as exc:
            msg = str(exc)
            assert msg.startswith(f"{path}:") or msg.startswith(f"{path} "), (kind, msg)
            assert "\n" not in msg and len(msg) < 600, (kind, msg[:200])
            if exc.line is not None:
                assert 1 <= exc.line <= mutated.count(b"\n") + 1, (kind, msg)
                counts["error_file_and_line"] += 1
            else:
                counts["error_file_only"] += 1
                file_only[kind] = file_only.get(kind, 0) + 1
            if line_at_fault is not None and kind in ("non_utf8", "nul"):
                assert exc.line == line_at_fault, (kind, msg)
        except ValueError as exc:  # the config loaders raise ValueError naming the file (TOML syntax: + line)
            assert name == "s0_experiment_toml", (kind, type(exc).__name__, str(exc)[:200])
            assert str(exc).startswith(str(path)), (kind, str(exc)[:200])
            counts[
                "error_file_and_line" if str(exc).startswith(f"{path}:") and "line" in str(exc) else "error_file_only"
            ] += 1  # TOML: the file and the key (filter.b = 1.5 ...)
        else:
            masked = check(out)
            counts["masked_counted" if masked > baseline else "clean"] += 1
    COUNTS[name] = counts
    print(f"\nfuzz {name}: {N_MUTATIONS} mutations -> {counts}; file-level errors by mutation: {file_only}")
    assert sum(counts.values()) == N_MUTATIONS
    if delim != "binary" and name != "s0_experiment_toml":  # text: only whole-file faults go without a line
        whole_file = {"empty", "header_only", "truncate", "delete", "flip"}
        if name == "pbo":  # fields swapped in the header's last line: no header end, so no records
            whole_file.add("swap_fields")
        assert set(file_only) <= whole_file, file_only
    assert counts["error_file_and_line"] + counts["error_file_only"] > N_MUTATIONS // 10  # the fuzzing bites


def _write(path, data):
    path.write_bytes(data)
    return path


def test_named_examples_of_the_issue(tmp_path):
    """The issue's cases, each by name: header-only .tag, 0xE9 in an epoch log, K2,inf in a control
    file, an accelerometer value of 9e99, a nan east value in a tenv3 file (masked, counted, and
    the LS slope stays finite)."""
    tag = tmp_path / "h.csv.tag"
    tag.write_bytes(b"TIMETAG RTKLIB EX".ljust(60, b"\0") + struct.pack("<IId", 1, 1756402240, 0.5))
    with pytest.raises(ReaderError, match=r"h\.csv\.tag: no time-tag records"):
        io.read_rtklib_tag(tag)
    log = tmp_path / "e.csv"
    log.write_bytes(_epoch_log_fixture().replace(b"P01,", b"P\xe901,", 1))
    with pytest.raises(ReaderError, match=r"e\.csv:28: not UTF-8 text: byte 0xE9 at column 2"):
        io.read_epoch_log(log)
    cp = tmp_path / "c.csv"
    cp.write_bytes(_control_fixture().replace(b"K2,32.8020000000", b"K2,inf"))
    with pytest.raises(ReaderError, match=r"c\.csv:4: column 'B': 'inf' is not a finite number"):
        io.read_control_points(cp)
    imu = tmp_path / "i.csv"
    imu.write_text(
        "".join(f"0.01,0.02,1.0,0.1,0.2,0.3,{1000 + 6 * k}\n" for k in range(20)).replace(
            "0.01,0.02,1.0,0.1,0.2,0.3,1030", "0.01,9e99,1.0,0.1,0.2,0.3,1030"
        )
    )
    with pytest.raises(ReaderError, match=r"i\.csv:6: .*ay = 9e\+99 .*exceeds 1000 m/s\^2"):
        io.read_rtklib_imu(imu, t_start=1.4e9)
    if not (DATA_ROOT / "gnss_daily_timeseries/LHAS.tenv3").exists():
        pytest.skip("shared data not present")
    lines = _head("gnss_daily_timeseries/LHAS.tenv3", 300).decode().splitlines()
    w = lines[50].split()
    w[8] = "nan"  # east fraction
    lines[50] = " ".join(w)
    f = tmp_path / "n.tenv3"
    f.write_text("\n".join(lines) + "\n")
    s = io.read_daily(f)
    assert s.n_masked == 1 and np.isnan(s.enu[49, 0])
    from jaxnav.monitoring import weighted_slope

    v, sd = weighted_slope(s.t, s.enu, np.sqrt(np.diagonal(s.cov, axis1=1, axis2=2)))
    assert np.all(np.isfinite(v)) and np.all(np.isfinite(sd))


# ----------------------------------------------------------------------------- exact field counts, skipped columns


def _pbo_fixture():
    """A small EarthScope/PBO daily .pos (format 1.1): 40 daily records of 25 fields."""
    import datetime as dt

    head = [
        "PBO Station Position Time Series. Reference Frame : IGS14",
        "Format Version: 1.1.0",
        "4-character ID: TEST",
        "Start Field Description",
        "End Field Description",
        "*YYYYMMDD HHMMSS JJJJJ.JJJJ X Y Z Sx Sy Sz Rxy Rxz Ryz NLat Elong Height dN dE dU Sn Se Su Rne Rnu Reu Soln",
    ]
    rows = []
    for k in range(40):
        d = dt.date(2015, 3, 1) + dt.timedelta(days=k)
        mjd = (d - dt.date(1858, 11, 17)).days + 0.5
        rows.append(
            f" {d:%Y%m%d} 120000 {mjd:.4f} -1.0e6 5.0e6 3.0e6 0.002 0.003 0.004 0.1 -0.2 0.3 "
            f"29.657 91.104 3624.7 {1e-4 * k:.5f} {2e-4 * k:.5f} {-1e-4 * k:.5f} 0.00100 0.00120 0.00400 "
            "0.010 -0.020 0.030 final"
        )
    return ("\n".join(head + rows) + "\n").encode()


#: name -> (source, suffix, [(field index, bad value, what)]) of the columns a reader parses only to check
SKIPPED_COLUMNS = {
    "tenv3": (
        lambda: _head("gnss_daily_timeseries/LHAS.tenv3", 120),
        ".tenv3",
        [
            (6, "1e400", "reference longitude"),
            (13, "inf", "antenna height"),
            (4, "-1e308", "GPS week"),
            (4, "nan", "GPS week"),
            (5, "9", "GPS day"),
            (1, "95MAY32", "date"),
            (1, "nan", "date"),
            (2, "2011.5", "decimal year vs MJD"),
        ],
    ),
    "pbo": (
        _pbo_fixture,
        ".pos",
        [
            (0, "-inf", "YYYYMMDD"),
            (1, "Infinity", "HHMMSS"),
            (0, "20150302", "date vs MJD"),
            (1, "235900", "time vs MJD"),
            (0, "20151399", "no such date"),
        ],
    ),
    "neu": (
        lambda: _head("gnss_daily_timeseries/bjfsCleanUnf.neu", 120),
        ".neu",
        [
            (2, "NaN", "day of year"),
            (2, "inf", "day of year"),
            (1, "1e400", "year"),
            (2, "400", "day of year"),
            (1, "2005", "year vs decimal year"),
            (2, "12.5", "fractional day"),
        ],
    ),
}
FIELD_COUNT_SOURCES = {
    "tenv3": (lambda: _head("gnss_daily_timeseries/LHAS.tenv3", 120), ".tenv3", None),
    "pbo": (_pbo_fixture, ".pos", None),
    "neu": (lambda: _head("gnss_daily_timeseries/bjfsCleanUnf.neu", 120), ".neu", None),
    "col": (lambda: _head("gnss_daily_timeseries/UH01_GOM20_neu_cm.col", 120), ".col", None),
}


def _data_line_indices(lines):
    """Indices of the records: lines of 7 or more fields starting with a number or the tenv3 site."""
    return [
        i for i, l in enumerate(lines) if len(l.split()) >= 7 and (l.split()[0][:1].isdigit() or l.startswith(b"LHAS "))
    ]


@pytest.mark.parametrize("name", list(FIELD_COUNT_SOURCES))
def test_wrong_field_count_is_an_error_at_its_line(name, tmp_path):
    """A record with one field more or fewer (or cut to the short variant) is a ReaderError naming file
    and line, never a read with shifted columns."""
    source, suffix, _ = FIELD_COUNT_SOURCES[name]
    lines = source().split(b"\n")[:-1]
    rng = random.Random(f"{SEED}-fields-{name}")
    idx = _data_line_indices(lines)
    cases = [("drop", rng.choice(idx)) for _ in range(4)] + [("add", rng.choice(idx)) for _ in range(4)]
    if name == "tenv3":
        cases.append(("cut20", idx[len(idx) // 2]))
    for kind, i in cases:
        mut = list(lines)
        w = mut[i].split()
        w = w[:-1] if kind == "drop" else w[:20] if kind == "cut20" else w[:7] + [b"0.5"] + w[7:]
        mut[i] = b" ".join(w)
        p = _write(tmp_path / f"{kind}{i}{suffix}", b"\n".join(mut) + b"\n")
        with pytest.raises(ReaderError) as exc:
            io.read_daily(p)
        assert exc.value.line == i + 1 and str(exc.value).startswith(f"{p}:{i + 1}:"), (kind, str(exc.value))
    io.read_daily(_write(tmp_path / f"clean{suffix}", b"\n".join(lines) + b"\n"))


@pytest.mark.parametrize("name", list(SKIPPED_COLUMNS))
def test_non_finite_skipped_columns_are_errors_at_their_line(name, tmp_path):
    """Columns read only for consistency (reference longitude, antenna height, GPS week and day, the
    calendar date against the MJD, day of year) are validated: a bad value is an error at its line."""
    source, suffix, cases = SKIPPED_COLUMNS[name]
    lines = source().split(b"\n")[:-1]
    idx = _data_line_indices(lines)
    i = idx[len(idx) // 3]
    for j, bad, what in cases:
        mut = list(lines)
        w = mut[i].split()
        w[j] = bad.encode()
        mut[i] = b" ".join(w)
        p = _write(tmp_path / f"c{j}{suffix}", b"\n".join(mut) + b"\n")
        with pytest.raises(ReaderError) as exc:
            io.read_daily(p)
        assert exc.value.line == i + 1, (what, str(exc.value))


def test_wrapped_tag_ticks_are_rejected_for_every_timing(tmp_path):
    """Tag ticks set to 0xFFFFFFF0 over the second half of the walk's tag file (a wrapped uint32 clock):
    the tag reader, and so every timing that reads the tag, refuses the file, naming it."""
    rel = "rtklibexplorer-gnss-imu/walk_0827/imu_1730.csv"
    if not (DATA_ROOT / rel).exists():
        pytest.skip("shared data not present")
    b = bytearray((DATA_ROOT / (rel + ".tag")).read_bytes())
    n = (len(b) - 76) // 8
    for k in range(n // 2, n):
        struct.pack_into("<I", b, 76 + 8 * k, 0xFFFFFFF0)
    csv = tmp_path / "imu.csv"
    csv.write_bytes((DATA_ROOT / rel).read_bytes())
    tag = _write(tmp_path / "imu.csv.tag", bytes(b))
    with pytest.raises(ReaderError, match=r"imu\.csv\.tag: .*wrapped or corrupted tick"):
        io.read_rtklib_tag(tag)
    for timing in ("counter", "arrival", "endpoints"):
        with pytest.raises(ReaderError, match=r"imu\.csv\.tag: "):
            io.read_rtklib_imu(csv, tag, timing=timing)
