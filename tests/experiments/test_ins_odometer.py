"""``jaxnav ins`` with ``[odometer]``: wheel speed from the KF-GINS IMU file's 8th column of a simulated car whose
wheel reads 2 % fast (true scale factor 1.02, 0.05 m/s noise, lever arm to the left rear wheel). The scale
factor is recovered (results.json ``odometer``), and through the 20 s GNSS outages the odometer cuts the drift
against the same run without it (both with the non-holonomic constraint). A CSV source and bad settings named."""

import json

import numpy as np
import pytest
from _recording import car_config, write_car

from jaxnav.ins import C_RFU_FRD
from jaxnav.ins.attitude import quat_to_dcm

SCALE = 1.02
WHEEL_FRD = np.array([-1.2, -0.7, 0.5])  # left rear wheel contact minus IMU, FRD, m
ODO = '[odometer]\nsource = "imu"\nsigma_m_s = 0.05\nrate_hz = 10.0\nlever_arm_frd_m = [-1.2, -0.7, 0.5]\n'
NHC = "[constraints]\nnhc = true\nnhc_rate_hz = 2.0\n"


def _wheel_speed(rec, seed=4):
    """(N,) forward speed of the wheel point of every IMU row, times SCALE, plus noise (m/s)."""
    tr = rec.truth
    C = np.asarray(quat_to_dcm(np.asarray(tr.q_bn)[1:]))
    v_b = np.einsum("nji,nj->ni", C, np.asarray(tr.v_n)[1:])
    w = np.asarray(tr.dtheta) / float(tr.dt)
    v_b = v_b + np.cross(w, C_RFU_FRD @ WHEEL_FRD)
    return SCALE * v_b[:, 1] + np.random.default_rng(seed).normal(0.0, 0.05, v_b.shape[0])


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    from jaxnav.cli import main

    folder = tmp_path_factory.mktemp("odo")
    rec = write_car(folder / "data", vibration=0.3)
    rows = np.loadtxt(rec.imu_file)
    sp = _wheel_speed(rec)
    np.savetxt(rec.imu_file, np.column_stack([rows, sp[-rows.shape[0] :]]), fmt=["%.4f"] + ["%.12e"] * 6 + ["%.4f"])
    out = {}
    for name, extra in (("odo", ODO + NHC), ("nhc", NHC)):
        cfg = car_config(rec, folder / "data", time_offset=0.15, extra=extra)
        cfg = cfg.rename(cfg.with_name(f"{name}.toml"))
        assert main(["ins", str(cfg), "--out", str(folder / name), "-q"]) == 0
        out[name] = json.loads((folder / name / "results.json").read_text())
    return rec, folder, out


def test_scale_factor_recovered_and_drift_cut(runs):
    _, _, out = runs
    o = out["odo"]["odometer"]
    assert o["source"] == "imu" and o["imu_samples_with_reading"] == o["imu_samples"]
    for key in ("scale_factor", "scale_factor_smoothed"):
        err = o[key] - SCALE
        assert abs(err) < 0.005 and abs(err) < 3.0 * o[key + "_sigma"] + 1e-4, (key, o[key], o[key + "_sigma"])
    assert out["odo"]["n_states"] == 15 and out["nhc"]["odometer"] is None
    e1, e0 = out["odo"]["evaluation"], out["nhc"]["evaluation"]
    assert e1["forward_rms_h_m"] < 0.5 * e0["forward_rms_h_m"], (e1["forward_rms_h_m"], e0["forward_rms_h_m"])
    assert e1["forward_max_h_m"] < e0["forward_max_h_m"]


def test_csv_source_gives_the_same_scale(runs, tmp_path):
    """The same readings as a CSV (seconds of week with gps_week, km/h) give the same estimate."""
    from _recording import SOW0, WEEK

    from jaxnav.cli import main

    rec, folder, out = runs
    rows = np.loadtxt(rec.imu_file)
    csv = folder / "data" / "wheel.csv"
    np.savetxt(
        csv,
        np.column_stack([rows[:, 0], rows[:, 7] * 3.6]),
        fmt="%.6f",
        delimiter=",",
        header="tow,speed_kmh",
        comments="",
    )
    extra = ODO.replace(
        'source = "imu"',
        f'source = "csv"\nfile = "wheel.csv"\ngps_week = {WEEK}\n'
        'columns = {t = "tow", speed = "speed_kmh"}\nunits = {speed = "km/h"}',
    )
    cfg = car_config(rec, folder / "data", time_offset=0.15, extra=extra + NHC)
    assert main(["ins", str(cfg), "--out", str(tmp_path / "o"), "-q"]) == 0
    o = json.loads((tmp_path / "o" / "results.json").read_text())["odometer"]
    assert o["scale_factor"] == pytest.approx(out["odo"]["odometer"]["scale_factor"], abs=2e-4)
    assert SOW0 > 0


@pytest.mark.parametrize(
    "section, match",
    [
        ('[odometer]\nsource = "csv"\n', "odometer.file is required"),
        ('[odometer]\nsource = "imu"\nfile = "x.csv"\n', "odometer.file is only used with source = 'csv'"),
        ('[odometer]\nsource = "imu"\nsigma_m_s = 50.0\n', "odometer.sigma_m_s = 50.0 is outside the plausible range"),
        ('[odometer]\nsource = "wheel"\n', "odometer.source must be one of"),
        ('[odometer]\nsource = "imu"\nscale = 1.0\n', "unknown key odometer.scale"),
    ],
)
def test_bad_odometer_settings_named(runs, tmp_path, section, match):
    from jaxnav.io import ConfigError, load_ins_config

    rec, folder, _ = runs
    cfg = car_config(rec, folder / "data", time_offset=0.15, extra=section)
    with pytest.raises(ConfigError, match=match):
        load_ins_config(cfg)


def test_heading_csv_input(runs, tmp_path):
    """A heading CSV (seconds of week, deg, per-reading sigma 0.3 deg, 1 Hz, true heading plus noise) with NHC:
    every reading reaches an IMU sample, the run stays healthy, and the outage drift is no worse than NHC alone
    (a wrong sign or unit would turn the heading updates against the solution)."""
    from _recording import SOW0, WEEK

    from jaxnav.cli import main

    rec, folder, out = runs
    tr = rec.truth
    k = np.arange(0, np.asarray(tr.t).size, int(round(1.0 / float(tr.dt))))[1:]
    hdg = np.mod(-np.degrees(np.asarray(tr.euler)[k, 2]) + np.random.default_rng(5).normal(0, 0.3, k.size), 360.0)
    csv = folder / "data" / "heading.csv"
    np.savetxt(csv, np.column_stack([SOW0 + np.asarray(tr.t)[k], hdg, np.full(k.size, 0.3)]), fmt="%.6f", delimiter=",")
    extra = (
        f'[heading]\nfile = "heading.csv"\ngps_week = {WEEK}\ncolumns = {{t = 0, heading = 1, sigma = 2}}\n'
        "rate_hz = 1.0\n"
    )
    cfg = car_config(rec, folder / "data", time_offset=0.15, extra=extra + NHC)
    assert main(["ins", str(cfg), "--out", str(tmp_path / "h"), "-q"]) == 0
    r = json.loads((tmp_path / "h" / "results.json").read_text())
    assert r["status_ok"] and r["heading"]["imu_samples_with_reading"] == k.size
    assert r["evaluation"]["forward_rms_h_m"] < 1.1 * out["nhc"]["evaluation"]["forward_rms_h_m"]
