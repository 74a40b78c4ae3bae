"""Standstill detection (issue 18): SHOE GLRT and threshold detector; precision/recall on a simulated car
with known stops and on the walk set's stops seen by RTK; cross-check with the S3 stance statistic."""

import math

import _car
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _paths import DATA_ROOT

from jaxnav import ins


def _car_params():
    nz = ins.noise_preset("consumer")
    dt = _car.car()["dt"]
    # per-sample white-noise std of the sensor (VRW, ARW over one 10 ms sample); threshold: ~6 at rest
    return ins.StandstillParams(
        sigma_a=nz.accel_vrw / math.sqrt(dt), sigma_w=nz.gyro_arw / math.sqrt(dt), threshold=25.0, g=9.806
    )


def test_car_stops_precision_recall():
    t, w, f = _car.measured(7)
    truth = _car.rest_truth(t)
    d = np.asarray(ins.detect_standstill(f, w, _car_params(), window=21, min_samples=50))
    s = ins.detection_scores(d, truth)
    print(f"\nsimulated car, SHOE: precision {s.precision:.4f} recall {s.recall:.4f} (tp {s.tp} fp {s.fp} fn {s.fn})")
    assert s.precision > 0.99 and s.recall > 0.97
    spans = ins.standstill_intervals(t, d)
    assert spans.shape == (3, 2)  # the start, the stop in the middle, the end
    np.testing.assert_allclose(spans[1], [43.0, 53.0], atol=0.3)  # rest 43..53 s (segment table)
    dt = np.asarray(ins.threshold_standstill(f, w, 0.05, 0.01, window=21, min_samples=50))
    s2 = ins.detection_scores(dt, truth)
    print(f"simulated car, threshold: precision {s2.precision:.4f} recall {s2.recall:.4f}")
    assert s2.precision > 0.99 and s2.recall > 0.95


def test_statistic_matches_s3_and_chi2_mean():
    """Same GLRT as jaxnav.survey's stance statistic (odd window, interior samples); at rest its mean is
    (6W - 2)/W (six unit-variance terms per sample less the two of the estimated gravity direction)."""
    from jaxnav.survey import DetectorParams, stance_statistic

    rng = np.random.default_rng(0)
    n, W = 4000, 21
    f = np.array([0.1, -0.2, 9.8]) / np.linalg.norm([0.1, -0.2, 9.8]) * 9.8 + rng.standard_normal((n, 3)) * 0.02
    w = rng.standard_normal((n, 3)) * 0.003
    p = ins.StandstillParams(sigma_a=0.02, sigma_w=0.003, threshold=25.0, g=9.8)
    T = np.asarray(ins.shoe_statistic(f, w, p, window=W))
    T3 = np.asarray(stance_statistic(jnp.asarray(f), jnp.asarray(w), DetectorParams(0.02, 0.003, 25.0, 9.8), window=W))
    np.testing.assert_allclose(T[W:-W], T3[W:-W], rtol=1e-9)
    assert np.mean(T) == pytest.approx((6 * W - 2) / W, rel=0.03)
    assert np.asarray(ins.detect_standstill(f, w, p, window=W)).all()


def test_jit_vmap_grad_and_min_run():
    t, w, f = _car.measured(8)
    p = _car_params()
    T = ins.shoe_statistic(f, w, p, window=21)
    g = jax.grad(lambda s: jnp.sum(ins.shoe_statistic(f, w, p._replace(sigma_a=s), window=21)))(p.sigma_a)
    assert np.isfinite(float(g)) and float(g) < 0  # larger noise -> smaller statistic
    thr = jnp.array([5.0, 25.0, 1e4])
    dd = jax.vmap(lambda h: ins.detect_standstill(f, w, p._replace(threshold=h), window=21))(thr)
    assert dd.shape == (3, t.size) and int(dd[0].sum()) <= int(dd[1].sum()) <= int(dd[2].sum())
    assert np.all(np.asarray(dd[1]) == np.asarray(T < 25.0))
    x = jnp.array([1, 1, 0, 1, 1, 1, 0, 0, 1, 1, 1, 1], bool)
    zero = jnp.zeros((12, 3))
    from jaxnav.ins.standstill import _min_run

    np.testing.assert_array_equal(np.asarray(_min_run(x, 3)), [0, 0, 0, 1, 1, 1, 0, 0, 1, 1, 1, 1])
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        ins.shoe_statistic(zero[:, :2], zero, window=3)
    with pytest.raises(ValueError, match="window"):
        ins.shoe_statistic(zero, zero, window=0)
    with pytest.raises(ValueError, match="same shape"):
        ins.detection_scores(np.zeros(3, bool), np.zeros(4, bool))


