"""Loosely coupled INS/GNSS with feedback: consistency (NEES/NIS), sensor-error convergence,
outage and RTS, the filter family's rules plugged in, bad input."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.stats import chi2

import jaxnav
from jaxnav import filters as jf
from jaxnav import ins, sim
from jaxnav.ins import attitude as A
from jaxnav.ins.integration import LCParams, PVMeasurements, loosely_coupled, smooth

SCENARIO = """
name = "well-specified"
[time]
duration_s = 300.0
imu_rate_hz = 50.0
[start]
lat_deg = 39.0
lon_deg = 108.0
height_m = 205.8795
heading_deg = 30.0
speed_mps = 20.0
[gyro]
bias_deg_per_h = 5.0
markov_deg_per_h = 1.0
markov_tau_s = 100.0
arw_deg_per_sqrt_h = 0.05
[accel]
bias_mg = 1.0
vrw_ug_per_sqrt_hz = 50.0
[gnss]
rate_hz = 1.0
first_epoch_s = 1.0
pos_sigma_m = 1.0
vel_sigma_mps = 0.05
outages_s = %s
[initial_errors]
attitude_arcsec = 60.0
velocity_mps = 0.2
position_m = 3.0
[[segments]]
kind = "cruise"
duration_s = 20.0
[[segments]]
kind = "turn"
duration_s = 20.0
dheading_deg = 90.0
hold_s = 30.0
[[segments]]
kind = "accelerate"
duration_s = 10.0
dspeed_mps = 10.0
hold_s = 30.0
[[segments]]
kind = "turn"
duration_s = 20.0
dheading_deg = -120.0
hold_s = 30.0
[[segments]]
kind = "climb"
duration_s = 5.0
dpitch_deg = 5.0
hold_s = 20.0
[[segments]]
kind = "pitch"
duration_s = 5.0
dpitch_deg = -5.0
hold_s = 20.0
[[segments]]
kind = "turn"
duration_s = 20.0
dheading_deg = 60.0
hold_s = 50.0
"""

SEEDS = 64


def _params(cfg, n_states=18):
    """The filter's model matches the simulation (P0 from the initial-error and sensor sigmas)."""
    v3 = lambda x: np.broadcast_to(np.asarray(x, float), (3,))
    ie, nz = cfg.initial_errors, cfg.noise
    lat, h = np.radians(39.0), 205.8795
    RM = float(jaxnav.geodesy.meridian_radius(lat)) + h
    RN = float(jaxnav.geodesy.prime_vertical_radius(lat)) + h
    pe = v3(ie.position)
    p0 = [
        v3(ie.attitude) ** 2,
        v3(ie.velocity) ** 2,
        np.array([pe[1] / RM, pe[0] / (RN * np.cos(lat)), pe[2]]) ** 2,
        v3(nz.gyro_bias_initial) ** 2,
    ]
    if n_states == 18:
        p0.append(v3(nz.gyro_bias_instability) ** 2)
    p0.append(v3(nz.accel_bias_initial) ** 2)
    Qc = ins.error_model_for(n_states).Qc(sim.imu_noise(cfg))
    return LCParams(P0=jnp.diag(jnp.asarray(np.concatenate(p0))), Qc=Qc, tau_markov=jnp.asarray(v3(nz.gyro_bias_tau)))


def _meas(cfg, gnss):
    M = gnss.t.shape[0]
    v3 = lambda x: np.broadcast_to(np.asarray(x, float), (3,))
    R = np.diag(np.concatenate([v3(cfg.gnss.pos_sigma) ** 2, v3(cfg.gnss.vel_sigma) ** 2]))
    return PVMeasurements(
        t=np.asarray(gnss.t),
        pos=gnss.pos,
        vel=gnss.vel,
        R=jnp.broadcast_to(R, (M, 6, 6)),
        mask=jnp.broadcast_to(gnss.valid[:, None], (M, 6)),
        lever=jnp.zeros((M, 3)),
    )


