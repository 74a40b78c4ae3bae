"""jaxnav.sim.lc_inputs / lc_params / gnss_measurements: a simulated run filtered with public helpers."""

import dataclasses

import jax
import numpy as np
import pytest

from jaxnav import geodesy, ins, sim
from jaxnav.experiments import cut_timeline


@pytest.fixture(scope="module")
def short_run():
    cfg = cut_timeline(sim.s0_scenario(), 100.0)
    cfg = dataclasses.replace(cfg, gnss=dataclasses.replace(cfg.gnss, outages=((40.0, 55.0),)))
    run = sim.simulate(cfg, jax.random.PRNGKey(3), trajectory=sim.make_trajectory(cfg))
    return cfg, run


def test_lc_params_follow_the_scenario_sigmas(short_run):
    cfg, _ = short_run
    p = sim.lc_params(cfg)
    sd = np.sqrt(np.diag(np.asarray(p.P0)))
    ie = cfg.initial_errors
    np.testing.assert_allclose(sd[0:3], np.broadcast_to(ie.attitude, 3), rtol=1e-12)
    np.testing.assert_allclose(sd[3:6], np.broadcast_to(ie.velocity, 3), rtol=1e-12)
    lat, h = float(cfg.origin[0]), float(cfg.origin[2])
    RM = float(geodesy.meridian_radius(lat)) + h
    RN = float(geodesy.prime_vertical_radius(lat)) + h
    pe = np.broadcast_to(ie.position, 3)
    np.testing.assert_allclose(sd[6:9] * [RM, RN * np.cos(lat), 1.0], [pe[1], pe[0], pe[2]], rtol=1e-12)
    assert p.P0.shape == (18, 18) and sim.lc_params(cfg, n_states=15).P0.shape == (15, 15)
    np.testing.assert_allclose(np.asarray(sim.lc_params(cfg, q_scale=2.0).Qc), 2.0 * np.asarray(p.Qc))
    with pytest.raises(ValueError, match="n_states must be 15 or 18, got 21"):
        sim.lc_params(cfg, n_states=21)


def test_gnss_measurements_mask_outages_and_check_the_lever(short_run):
    cfg, run = short_run
    m = sim.gnss_measurements(cfg, run.gnss)
    t = np.asarray(m.t)
    out = (t >= 40.0) & (t < 55.0)
    assert out.any() and not np.asarray(m.mask)[out].any() and np.asarray(m.mask)[~out].all()
    np.testing.assert_allclose(np.sqrt(np.asarray(m.R)[0].diagonal()),
                               np.concatenate([np.broadcast_to(cfg.gnss.pos_sigma, 3),
                                               np.broadcast_to(cfg.gnss.vel_sigma, 3)]))
    with pytest.raises(ValueError, match=r"lever must have shape \(3,\), got \(2,\)"):
        sim.gnss_measurements(cfg, run.gnss, lever=[0.1, 0.2])


def test_public_helpers_filter_a_run_within_its_sigmas(short_run):
    """The filter fed by the helpers keeps the position error inside 4 sigma at the end."""
    cfg, run = short_run
    res = ins.loosely_coupled(*sim.lc_inputs(cfg, run), sim.lc_params(cfg), dt_imu=cfg.dt)
    idx = np.asarray(run.gnss.index)
    d = np.asarray(res.epochs.nav.pos[-1] - run.truth.pos[idx[-1]])
    lat = float(run.truth.pos[idx[-1], 0])
    err = np.array([d[0] * float(geodesy.meridian_radius(lat)), d[1] * float(geodesy.prime_vertical_radius(lat))
                    * np.cos(lat), d[2]])
    sig = np.sqrt(np.diag(np.asarray(res.epochs.covs[-1]))[6:9]) * np.array(
        [float(geodesy.meridian_radius(lat)), float(geodesy.prime_vertical_radius(lat)) * np.cos(lat), 1.0])
    assert np.all(np.abs(err) < 4 * sig), (err, sig)
    assert np.all(sig < 5.0)
