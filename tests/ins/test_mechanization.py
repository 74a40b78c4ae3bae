"""Strapdown mechanization: stationary, Schuler period, reverse-navigation closure, bad input."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxnav
from jaxnav import ins
from jaxnav.ins import attitude as A

LAT, LON, H = np.radians(39.0), np.radians(108.0), 205.8795
POS = jnp.array([LAT, LON, H])


def _stationary_imu(att, dt, N):
    """Ideal increments of an IMU at rest: w_ib^b = C_nb w_ie^n, f^b = -C_nb g^n (exact, constant)."""
    q = A.euler_to_quat(att)
    C = A.quat_to_dcm(q)
    e = ins.earth_params(POS, jnp.zeros(3))
    return q, jnp.tile(C.T @ e.w_ie_n * dt, (N, 1)), jnp.tile(C.T @ (-e.g_n) * dt, (N, 1))


def test_stationary_one_hour_stays_put():
    att = jnp.array([0.01, -0.02, A.heading_to_yaw(np.radians(30))])
    q, dth, dv = _stationary_imu(att, 0.01, 360_000)
    r = ins.mechanize(ins.NavState(q, jnp.zeros(3), POS), dth, dv, 0.01, save_every=1000)
    assert int(r.status) == 0
    assert float(jnp.max(jnp.abs(r.nav.v_n))) < 1e-6  # m/s after 1 h
    dpos = (r.nav.pos - POS) * jnp.array([6.4e6, 6.4e6 * np.cos(LAT), 1.0])
    assert float(jnp.max(jnp.abs(dpos))) < 1e-3  # m
    att_err = A.quat_to_euler(r.nav.q_bn) - att
    assert float(jnp.max(jnp.abs(att_err))) < 1e-9  # rad


def _fit_period(t, y, lo, hi):
    best = None
    for P in np.linspace(lo, hi, 4001):
        w = 2 * np.pi / P
        X = np.c_[np.sin(w * t), np.cos(w * t), np.ones_like(t), t]
        res = np.sum((X @ np.linalg.lstsq(X, y, rcond=None)[0] - y) ** 2)
        if best is None or res < best[1]:
            best = (P, res)
    return best[0]


@pytest.mark.parametrize("kind", ["velocity", "tilt"])
def test_schuler_period_84_4_min(kind):
    """2 h at rest with an initial north-velocity or tilt error: horizontal error oscillates at 84.4 min."""
    dt, N = 0.1, 72_000
    q, dth, dv = _stationary_imu(jnp.zeros(3), dt, N)
    if kind == "velocity":
        nav0 = ins.NavState(q, jnp.array([0.0, 0.1, 0.0]), POS)
    else:
        nav0 = ins.NavState(A.euler_to_quat(jnp.array([1e-4, 0.0, 0.0])), jnp.zeros(3), POS)
    r = ins.mechanize(nav0, dth, dv, dt, save_every=100, hold_height=True)
    t = np.arange(1, N // 100 + 1) * 10.0
    period = _fit_period(t, np.asarray(r.nav.v_n[:, 1]), 4000.0, 6000.0)
    g = float(ins.normal_gravity(LAT, H))
    R = float(jnp.sqrt(jaxnav.geodesy.meridian_radius(LAT) * jaxnav.geodesy.prime_vertical_radius(LAT)))
    schuler = 2 * np.pi * np.sqrt(R / g)
    assert abs(schuler / 60 - 84.4) < 0.1
    assert abs(period / schuler - 1) < 0.01, (period / 60, schuler / 60)


def _manoeuvre(dt, N, key=0):
    """Smooth synthetic increments: gravity-cancelling specific force plus sinusoidal rates."""
    t = np.arange(N) * dt
    w = np.stack([0.02 * np.sin(0.3 * t), 0.03 * np.sin(0.2 * t + 1), 0.05 * np.cos(0.1 * t)], 1)
    f = np.stack([0.5 * np.sin(0.05 * t), 1.0 * np.cos(0.07 * t), 9.8 + 0.2 * np.sin(0.3 * t)], 1)
    return jnp.asarray(w * dt), jnp.asarray(f * dt)


def test_reverse_navigation_retraces_to_start():
    dt, N = 0.01, 20_000  # 200 s at 100 Hz
    dth, dv = _manoeuvre(dt, N)
    nav0 = ins.NavState(
        A.euler_to_quat(jnp.array([0.0, 0.0, A.heading_to_yaw(np.radians(30))])), jnp.array([41.0, 71.0, 0.5]), POS
    )
    fwd = ins.mechanize(nav0, dth, dv, dt)
    bwd = ins.mechanize_backward(fwd.final.nav, dth, dv, dt, a0=fwd.final.a_prev)
    scale = jnp.array([6.4e6, 6.4e6 * np.cos(LAT), 1.0])
    closure = np.asarray((bwd.nav.pos[0] - POS) * scale)
    assert np.max(np.abs(closure)) < 1e-4  # metres after 200 s out and back (measured 2e-6)
    assert float(jnp.max(jnp.abs(bwd.nav.v_n[0] - nav0.v_n))) < 1e-6
    assert float(jnp.max(jnp.abs(A.quat_to_rv(A.quat_mul(A.quat_conj(nav0.q_bn), bwd.nav.q_bn[0]))))) < 1e-9
    # backward rows are aligned with the forward time axis: row i is the state at the start of sample i
    mid = np.asarray((bwd.nav.pos[N // 2] - fwd.nav.pos[N // 2 - 1]) * scale)
    assert np.max(np.abs(mid)) < 0.01


def test_rates_equal_increments_and_save_every():
    dt, N = 0.01, 1000
    dth, dv = _manoeuvre(dt, N)
    nav0 = ins.NavState(jnp.array([1.0, 0, 0, 0]), jnp.zeros(3), POS)
    a = ins.mechanize(nav0, dth, dv, dt)
    b = ins.mechanize(nav0, dth / dt, dv / dt, dt, kind="rates")
    c = ins.mechanize(nav0, dth, dv, jnp.full(N, dt), save_every=10)
    np.testing.assert_allclose(a.nav.pos, b.nav.pos, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(a.nav.pos[9::10], c.nav.pos)
    np.testing.assert_array_equal(a.nav.q_bn[9::10], c.nav.q_bn)


def test_bad_imu_input_gives_clear_errors():
    dt, N = 0.01, 100
    dth, dv = _manoeuvre(dt, N)
    nav0 = ins.NavState(jnp.array([1.0, 0, 0, 0]), jnp.zeros(3), POS)
    t = np.arange(N) * dt
    bad = np.array(dth)
    bad[37, 1] = np.nan
    with pytest.raises(ValueError, match="NaN/inf IMU sample at index 37"):
        ins.mechanize(nav0, bad, dv, dt)
    t2 = t.copy()
    t2[50] = t2[49]
    with pytest.raises(ValueError, match="not increasing at index 50"):
        ins.mechanize(nav0, dth, dv, dt, t=t2)
    t3 = t.copy()
    t3[60:] += 0.05
    with pytest.raises(ValueError, match="gap of 0.06 s after index 59"):
        ins.mechanize(nav0, dth, dv, dt, t=t3)
    with pytest.raises(ValueError, match=r"dtheta has shape \(100, 2\)"):
        ins.mechanize(nav0, dth[:, :2], dv, dt)
    with pytest.raises(ValueError, match=r"dt has shape \(99,\)"):
        ins.mechanize(nav0, dth, dv, jnp.full(99, dt))
    with pytest.raises(ValueError, match="enable_x64"):
        ins.mechanize(nav0._replace(pos=POS.astype(jnp.float32)), dth, dv, dt)
    with pytest.raises(ValueError, match="save_every=7"):
        ins.mechanize(nav0, dth, dv, dt, save_every=7)
    # inside jit/vmap the values cannot be checked on the host: a status flag says it instead
    r = jax.jit(lambda d: ins.mechanize(nav0, d, dv, dt).status)(jnp.asarray(bad))
    assert int(r) & jaxnav._status.NONFINITE_IMU
    with pytest.raises(jaxnav.StatusError, match="NaN/inf IMU sample"):
        jaxnav.raise_for_status(r)


def test_quaternion_update_gradient_finite_at_zero_rotation():
    dt, N = 0.01, 50
    dv = jnp.tile(jnp.array([0.0, 0.0, 9.8]) * dt, (N, 1))
    nav0 = ins.NavState(jnp.array([1.0, 0, 0, 0]), jnp.zeros(3), POS)

    def final_yaw(scale):
        r = ins.mechanize(nav0, jnp.zeros((N, 3)) * scale, dv, dt, validate=False)
        return A.quat_to_euler(r.nav.q_bn[-1])[2] + jnp.sum(r.nav.v_n[-1])

    g = jax.grad(final_yaw)(1.0)
    assert np.isfinite(float(g))


@pytest.fixture(scope="module")
def s0_window():
    """S0 ideal IMU, a manoeuvring 200 s window (600-800 s): increments, true states, ENU scale (m/rad)."""
    from jaxnav import sim

    tr = sim.make_trajectory(sim.s0_scenario())
    a, K = 60_000, 20_000
    assert len(np.unique(np.asarray(tr.segment[a : a + K]))) >= 3  # several segments, not a cruise
    q, v, p = tr.q_bn[a : a + K + 1], tr.v_n[a : a + K + 1], tr.pos[a : a + K + 1]
    scale = np.array([6.37e6, 6.37e6 * np.cos(float(p[0, 0])), 1.0])
    return tr.dtheta[a : a + K], tr.dv[a : a + K], q, v, p, scale


def test_reverse_navigation_on_s0_ideal_imu_retraces_truth(s0_window):
    """Backward from the true end state follows the truth back to the start; backward from the
    forward end state closes on the start."""
    dth, dv, q, v, p, scale = s0_window
    fwd = ins.mechanize(ins.NavState(q[0], v[0], p[0]), dth, dv, 0.01)
    assert np.max(np.abs(np.asarray(fwd.nav.pos - p[1:]) * scale)) < 1e-5
    bwd = ins.mechanize_backward(ins.NavState(q[-1], v[-1], p[-1]), dth, dv, 0.01)
    assert np.max(np.abs(np.asarray(bwd.nav.pos - p[:-1]) * scale)) < 1e-5  # measured 2.4e-7 m
    assert float(jnp.max(jnp.abs(bwd.nav.v_n - v[:-1]))) < 1e-6
    closed = ins.mechanize_backward(fwd.final.nav, dth, dv, 0.01, a0=fwd.final.a_prev)
    assert np.max(np.abs(np.asarray(closed.nav.pos[0] - p[0]) * scale)) < 1e-8  # measured 6e-12 m


# ------------------------------------------------------------------------------------------
# two-speed mechanization (nav_every > 1)


def test_two_speed_follows_truth_and_per_sample(s0_window):
    """Navigation-frame terms once per M samples on the manoeuvring S0 window, against the truth
    and the per-sample scan. Measured (200 s): M = 10 (0.1 s) 1.7e-6 m, 4.9e-7 m/s from the
    truth, 6.5e-11 in q from the per-sample run; M = 100 (1 s) 1.7e-4 m, 4.9e-5 m/s. The
    per-sample run itself is 5e-7 m, 2.3e-8 m/s from the truth. The error grows as (M dt)^2
    (M = 100 is measured, not run here, to keep the suite short)."""
    M, tol_m, tol_v = 10, 1e-5, 2e-6
    dth, dv, q, v, p, scale = s0_window
    n0 = ins.NavState(q[0], v[0], p[0])
    ref = ins.mechanize(n0, dth, dv, 0.01)
    r = ins.mechanize(n0, dth, dv, 0.01, nav_every=M)
    assert r.nav.pos.shape == ref.nav.pos.shape and int(r.status) == 0
    assert np.max(np.abs(np.asarray(r.nav.pos - p[1:]) * scale)) < tol_m
    assert float(jnp.max(jnp.abs(r.nav.v_n - v[1:]))) < tol_v
    assert np.max(np.abs(np.asarray(r.nav.pos - ref.nav.pos) * scale)) < tol_m
    assert float(jnp.max(jnp.abs(r.nav.q_bn - ref.nav.q_bn))) < 1e-4 * tol_m
    # the states kept at block ends (one scan), nested chunks, and every 5th sample are the same rows
    for se in (M, 2 * M, 5):
        r2 = ins.mechanize(n0, dth, dv, 0.01, nav_every=M, save_every=se)
        for a, b in zip(r2.nav, r.nav):
            np.testing.assert_allclose(np.asarray(a), np.asarray(b[se - 1 :: se]), rtol=1e-14, atol=1e-12)
        for a, b in zip(r2.final.nav, r.final.nav):
            np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-14, atol=1e-12)
    # reverse navigation with the same blocks closes on the start
    closed = ins.mechanize_backward(r.final.nav, dth, dv, 0.01, a0=r.final.a_prev, nav_every=M)
    assert np.max(np.abs(np.asarray(closed.nav.pos[0] - p[0]) * scale)) < 1e-8  # measured 8.7e-10 m


def test_two_speed_tail_short_record_vmap_and_bad_input(s0_window):
    """N not a multiple of nav_every (a shorter last block), N < nav_every, the vmapped batch over
    initial states (the body-frame work is shared), NaN flags and a bad nav_every."""
    dth, dv, q, v, p, scale = s0_window
    n0 = ins.NavState(q[0], v[0], p[0])
    ref = ins.mechanize(n0, dth[:1003], dv[:1003], 0.01)
    r1003 = ins.mechanize(n0, dth[:1003], dv[:1003], 0.01, nav_every=10)
    assert r1003.nav.pos.shape == (1003, 3)
    assert np.max(np.abs(np.asarray(r1003.nav.pos - ref.nav.pos) * scale)) < 1e-5
    np.testing.assert_allclose(np.asarray(r1003.nav.pos[-1]), np.asarray(r1003.final.nav.pos), rtol=0, atol=1e-15)
    assert np.max(np.abs(np.asarray(r1003.final.nav.pos - ref.final.nav.pos) * scale)) < 1e-5  # 3.8e-7 m
    r7 = ins.mechanize(n0, dth[:7], dv[:7], 0.01, nav_every=10)
    assert r7.nav.pos.shape == (7, 3)
    assert np.max(np.abs(np.asarray(r7.nav.pos - ref.nav.pos[:7]) * scale)) < 1e-6

    dv0 = jnp.array([[0.0, 0.0, 0.0], [0.1, -0.05, 0.0], [0.0, 0.2, 0.0]])
    batch = ins.NavState(jnp.tile(q[0], (3, 1)), v[0] + dv0, jnp.tile(p[0], (3, 1)))
    run = lambda n: ins.mechanize(n, dth[:2000], dv[:2000], 0.01, nav_every=10, save_every=100).nav
    out = jax.jit(jax.vmap(run))(batch)
    for i in range(3):
        one = run(jax.tree_util.tree_map(lambda a: a[i], batch))
        for a, b in zip(out, one):
            np.testing.assert_allclose(np.asarray(a[i]), np.asarray(b), rtol=1e-13, atol=1e-13)

    bad = np.asarray(dth[:100]).copy()
    bad[37, 1] = np.nan
    res = ins.mechanize(n0, bad, dv[:100], 0.01, nav_every=10, validate=False)
    assert int(res.status) & jaxnav._status.NONFINITE_IMU
    assert not int(res.status) & jaxnav._status.IMU_INCREMENT_TOO_LARGE
    # a rotation increment above pi in one sample leaves the range of the block path's attitude series
    big = np.asarray(dth[:100]).copy()
    big[50] = [0.0, 0.0, 3.2]
    flagged = ins.mechanize(n0, big, dv[:100], 0.01, nav_every=10, validate=False).status
    assert int(flagged) == jaxnav._status.IMU_INCREMENT_TOO_LARGE
    assert int(ins.mechanize(n0, big, dv[:100], 0.01, validate=False).status) == 0  # per sample: sin/cos, exact
    with pytest.raises(jaxnav.StatusError, match="exceeded pi rad in one sample"):
        jaxnav.raise_for_status(flagged)
    with pytest.raises(ValueError, match="nav_every=0 must be an integer >= 1"):
        ins.mechanize(n0, dth[:100], dv[:100], 0.01, nav_every=0)