def _true_error(ep, truth, errors, gnss_index, n_states=18):
    """Error state computed - true (nav) and true - applied (sensors) at the epochs, (M, n)."""
    q_t, v_t, p_t = truth.q_bn[gnss_index], truth.v_n[gnss_index], truth.pos[gnss_index]
    phi = -A.quat_to_rv(A.quat_mul(ep.nav.q_bn, A.quat_conj(q_t)))
    parts = [phi, ep.nav.v_n - v_t, ep.nav.pos - p_t, errors.gyro_bias[None] - ep.biases.gyro]
    if n_states == 18:
        parts.append(errors.gyro_markov[gnss_index - 1] - ep.biases.markov)
    parts.append(errors.accel_bias[None] - ep.biases.accel)
    return jnp.concatenate(parts, axis=-1)


@pytest.fixture(scope="module")
def runs():
    cfg = sim.loads_scenario(SCENARIO % "[]")
    truth = sim.make_trajectory(cfg)
    params = _params(cfg)
    t_imu = np.asarray(truth.t[1:])
    r0 = sim.simulate(cfg, jax.random.PRNGKey(0), trajectory=truth)
    t_gnss, gidx = np.asarray(r0.gnss.t), np.asarray(r0.gnss.index)

    def one(key):
        r = sim.simulate(cfg, key, trajectory=truth)
        res = loosely_coupled(
            r.nav0, t_imu, r.imu.dtheta, r.imu.dv, _meas(cfg, r.gnss._replace(t=t_gnss)), params, dt_imu=cfg.dt
        )
        e = _true_error(res.epochs, truth, r.errors, gidx)
        P = res.epochs.covs
        nees = jnp.einsum("ti,ti->t", e, jnp.linalg.solve(P, e[..., None])[..., 0])
        return nees, res.epochs.nis, e, jnp.sqrt(jnp.diagonal(P, axis1=1, axis2=2)), res.status

    out = jax.jit(jax.vmap(one))(jax.random.split(jax.random.PRNGKey(42), SEEDS))
    return cfg, truth, params, t_imu, gidx, out


def test_average_nees_and_nis_inside_95pct_chi2_bounds(runs):
    cfg, truth, params, t_imu, gidx, (nees, nis, e, sig, status) = runs
    assert not np.any(np.asarray(status) & ~1)
    nees, nis = np.asarray(nees), np.asarray(nis)
    n, m, S = 18, 6, nees.shape[0]
    lo, hi = chi2.ppf([0.025, 0.975], S * n) / S
    per_epoch = nees.mean(axis=0)
    frac = np.mean((per_epoch > lo) & (per_epoch < hi))
    assert frac > 0.9, (frac, per_epoch.mean())
    # the time average of correlated epochs is held to the per-epoch band (measured 17.6)
    assert lo < nees.mean() < hi, nees.mean()
    lo, hi = chi2.ppf([0.025, 0.975], S * m) / S
    per_epoch = nis.mean(axis=0)
    assert np.mean((per_epoch > lo) & (per_epoch < hi)) > 0.9
    assert lo < nis.mean() < hi


def test_sensor_errors_converge_inside_3_sigma(runs):
    cfg, truth, params, t_imu, gidx, (nees, nis, e, sig, status) = runs
    e, sig = np.asarray(e), np.asarray(sig)
    last = slice(-50, None)
    for name, sl in (("gyro bias", slice(9, 12)), ("accel bias", slice(15, 18))):
        z = np.abs(e[:, last, sl]) / sig[:, last, sl]
        assert np.mean(z < 3.0) > 0.97, name
    # the bias uncertainty shrank well below its prior: the sensor errors are estimated
    assert np.all(sig[:, -1, 9:12].mean(0) < 0.5 * np.sqrt(np.diag(params.P0))[9:12])
    assert np.all(sig[:, -1, 15:18].mean(0) < 0.5 * np.sqrt(np.diag(params.P0))[15:18])


