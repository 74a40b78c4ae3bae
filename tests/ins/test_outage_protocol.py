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
