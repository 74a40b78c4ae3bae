"""Coarse alignment (issue 18): GNSS-course heading carried back through a turn on a simulated car,
gyrocompassing on a simulated navigation-grade static IMU, the auto criterion, given heading/attitude."""

import math

import _car
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from jaxnav import ins
from jaxnav.geodesy import WGS84
from jaxnav.io import PosSolution


def _pos_solution(t, llh, v):
    M = t.size
    cov = np.tile(np.eye(3) * 0.01**2, (M, 1, 1))
    return PosSolution(
        path="sim",
        t=t,
        lat=llh[:, 0],
        lon=llh[:, 1],
        h=llh[:, 2],
        q=np.ones(M, int),
        ns=np.full(M, 12),
        cov_enu=cov,
        age=np.zeros(M),
        ratio=np.full(M, 99.0),
        v_enu=v,
        vcov_enu=np.tile(np.eye(3) * 0.02**2, (M, 1, 1)),
    )


def _wrap_deg(x):
    return (x + 180.0) % 360.0 - 180.0


def test_gnss_course_heading_after_a_turn():
    """GNSS only after the first 90 deg turn (acquired late): the course there, carried back through the
    turn by the bias-corrected gyro, gives the heading at the start to 1 deg (consumer-class gyro with a
    0.2-0.3 deg/s turn-on bias, estimated from the 20 s static start)."""
    c = _car.car()
    bias = np.array([0.003, -0.004, 0.005])  # rad/s
    t, w, f = _car.measured(3, gyro_bias=bias)
    tg, v, llh = _car.gnss(10.0)
    late = tg >= 31.0  # after the 90 deg turn (24..30 s)
    sol = _pos_solution(tg[late], llh[late], v[late])
    al = ins.coarse_alignment(t, f, w, sol, static_s=15.0, min_speed=5.0, position=c["pos"][0])
    assert al.heading_method == "gnss_course"
    assert al.t_heading > 31.0 and abs(math.degrees(al.yaw_change)) > 80.0  # the turn was integrated
    err = _wrap_deg(math.degrees(al.att0[2] - c["euler"][0, 2]))
    assert abs(err) < 1.0, err
    np.testing.assert_allclose(al.att0[:2], c["euler"][0, :2], atol=math.radians(0.2))
    # the gyro bias is recovered to the noise of a 15 s mean (~4e-5 rad/s) plus the Earth-rate model
    np.testing.assert_allclose(al.gyro_bias, bias, atol=2e-4)
    # auto: a consumer gyro cannot gyrocompass, so the same result, and the criterion says why
    al2 = ins.coarse_alignment(
        t,
        f,
        w,
        sol,
        static_s=15.0,
        min_speed=5.0,
        position=c["pos"][0],
        heading="auto",
        gyro_bias_sigma=ins.noise_preset("consumer").gyro_bias_instability,
    )
    assert al2.heading_method == "gnss_course" and al2.gyrocompass_sigma > math.radians(10)
    assert al2.att0[2] == pytest.approx(al.att0[2], abs=1e-12)


def _static_nav_grade(seed, heading_deg, T=120.0, rate=100.0, lat=math.radians(45.0)):
    """A static navigation-grade IMU: exact Earth rate and gravity in a tilted body, plus white noise and
    a drawn gyro bias (sigma = the preset's bias instability). Built with scipy, not jaxnav's attitude code."""
    rng = np.random.default_rng(seed)
    nz = ins.noise_preset("navigation")
    pitch, roll, yaw = math.radians(1.5), math.radians(-2.0), -math.radians(heading_deg)
    C_bn = Rotation.from_euler("ZXY", [yaw, pitch, roll]).as_matrix()  # Rz(yaw) Rx(pitch) Ry(roll)
    w_n = WGS84.omega * np.array([0.0, math.cos(lat), math.sin(lat)])
    f_n = np.array([0.0, 0.0, 9.806])
    n = int(T * rate)
    dt = 1.0 / rate
    b = rng.standard_normal(3) * nz.gyro_bias_instability
    w = C_bn.T @ w_n + b + rng.standard_normal((n, 3)) * nz.gyro_arw / math.sqrt(dt)
    f = C_bn.T @ f_n + rng.standard_normal((n, 3)) * nz.accel_vrw / math.sqrt(dt)
    return np.arange(1, n + 1) * dt, f, w, np.array([lat, 0.1, 100.0]), nz