@pytest.fixture(scope="module")
def outage_run():
    cfg = sim.loads_scenario(SCENARIO % "[[150.0, 210.0]]")
    truth = sim.make_trajectory(cfg)
    r = sim.simulate(cfg, jax.random.PRNGKey(7), trajectory=truth)
    params = _params(cfg)
    t_imu = np.asarray(truth.t[1:])
    res = loosely_coupled(r.nav0, t_imu, r.imu.dtheta, r.imu.dv, _meas(cfg, r.gnss), params, dt_imu=cfg.dt)
    return cfg, truth, r, params, t_imu, res


def _pos_err_m(nav_pos, true_pos):
    lat = true_pos[:, 0]
    RM, RN = jaxnav.geodesy.meridian_radius(lat), jaxnav.geodesy.prime_vertical_radius(lat)
    d = nav_pos - true_pos
    return np.asarray(jnp.hypot(d[:, 0] * RM, d[:, 1] * RN * jnp.cos(lat)))


def test_gnss_outage_error_grows_filter_reconverges_and_rts_reduces_it(outage_run):
    cfg, truth, r, params, t_imu, res = outage_run
    ep = res.epochs
    gidx = np.asarray(r.gnss.index)
    t = np.asarray(ep.t)
    assert int(res.n_skipped) == 60 and int(res.status) & ~1 == 0
    assert np.all(np.isfinite(np.asarray(ep.nav.pos))) and np.all(np.isfinite(np.asarray(ep.covs)))
    err = _pos_err_m(ep.nav.pos, truth.pos[gidx])
    inside = (t >= 150) & (t < 210)
    before = (t >= 100) & (t < 150)
    after = t >= 240
    assert err[inside].max() > 3 * err[before].mean()  # drift during the outage
    assert err[after].mean() < 2 * err[before].mean()  # reconverged
    sig_h = np.sqrt(np.asarray(ep.covs[:, 6, 6]) * 6.37e6**2)
    assert sig_h[inside].max() > 3 * sig_h[before].mean()  # the filter knows it drifted
    nav_s, biases_s, covs_s = smooth(res)
    err_s = _pos_err_m(nav_s.pos, truth.pos[gidx])
    # RTS uses the fixes after the outage: the outage error drops substantially
    assert np.sqrt(np.mean(err_s[inside] ** 2)) < 0.5 * np.sqrt(np.mean(err[inside] ** 2))
    assert np.all(np.asarray(covs_s[:, 6, 6]) <= np.asarray(ep.covs[:, 6, 6]) * (1 + 1e-9))


@pytest.mark.parametrize("kind", ["attenuated", "fading", "sage_husa", "15-state"])
def test_filter_family_plugins_and_15_states(outage_run, kind):
    cfg, truth, r, params, t_imu, base = outage_run
    kw, n = {}, 18
    if kind == "attenuated":
        kw = dict(inflation=jf.attenuated(0.254))
    elif kind == "fading":
        kw = dict(inflation=jf.fading(window=5))
    elif kind == "sage_husa":
        kw = dict(estimator=jf.sage_husa(0.98, estimate="R"))
    else:
        n = 15
        params = _params(cfg, 15)
    res = loosely_coupled(
        r.nav0,
        t_imu,
        r.imu.dtheta,
        r.imu.dv,
        _meas(cfg, r.gnss),
        params,
        dt_imu=cfg.dt,
        error_model=ins.error_model_for(n),
        save=ins.LCSave(("nav", "covs", "factors", "nis")),
        **kw,
    )
    assert int(res.status) & ~1 == 0 and res.epochs.covs.shape[1:] == (n, n)
    f = np.asarray(res.epochs.factors)
    if kind == "attenuated":
        np.testing.assert_allclose(f[:3], [1.0, 1.254, 1 + 0.254 + 0.254**2])
        t = np.asarray(res.epochs.t)  # S_k counts updates: factor 1 in the outage (P grew by 1.34 per epoch there)
        np.testing.assert_array_equal(f[(t >= 150) & (t < 210)], 1.0)
    elif kind == "fading":
        assert f.min() >= 1.0 and f.max() > 1.0
    else:
        np.testing.assert_array_equal(f, 1.0)
    gidx = np.asarray(r.gnss.index)
    err = _pos_err_m(res.epochs.nav.pos, truth.pos[gidx])
    assert np.sqrt(np.mean(err[-60:] ** 2)) < 3.0  # metres with 1 m GNSS noise


