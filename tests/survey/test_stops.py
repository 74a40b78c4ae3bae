"""S3 step 2: stop kinds, stop-list files and checks, data classes, the static/dynamic detector."""

import numpy as np
import pytest
from _paths import DATA_ROOT

from jaxnav.io import read_stop_list, write_stop_list
from jaxnav.survey import (
    STOP_KINDS,
    DetectorParams,
    classify,
    make_stop_list,
    match_stops,
    stance_statistic,
    static_spans,
    validate_stops,
)

DATA = DATA_ROOT / "rtklibexplorer-gnss-imu"


def _stops():
    kinds = ["known_coordinate", "zupt", "target", "levelling", "known_coordinate", "target", "known_position"]
    t0 = np.array([0.0, 50.0, 90.0, 130.0, 170.0, 210.0, 250.0])
    pos = np.full((7, 3), np.nan)
    pos[0] = [0.56, 2.07, 15.0]
    pos[4] = [0.5601, 2.0701, 16.0]
    pos[3, 2] = 15.5
    pos[6, :2] = [0.5602, 2.0702]
    return make_stop_list(t0, t0 + 15.0, kinds, pos, np.full((7, 3), 0.01), [f"S{i}" for i in range(7)])


def test_stop_list_round_trip(tmp_path):
    s = _stops()
    f = tmp_path / "stops.csv"
    write_stop_list(f, s)
    r = read_stop_list(f)
    assert r.name == s.name
    np.testing.assert_array_equal(r.kind, s.kind)
    np.testing.assert_allclose(r.t_start, s.t_start)
    np.testing.assert_allclose(r.pos[0], s.pos[0], rtol=0, atol=1e-12)
    assert np.isnan(r.pos[1]).all()
    assert [STOP_KINDS[k] for k in r.kind][:3] == ["known_coordinate", "zupt", "target"]


@pytest.mark.parametrize(
    "line,msg",
    [
        ("A, known_coordinate, 0, 10", "needs its known coordinates"),
        ("A, spaceship, 0, 10", "unknown stop kind"),
        ("A, zupt, 10, 5", "t_end > t_start"),
        ("A, zupt, ten, 20", "non-numeric"),
        ("A, zupt, 1", "columns"),
    ],
)
def test_stop_list_errors_name_file_and_line(tmp_path, line, msg):
    f = tmp_path / "bad.csv"
    f.write_text("# header\nK0, known_coordinate, 0, 10, 32.0, 118.0, 10.0\n" + line + "\n")
    with pytest.raises(ValueError, match=msg) as e:
        read_stop_list(f)
    assert str(e.value).startswith(f"{f}:3: ")  # file and line, as every reader error


def test_validate_stops_rejects_mismatched_span_and_orphan_target():
    s = _stops()
    validate_stops(s, -1.0, 300.0)
    with pytest.raises(ValueError, match="does not match this data"):
        validate_stops(s, 1000.0, 2000.0)  # e.g. GPS time against a relative stop list
    with pytest.raises(ValueError, match="does not match this data"):
        validate_stops(s, 0.0, 200.0)
    bad = make_stop_list(s.t_start[1:], s.t_end[1:], s.kind[1:], s.pos[1:], s.sigma[1:], s.name[1:])
    with pytest.raises(ValueError, match="no known-coordinate point before it"):
        validate_stops(bad, -1.0, 300.0)
    ov = make_stop_list([0.0, 5.0], [10.0, 20.0], ["known_coordinate", "zupt"], s.pos[:2], s.sigma[:2])
    with pytest.raises(ValueError, match="overlap"):
        validate_stops(ov, -1.0, 300.0)


def test_classify_three_classes():
    s = _stops()
    t = np.arange(1, 30001) * 0.01
    c = classify(s, t)
    assert c.sample_class[np.searchsorted(t, 5.0)] == 1 and c.sample_class[np.searchsorted(t, 30.0)] == 2
    assert c.sample_class[-1] == 0  # after the last stop
    assert c.stop_of_sample[np.searchsorted(t, 95.0)] == 2
    # class 3: target whose previous stop is a known-coordinate point (S5 after K at S4), not S2 (after ZUPT)
    np.testing.assert_array_equal(c.class3, [False, False, False, False, False, True, False])
    np.testing.assert_array_equal(c.prev_known, [-1, 0, 0, 0, 0, 4, 4])
    np.testing.assert_array_equal(c.next_known, [4, 4, 4, 4, -1, -1, -1])


