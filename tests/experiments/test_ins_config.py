"""``jaxnav ins`` configs: every bad key is named with its file before any data is read; the mounting
convention (C_vehicle_sensor = Rz(yaw) Ry(pitch) Rx(roll), Groves-style angles transposed) and the
FRD -> RFU conversions of mounting and lever arm, checked against scipy's rotations."""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from jaxnav.ins import C_RFU_FRD, sensor_to_body
from jaxnav.io import INS_CONFIG_DIR, ConfigError, load_ins_config

BASE = """
[imu]
file = "imu.csv"
format = "rtklib-csv"
[gnss]
file = "sol.pos"
[noise]
grade = "consumer"
"""


def _write(tmp_path, text, name="c.toml"):
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


def test_minimal_config_paths_relative_to_the_file(tmp_path):
    cfg = load_ins_config(_write(tmp_path, BASE))
    assert cfg.imu.file == tmp_path / "imu.csv" and cfg.gnss.file == tmp_path / "sol.pos"
    assert cfg.noise.states == 15 and cfg.evaluate is None and cfg.imu.time_offset_s == 0.0
    np.testing.assert_allclose(cfg.imu.mounting, np.eye(3))
    assert cfg.name == "c"


BAD = [
    ("[imu]\nfile='a'\n[gnss]\nfile='b'\n[noise]\ngrade='consumer'\n[extra]\nx=1\n", "unknown section [extra]"),
    (BASE + "[alignment]\nstatic=2\n", "unknown key alignment.static"),
    (BASE.replace('format = "rtklib-csv"', 'format = "xsens"'), "imu.format must be one of"),
    (BASE.replace('file = "imu.csv"', "file = 3"), "imu.file must be a string"),
    (BASE + "[evaluate]\noutage_s = -1\n", "evaluate.outage_s = -1.0 must be > 0"),
    (BASE + "[evaluate]\noutage_s = true\n", "evaluate.outage_s must be a number"),
    (BASE + "[evaluate]\nshifts = 0\n", "evaluate.shifts = 0 must be >= 1"),
    (BASE + "[evaluate]\nshifts = 2.5\n", "evaluate.shifts must be an integer"),
    (BASE + "[evaluate]\nshifts = 101\n", "evaluate.shifts = 101 must be <= 100"),
    (BASE + "[evaluate]\nshifts = 2\nshift_s = 0.01\n", "evaluate.shift_s = 0.01 is outside the plausible range"),
    (BASE + "[evaluate]\nshift_s = 5.0\n", "evaluate.shift_s is only used with shifts > 1"),
    (BASE + "[evaluate]\nshifts = 3\nshift_s = 30.0\n", "evaluate.shift_s = 30 s: the last of the 3 shifts"),
    (BASE + "[evaluate]\nshifts = 2\noutages = false\ntruth = 't.nav'\n", "evaluate.shifts > 1 shifts the"),
    (BASE.replace('format = "rtklib-csv"', 'format = "kf-gins"\ntag = "x.tag"'), "imu.tag is only used with"),
    (
        BASE.replace('format = "rtklib-csv"', "mounting_rpy_deg = [0, 0, 0]\nmounting_groves_rpy_deg = [1, 2, 3]"),
        "conflicts with mounting_rpy_deg",
    ),
    (BASE.replace('format = "rtklib-csv"', "mounting_dcm = [[1, 0, 0], [0, 1, 0], [0, 0, 2]]"), "must be a rotation"),
    (BASE.replace('format = "rtklib-csv"', "mounting_rpy_deg = [0, 0]"), "list of 3 finite numbers"),
    (BASE.replace('format = "rtklib-csv"', "time_offset_s = 99"), "imu.time_offset_s = 99.0 must be <= 10"),
    (BASE.replace('format = "rtklib-csv"', 'time_offset_s = "guess"'), "imu.time_offset_s must be a number"),
    (BASE + "[gnss2]\n", "unknown section"),
    (BASE.replace('grade = "consumer"', 'grade = "phone"'), "noise.grade must be one of"),
    (BASE.replace('grade = "consumer"', "states = 15"), "noise.grade is required unless"),
    (BASE.replace('grade = "consumer"', 'grade = "consumer"\nstates = 16'), "noise.states must be one of"),
    (BASE + "[tune]\nparams = ['arw', 'b']\n", "tune.params must be a non-empty list"),
    (BASE + "[tune]\ncalibrate = 'yes'\n", "tune.calibrate must be 'auto', true or false"),
    (BASE + "[tune]\ncalibrate_steps = 0\n", "tune.calibrate_steps"),
    (
        BASE.replace('file = "sol.pos"', 'file = "sol.pos"\nuse_velocity = false')
        + "[tune]\nparams = ['vel_sigma_scale']\n",
        "tune.params: vel_sigma_scale needs gnss.use_velocity = true",
    ),
    (BASE + "[constraints]\nzupt = true\n", "constraints.zupt must be 'auto' or false"),
    (BASE + "[alignment]\nheading = 'north'\n", "alignment.heading must be"),
    (BASE.replace('file = "imu.csv"', 'file = "${JAXNAV_NOT_SET_HERE}/imu.csv"'), "JAXNAV_NOT_SET_HERE"),
    (
        BASE.replace('[gnss]\nfile = "sol.pos"', '[gnss]\nfile = "sol.pos"\nlever_arm_frd_m = [0, 0, 500]'),
        "lever arm beyond 100 m",
    ),
    (BASE.replace("[imu]", "[imu]\nfile2 = 'x'"), "unknown key imu.file2"),
    ("[imu]\nfile = 'a'\n", "missing section [gnss]"),
    ("[imu\nfile = 'a'\n", "invalid TOML"),
]