def test_bad_measurements_are_skipped_and_counted_and_time_ranges_checked(outage_run):
    cfg, truth, r, params, t_imu, base = outage_run
    meas = _meas(cfg, r.gnss)
    pos = np.array(meas.pos)
    R = np.array(meas.R)
    pos[20, 0] = np.nan  # a NaN latitude: the north component is masked and counted
    R[30, 3, 3] = 1e12  # a huge velocity sigma: that component is masked
    res = loosely_coupled(
        r.nav0,
        t_imu,
        r.imu.dtheta,
        r.imu.dv,
        meas._replace(pos=pos, R=R),
        params,
        dt_imu=cfg.dt,
        save=ins.LCSave(("nav", "valid")),
    )
    assert int(res.n_nonfinite) == int(base.n_nonfinite) + 1  # the north component; E and U stay valid
    v = np.asarray(res.epochs.valid)
    assert v[20] == 5 and v[30] == 5  # NaN lat masks 1 of 6 (lat), huge sigma masks 1 of 6
    assert np.all(np.isfinite(np.asarray(res.epochs.nav.pos)))
    with pytest.raises(ValueError, match="not inside the IMU span"):
        loosely_coupled(r.nav0, t_imu, r.imu.dtheta, r.imu.dv, meas._replace(t=np.asarray(meas.t) + 1e4), params)
    with pytest.raises(ValueError, match="not strictly increasing"):
        tt = np.array(meas.t)
        tt[5] = tt[4]
        loosely_coupled(r.nav0, t_imu, r.imu.dtheta, r.imu.dv, meas._replace(t=tt), params)
    with pytest.raises(ValueError, match=r"meas.R has shape"):
        loosely_coupled(r.nav0, t_imu, r.imu.dtheta, r.imu.dv, meas._replace(R=R[:, :3, :3]), params)


def test_taylor_discretization_equals_van_loan_and_flags_truncation(outage_run):
    """The default per-epoch Taylor discretisation gives Van Loan's filter to rounding; too few terms are flagged."""
    from jaxnav import _status

    cfg, truth, r, params, t_imu, base = outage_run
    meas = _meas(cfg, r.gnss)
    run = lambda **kw: loosely_coupled(
        r.nav0,
        t_imu,
        r.imu.dtheta,
        r.imu.dv,
        meas,
        params,
        dt_imu=cfg.dt,
        save=ins.LCSave(("nav", "covs")),
        **kw,
    )
    vl = run(discretization=ins.LCDiscretization("van_loan"))
    dlat = np.abs(np.asarray(vl.epochs.nav.pos) - np.asarray(base.epochs.nav.pos))[:, :2].max() * 6.4e6
    assert dlat < 1e-6  # m
    np.testing.assert_allclose(np.asarray(base.epochs.covs), np.asarray(vl.epochs.covs), rtol=1e-8, atol=1e-20)
    assert not int(base.status) & _status.DISCRETIZATION_INACCURATE
    assert int(run(discretization=ins.LCDiscretization(order=1)).status) & _status.DISCRETIZATION_INACCURATE
    with pytest.raises(ValueError, match="discretization must be"):
        run(discretization=ins.LCDiscretization("expm"))


