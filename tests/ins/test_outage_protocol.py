"""Library pieces of the GNSS outage protocol and the likelihood time-offset search, on synthetic inputs."""

import numpy as np
import pytest

from jaxnav import ins


def test_outage_and_training_windows():
    w = ins.outage_windows(0.0, 300.0, first_s=40.0, outage_s=15.0, gap_s=45.0, end_margin_s=30.0)
    np.testing.assert_allclose(w, [[40, 55], [100, 115], [160, 175], [220, 235]])
    tw = ins.training_windows(w, 300.0, 15.0)
    np.testing.assert_allclose(tw, [[70, 85], [130, 145], [190, 205]])  # centred in each GNSS-on gap
    assert not ins.in_windows(np.array([55.0, 99.9]), w).any() and ins.in_windows(np.array([40.0]), w).all()
    np.testing.assert_allclose(ins.training_windows(w[:1], 80.0, 15.0), [[55.5, 70.5]])


def test_score_outages_per_window():
    t = np.arange(10.0)
    fixed = np.array([1, 1, 1, 0, 1, 1, 1, 1, 1, 1], bool)
    w = np.array([[2.0, 5.0], [7.0, 9.0]])
    withheld = ins.in_windows(t, w)
    e = np.arange(10.0)
    s = ins.score_outages(t, e, e / 2, fixed, withheld, w)
    np.testing.assert_array_equal(s.n_ref, [2, 2])  # epoch 3 is not fixed
    np.testing.assert_allclose(s.fwd_max, [4.0, 8.0])
    assert s.fwd_rms_all == pytest.approx(np.sqrt(np.mean(np.array([2.0, 4, 7, 8]) ** 2)))
    assert s.sm_max_mean == pytest.approx(3.0) and np.isnan(s.err_fwd[3])


def test_sigmas_use_the_error_models_index():
    idx = ins.ERROR_MODEL_18.idx
    P = np.zeros((1, 18, 18))
    P[0, idx.dpos, idx.dpos] = np.diag([1e-14, 4e-14, 9.0])
    pos = np.array([[0.5, 2.0, 100.0]])
    s = ins.position_sigmas_enu(P, pos, idx)
    C = ins.position_cov_enu(P, pos, idx)
    np.testing.assert_allclose(np.sqrt(np.diagonal(C[0])), s[0], rtol=1e-12)
    assert s[0, 2] == pytest.approx(3.0) and ins.horizontal_sigma(P, pos, idx)[0] == pytest.approx(np.hypot(*s[0, :2]))
    P[0, idx.phi, idx.phi] = np.diag([1e-4, 4e-4, 9e-4])
    a = ins.attitude_sigmas(P, np.array([0.0]), idx)  # heading north: roll about north, pitch about east
    np.testing.assert_allclose(a[0], [0.02, 0.01, 0.03])


def test_likelihood_search_and_drift_on_a_known_quadratic():
    true_o, true_c = 0.123, 0.004

    def ll(o, c=0.0):
        return -0.5 * ((o - true_o) / 0.01) ** 2 - 0.5 * ((c - true_c) / 0.02) ** 2

    r = ins.likelihood_time_offset(ll, 0.3)
    assert r.offset_s == pytest.approx(true_o, abs=1e-9) and r.sigma_s == pytest.approx(0.01, rel=1e-6)
    assert not r.at_edge and r.fine_s.size == 11
    d = ins.clock_drift(ll, r.offset_s, np.linspace(0.0, 100.0, 50), 0.3)
    assert d["offset_mid_s"] == pytest.approx(true_o, abs=1e-9) and d["change_s"] == pytest.approx(true_c, abs=1e-9)
    assert d["change_sigma_s"] == pytest.approx(0.02, rel=1e-6) and not d["significant"]
    assert ins.parabola_peak([0.0, 1.0, 2.0], [0.0, 1.0, 0.0]) == (1.0, pytest.approx(1 / np.sqrt(2)))
    sel = ins.offset_search_epochs(np.arange(0.0, 10.0), np.linspace(1.0, 8.0, 100), 0.5, [[4.0, 5.0]])
    assert sel["use"].tolist() == [False, False, True, True, False, False, True, True, False, False]
    assert (sel["n_used"], sel["n_withheld"]) == (4, 2)