@pytest.mark.parametrize("text, msg", BAD, ids=[m for _, m in BAD])
def test_bad_configs_name_file_and_key(tmp_path, text, msg):
    p = _write(tmp_path, text)
    with pytest.raises(ValueError) as exc:
        load_ins_config(p)
    assert msg in str(exc.value)
    assert str(p) in str(exc.value)


def test_unknown_shipped_name_lists_the_shipped_ones():
    with pytest.raises(ConfigError, match="walk_0827"):
        load_ins_config("no_such_recording")


def test_shipped_configs_load(monkeypatch):
    monkeypatch.setenv("JAXNAV_DATA", "/data")
    for p in sorted(INS_CONFIG_DIR.glob("*.toml")):
        cfg = load_ins_config(p.stem)
        assert str(cfg.imu.file).startswith("/data/")


@pytest.mark.parametrize("rpy", [(180.0, -6.79, 185.35), (10.0, 20.0, 30.0), (-35.0, 5.0, 100.0)])
def test_mounting_conventions_against_scipy(tmp_path, rpy):
    """mounting_rpy_deg: the sensor's attitude in FRD (intrinsic z-y'-x'' = extrinsic x, y, z); Groves-style angles
    describe the inverse rotation; for (180, -6.79, 185.35) the two readings differ by 13.6 deg."""
    txt = BASE.replace('format = "rtklib-csv"', f"mounting_rpy_deg = {list(rpy)}")
    C = load_ins_config(_write(tmp_path, txt)).imu.mounting
    ref = Rotation.from_euler("ZYX", [rpy[2], rpy[1], rpy[0]], degrees=True).as_matrix()
    np.testing.assert_allclose(C, ref, atol=1e-12)
    txt_g = BASE.replace('format = "rtklib-csv"', f"mounting_groves_rpy_deg = {list(rpy)}")
    Cg = load_ins_config(_write(tmp_path, txt_g, "g.toml")).imu.mounting
    np.testing.assert_allclose(Cg, ref.T, atol=1e-12)
    if rpy == (180.0, -6.79, 185.35):
        angle = math.degrees(Rotation.from_matrix(C @ Cg.T).magnitude())
        assert angle == pytest.approx(13.6, abs=0.05)