def test_two_speed_mechanization_inside_the_filter(outage_run):
    """nav_every > 1: the samples between fixes by the two-speed mechanization, F's averages from
    the blocks. Measured on this 300 s run with a 60 s outage (50 Hz IMU): propagation=ins.LCPropagation(nav_every=10) (0.2 s)
    stays within 0.10 mm of the per-sample loop (covariances 4e-6 relative), 7 (blocks that do
    not divide the 50 samples of an epoch, the last one short) within 0.07 mm (50, i.e. 1 s: 0.8 mm,
    not run here); the error against the truth is the same (1.2009 m RMS, 5.976 m in the outage)."""
    cfg, truth, r, params, t_imu, base = outage_run
    meas = _meas(cfg, r.gnss)
    gidx = np.asarray(r.gnss.index)
    for K, tol in ((10, 5e-4), (7, 5e-4)):
        res = loosely_coupled(
            r.nav0,
            t_imu,
            r.imu.dtheta,
            r.imu.dv,
            meas,
            params,
            dt_imu=cfg.dt,
            propagation=ins.LCPropagation(nav_every=K),
        )
        assert int(res.status) == 0, K
        assert _pos_err_m(res.epochs.nav.pos, base.epochs.nav.pos).max() < tol, K
        scale = float(jnp.max(jnp.abs(base.epochs.covs)))
        assert float(jnp.max(jnp.abs(res.epochs.covs - base.epochs.covs))) < 1e-4 * scale, K
        err = _pos_err_m(res.epochs.nav.pos, truth.pos[gidx])
        err0 = _pos_err_m(base.epochs.nav.pos, truth.pos[gidx])
        assert abs(np.sqrt(np.mean(err**2)) - np.sqrt(np.mean(err0**2))) < 1e-3, K
    with pytest.raises(ValueError, match="imu_every needs the per-sample loop"):
        loosely_coupled(
            r.nav0,
            t_imu,
            r.imu.dtheta,
            r.imu.dv,
            meas,
            params,
            propagation=ins.LCPropagation(nav_every=10),
            save=ins.LCSave(imu_every=5),
        )
    with pytest.raises(ValueError, match="nav_every=0 must be an integer"):
        loosely_coupled(r.nav0, t_imu, r.imu.dtheta, r.imu.dv, meas, params, propagation=ins.LCPropagation(nav_every=0))


def test_epochs_between_imu_samples_are_handled_by_time(outage_run):
    """Shift the fixes by a third of an IMU interval: the INS state is extrapolated to the epoch time."""
    cfg, truth, r, params, t_imu, base = outage_run
    dt = cfg.dt
    meas = _meas(cfg, r.gnss)
    shift = dt / 3
    # the truth moves by v * shift: present fixes shifted consistently in time and position
    gidx = np.asarray(r.gnss.index)
    lat = truth.pos[gidx, 0]
    RM, RN = jaxnav.geodesy.meridian_radius(lat), jaxnav.geodesy.prime_vertical_radius(lat)
    v = truth.v_n[gidx]
    dpos = jnp.stack([v[:, 1] / RM, v[:, 0] / (RN * jnp.cos(lat)), v[:, 2]], -1) * shift
    m2 = meas._replace(t=np.asarray(meas.t) + shift, pos=meas.pos + dpos)
    m2 = jax.tree_util.tree_map(lambda a: a[:-1], m2)  # the last shifted fix is past the IMU data
    res = loosely_coupled(r.nav0, t_imu, r.imu.dtheta, r.imu.dv, m2, params, dt_imu=dt, save=ins.LCSave(("nav",)))
    d = _pos_err_m(res.epochs.nav.pos, base.epochs.nav.pos[:-1])
    assert d.max() < 0.05  # metres, against metre-level fixes: the epoch time is honoured
    # ignoring the time offset (matching by index) is visibly worse
    m3 = jax.tree_util.tree_map(lambda a: a[:-1], meas._replace(pos=meas.pos + dpos))
    res3 = loosely_coupled(r.nav0, t_imu, r.imu.dtheta, r.imu.dv, m3, params, dt_imu=dt, save=ins.LCSave(("nav",)))
    assert _pos_err_m(res3.epochs.nav.pos, base.epochs.nav.pos[:-1]).max() > 5 * d.max()