def test_shifted_outage_windows_tile_one_period():
    kw = dict(first_s=40.0, outage_s=15.0, gap_s=45.0, end_margin_s=30.0)
    ws = ins.shifted_outage_windows(100.0, 500.0, shifts=4, **kw)
    assert len(ws) == 4
    np.testing.assert_array_equal(ws[0], ins.outage_windows(100.0, 500.0, **kw))  # shift 0: the protocol itself
    for k, w in enumerate(ws):
        assert w.shape[1] == 2 and len(w) >= 1
        np.testing.assert_allclose(w[:, 1] - w[:, 0], 15.0)
        np.testing.assert_allclose(w[0, 0], 100.0 + 40.0 + 15.0 * k)  # default step: one 60 s period / 4
        assert w[0, 0] >= 140.0 and w[-1, 1] <= 500.0 - 30.0  # inside the span, the end margin kept
    # the default step equals outage_s here, so the shifts' windows tile [140 s, last end) without a hole
    starts = np.sort(np.concatenate([w[:, 0] for w in ws]))
    np.testing.assert_allclose(np.diff(starts), 15.0)
    t = np.arange(140.0, starts[-1] + 15.0, 0.25)
    inside = np.array([ins.in_windows(t, w) for w in ws])
    assert inside.any(0).all() and (inside.sum(0) == 1).all()  # each instant bridged by exactly one shift
    # an explicit step; one shift is the unshifted protocol
    w2 = ins.shifted_outage_windows(100.0, 500.0, shifts=2, shift_s=10.0, **kw)
    np.testing.assert_allclose(w2[1], w2[0][: len(w2[1])] + 10.0)
    np.testing.assert_array_equal(ins.shifted_outage_windows(100.0, 500.0, **kw)[0], ws[0])
    for bad in (dict(shifts=0), dict(shifts=2, shift_s=0.0), dict(shifts=1.5)):
        with pytest.raises(ValueError):
            ins.shifted_outage_windows(100.0, 500.0, **bad, **kw)


def test_pooled_drifts_equal_a_direct_computation():
    """Per-outage maxima of shifted schedules pooled by the library equal numpy from the per-epoch errors."""
    rng = np.random.default_rng(3)
    t_ref = np.arange(0.0, 300.0, 0.1)
    ref = np.stack([np.full(t_ref.size, 0.7), np.full(t_ref.size, 0.2), np.full(t_ref.size, 100.0)], -1)
    t_sol = np.arange(0.05, 299.0, 0.5)
    e_true = np.cumsum(rng.normal(0.0, 0.05, (t_sol.size, 3)), 0)  # a random-walk drift, m
    from jaxnav.geodesy import enu_to_curvilinear

    pos = ref[: t_sol.size] + np.asarray(enu_to_curvilinear(ref[: t_sol.size], e_true))
    kw = dict(first_s=30.0, outage_s=20.0, gap_s=40.0, end_margin_s=10.0)
    sched = ins.shifted_outage_windows(t_sol[0], t_sol[-1], shifts=3, **kw)
    sched[2] = np.vstack([sched[2], [[299.5, 299.9]]])  # a window with no epoch: NaN, counted as unscored
    got_h, got_3d, direct_h, direct_3d = [], [], [], []
    for w in sched:
        e = ins.trajectory_errors(t_sol, pos, None, None, t_ref, ref, windows=w)
        m3, mh, n = ins.outage_drift_maxima(e, len(w))
        p = ins.error_statistics(e, n_windows=len(w))["outage_protocol"]
        np.testing.assert_array_equal(p["max_3d_drift_m"], m3)
        np.testing.assert_array_equal(p["max_h_drift_m"], mh)
        got_h.append(mh)
        got_3d.append(m3)
        for j, (a, b) in enumerate(w):  # independent: the per-epoch errors inside [a, b)
            s = (e.t >= a) & (e.t < b)
            assert n[j] == s.sum()
            if s.any():
                direct_3d.append(np.max(np.sqrt(np.sum(e.pos_enu[s] ** 2, 1))))
                direct_h.append(np.max(np.sqrt(e.pos_enu[s, 0] ** 2 + e.pos_enu[s, 1] ** 2)))
    st = ins.pooled_outage_drifts(got_h, got_3d)
    dh, d3 = np.array(direct_h), np.array(direct_3d)
    assert st["n_outages"] == d3.size == sum(len(w) for w in sched) - 1 and st["n_unscored_outages"] == 1
    assert st["rms_of_max_3d_drift_m"] == pytest.approx(np.sqrt(np.mean(d3**2)), rel=1e-12)
    assert st["mean_of_max_3d_drift_m"] == pytest.approx(np.mean(d3), rel=1e-12)
    assert st["max_of_max_3d_drift_m"] == pytest.approx(np.max(d3), rel=1e-12)
    assert st["rms_of_max_h_drift_m"] == pytest.approx(np.sqrt(np.mean(dh**2)), rel=1e-12)
    assert st["mean_of_max_h_drift_m"] == pytest.approx(np.mean(dh), rel=1e-12)
    assert st["max_of_max_h_drift_m"] == pytest.approx(np.max(dh), rel=1e-12)
    assert d3.max() > 0.1 and np.all(dh <= d3)
    # horizontal only (the withheld-fix scores): no 3-D keys; nothing scored: NaN, not an error
    assert "rms_of_max_3d_drift_m" not in ins.pooled_outage_drifts(got_h)
    empty = ins.pool_drifts([np.array([np.nan])])
    assert empty["n_outages"] == 0 and empty["n_unscored"] == 1 and np.isnan(empty["rms_m"])
