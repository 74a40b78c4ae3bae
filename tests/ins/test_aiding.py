"""INS aiding through the general measurement interface (issue 18): the H of every built-in model
against autodiff of its nonlinear measurement, and on simulated runs with known truth: the
non-holonomic constraint on a car with 60 s GNSS outages, ZUPT/ZARU on a stop-and-go walk, the
chi-square gate on injected GNSS outliers, and the 21-state model recovering a gyro scale factor."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxnav
from jaxnav import _status, ins, sim
from jaxnav.ins import LCParams, PVMeasurements, loosely_coupled
from jaxnav.ins import attitude as A
from jaxnav.ins import measurements as ms

# ----------------------------------------------------------------------------- 1. H = dz/dx


def _nav():
    deg = np.pi / 180
    q = A.euler_to_quat(jnp.array([4.0, -7.0, 130.0]) * deg)
    return ins.NavState(q_bn=q, v_n=jnp.array([8.0, -11.0, 0.4]), pos=jnp.array([47.3 * deg, 8.5 * deg, 420.0]))


def _perturb(nav, x):
    """The computed state for error x (phi-angle convention C_c = (I - [phi x]) C, dV, dpos)."""
    q = A.quat_mul(A.rv_to_quat(-x[0:3]), nav.q_bn)
    return ins.NavState(q_bn=q, v_n=nav.v_n + x[3:6], pos=nav.pos + x[6:9])


def _cases():
    Cvb = A.euler_to_dcm(jnp.array([0.02, -0.03, 0.05]))
    lever = jnp.array([0.3, -1.2, -0.4])
    return {
        "gnss_pv": (
            ms.GNSS_PV,
            ms.GnssData(
                pos=_nav().pos + jnp.array([1e-7, -2e-7, 1.0]),
                vel=jnp.array([8.1, -11.2, 0.3]),
                R=jnp.eye(6),
                mask=jnp.ones(6, bool),
                lever=lever,
            ),
            1.0,
            9,
        ),
        "zupt": (ms.ZUPT, None, ms.ZuptParams(0.02), 12),
        "zaru": (ms.ZARU, None, ms.ZaruParams(1e-3), 12),
        "nhc": (ms.NHC, None, ms.VehicleParams(0.1, Cvb, jnp.zeros(3)), 12),
        "nhc_lever": (ms.NHC, None, ms.VehicleParams(0.1, Cvb, lever), 9),
        "odometer": (ms.ODOMETER, jnp.asarray(13.0), ms.VehicleParams(0.1, Cvb, lever), 9),
        "heading": (ms.HEADING, jnp.asarray(2.0), ms.HeadingParams(0.01, jnp.array([0.3, 0.9, 0.1])), 12),
    }


@pytest.mark.parametrize("name", list(_cases()))
def test_H_equals_the_jacobian_of_the_nonlinear_measurement(name):
    """z(x) = h(computed state(x)) - measured; H must be dz/dx at x = 0 (first-order error model). The gyro bias
    enters as the corrected rate w + eps_b; columns compared: all 12 (nav + eps_b), or the 9 navigation columns
    for models that neglect the tiny gyro-bias term of a lever-arm velocity (GNSS, NHC/odometer with lever)."""
    model, data, params, ncol = _cases()[name]
    nav = _nav()
    w = jnp.array([0.02, -0.05, 0.3])
    n = 15

    def z_of(x):
        ctx = ms.MeasContext(
            nav=_perturb(nav, x),
            w_ib_b=w + x[9:12],
            w_mean_b=w + x[9:12],
            T_mean=jnp.asarray(2.0),
            dtx=jnp.asarray(0.0),
        )
        return model.fn(ctx, data, params, ins.IDX15, n).z

    x0 = jnp.zeros(n)
    J = np.asarray(jax.jit(jax.jacfwd(z_of))(x0))
    ctx = ms.MeasContext(nav=nav, w_ib_b=w, w_mean_b=w, T_mean=jnp.asarray(2.0), dtx=jnp.asarray(0.0))
    rows = model.fn(ctx, data, params, ins.IDX15, n)
    H = np.asarray(rows.H)
    assert H.shape == (model.size, n) and rows.R.shape == (model.size, model.size)
    scale = np.abs(J[:, :ncol]).max(axis=1, keepdims=True)
    err = np.abs(H[:, :ncol] - J[:, :ncol]) / scale  # relative to each row's largest entry
    # GNSS velocity and NHC/odometer with a lever arm neglect Earth/transport-rate terms (< 1e-4 of the row)
    tol = 1e-4 if name in ("gnss_pv", "nhc_lever", "odometer") else 1e-6
    assert err.max() < tol, (err.max(), np.unravel_index(err.argmax(), err.shape))
    assert np.all(np.abs(J[:, :ncol]).max(axis=1) > 0)  # every row observes something


def test_heading_residual_is_wrapped_and_vertical_axis_masked():
    nav = _nav()
    ctx = ms.MeasContext(
        nav=nav, w_ib_b=jnp.zeros(3), w_mean_b=jnp.zeros(3), T_mean=jnp.asarray(0.0), dtx=jnp.asarray(0.0)
    )
    u = A.quat_to_dcm(nav.q_bn) @ jnp.array([0.0, 1.0, 0.0])
    psi = float(jnp.arctan2(u[0], u[1]))
    for meas in (psi + 2 * np.pi - 0.01, psi - 2 * np.pi - 0.01):
        r = ms.HEADING.fn(ctx, jnp.asarray(meas), ms.HeadingParams(0.01, jnp.array([0.0, 1.0, 0.0])), ins.IDX15, 15)
        np.testing.assert_allclose(float(r.z[0]), 0.01, atol=1e-9)
    r = ms.HEADING.fn(
        ctx, jnp.asarray(1.0), ms.HeadingParams(0.01, A.quat_to_dcm(nav.q_bn).T @ jnp.array([0.0, 0, 1])), ins.IDX15, 15
    )
    assert not bool(r.mask[0])
    # ZARU without standstill samples in the interval is masked
    r = ms.ZARU.fn(ctx, None, ms.ZaruParams(1e-3), ins.IDX15, 15)
    assert not np.any(np.asarray(r.mask))


def test_chi2_quantile_matches_scipy():
    from scipy.stats import chi2

    for p in (0.9, 0.99, 0.999, 0.9999):
        for k in range(1, 9):
            np.testing.assert_allclose(ins.chi2_quantile(p, k), chi2.ppf(p, k), rtol=1e-9)
    with pytest.raises(ValueError, match="gate probability"):
        ins.chi2_quantile(1.0, 3)


# ----------------------------------------------------------------------------- 2. simulated car

CAR = """
name = "car"
[time]
duration_s = 330.0
imu_rate_hz = 50.0
[start]
lat_deg = 48.0
lon_deg = 11.0
height_m = 500.0
heading_deg = 20.0
speed_mps = 15.0
[gyro]
bias_deg_per_h = 30.0
arw_deg_per_sqrt_h = 0.3
[accel]
bias_mg = 3.0
vrw_ug_per_sqrt_hz = 150.0
[gnss]
rate_hz = 1.0
first_epoch_s = 1.0
pos_sigma_m = 1.0
vel_sigma_mps = 0.05
outages_s = [[100.0, 160.0], [220.0, 280.0]]
[initial_errors]
attitude_arcsec = 300.0
velocity_mps = 0.1
position_m = 1.0
[[segments]]
kind = "cruise"
duration_s = 30.0
[[segments]]
kind = "turn"
duration_s = 10.0
dheading_deg = 90.0
hold_s = 20.0
[[segments]]
kind = "accelerate"
duration_s = 5.0
dspeed_mps = 5.0
hold_s = 20.0
[[segments]]
kind = "turn"
duration_s = 15.0
dheading_deg = -120.0
hold_s = 20.0
[[segments]]
kind = "turn"
duration_s = 10.0
dheading_deg = 60.0
hold_s = 30.0
[[segments]]
kind = "accelerate"
duration_s = 5.0
dspeed_mps = -8.0
hold_s = 20.0
[[segments]]
kind = "turn"
duration_s = 10.0
dheading_deg = 90.0
hold_s = 30.0
"""
OUTAGES = ((100.0, 160.0), (220.0, 280.0))


def _v3(x):
    return np.broadcast_to(np.asarray(x, float), (3,))


def _gnss_meas(gn):
    M = gn.t.shape[0]
    R = np.diag([1.0] * 3 + [0.05**2] * 3)
    return PVMeasurements(
        t=np.asarray(gn.t),
        pos=gn.pos,
        vel=gn.vel,
        R=jnp.broadcast_to(R, (M, 6, 6)),
        mask=jnp.broadcast_to(gn.valid[:, None], (M, 6)),
        lever=jnp.zeros((M, 3)),
    )


def _horizontal_error(res, truth):
    """(t (M',), horizontal position error (M',), m) of the filter's epochs against the truth."""
    ep = res.epochs
    t = np.asarray(ep.t)
    k = np.searchsorted(np.asarray(truth.t), t - 1e-9)
    tp = np.asarray(truth.pos)[k]
    lat = tp[:, 0]
    RM = np.asarray(jaxnav.geodesy.meridian_radius(lat))
    RN = np.asarray(jaxnav.geodesy.prime_vertical_radius(lat))
    d = np.asarray(ep.nav.pos) - tp
    return t, np.hypot(d[:, 0] * RM, d[:, 1] * RN * np.cos(lat))