def test_zupt_and_known_position_pseudo_measurements(outage_run):
    """Stop updates use the same PV structure: ZUPT (velocity 0) and a known point, masked per component."""
    cfg, truth, r, params, t_imu, base = outage_run
    gidx = np.asarray(r.gnss.index)
    M = len(gidx)
    # replace the fixes by perfect knowledge of the true velocity (a "ZUPT" against the truth's
    # velocity) and, every 20 s, of the true height only
    vel_true = np.asarray(truth.v_n[gidx])
    pos_true = np.asarray(truth.pos[gidx])
    mask = np.zeros((M, 6), bool)
    mask[:, 3:] = True
    mask[::20, 2] = True
    R = np.broadcast_to(np.diag([1.0, 1.0, 0.01**2, 1e-4, 1e-4, 1e-4]), (M, 6, 6))
    meas = PVMeasurements(t=np.asarray(r.gnss.t), pos=pos_true, vel=vel_true, R=R, mask=mask, lever=np.zeros((M, 3)))
    res = loosely_coupled(
        r.nav0, t_imu, r.imu.dtheta, r.imu.dv, meas, params, dt_imu=cfg.dt, save=ins.LCSave(("nav", "valid", "covs"))
    )
    v = np.asarray(res.epochs.valid)
    assert v[0] == 4 and v[1] == 3  # height + 3 velocities, then velocities only
    dv = np.asarray(res.epochs.nav.v_n) - vel_true
    assert np.sqrt(np.mean(dv[50:] ** 2)) < 0.02  # m/s
    dh = np.asarray(res.epochs.nav.pos[:, 2]) - pos_true[:, 2]
    assert np.max(np.abs(dh[::20][3:])) < 0.05  # the known heights hold the vertical channel


def test_long_gaps_are_split_into_prediction_only_epochs(outage_run):
    """The outage's 60 epochs taken out of the measurements: the 61 s interval (3050 samples against 50 in
    the others) is cut every 50 samples, at the times of the epochs taken out, so the run equals the one
    with those epochs masked; the cuts are not skipped updates and map to no GNSS row."""
    from jaxnav.ins.integration import _split_samples

    cfg, truth, r, params, t_imu, base = outage_run
    meas = _meas(cfg, r.gnss)
    t = np.asarray(meas.t)
    keep = ~((t >= 150) & (t < 210))
    gap = jax.tree_util.tree_map(lambda a: np.asarray(a)[keep], meas)
    split = _split_samples(t_imu, gap.t, None)
    assert split.sum() == 60 and np.allclose(t_imu[split], t[~keep], atol=1e-9)
    assert _split_samples(t_imu, gap.t, 0) is None and _split_samples(t_imu, t, None) is None  # off; no gap
    assert _split_samples(t_imu, gap.t, 1000).sum() == 3  # an explicit cap: 3050 samples in 4 pieces
    res = loosely_coupled(r.nav0, t_imu, r.imu.dtheta, r.imu.dv, gap, params, dt_imu=cfg.dt)
    row = np.asarray(res.epochs.gnss_row)
    assert row.size == t.size and np.array_equal(row[keep], np.arange(keep.sum())) and np.all(row[~keep] == -1)
    assert int(res.n_skipped) == 0 and int(base.n_skipped) == 60
    np.testing.assert_allclose(np.asarray(res.epochs.nav.pos), np.asarray(base.epochs.nav.pos), rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(res.epochs.covs), np.asarray(base.epochs.covs), rtol=1e-9, atol=1e-20)
    with pytest.raises(ValueError, match="max_epoch_samples"):
        loosely_coupled(
            r.nav0, t_imu, r.imu.dtheta, r.imu.dv, gap, params, propagation=ins.LCPropagation(max_epoch_samples=-1)
        )