def test_walk_set_stops():
    """walk_0827: standstill where RTK horizontal speed < 0.1 m/s (spans >= 1 s), scored inside the GNSS
    span. Handheld: the device is handled at rest (3.3-7 s), which the RTK-based truth counts as still."""
    from jaxnav import io
    from jaxnav.survey import static_spans

    d = DATA_ROOT / "rtklibexplorer-gnss-imu" / "walk_0827"
    if not d.exists():
        pytest.skip("shared data walk_0827 not present")
    from jaxnav.experiments.walk import load_walk

    wk = load_walk(d)
    C_bs = ins.sensor_to_body(ins.mounting_from_groves_deg(180.0, 0.0, -90.0))
    t, dth, dv, dt = io.imu_increments(wk.imu, C_bs)
    f, w = dv / dt[:, None], dth / dt[:, None]
    gt, v = np.asarray(wk.pos.t), np.asarray(wk.pos.v_enu)
    sel = (gt >= t[0]) & (gt <= t[-1])
    ref = static_spans(np.hypot(v[sel, 0], v[sel, 1]) < 0.1, gt[sel], min_duration=1.0, min_gap=0.5)
    truth = np.zeros(t.size, bool)
    for a, b in ref:
        truth |= (t > a) & (t <= b)
    inside = (t >= gt[0]) & (t <= gt[-1])
    g = float(np.linalg.norm(f[t < t[0] + 1.5].mean(0)))
    p = ins.StandstillParams(sigma_a=0.05, sigma_w=0.01, threshold=100.0, g=g)
    det = np.asarray(ins.detect_standstill(f, w, p, window=31, min_samples=80))
    s = ins.detection_scores(det[inside], truth[inside])
    print(
        f"\nwalk_0827 SHOE: precision {s.precision:.4f} recall {s.recall:.4f}; RTK spans "
        f"{(ref - t[0]).round(2).tolist()}, detected {(ins.standstill_intervals(t, det) - t[0]).round(2).tolist()}"
    )
    assert s.precision > 0.98 and s.recall > 0.8


def test_gnss_speed_test_velocity_and_position_differences():
    """q = sqrt(v' C^-1 v): from the reported velocity, and from position differences where it is absent."""
    M = 9
    t = np.arange(M) * 0.5
    p = np.zeros((M, 3))
    p[:, 0] = 2.0 * t  # 2 m/s east
    R = np.zeros((M, 6, 6))
    R[:, :3, :3] = np.eye(3) * 0.02**2
    R[:, 3:, 3:] = np.eye(3) * 0.05**2
    v = np.tile([2.0, 0.0, 0.0], (M, 1))
    q, spd, sig = ins.gnss_speed_test(t, p, v, R, np.ones(M, bool), np.ones(M, bool))
    np.testing.assert_allclose(q, 2.0 / 0.05)
    np.testing.assert_allclose(sig, 0.05)
    q2, spd2, sig2 = ins.gnss_speed_test(t, p, np.full((M, 3), np.nan), R, np.ones(M, bool), np.zeros(M, bool))
    # central difference over 1 s inside, one-sided 0.5 s at the ends; sigma sqrt(2) 0.02 / dt
    np.testing.assert_allclose(spd2, 2.0)
    np.testing.assert_allclose(sig2[1:-1], math.sqrt(2) * 0.02 / 1.0)
    np.testing.assert_allclose(sig2[[0, -1]], math.sqrt(2) * 0.02 / 0.5)
    np.testing.assert_allclose(q2, spd2 / sig2)
    with pytest.raises(ValueError, match="R"):
        ins.gnss_speed_test(t, p, v, R[:, :3, :3], np.ones(M, bool), np.ones(M, bool))


def test_gnss_motion_labels_need_two_epochs_to_veto():
    tg = np.arange(6) * 1.0
    q = np.array([0.5, 0.5, 5.0, 0.5, 5.0, 5.0])
    t = np.array([0.5, 1.5, 2.5, 4.5, 5.2, 9.0])
    moving, static, covered = ins.gnss_motion_labels(t, tg, q, k_moving=3.0, max_gap_s=1.5)
    # 0.5: both still; 1.5 / 2.5: one epoch beyond 3 sigma, not both; 4.5: both moving;
    # 5.2: only the epoch before is near (moving); 9.0: no epoch near
    assert moving.tolist() == [False, False, False, True, True, False]
    assert static.tolist() == [True, False, False, False, False, False]
    assert covered.tolist() == [True, True, True, True, False, False]


def test_quiet_threshold():
    rng = np.random.default_rng(0)
    stat = np.concatenate([rng.chisquare(6, 500) / 6, 1e3 + rng.random(500)])
    quiet = np.arange(1000) < 500
    g = ins.quiet_threshold(stat, quiet, margin=2.0)
    assert g == pytest.approx(2.0 * np.quantile(stat[:500], 0.95))
    assert math.isnan(ins.quiet_threshold(stat, np.zeros(1000, bool)))