def _outage_max(t, e, outages=OUTAGES):
    return np.array([e[(t >= a) & (t < b)].max() for a, b in outages])


@pytest.fixture(scope="module")
def car():
    cfg = sim.loads_scenario(CAR)
    truth = sim.make_trajectory(cfg)
    r = sim.simulate(cfg, jax.random.PRNGKey(3), trajectory=truth)
    nz = cfg.noise
    P0 = ins.ERROR_MODEL_15.P0(
        truth.pos[0],
        att=_v3(cfg.initial_errors.attitude),
        vel=0.1,
        pos_enu=1.0,
        gyro_bias=_v3(nz.gyro_bias_initial),
        accel_bias=_v3(nz.accel_bias_initial),
    )
    params = LCParams(P0=P0, Qc=ins.ERROR_MODEL_15.Qc(sim.imu_noise(cfg)), tau_markov=300.0)
    meas = _gnss_meas(r.gnss)
    t_imu = np.asarray(truth.t[1:])
    base = loosely_coupled(
        r.nav0,
        t_imu,
        r.imu.dtheta,
        r.imu.dv,
        meas,
        params,
        dt_imu=cfg.dt,
        error_model=ins.ERROR_MODEL_15,
        save=ins.LCSave(("nav",)),
    )
    return cfg, truth, r, params, meas, t_imu, base


