"""``jaxnav ins`` end to end on a simulated car written as KF-GINS files (known truth).

From a config alone: a non-symmetric mounting, an antenna lever arm, IMU time tags 0.15 s late, 2 Hz
RTK-level GNSS withheld on simulated 20 s outages; the 21-state model (Gauss-Markov biases and scale
factors from the industrial grade's datasheet values), automatic standstill detection with ZUPT and
ZARU, and the non-holonomic constraint. Checked: the time offset recovered by the
likelihood to 10 ms, the solution against the truth, errors explained by the reported sigmas, the RTS
smoother better than the forward filter inside the outages, every output file readable, and the
scores against the car's true trajectory (``[evaluate] truth``, KF-GINS ``truth.nav``).
"""

import math

import numpy as np
import pytest
from _recording import car_config, write_car, write_truth_nav


@pytest.fixture(scope="module")
def done(tmp_path_factory):
    from jaxnav.cli import main

    folder = tmp_path_factory.mktemp("car")
    rec = write_car(folder / "data")
    write_truth_nav(rec, folder / "data" / "truth.nav", step=5)
    cfg = car_config(
        rec,
        folder / "data",
        states=21,
        evaluate_extra='truth = "truth.nav"\ntruth_format = "kf-gins"\nshifts = 2',
        extra='[constraints]\nzupt = "auto"\nzaru = true\nnhc = true\ndetector_threshold = 30.0\n'
        "detector_sigma_a_m_s2 = 0.01\ndetector_sigma_w_deg_s = 0.05\ndetector_min_s = 1.0\n",
    )
    out = folder / "out"
    argv = ["ins", str(cfg), "--out", str(out), "-q"]
    assert main(argv) == 0
    from _outputs import check_provenance

    return rec, out, check_provenance(out, argv, config=True)


def test_time_offset_recovered(done):
    rec, _, r = done
    # tags are late by 0.15 s: 0.15 s must be added... i.e. the offset added to the IMU times is +0.15
    assert r["time_offset_s"] == pytest.approx(-rec.tag_error_s, abs=0.01)
    assert r["time_offset"]["first_guess_corr"] > 0.9


def test_run_healthy_and_evaluated(done):
    _, _, r = done
    from jaxnav._status import INFO_FLAGS

    assert r["status"] & ~INFO_FLAGS == 0 and r["n_nonfinite"] == 0 and r["n_states"] == 21
    c = r["constraints"]
    # the drive stands still twice: 20 s at the start and 8 s in the middle
    assert c["standstill_intervals"] == 2 and 20.0 < c["standstill_s"] < 30.0
    assert c["n_filter_epochs"] > c["n_gnss_epochs"]  # ZUPT and NHC epochs between the fixes
    ev = r["evaluation"]
    assert ev["n_windows"] >= 2 and ev["n_scored_windows"] == ev["n_windows"]
    # with GNSS: cm level; industrial IMU, 20 s outages: decimetres forward, smoothed clearly better
    assert ev["forward_rms_h_outside_outages_m"] < 0.05
    assert 0.02 < ev["forward_max_h_m"] < 5.0
    assert ev["smoothed_rms_h_m"] < 0.5 * ev["forward_rms_h_m"]
    # errors explained by the sigmas
    assert ev["forward_share_within_3_sigma_h"] > 0.9 and ev["smoothed_share_within_3_sigma_h"] > 0.9


def _read_csv(path):
    import csv

    lines = [ln for ln in path.read_text(encoding="utf-8").splitlines() if not ln.startswith("#")]
    rows = list(csv.DictReader(lines))
    return {k: np.array([float(r[k]) for r in rows]) for k in rows[0] if k != "gpst_iso"}


def test_trajectory_against_truth(done):
    rec, out, _ = done
    from jaxnav.geodesy import curvilinear_to_enu

    a = _read_csv(out / "trajectory.csv")
    t = a["gpst_s"]
    tr = rec.truth
    t_true = np.asarray(tr.t)
    from _recording import SOW0, WEEK

    t_rel = t - (WEEK * 604800.0 + SOW0)
    pos_true = np.stack([np.interp(t_rel, t_true, np.asarray(tr.pos)[:, i]) for i in range(3)], -1)
    pos = np.stack([np.radians(a["lat_deg"]), np.radians(a["lon_deg"]), a["h_m"]], -1)
    err = np.asarray(curvilinear_to_enu(pos_true, pos - pos_true))
    sig = np.stack([a["sigma_e_m"], a["sigma_n_m"], a["sigma_u_m"]], -1)
    assert np.all(np.isfinite(err))
    # smoothed IMU position against the true IMU position everywhere (outages included)
    assert np.max(np.hypot(err[:, 0], err[:, 1])) < 1.0
    z = np.abs(err) / sig
    assert np.mean(z < 3.0) > 0.95
    heading_true = np.mod(-np.degrees(np.interp(t_rel, t_true, np.asarray(tr.euler)[:, 2])), 360.0)
    dh = (a["heading_deg"] - heading_true + 180.0) % 360.0 - 180.0
    assert np.sqrt(np.mean(dh[t_rel > 40] ** 2)) < 0.5  # deg: the mounting is undone correctly