def test_stance_statistic_equals_direct_loop():
    rng = np.random.default_rng(0)
    N, W = 300, 20
    f = np.array([0.1, -0.2, 9.8]) + 0.05 * rng.normal(size=(N, 3))
    w = 0.01 * rng.normal(size=(N, 3))
    prm = DetectorParams(sigma_a=0.05, sigma_g=0.01, threshold=3.0, gravity=9.79)
    T = np.asarray(stance_statistic(f, w, prm, window=W))
    Tml = np.asarray(stance_statistic(f, w, DetectorParams(sigma_a=0.05, sigma_g=0.01), window=W))
    for k in (0, 7, 150, N - 1):
        lo = min(max(k - W // 2, 0), N - W)
        fw, ww = f[lo : lo + W], w[lo : lo + W]
        u = fw.mean(0) / np.linalg.norm(fw.mean(0))
        ref = np.mean(np.sum((fw - 9.79 * u) ** 2, 1) / 0.05**2 + np.sum(ww**2, 1) / 0.01**2)
        np.testing.assert_allclose(T[k], ref, rtol=1e-9)
        ref_ml = np.mean(np.sum((fw - fw.mean(0)) ** 2, 1) / 0.05**2 + np.sum(ww**2, 1) / 0.01**2)
        np.testing.assert_allclose(Tml[k], ref_ml, rtol=1e-8)
    assert 4.0 < Tml.mean() < 8.0  # chi^2 with 6 dof per sample, less 3 for the estimated mean, over W


def test_static_spans_and_matching():
    t = np.arange(1, 1001) * 0.1
    s = np.zeros(1000, bool)
    s[100:300] = True  # 10.0-30.0 s
    s[150:152] = False  # a 0.2 s flicker inside a stop is closed
    s[500:510] = True  # 1 s: too short
    s[700:900] = True
    sp = static_spans(s, t, min_duration=2.0, min_gap=0.5)
    np.testing.assert_allclose(sp, [[10.0, 30.0], [70.0, 90.0]], atol=1e-9)
    sc = match_stops(sp, [[10.5, 29.5], [50.0, 60.0], [71.0, 89.0]], t=t, static=s)
    assert sc.n_matched == 2 and sc.precision == 1.0 and abs(sc.recall - 2 / 3) < 1e-12
    np.testing.assert_allclose(sc.start_error, [-0.5, -1.0])


@pytest.mark.skipif(not (DATA / "walk_0827" / "imu_1730.csv").exists(), reason=f"walk data not found at {DATA}")
def test_detector_on_real_walk_set():
    """walk_0827: RTK says static for ~10 s at the start and ~19 s at the end. The detector finds the
    end stop to ~1.5 s; at the start the IMU is handled from t = 3.1 s on while the antenna stays put."""
    from jaxnav.experiments.s3 import walk_detection

    r = walk_detection(DATA)
    spans = np.asarray(r["detected_spans_s"])
    assert len(spans) == 2
    end = spans[-1]
    assert abs(end[0] - 113.8) < 2.0 and end[1] > 130.0
    assert spans[0][0] < 0.5 and 2.0 < spans[0][1] < 5.0
    assert r["recall"] >= 0.5 and r["precision"] >= 0.5


def test_detection_scores_over_runs():
    """detection_scores averages match_stops over runs: one perfect run and one that misses the second stop."""
    from jaxnav.survey import detection_scores

    t = np.arange(0.0, 60.0, 0.1)
    true = np.array([[10.0, 20.0], [35.0, 45.0]])
    perfect = ((t > 10.0) & (t <= 20.0)) | ((t > 35.0) & (t <= 45.0))
    half = (t > 10.0) & (t <= 20.0)
    d = detection_scores(np.stack([perfect, half]), t, true)
    assert d["recall_mean"] == pytest.approx(0.75) and d["recall_min"] == pytest.approx(0.5)
    assert d["precision_mean"] == pytest.approx(1.0) and d["n_true_stops"] == 2
    assert d["boundary_error_s_mean_abs"] < 0.2