def test_nhc_cuts_the_car_outage_drift_several_fold(car):
    """Two 60 s GNSS outages on a car with a MEMS-grade IMU (30 deg/h, 3 mg): GNSS-only drifts 26 m and 8 m
    (max horizontal); with the non-holonomic constraint at 2 Hz, 4.0 m and 0.7 m (measured)."""
    cfg, truth, r, params, meas, t_imu, base = car
    res = loosely_coupled(
        r.nav0,
        t_imu,
        r.imu.dtheta,
        r.imu.dv,
        meas,
        params,
        dt_imu=cfg.dt,
        error_model=ins.ERROR_MODEL_15,
        aids=(ins.nhc(sigma=0.1, rate_hz=2.0),),
        save=ins.LCSave(("nav", "valid")),
    )
    assert int(res.status) & ~_status.INFO_FLAGS == 0
    t0, e0 = _horizontal_error(base, truth)
    t1, e1 = _horizontal_error(res, truth)
    m0, m1 = _outage_max(t0, e0), _outage_max(t1, e1)
    assert np.all(m0 > 3.0 * m1), (m0, m1)
    assert m0.max() > 10.0  # the outage is long enough to matter
    # epochs: every GNSS epoch plus the 2 Hz constraint samples between them; the rows map back to meas
    row = np.asarray(res.epochs.gnss_row)
    assert np.array_equal(row[row >= 0], np.arange(meas.t.shape[0]))
    assert (row < 0).sum() == pytest.approx(cfg.duration, abs=2)  # one extra epoch per second (2 Hz - 1 Hz)
    valid = np.asarray(res.epochs.valid)
    assert np.all(valid[row < 0] == 2) and np.all(
        valid[(row >= 0) & np.asarray(meas.mask[:, 0])[np.maximum(row, 0)]] == 8
    )


def _inject_outliers(meas, idx, east_m):
    """Add ``east_m`` metres east to the fixes at ``idx`` (the true sigma is 1 m)."""
    pos = np.array(meas.pos)
    lat = pos[idx, 0]
    RN = np.asarray(jaxnav.geodesy.prime_vertical_radius(lat)) + pos[idx, 2]
    pos[idx, 1] += east_m / (RN * np.cos(lat))
    return meas._replace(pos=pos)


