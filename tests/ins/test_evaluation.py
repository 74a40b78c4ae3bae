"""Scoring against a reference trajectory: ``trajectory_errors`` / ``error_statistics`` equal an
independent numpy computation on a small synthetic case; the KF-GINS ``truth.nav`` and CSV readers
(values, units, and errors naming file and line)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from jaxnav import ins
from jaxnav.io import ReaderError, read_csv_truth, read_kfgins_truth

A, F = 6378137.0, 1 / 298.257223563
E2 = F * (2 - F)


def _case(seed=0):
    """A 60 s reference at 10 Hz (a gentle curve near 40 N) and a 2 Hz solution with known errors."""
    rng = np.random.default_rng(seed)
    t_ref = 1000.0 + np.arange(0, 60.0 + 1e-9, 0.1)
    lat = math.radians(40.0) + 1e-6 * np.sin(t_ref / 10)
    lon = math.radians(-105.0) + 2e-6 * (t_ref - 1000.0)
    h = 1600.0 + 0.1 * (t_ref - 1000.0)
    v = np.stack([np.cos(t_ref / 7), np.sin(t_ref / 9), 0.1 + 0 * t_ref], -1)
    heading = np.radians((350.0 + 0.5 * (t_ref - 1000.0)) % 360.0)  # crosses north
    rpy = np.stack([0.01 * np.sin(t_ref), 0.02 * np.cos(t_ref), heading], -1)
    t_sol = 1000.25 + np.arange(0, 59.0, 0.5)
    interp = lambda y: np.interp(t_sol, t_ref, y)
    d = rng.normal(0, 1e-6, (t_sol.size, 2))
    pos_sol = np.stack([interp(lat) + d[:, 0], interp(lon) + d[:, 1], interp(h) + rng.normal(0, 0.5, t_sol.size)], -1)
    v_sol = np.stack([interp(v[:, j]) for j in range(3)], -1) + rng.normal(0, 0.05, (t_sol.size, 3))
    hd_true = np.interp(t_sol, t_ref, np.unwrap(heading))
    rpy_sol = np.stack([interp(rpy[:, 0]) + 0.001, interp(rpy[:, 1]) - 0.002, np.mod(hd_true + 0.01, 2 * np.pi)], -1)
    cov = np.zeros((t_sol.size, 3, 3))
    cov[:, 0, 0], cov[:, 1, 1], cov[:, 2, 2] = 4.0, 9.0, 0.25
    cov[:, 0, 1] = cov[:, 1, 0] = 1.0
    windows = np.array([[1010.0, 1020.0], [1040.0, 1050.0]])
    return t_ref, np.stack([lat, lon, h], -1), v, rpy, t_sol, pos_sol, v_sol, rpy_sol, cov, windows


def _independent(t_ref, pref, vref, rref, t_sol, psol, vsol, rsol, cov, windows):
    """The same by hand: reference interpolated at the solution epochs, radii of curvature at the reference."""
    lat = np.interp(t_sol, t_ref, pref[:, 0])
    lon = np.interp(t_sol, t_ref, pref[:, 1])
    h = np.interp(t_sol, t_ref, pref[:, 2])
    w = np.sqrt(1 - E2 * np.sin(lat) ** 2)
    RN, RM = A / w, A * (1 - E2) / w**3
    e = np.stack([(psol[:, 1] - lon) * (RN + h) * np.cos(lat), (psol[:, 0] - lat) * (RM + h), psol[:, 2] - h], -1)
    dv = vsol - np.stack([np.interp(t_sol, t_ref, vref[:, j]) for j in range(3)], -1)
    ra = np.stack([np.interp(t_sol, t_ref, np.unwrap(rref[:, j])) for j in range(3)], -1)
    da = (rsol - ra + np.pi) % (2 * np.pi) - np.pi
    nees = np.array([ek @ np.linalg.inv(ck) @ ek for ek, ck in zip(e, cov)])
    d3 = np.sqrt((e**2).sum(1))
    dh = np.sqrt((e[:, :2] ** 2).sum(1))
    inw = [(t_sol >= a) & (t_sol < b) for a, b in windows]
    maxd = np.array([d3[s].max() for s in inw])
    return e, dv, da, nees, d3, dh, inw, maxd


def test_scores_equal_an_independent_computation():
    c = _case()
    t_ref, pref, vref, rref, t_sol, psol, vsol, rsol, cov, windows = c
    err = ins.trajectory_errors(t_sol, psol, vsol, rsol, t_ref, pref, vref, rref, cov_pos_enu=cov, windows=windows)
    assert err.at == "solution" and err.n_dropped == 0 and err.t.size == t_sol.size
    e, dv, da, nees, d3, dh, inw, maxd = _independent(*c)
    np.testing.assert_allclose(err.pos_enu, e, atol=1e-6)
    np.testing.assert_allclose(err.vel_enu, dv, atol=1e-12)
    np.testing.assert_allclose(err.att, da, atol=1e-12)
    np.testing.assert_allclose(err.att[:, 2], 0.01, atol=1e-9)  # heading error across north: wrapped
    np.testing.assert_allclose(err.nees_pos, nees, rtol=1e-9)
    st = ins.error_statistics(err, n_windows=2)
    rms = lambda x: math.sqrt(np.mean(np.square(x)))
    a = st["all"]
    assert a["pos_h_rms_m"] == pytest.approx(rms(dh), rel=1e-9)
    assert a["pos_3d_max_m"] == pytest.approx(d3.max(), rel=1e-9)
    assert a["pos_u_rms_m"] == pytest.approx(rms(e[:, 2]), rel=1e-9)
    assert a["vel_3d_rms_m_s"] == pytest.approx(rms(np.sqrt((dv**2).sum(1))), rel=1e-9)
    assert a["roll_rms_rad"] == pytest.approx(0.001, rel=1e-6) and a["pitch_rms_rad"] == pytest.approx(0.002, rel=1e-6)
    assert a["nees_pos_mean"] == pytest.approx(nees.mean(), rel=1e-9)
    sig = np.sqrt(np.array([4.0, 9.0, 0.25]))
    assert a["share_pos_within_3_sigma"] == pytest.approx(np.mean(np.abs(e) <= 3 * sig), abs=1e-12)
    o = st["outages"]
    s = inw[0] | inw[1]
    assert o["n_epochs"] == s.sum() and o["pos_3d_rms_m"] == pytest.approx(rms(d3[s]), rel=1e-9)
    p = st["outage_protocol"]
    np.testing.assert_allclose(p["max_3d_drift_m"], maxd, rtol=1e-9)
    assert p["rms_of_max_3d_drift_m"] == pytest.approx(rms(maxd), rel=1e-9)


def test_denser_solution_is_scored_at_the_reference_epochs_and_gaps_are_skipped():
    t_ref, pref, vref, rref, *_ = _case()
    keep = (t_ref < 1020.0) | (t_ref > 1030.0)  # a 10 s gap in the reference
    t_r = t_ref[keep][::20]  # 2 s reference
    err = ins.trajectory_errors(t_ref, pref, vref, rref, t_r, pref[keep][::20], vref[keep][::20], rref[keep][::20])
    assert err.at == "reference"
    np.testing.assert_allclose(err.pos_enu, 0.0, atol=1e-9)
    # solution denser: scored at the reference epochs; the reference itself with a gap
    err2 = ins.trajectory_errors(t_r, pref[keep][::20], None, None, t_ref, pref, max_gap=3.0, at="solution")
    assert err2.n_dropped == 0
    err3 = ins.trajectory_errors(t_ref, pref, None, None, t_r, pref[keep][::20], at="solution", max_gap=3.0)
    assert err3.n_dropped > 0 and not np.any((err3.t > 1020.0) & (err3.t < 1030.0))
    with pytest.raises(ValueError, match="no common epoch"):
        ins.trajectory_errors(t_ref + 1e6, pref, None, None, t_ref, pref)


def test_solution_errors_of_nav_states_against_a_reference_in_another_week_count():
    """``solution_errors`` on NavStates: a duplicated epoch counts once, a reference in GPST since 1980 is put
    on the solution's seconds of week, and the sigmas are the covariance's (IMU states of the 15-state model)."""
    from types import SimpleNamespace

    from jaxnav.ins.attitude import euler_to_quat, heading_to_yaw, quat_to_roll_pitch_heading
    from jaxnav.io import nav_solution

    t_ref, pref, vref, rref, t_sol, pos_sol, v_sol, rpy_sol, cov, windows = _case()
    q = np.asarray(euler_to_quat(np.stack([rpy_sol[:, 1], rpy_sol[:, 0], heading_to_yaw(rpy_sol[:, 2])], -1)))
    np.testing.assert_allclose(np.asarray(quat_to_roll_pitch_heading(q)), rpy_sol, atol=1e-12)
    dup = np.r_[np.arange(t_sol.size), 5]  # epoch 5 again at the end, as a pseudo-measurement update
    order = np.argsort(t_sol[dup], kind="stable")
    sel = dup[order]
    nav = ins.NavState(q_bn=q[sel], v_n=v_sol[sel], pos=pos_sol[sel])
    idx = ins.ERROR_MODEL_15.idx
    P = np.zeros((sel.size, 15, 15))
    P[:, idx.dv, idx.dv] = np.eye(3) * 0.04
    P[:, idx.phi, idx.phi] = np.eye(3) * 1e-4
    P[:, idx.dpos, idx.dpos] = np.diag([1e-12, 1e-12, 0.25])
    week = 2071 * 604800.0
    truth = SimpleNamespace(t=t_ref + week, pos=pref, v_enu=vref, rpy=rref)
    got = ins.solution_errors(t_sol[sel], nav, P, truth, idx, windows=windows)
    ref = ins.trajectory_errors(
        t_sol,
        pos_sol,
        v_sol,
        rpy_sol,
        t_ref,
        pref,
        vref,
        rref,
        cov_pos_enu=ins.position_cov_enu(P[: t_sol.size], pos_sol, idx),
        sig_vel=np.full((t_sol.size, 3), 0.2),
        sig_att=ins.attitude_sigmas(P[: t_sol.size], rpy_sol[:, 2], idx),
        windows=windows,
    )
    for f in ("t", "pos_enu", "vel_enu", "att", "sig_pos_enu", "sig_vel", "sig_att"):
        np.testing.assert_allclose(getattr(got, f), getattr(ref, f), atol=1e-9, err_msg=f)
    with pytest.raises(ValueError, match="no common epoch"):
        ins.solution_errors(t_sol[sel] + 1e5, nav, P, truth, idx)
    sol = nav_solution(t_sol[sel], nav, P, idx)
    np.testing.assert_allclose(sol.rpy, rpy_sol[sel], atol=1e-12)
    np.testing.assert_allclose(sol.sig_vel, 0.2, rtol=1e-12)
    np.testing.assert_allclose(sol.sig_pos_enu[:, 2], 0.5, rtol=1e-12)
    assert not sol.gnss_used.any() and not sol.quality.any()


TRUTH = (
    "2071 378043.000 30.444 114.471 20.0 1.0 2.0 -0.5 0.1 -0.2 359.5\n"
    "2071 378043.005 30.444 114.471 20.0 1.0 2.0 -0.5 0.1 -0.2 0.5\n"
)


def test_kfgins_truth_reader(tmp_path):
    f = tmp_path / "truth.nav"
    f.write_text(TRUTH)
    tr = read_kfgins_truth(f)
    assert tr.t[0] == pytest.approx(2071 * 604800 + 378043.0)
    np.testing.assert_allclose(tr.pos[0], [math.radians(30.444), math.radians(114.471), 20.0])
    np.testing.assert_allclose(tr.v_enu[0], [2.0, 1.0, 0.5])  # east, north, up
    np.testing.assert_allclose(np.degrees(tr.rpy[1]), [0.1, -0.2, 0.5])
    bad = tmp_path / "bad.nav"
    bad.write_text(TRUTH + "2071 378043.010 30.444 114.471 20.0 1.0 2.0 -0.5 0.1 -0.2\n")
    with pytest.raises(ReaderError, match=r"bad\.nav:3: 10 fields, expected 11"):
        read_kfgins_truth(bad)
    bad.write_text(TRUTH + "2071 378043.010 30.444 114.471 20.0 1.0 2.0 -0.5 0.1 -95.0 1.0\n")
    with pytest.raises(ReaderError, match=r"bad\.nav:3: pitch -95"):
        read_kfgins_truth(bad)
    bad.write_text(TRUTH + "2071 378043.000 30.444 114.471 20.0 1.0 2.0 -0.5 0.1 -0.2 1.0\n")
    with pytest.raises(ReaderError, match=r"bad\.nav:3: .*must increase"):
        read_kfgins_truth(bad)
    bad.write_text("2071 378043.000 91.0 114.471 20.0 1.0 2.0 -0.5 0.1 -0.2 1.0\n")
    with pytest.raises(ReaderError, match=r"bad\.nav:1: latitude 91"):
        read_kfgins_truth(bad)


def test_csv_truth_reader(tmp_path):
    f = tmp_path / "ref.csv"
    f.write_text(
        "time,lat,lon,height,vu,ve,vn,hdg\n10.0,0.5,1.0,5.0,0.1,1.0,2.0,0.25\n10.5,0.5,1.0,5.0,0.1,1.0,2.0,0.3\n"
    )
    with pytest.raises(ValueError, match="map all of"):
        read_csv_truth(f, {"t": "time", "lat": "lat", "lon": "lon", "h": "height", "heading": "hdg"})
    tr = read_csv_truth(
        f,
        {"t": "time", "lat": "lat", "lon": "lon", "h": "height", "ve": "ve", "vn": "vn", "vu": "vu"},
        {"angle": "rad"},
    )
    np.testing.assert_allclose(tr.pos[0], [0.5, 1.0, 5.0])
    np.testing.assert_allclose(tr.v_enu[1], [1.0, 2.0, 0.1])
    assert np.all(np.isnan(tr.rpy))
    with pytest.raises(ValueError, match="unknown column key"):
        read_csv_truth(f, {"t": 0, "lat": 1, "lon": 2, "h": 3, "speed": 4})
    f.write_text("10.0,0.5,1.0,x\n")
    with pytest.raises(ReaderError, match=r"ref\.csv:1: column 'h'"):
        read_csv_truth(f, {"t": 0, "lat": 1, "lon": 2, "h": 3})