def test_gyrocompass_navigation_grade():
    t, f, w, pos, nz = _static_nav_grade(0, 37.0)
    al = ins.coarse_alignment(
        t, f, w, None, static_s=120.0, position=pos, heading="auto", gyro_bias_sigma=nz.gyro_bias_instability
    )
    assert al.heading_method == "gyrocompass"
    assert al.heading_sigma < math.radians(0.2)
    err = _wrap_deg(math.degrees(al.att0[2]) + 37.0)
    assert abs(err) < 1.0 and abs(err) < 4 * math.degrees(al.heading_sigma), (err, math.degrees(al.heading_sigma))
    # the ARW seen in the data is the simulated one
    assert al.gyro_arw == pytest.approx(nz.gyro_arw, rel=0.05)
    # headings all round the compass
    for h in (0.0, 95.0, 181.0, 300.0):
        t, f, w, pos, _ = _static_nav_grade(1, h)
        al = ins.coarse_alignment(t, f, w, None, static_s=120.0, position=pos, heading="gyrocompass")
        assert abs(_wrap_deg(math.degrees(-al.att0[2]) - h)) < 1.0


def test_gyrocompass_sigma_matches_scatter():
    """Monte Carlo over 40 draws: the heading errors' RMS is within a factor 1.6 of the predicted sigma."""
    errs, sig = [], []
    for s in range(40):
        t, f, w, pos, nz = _static_nav_grade(100 + s, 37.0, T=30.0, rate=50.0)
        al = ins.coarse_alignment(
            t,
            f,
            w,
            None,
            static_s=30.0,
            position=pos,
            heading="gyrocompass",
            gyro_arw=nz.gyro_arw,
            gyro_bias_sigma=nz.gyro_bias_instability,
        )
        errs.append(math.remainder(al.att0[2] + math.radians(37.0), 2 * math.pi))
        sig.append(al.heading_sigma)
    ratio = math.sqrt(np.mean(np.square(errs))) / np.mean(sig)
    assert 1 / 1.6 < ratio < 1.6, ratio


def test_given_heading_and_attitude():
    t, f, w, pos, _ = _static_nav_grade(2, 10.0, T=5.0)
    al = ins.coarse_alignment(t, f, w, None, static_s=5.0, position=pos, heading=math.radians(10.0))
    assert al.heading_method == "given" and math.isnan(al.heading_sigma)
    assert math.degrees(al.att0[2]) == pytest.approx(-10.0)
    att = np.array([0.01, -0.02, 0.3])
    al = ins.coarse_alignment(t, f, w, None, static_s=5.0, position=pos, attitude=att)
    assert al.heading_method == "given"
    np.testing.assert_array_equal(al.att0, att)


def test_gnss_position_moved_from_the_antenna_to_the_imu():
    """With ``lever_rfu`` the first GNSS fix (the antenna's) becomes the IMU's: the antenna at the aligned
    attitude, C_bn l, in ENU metres (radii of curvature at the fix written out here); a given position stays."""
    t, f, w, pos, _ = _static_nav_grade(2, 10.0, T=5.0)
    sol = _pos_solution(np.array([t[0], t[-1]]), np.array([pos, pos]), np.zeros((2, 3)))
    lever = np.array([0.3, -1.2, 0.8])
    kw = dict(static_s=5.0, heading=math.radians(30.0))
    a0 = ins.coarse_alignment(t, f, w, sol, **kw)
    a1 = ins.coarse_alignment(t, f, w, sol, lever_rfu=lever, **kw)
    np.testing.assert_array_equal(a0.nav0.pos, pos)
    C_bn = Rotation.from_quat(np.roll(np.asarray(a1.nav0.q_bn), -1)).as_matrix()
    lat, h = pos[0], pos[2]
    RM = WGS84.a * (1 - WGS84.e2) / (1 - WGS84.e2 * math.sin(lat) ** 2) ** 1.5 + h
    RN = WGS84.a / math.sqrt(1 - WGS84.e2 * math.sin(lat) ** 2) + h
    d = np.asarray(a1.nav0.pos) - pos
    enu = np.array([d[1] * RN * math.cos(lat), d[0] * RM, d[2]])
    np.testing.assert_allclose(enu, -C_bn @ lever, atol=1e-9)
    a2 = ins.coarse_alignment(t, f, w, sol, position=pos, lever_rfu=lever, **kw)
    np.testing.assert_array_equal(a2.nav0.pos, pos)


def test_bad_input():
    t, f, w, pos, _ = _static_nav_grade(3, 0.0, T=2.0)
    with pytest.raises(ValueError, match="heading must be"):
        ins.coarse_alignment(t, f, w, None, position=pos, heading="north")
    with pytest.raises(ValueError, match="at least 2 needed"):
        ins.coarse_alignment(t, f, w, None, position=pos, static_s=0.0)
    with pytest.raises(ValueError, match="needs pos_sol or position"):
        ins.coarse_alignment(t, f, w, None)
    with pytest.raises(ValueError, match="needs pos_sol"):
        ins.coarse_alignment(t, f, w, None, position=pos, heading="gnss")
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        ins.coarse_alignment(t, f[:, :2], w, None, position=pos)