def test_chi2_gate_rejects_injected_gnss_outliers_and_counts_them(car):
    """Measured: 8 of 8 outliers gated, no false alarm (p = 0.999 and 0.9999); RMS at the good epochs 0.46 m
    gated, 0.79 m ungated, 0.45 m without outliers."""
    cfg, truth, r, params, meas, t_imu, base = car
    t = np.asarray(meas.t)
    idx = np.array([20, 45, 70, 95, 170, 190, 290, 310])  # outside the outages
    bad = _inject_outliers(meas, idx, 15.0)
    run = lambda m, **kw: loosely_coupled(
        r.nav0,
        t_imu,
        r.imu.dtheta,
        r.imu.dv,
        m,
        params,
        dt_imu=cfg.dt,
        error_model=ins.ERROR_MODEL_15,
        save=ins.LCSave(("nav",)),
        **kw,
    )
    ungated = run(bad)
    gated = loosely_coupled(
        r.nav0,
        t_imu,
        r.imu.dtheta,
        r.imu.dv,
        bad,
        params,
        dt_imu=cfg.dt,
        error_model=ins.ERROR_MODEL_15,
        gate=ins.LCGate(0.9999),
        save=ins.LCSave(("nav", "gated", "gnss_nis")),
    )
    g = np.asarray(gated.epochs.gated)
    assert np.all(g[idx])  # every outlier rejected
    assert int(gated.n_gated) == int(g.sum()) and g.sum() <= len(idx) + 2  # few false alarms at p = 1e-4
    assert int(gated.status) & _status.GNSS_GATED and int(ungated.status) & _status.GNSS_GATED == 0
    _status.raise_for_status(gated.status)  # information, not an error
    nis = np.asarray(gated.epochs.gnss_nis)
    assert np.all(nis[idx] > ins.chi2_quantile(0.9999, 6)) and np.all(nis[~np.asarray(meas.mask[:, 0])] == 0)
    _, e_clean = _horizontal_error(base, truth)
    _, e_bad = _horizontal_error(ungated, truth)
    _, e_gate = _horizontal_error(gated, truth)
    ok = ~np.isin(np.arange(t.size), idx) & np.asarray(meas.mask[:, 0])  # epochs with good fixes
    rms = lambda e: float(np.sqrt(np.mean(e[ok] ** 2)))
    assert rms(e_gate) < 1.1 * rms(e_clean) and rms(e_bad) > 1.3 * rms(e_gate), (rms(e_clean), rms(e_bad), rms(e_gate))
    with pytest.raises(ValueError, match="gate probability"):
        run(bad, gate=ins.LCGate(1.5))


def test_21_state_model_recovers_an_injected_gyro_scale_factor(car):
    """A 1 % z-gyro scale-factor error (0.3 % on x and y: barely excited) on the car's turns (360 deg in all):
    the 21-state filter estimates s_gz inside 3 sigma, its sigma shrunk from the 2 % prior to a fraction of
    the error, and a higher innovation likelihood than the 15-state filter that ignores it. Heading (and with it
    the scale factor) is observed only while the car turns or accelerates (f_n x phi in the velocity error)."""
    cfg, truth, r, params, meas, t_imu, base = car
    s_true = np.array([3e-3, -3e-3, 1e-2])
    dth = r.imu.dtheta * (1.0 + s_true)  # measured = (1 + s) true + bias ... (bias scaled: 0.5 % of 30 deg/h)
    nz = cfg.noise
    bias_sd = jnp.concatenate([jnp.asarray(_v3(nz.gyro_bias_initial)), jnp.asarray(_v3(nz.accel_bias_initial))])
    P0 = ins.ERROR_MODEL_21.P0(
        truth.pos[0],
        att=_v3(cfg.initial_errors.attitude),
        vel=0.1,
        pos_enu=1.0,
        gyro_bias=bias_sd[:3],
        accel_bias=bias_sd[3:],
        gyro_scale=2e-2,
        accel_scale=1e-3,
    )
    Qc = ins.ERROR_MODEL_21.Qc(
        ins.ImuNoise(gyro_arw=_v3(nz.gyro_arw), accel_vrw=_v3(nz.accel_vrw))
    )  # random-constant biases, scale factors
    p21 = LCParams(P0=P0, Qc=Qc, tau_markov=jnp.full(6, jnp.inf))
    res = loosely_coupled(
        r.nav0,
        t_imu,
        dth,
        r.imu.dv,
        meas,
        p21,
        dt_imu=cfg.dt,
        error_model=ins.ERROR_MODEL_21,
        save=ins.LCSave(("nav", "biases", "covs", "pred_covs", "Phi", "corrections")),
    )
    assert int(res.status) & ~_status.INFO_FLAGS == 0
    est = np.asarray(res.final_biases.gyro_scale)
    sd = np.sqrt(np.asarray(res.epochs.covs[-1]).diagonal()[18 - 3 : 18])
    assert abs(est[2] - s_true[2]) < 3 * sd[2] and sd[2] < 0.25 * s_true[2], (est, sd)
    assert abs(est[2] - s_true[2]) < 0.35 * s_true[2], (est, sd)
    r15 = loosely_coupled(
        r.nav0,
        t_imu,
        dth,
        r.imu.dv,
        meas,
        params,
        dt_imu=cfg.dt,
        error_model=ins.ERROR_MODEL_15,
        save=ins.LCSave(("nav",)),
    )
    # the innovations are better explained with the scale factor modelled than absorbed by the 15-state biases
    assert float(res.loglik) > float(r15.loglik) + 10.0, (float(res.loglik), float(r15.loglik))
    # the two-speed mechanization inside the filter carries the scale-factor sums too (measured: 0.45 mm)
    r10 = loosely_coupled(
        r.nav0,
        t_imu,
        dth,
        r.imu.dv,
        meas,
        p21,
        dt_imu=cfg.dt,
        error_model=ins.ERROR_MODEL_21,
        propagation=ins.LCPropagation(nav_every=10),
        save=ins.LCSave(("nav",)),
    )
    np.testing.assert_allclose(np.asarray(r10.final_biases.gyro_scale), est, atol=1e-6)
    assert np.abs(np.asarray(r10.epochs.nav.pos) - np.asarray(res.epochs.nav.pos))[:, :2].max() * 6.4e6 < 5e-3
    # smoothing works on the 21 states (scale factors fed back too)
    nav_s, b_s, P_s = ins.smooth(res, error_model=ins.ERROR_MODEL_21)
    assert P_s.shape[1:] == (21, 21) and np.all(np.isfinite(np.asarray(b_s.gyro_scale)))