def test_output_files_readable(done):
    _, out, r = done
    import geojson

    from jaxnav.io import read_pos

    names = {p.name for p in out.iterdir()}
    for n in (
        "trajectory.csv",
        "trajectory_forward.csv",
        "track.geojson",
        "track.kml",
        "results.json",
        "track_outages.png",
        "differences_to_gnss.png",
        "attitude.png",
        "biases.png",
    ):
        assert n in names, n
    pos_files = [p for p in out.iterdir() if p.suffix == ".pos"]
    sol = read_pos(pos_files[0])
    assert sol.t.size > 300 and np.all(np.isin(sol.q, [0, 1]))
    assert np.count_nonzero(sol.q == 0) > 0  # the outage epochs are marked inertial-only
    gj = geojson.loads((out / "track.geojson").read_text())
    assert gj.is_valid and len(gj["features"]) >= 2
    assert "<kml" in (out / "track.kml").read_text()[:400]
    text = (out / "results.json").read_text()
    assert "NaN" not in text and "Infinity" not in text
    assert r["provenance"]["config"]["imu"]["format"] == "kf-gins" and r["provenance"]["jaxnav_version"]
    assert {"trajectory.csv", "track.kml", "biases.png", "results.json"} <= set(r["files"])
    assert r["mounting"]["source"].startswith("mounting_rpy_deg")


def test_scored_against_the_true_trajectory(done):
    """``[evaluate] truth``: position, velocity and attitude errors against the simulated car's truth,
    the outage drift protocol and the NEES, under ``evaluation.truth`` with units in the keys."""
    _, out, r = done
    tr = r["evaluation"]["truth"]
    assert tr["format"] == "kf-gins" and tr["n_records"] > 1000
    f, s = tr["forward"], tr["smoothed"]
    assert f["n_epochs"] > 100 and f["n_dropped_epochs"] <= 2
    # RTK-level GNSS and an industrial IMU: cm with GNSS, decimetres at worst in the 20 s outages
    assert 0.0 < f["all"]["pos_3d_rms_m"] < 0.5 and f["outages"]["pos_3d_max_m"] < 5.0
    assert s["outages"]["pos_3d_rms_m"] < f["outages"]["pos_3d_rms_m"]
    p = f["outage_protocol"]
    assert p["n_windows"] == p["n_scored_windows"] == r["evaluation"]["n_windows"] >= 2
    assert p["rms_of_max_3d_drift_m"] == pytest.approx(math.sqrt(np.mean(np.square(p["max_3d_drift_m"]))))
    # velocity cm/s; attitude of the vehicle frame (the mounting undone), heading within a degree
    assert f["all"]["vel_3d_rms_m_s"] < 0.2 and s["all"]["heading_rms_deg"] < 1.0
    assert s["all"]["roll_rms_deg"] < 0.5 and s["all"]["pitch_rms_deg"] < 0.5
    # consistency: errors explained by the sigmas
    assert 0.3 < f["all"]["nees_pos_mean"] < 10.0 and f["all"]["share_pos_within_3_sigma"] > 0.9
    assert (out / "truth_errors.png").is_file() and "truth_errors.png" in r["files"]


def test_shifted_outages(done):
    """``[evaluate] shifts = 2``: the outage schedule repeated 30 s later (half the 60 s period) as a run of
    its own (time offset and standstill refitted on the epochs it sees), scored against the truth; shift 0
    is the unshifted protocol, its drifts those of ``evaluation.truth``."""
    _, out, r = done
    so = r["evaluation"]["shifted_outages"]
    assert so["shifts"] == 2 and so["shift_s"] == 30.0 and so["period_s"] == 60.0
    assert "shifted_outages.png" in r["files"] and (out / "shifted_outages.png").stat().st_size > 10_000
    rows = so["per_outage"]
    s0 = [o for o in rows if o["shift"] == 0]
    s1 = [o for o in rows if o["shift"] == 1]
    tr = r["evaluation"]["truth"]
    # shift 0 reproduces the unshifted protocol: same windows, same per-outage drifts
    assert [o["gpst_start_s"] for o in s0] == [w["gpst_start_s"] for w in r["evaluation"]["windows"]]
    for w in ("forward", "smoothed"):
        p = tr[w]["outage_protocol"]
        assert [o[f"{w}_max_3d_m"] for o in s0] == p["max_3d_drift_m"]
        assert [o[f"{w}_max_h_m"] for o in s0] == p["max_h_drift_m"]
    # shift 1 starts 30 s later; its own run withholds its own windows and fits its own time offset
    assert [o["start_since_imu_start_s"] - 30.0 for o in s1] == pytest.approx(
        [o["start_since_imu_start_s"] for o in s0][: len(s1)]
    )
    sh = so["per_shift"]
    assert sh[0]["time_offset_s"] == r["time_offset_s"] and sh[1]["time_offset_source"] == "estimate"
    assert sh[1]["time_offset_s"] == pytest.approx(0.15, abs=0.01)  # the tags are 0.15 s late
    assert so["n_outages"] == len(rows) == sh[0]["n_windows"] + sh[1]["n_windows"] >= 4
    # pooled over both shifts: RMS / mean / max of the per-outage maxima
    for w in ("forward", "smoothed"):
        d3 = np.array([o[f"{w}_max_3d_m"] for o in rows])
        assert so[w]["rms_of_max_3d_drift_m"] == pytest.approx(math.sqrt(np.mean(d3**2)))
        assert so[w]["max_of_max_3d_drift_m"] == pytest.approx(d3.max())
        assert so[w]["mean_of_max_h_drift_m"] == pytest.approx(np.mean([o[f"{w}_max_h_m"] for o in rows]))
    assert so["smoothed"]["rms_of_max_3d_drift_m"] < so["forward"]["rms_of_max_3d_drift_m"] < 5.0