def test_frd_to_rfu_body_and_lever_arm():
    # a sensor aligned with the FRD vehicle: its x (forward) is jaxnav's body y, its z (down) is -up
    C_bs = sensor_to_body(np.eye(3))
    np.testing.assert_allclose(C_bs @ [1, 0, 0], [0, 1, 0])
    np.testing.assert_allclose(C_bs @ [0, 1, 0], [1, 0, 0])
    np.testing.assert_allclose(C_bs @ [0, 0, 1], [0, 0, -1])
    np.testing.assert_allclose(C_RFU_FRD @ [0.0, -0.05, 0.0], [-0.05, 0.0, 0.0])


def test_walk_config_reproduces_the_walk_mounting(monkeypatch):
    from jaxnav.experiments.walk import WALK_LEVER_RFU, WALK_SENSOR_TO_BODY

    monkeypatch.setenv("JAXNAV_DATA", "/data")
    cfg = load_ins_config("walk_0827")
    np.testing.assert_allclose(sensor_to_body(cfg.imu.mounting), WALK_SENSOR_TO_BODY, atol=1e-12)
    np.testing.assert_allclose(C_RFU_FRD @ cfg.gnss.lever_arm_frd, WALK_LEVER_RFU, atol=1e-12)
    assert cfg.evaluate is not None and cfg.evaluate.outage_s == 15.0


def test_calibrate_default_and_keys(tmp_path):
    """``[tune] calibrate`` is "auto" unless given; true, false and ``calibrate_steps`` are read as given."""
    assert load_ins_config(_write(tmp_path, BASE)).tune.calibrate == "auto"
    t = load_ins_config(_write(tmp_path, BASE + "[tune]\ncalibrate = false\ncalibrate_steps = 5\n", "f.toml")).tune
    assert t.calibrate is False and t.calibrate_steps == 5
    assert load_ins_config(_write(tmp_path, BASE + "[tune]\ncalibrate = true\n", "t.toml")).tune.calibrate is True


def test_evaluate_shifts_default_and_keys(tmp_path):
    """``[evaluate] shifts`` is 1 unless given; its step defaults to one outage period over the shifts."""
    ev = load_ins_config(_write(tmp_path, BASE + "[evaluate]\noutage_s = 15.0\ngap_s = 45.0\n")).evaluate
    assert ev.shifts == 1
    ev = load_ins_config(_write(tmp_path, BASE + "[evaluate]\nshifts = 4\n", "s.toml")).evaluate
    assert ev.shifts == 4 and ev.shift_s == pytest.approx((15.0 + 45.0) / 4)
    ev = load_ins_config(_write(tmp_path, BASE + "[evaluate]\nshifts = 3\nshift_s = 10\n", "t.toml")).evaluate
    assert ev.shifts == 3 and ev.shift_s == 10.0


def test_a_shift_without_an_outage_window_is_refused_naming_the_keys(tmp_path):
    """Checked on the IMU span before any fit: a shifted schedule the end margin leaves empty is an error."""
    from jaxnav.experiments.ins_output import check_shifts

    ev = "[evaluate]\nfirst_s = 40.0\noutage_s = 15.0\ngap_s = 45.0\nend_margin_s = 30.0\nshifts = 4\n"
    p = _write(tmp_path, BASE + ev)
    cfg = load_ins_config(p)
    check_shifts(cfg, np.array([0.0, 200.0]))  # every shift has a window
    with pytest.raises(ConfigError) as exc:
        check_shifts(cfg, np.array([0.0, 100.0]))  # windows must end by 70 s: shift 2 (70-85 s) has none
    assert f"{p}: evaluate.shifts = 4 with shift_s = 15 s: shift 2 " in str(exc.value)