# ----------------------------------------------------------------------------- 3. stop-and-go walk

WALK = """
name = "stop-and-go walk"
[time]
duration_s = 150.0
imu_rate_hz = 50.0
[start]
lat_deg = 52.0
lon_deg = 13.0
height_m = 40.0
heading_deg = 0.0
speed_mps = 1.4
[gyro]
bias_deg_per_h = 200.0
arw_deg_per_sqrt_h = 0.5
[accel]
bias_mg = 10.0
vrw_ug_per_sqrt_hz = 300.0
[gnss]
rate_hz = 1.0
first_epoch_s = 1.0
pos_sigma_m = 2.0
vel_sigma_mps = 0.1
outages_s = [[50.0, 140.0]]
[initial_errors]
attitude_arcsec = 1800.0
velocity_mps = 0.1
position_m = 2.0
"""
WALK_CYCLE = """
[[segments]]
kind = "cruise"
duration_s = 6.0
[[segments]]
kind = "accelerate"
duration_s = 1.0
dspeed_mps = -1.4
[[segments]]
kind = "rest"
duration_s = 4.0
[[segments]]
kind = "accelerate"
duration_s = 1.0
dspeed_mps = 1.4
[[segments]]
kind = "turn"
duration_s = 2.0
dheading_deg = %s
"""


def test_zupt_and_zaru_cut_the_drift_of_a_stop_and_go_walk():
    """A consumer-grade IMU (200 deg/h, 10 mg) carried on a walk that stops for 4 s every 14 s, with a 90 s
    GNSS outage. Measured: GNSS-only drifts 83 m (max horizontal) in the outage; with ZUPT and ZARU at the
    standstill samples (5 Hz) 0.9 m (ZUPT alone: 2.9 m)."""
    cfg = sim.loads_scenario(WALK + "".join(WALK_CYCLE % h for h in (60, -90, 45, 120, -30, 80, -100, 50, 90, -60)))
    truth = sim.make_trajectory(cfg)
    r = sim.simulate(cfg, jax.random.PRNGKey(5), trajectory=truth)
    v = np.linalg.norm(np.asarray(truth.v_n), axis=1)
    still = (v[1:] < 1e-9) & (v[:-1] < 1e-9)  # per IMU sample: at rest over the whole interval
    nz = cfg.noise
    P0 = ins.ERROR_MODEL_15.P0(
        truth.pos[0],
        att=_v3(cfg.initial_errors.attitude),
        vel=0.1,
        pos_enu=2.0,
        gyro_bias=_v3(nz.gyro_bias_initial),
        accel_bias=_v3(nz.accel_bias_initial),
    )
    params = LCParams(P0=P0, Qc=ins.ERROR_MODEL_15.Qc(sim.imu_noise(cfg)), tau_markov=300.0)
    gn = r.gnss
    M = gn.t.shape[0]
    meas = PVMeasurements(
        t=np.asarray(gn.t),
        pos=gn.pos,
        vel=gn.vel,
        R=jnp.broadcast_to(np.diag([4.0] * 3 + [0.01] * 3), (M, 6, 6)),
        mask=jnp.broadcast_to(gn.valid[:, None], (M, 6)),
        lever=jnp.zeros((M, 3)),
    )
    t_imu = np.asarray(truth.t[1:])
    run = lambda aids: loosely_coupled(
        r.nav0,
        t_imu,
        r.imu.dtheta,
        r.imu.dv,
        meas,
        params,
        dt_imu=cfg.dt,
        error_model=ins.ERROR_MODEL_15,
        aids=aids,
        save=ins.LCSave(("nav",)),
    )
    base = run(())
    aided = run((ins.zupt(still, sigma=0.02, rate_hz=5.0), ins.zaru(still, density=1e-3, rate_hz=5.0)))
    assert int(aided.status) & ~_status.INFO_FLAGS == 0
    out = ((50.0, 140.0),)
    m0 = _outage_max(*_horizontal_error(base, truth), out)[0]
    m1 = _outage_max(*_horizontal_error(aided, truth), out)[0]
    assert m0 > 20.0 and m0 > 10.0 * m1, (m0, m1)
    # the z gyro bias (unobservable by GNSS without turns) is held by ZARU through the outage
    err_z = abs(float(aided.final_biases.gyro[2] - r.errors.gyro_bias[2]))
    assert err_z < 0.1 * cfg.noise.gyro_bias_initial[2], err_z
    with pytest.raises(ValueError, match="active must be a"):
        run((ins.zupt(still[:-1]),))


