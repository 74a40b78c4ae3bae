"""``jaxnav ins`` time offset search when trial offsets move GNSS epochs out of the IMU span.

The simulated car's IMU log starts 40 ms before the first GNSS epoch, so the search (+-0.1 s)
tries offsets that put that epoch before the first IMU sample, and some inside the first sample's
interval. The search must finish, score the same epochs at every trial, recover the time-tag
error, report a sigma, and fit nothing on the fixes ``[evaluate]`` withholds.
"""

import numpy as np
import pytest
from _recording import WEEK, car_config, write_car

TAG_ERROR = -0.0437  # not a multiple of the grid step: some trials put a GNSS epoch inside an IMU interval


@pytest.fixture(scope="module")
def car(tmp_path_factory):
    from jaxnav.io import load_ins_config

    folder = tmp_path_factory.mktemp("car_offset")
    rec = write_car(folder, tag_error_s=TAG_ERROR, imu_start_s=0.96)
    p = car_config(rec, folder)
    p.write_text(p.read_text().replace("time_offset_search_s = 0.2", "time_offset_search_s = 0.1"))
    return rec, load_ins_config(p)


def _search(cfg, pos):
    from jaxnav.experiments.ins_run import recording_time_offset
    from jaxnav.ins import sensor_to_body
    from jaxnav.io import read_ins_inputs

    imu, _ = read_ins_inputs(cfg)
    lever = sensor_to_body(np.eye(3)) @ np.asarray(cfg.gnss.lever_arm_frd, float)
    return recording_time_offset(cfg, imu, pos, sensor_to_body(cfg.imu.mounting), lever, progress=None)


def test_search_across_imu_start(car):
    from jaxnav.io import read_ins_inputs

    rec, cfg = car
    imu, pos = read_ins_inputs(cfg)
    assert pos.t[0] < imu.t[0] + 0.1  # some trial offsets push the first GNSS epoch before the IMU
    off, info = _search(cfg, pos)
    assert off == pytest.approx(-TAG_ERROR, abs=0.01)
    assert info["n_epochs_dropped_at_span_edges"] >= 1
    assert 0.0 < info["sigma_s"] < 0.02
    assert info["n_epochs_withheld_by_evaluate"] > 0
    dr = info["drift"]  # a constant offset: both halves agree, no drift flagged
    assert not dr["significant"] and abs(dr["change_s"]) < 0.005
    for w in dr["windows"]:
        assert w["offset_s"] == pytest.approx(-TAG_ERROR, abs=0.01)
    # fitted on the epochs the filter sees: none inside an [evaluate] outage at any trial offset
    from jaxnav.experiments.ins_run import _search_epochs, prepare
    from jaxnav.ins import sensor_to_body
    from jaxnav.io import imu_increments

    prep = prepare(cfg._replace(imu=cfg.imu._replace(time_offset_s=off)), imu=imu, pos=pos, progress=None)
    t_imu = imu_increments(imu, sensor_to_body(cfg.imu.mounting))[0]
    sub, counts = _search_epochs(cfg, pos, t_imu, cfg.imu.time_offset_search_s)
    assert counts["n_epochs_used"] == sub.t.size == info["n_epochs_used"]
    assert not np.isin(np.asarray(prep.meas.t)[prep.withheld], sub.t).any()
    for a, b in prep.outages:
        assert not np.any((sub.t >= a - 0.05) & (sub.t < b + 0.05))  # windows move with the offset (<= 0.1 s)


def test_too_little_overlap_is_a_clear_error(car):
    from jaxnav.io import read_ins_inputs

    _, cfg = car
    imu, pos = read_ins_inputs(cfg)
    late = pos._replace(t=np.asarray(pos.t) + (imu.t[-1] - pos.t[0]) - 2.0)  # 2 s of overlap
    with pytest.raises(ValueError, match="time_offset_search_s"):
        _search(cfg, late)


def test_clock_drift_detected(tmp_path):
    """IMU time tags that drift: the tag error goes from +0.03 s to -0.03 s over the 200 s drive (300 ppm, a
    cheap logger's crystal). The drift of a linear clock model is recovered within 3 sigma and 15 %, and
    flagged; the model's offsets at the halves match the tags there, and the run's single offset lies
    between them. (The estimate scatters by about its sigma between seeds: 293-340 ppm on seeds 0-3, so
    a 10 % bound would fail on some seeds.)"""
    from jaxnav.io import load_ins_config, read_ins_inputs

    tag0, rate = 0.03, -3e-4
    rec = write_car(tmp_path, tag_error_s=tag0, imu_rate=50.0)
    rows = np.loadtxt(rec.imu_file)
    t0 = rows[0, 0]
    rows[:, 0] += rate * (rows[:, 0] - t0)
    np.savetxt(rec.imu_file, rows, fmt=["%.4f"] + ["%.12e"] * 6)
    p = car_config(rec, tmp_path)
    p.write_text(p.read_text().replace("time_offset_search_s = 0.2", "time_offset_search_s = 0.1"))
    cfg = load_ins_config(p)
    _, pos = read_ins_inputs(cfg)
    off, info = _search(cfg, pos)
    dr = info["drift"]
    assert dr.get("significant") and "clock drift" in dr["warning"], dr
    # offset to add = -tag error = -tag0 - rate (t - t0): +300 ppm
    d, sd = dr["drift_s_per_s"], dr["drift_sigma_s_per_s"]
    assert abs(d + rate) < 0.15 * abs(rate) and abs(d + rate) < 3 * sd + 1e-5, (d, sd)
    tt0 = WEEK * 604800.0 + t0  # GPST of the first tag
    for w in dr["windows"]:
        assert w["offset_s"] == pytest.approx(-tag0 - rate * (w["t_mean_s"] - tt0), abs=0.01)
    assert dr["windows"][0]["offset_s"] < off < dr["windows"][1]["offset_s"]
