"""jaxnav.sim.imu_noise / lc_inputs with jaxnav.ins.lc_params / gnss_measurements: a simulated run filtered with
public helpers."""

import dataclasses

import jax
import numpy as np
import pytest

from jaxnav import geodesy, ins, sim


@pytest.fixture(scope="module")
def short_run():
    cfg = sim.cut_timeline(sim.s0_scenario(), 100.0)
    cfg = dataclasses.replace(cfg, gnss=dataclasses.replace(cfg.gnss, outages=((40.0, 55.0),)))
    run = sim.simulate(cfg, jax.random.PRNGKey(3), trajectory=sim.make_trajectory(cfg))
    return cfg, run


def _params(cfg, model=ins.ERROR_MODEL_18):
    ie = cfg.initial_errors
    return ins.lc_params(model, sim.imu_noise(cfg), cfg.origin, att=ie.attitude, vel=ie.velocity, pos_enu=ie.position)


def test_lc_params_follow_the_scenario_sigmas(short_run):
    cfg, _ = short_run
    p = _params(cfg)
    sd = np.sqrt(np.diag(np.asarray(p.P0)))
    ie, nz = cfg.initial_errors, cfg.noise
    np.testing.assert_allclose(sd[0:3], np.broadcast_to(ie.attitude, 3), rtol=1e-12)
    np.testing.assert_allclose(sd[3:6], np.broadcast_to(ie.velocity, 3), rtol=1e-12)
    lat, h = float(cfg.origin[0]), float(cfg.origin[2])
    RM = float(geodesy.meridian_radius(lat)) + h
    RN = float(geodesy.prime_vertical_radius(lat)) + h
    pe = np.broadcast_to(ie.position, 3)
    np.testing.assert_allclose(sd[6:9] * [RM, RN * np.cos(lat), 1.0], [pe[1], pe[0], pe[2]], rtol=1e-12)
    np.testing.assert_allclose(
        sd[9:18], np.concatenate([nz.gyro_bias_initial, nz.gyro_bias_instability, nz.accel_bias_initial]), rtol=1e-12
    )
    np.testing.assert_allclose(
        np.diag(np.asarray(p.Qc)),
        np.concatenate(
            [
                np.square(nz.gyro_arw),
                2 * np.square(nz.gyro_bias_instability) / nz.gyro_bias_tau,
                np.square(nz.accel_vrw),
            ]
        ),
        rtol=1e-12,
    )
    np.testing.assert_array_equal(p.tau_markov, nz.gyro_bias_tau)
    assert _params(cfg, ins.ERROR_MODEL_15).P0.shape == (15, 15) and _params(cfg, ins.ERROR_MODEL_21).Qc.shape == (
        18,
        18,
    )


def test_gnss_measurements_mask_outages_floor_sigmas_and_check_shapes(short_run):
    cfg, run = short_run
    m = sim.lc_inputs(cfg, run).meas
    t = np.asarray(m.t)
    out = (t >= 40.0) & (t < 55.0)
    assert out.any() and not np.asarray(m.mask)[out].any() and np.asarray(m.mask)[~out].all()
    np.testing.assert_allclose(
        np.sqrt(np.asarray(m.R)[0].diagonal()),
        np.concatenate([np.broadcast_to(cfg.gnss.pos_sigma, 3), np.broadcast_to(cfg.gnss.vel_sigma, 3)]),
    )
    g = run.gnss
    c = np.array([[4e-4, 1e-4, 0.0], [1e-4, 1e-2, 0.0], [0.0, 0.0, 9e-2]])  # sigmas 0.02, 0.1, 0.3 m
    vel = np.asarray(g.vel).copy()
    vel[3, 1] = np.nan
    f = ins.gnss_measurements(t, g.pos, vel, c, np.full((3, 3), np.nan), pos_sigma_floor=0.05, vel_sigma_floor=2.0)
    R = np.asarray(f.R)[0]
    np.testing.assert_allclose(np.sqrt(R.diagonal()), [0.05, 0.1, 0.3, 2.0, 2.0, 2.0], rtol=1e-12)
    np.testing.assert_allclose(R[0, 1] / np.sqrt(R[0, 0] * R[1, 1]), 0.05, rtol=1e-12)  # correlation kept
    np.testing.assert_array_equal(np.asarray(f.mask)[3], [True, True, True, True, False, True])  # the NaN component
    assert float(f.vel[3, 1]) == 0.0
    with pytest.raises(ValueError, match=r"lever \(2,\)"):
        ins.gnss_measurements(t, g.pos, g.vel, c, c, lever=[0.1, 0.2])


def test_public_helpers_filter_a_run_within_its_sigmas(short_run):
    """The filter fed by the helpers keeps the position error inside 4 sigma at the end."""
    cfg, run = short_run
    res = ins.loosely_coupled(*sim.lc_inputs(cfg, run), _params(cfg), dt_imu=cfg.dt)
    idx = np.asarray(run.gnss.index)
    d = np.asarray(res.epochs.nav.pos[-1] - run.truth.pos[idx[-1]])
    lat = float(run.truth.pos[idx[-1], 0])
    err = np.array(
        [
            d[0] * float(geodesy.meridian_radius(lat)),
            d[1] * float(geodesy.prime_vertical_radius(lat)) * np.cos(lat),
            d[2],
        ]
    )
    sig = np.sqrt(np.diag(np.asarray(res.epochs.covs[-1]))[6:9]) * np.array(
        [float(geodesy.meridian_radius(lat)), float(geodesy.prime_vertical_radius(lat)) * np.cos(lat), 1.0]
    )
    assert np.all(np.abs(err) < 4 * sig), (err, sig)
    assert np.all(sig < 5.0)