def test_odometer_and_heading_close_the_loop_on_the_car(car):
    """Odometer speed (10 Hz, 0.05 m/s noise) and heading (1 Hz, 0.5 deg noise) from the truth with NHC: vehicle
    dead reckoning through the outages. Checks the signs of z = predicted - measured in a closed loop (a
    flipped sign diverges): the outage drift drops well below GNSS-only (and below NHC alone), the heading
    error stays at the noise level. Measured: 0.39 m / 0.19 m. (Odometer and heading without NHC leave the lateral velocity to the
    accelerometers: measured 3.0 m / 7.0 m against 26.4 m / 8.0 m GNSS-only.)"""
    cfg, truth, r, params, meas, t_imu, base = car
    rng = np.random.default_rng(1)
    N = t_imu.size
    k = np.arange(N)
    v = np.asarray(truth.v_n)[1:]
    speed = np.where((k + 1) % 5 == 0, np.linalg.norm(v, axis=1) + 0.05 * rng.standard_normal(N), np.nan)
    u = np.asarray(A.quat_to_dcm(truth.q_bn[1:]))[:, :, 1]  # body forward axis in ENU
    hdg = np.arctan2(u[:, 0], u[:, 1]) + np.radians(0.5) * rng.standard_normal(N)
    hdg = np.where((k + 1) % 50 == 0, hdg, np.nan)
    aids = (ins.odometer(speed, sigma=0.05), ins.heading(hdg, sigma=np.radians(0.5)), ins.nhc(sigma=0.1))
    res = loosely_coupled(
        r.nav0,
        t_imu,
        r.imu.dtheta,
        r.imu.dv,
        meas,
        params,
        dt_imu=cfg.dt,
        error_model=ins.ERROR_MODEL_15,
        aids=aids,
        save=ins.LCSave(("nav", "valid")),
    )
    assert int(res.status) & ~_status.INFO_FLAGS == 0
    m0 = _outage_max(*_horizontal_error(base, truth))
    m1 = _outage_max(*_horizontal_error(res, truth))
    assert np.all(m1 < 0.1 * m0) and m1.max() < 2.0, (m0, m1)
    t = np.asarray(res.epochs.t)
    kk = np.searchsorted(np.asarray(truth.t), t - 1e-9)
    dq = A.quat_mul(res.epochs.nav.q_bn, A.quat_conj(truth.q_bn[kk]))
    yaw = np.abs(np.asarray(A.quat_to_rv(dq))[:, 2])
    assert np.degrees(yaw[t > 30].max()) < 1.0
    with pytest.raises(ValueError, match="speed must be 1-D"):
        ins.odometer(speed[:, None])


@pytest.mark.slow
def test_aid_parameters_are_array_leaves_under_grad(car):
    """d loglik / d log(NHC sigma) by forward mode through the whole run (first 20 s of the car) equals central
    finite differences; the aid's parameters are ordinary pytree leaves. (Reverse mode with ``remat=True``
    on 40 s agreed to 1e-5 as well, measured once: 159 s of compilation on the loaded test machine, not kept.)"""
    cfg, truth, r, params, meas, t_imu, base = car
    n = 1000
    m = jax.tree_util.tree_map(lambda a: a[:20], meas)
    t_i, dth, dvv = t_imu[:n], r.imu.dtheta[:n], r.imu.dv[:n]

    def loglik(log_sigma):
        aid = ins.nhc(sigma=0.1, rate_hz=2.0)
        aid = aid._replace(params=aid.params._replace(sigma=jnp.exp(log_sigma)))
        return loosely_coupled(
            r.nav0,
            t_i,
            dth,
            dvv,
            m,
            params,
            dt_imu=cfg.dt,
            error_model=ins.ERROR_MODEL_15,
            aids=(aid,),
            save=ins.LCSave(("valid",)),
        ).loglik

    x = jnp.log(jnp.array([0.1, 0.2]))
    g = np.asarray(jax.jit(jax.jacfwd(loglik))(x))
    f = jax.jit(loglik)
    h = 1e-4
    fd = np.array([(float(f(x.at[i].add(h))) - float(f(x.at[i].add(-h)))) / (2 * h) for i in range(2)])
    np.testing.assert_allclose(g, fd, rtol=1e-5, atol=1e-6 * np.abs(fd).max())
    assert np.all(np.abs(g) > 0)


def test_inactive_aids_leave_the_gnss_filter_unchanged_and_bad_aid_input_is_named(car):
    """Reduction identity: an aid that is never active adds rows that are always masked (exactly removed by
    the update) and no epochs: the result equals the GNSS-only filter to rounding."""
    cfg, truth, r, params, meas, t_imu, base = car
    N = t_imu.size
    res = loosely_coupled(
        r.nav0,
        t_imu,
        r.imu.dtheta,
        r.imu.dv,
        meas,
        params,
        dt_imu=cfg.dt,
        error_model=ins.ERROR_MODEL_15,
        aids=(ins.zupt(np.zeros(N, bool)),),
        save=ins.LCSave(("nav",)),
    )
    assert res.epochs.t.shape == base.epochs.t.shape
    d = np.abs(np.asarray(res.epochs.nav.pos) - np.asarray(base.epochs.nav.pos))[:, :2].max() * 6.4e6
    assert d < 1e-6, d  # metres
    np.testing.assert_allclose(float(res.loglik), float(base.loglik), rtol=1e-10)
    run = lambda **kw: loosely_coupled(
        r.nav0,
        t_imu,
        r.imu.dtheta,
        r.imu.dv,
        meas,
        params,
        dt_imu=cfg.dt,
        error_model=ins.ERROR_MODEL_15,
        **kw,
    )
    with pytest.raises(ValueError, match="data leaves must have"):
        run(aids=(ins.odometer(np.ones(N + 1), active=np.ones(N, bool)),))
    with pytest.raises(ValueError, match="'gnss_nis' needs a gate"):
        run(save=ins.LCSave(("nav", "gnss_nis")))
    with pytest.raises(ValueError, match="at most one aid"):
        run(aids=(ins.zaru(np.ones(N, bool)), ins.zaru(np.ones(N, bool))))
    with pytest.raises(ValueError, match="tau_markov has shape"):
        loosely_coupled(
            r.nav0,
            t_imu,
            r.imu.dtheta,
            r.imu.dv,
            meas,
            LCParams(P0=jnp.eye(21), Qc=jnp.eye(18), tau_markov=jnp.ones(3)),
            error_model=ins.ERROR_MODEL_21,
        )
    with pytest.raises(ValueError, match="aids must be Aid"):
        run(aids=(ins.NavState,))


def test_odometer_scale_column_is_the_jacobian_of_the_reading():
    """Reading s = (1 + k) v_fwd with k = k_hat + s_odo: dz/ds_odo at fixed computed state is -v_fwd, and the
    navigation columns carry the factor (1 + k_hat)."""
    nav, w = _nav(), jnp.array([0.02, -0.05, 0.3])
    idx, n = ins.ERROR_MODEL_15.with_odometer_scale().idx, 16
    p = ms.VehicleParams(0.1, jnp.eye(3), jnp.array([0.3, -1.2, -0.4]))
    b = ins.SensorBiases(jnp.zeros(3), jnp.zeros(3), jnp.zeros(3), odo_scale=jnp.array([0.03]))
    ctx = ms.MeasContext(nav=nav, w_ib_b=w, w_mean_b=w, T_mean=jnp.asarray(0.0), dtx=jnp.asarray(0.0), biases=b)
    v_fwd = float(ms._vehicle_velocity(ctx, p, jaxnav.geodesy.WGS84)[0][1])

    def z_of(x):
        c = ctx._replace(nav=_perturb(nav, x))
        reading = (1.03 + x[15]) * v_fwd  # the true scale moves with the state, the true speed does not
        return ms.ODOMETER.fn(c, reading, p, idx, n).z

    J = np.asarray(jax.jit(jax.jacfwd(z_of))(jnp.zeros(n)))
    H = np.asarray(ms.ODOMETER.fn(ctx, 1.03 * v_fwd, p, idx, n).H)
    np.testing.assert_allclose(H[0, 15], -v_fwd, rtol=1e-12)
    np.testing.assert_allclose(H[:, [15]], J[:, [15]], rtol=1e-12)
    np.testing.assert_allclose(H[:, :9], J[:, :9], atol=1e-4 * np.abs(J[:, :9]).max())


def test_odometer_scale_factor_state_recovered_and_outage_drift_cut(car):
    """A wheel reading 2 % fast (true scale 1.02, 0.05 m/s noise, 10 Hz) on the car with two 60 s outages. With
    the scale-factor state (:meth:`ErrorModel.with_odometer_scale`) the filter recovers 1.02 to well within
    0.5 % and inside 3 of its sigmas, and the outage drift falls far below GNSS-only; without the state the
    unmodelled 2 % costs more than it gives. Measured: scale 1.0201 +- 0.0001; outage max 26.4 / 8.0 m
    GNSS-only, 0.97 / 0.28 m with the state, 31.0 / 19.2 m with the wheel read as exact."""
    cfg, truth, r, params, meas, t_imu, base = car
    rng = np.random.default_rng(2)
    N = t_imu.size
    v = np.asarray(truth.v_n)[1:]
    ok = (np.arange(N) + 1) % 5 == 0
    speed = np.where(ok, 1.02 * np.linalg.norm(v, axis=1) + 0.05 * rng.standard_normal(N), np.nan)
    model = ins.ERROR_MODEL_15.with_odometer_scale()
    assert model.n == 16 and model.names[-1] == "s_odo" and model.p == ins.ERROR_MODEL_15.p
    P0 = model.P0(
        truth.pos[0],
        att=_v3(cfg.initial_errors.attitude),
        vel=0.1,
        pos_enu=1.0,
        gyro_bias=_v3(cfg.noise.gyro_bias_initial),
        accel_bias=_v3(cfg.noise.accel_bias_initial),
        odo_scale=0.05,
    )
    aids = (ins.odometer(speed, sigma=0.05), ins.nhc(sigma=0.1))
    res = loosely_coupled(
        r.nav0,
        t_imu,
        r.imu.dtheta,
        r.imu.dv,
        meas,
        params._replace(P0=P0),
        dt_imu=cfg.dt,
        error_model=model,
        aids=aids,
        save=ins.LCSave(("nav", "biases", "covs")),
    )
    assert int(res.status) & ~_status.INFO_FLAGS == 0
    k = float(res.final_biases.odo_scale[0])
    sig = float(np.sqrt(res.epochs.covs[-1, 15, 15]))
    assert abs(k - 0.02) < 0.005 and abs(k - 0.02) < 3 * sig, (k, sig)
    fixed = loosely_coupled(
        r.nav0,
        t_imu,
        r.imu.dtheta,
        r.imu.dv,
        meas,
        params,
        dt_imu=cfg.dt,
        error_model=ins.ERROR_MODEL_15,
        aids=aids,
        save=ins.LCSave(("nav",)),
    )
    m0 = _outage_max(*_horizontal_error(base, truth))
    m1 = _outage_max(*_horizontal_error(res, truth))
    m2 = _outage_max(*_horizontal_error(fixed, truth))
    assert np.all(m1 < 0.1 * m0) and np.all(m1 < m2), (m0, m1, m2, k, sig)


def test_heading_per_reading_sigma():
    """ins.heading with a sigma per reading: R of an epoch is its own sigma^2, a NaN sigma takes default_sigma."""
    nav = _nav()
    ctx = ms.MeasContext(
        nav=nav, w_ib_b=jnp.zeros(3), w_mean_b=jnp.zeros(3), T_mean=jnp.asarray(0.0), dtx=jnp.asarray(0.0)
    )
    a = ins.heading(np.array([1.0, np.nan, 1.2]), sigma=np.array([0.02, 0.5, np.nan]), default_sigma=0.1)
    assert a.active.tolist() == [True, False, True]
    R = [float(ms.HEADING.fn(ctx, (a.data[0][i], a.data[1][i]), a.params, ins.IDX15, 15).R[0, 0]) for i in (0, 2)]
    np.testing.assert_allclose(R, [0.02**2, 0.1**2])
    with pytest.raises(ValueError, match="shape of heading"):
        ins.heading(np.zeros(3), sigma=np.zeros(2))
