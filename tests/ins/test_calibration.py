"""The run's noise record, the GNSS consistency check and the noise calibration, on runs given as functions.

The calibration is checked against a closed form: for Gaussian innovations whose covariance is
s^2 R, the maximum-likelihood factor is s^2 = mean(nu' R^-1 nu) / dof per block.
"""

from typing import Any, NamedTuple

import jax.numpy as jnp
import numpy as np
import pytest

from jaxnav import ins, tune


class _Epochs(NamedTuple):
    gnss_row: Any
    innovations: Any
    innov_covs: Any


class _Result(NamedTuple):
    epochs: _Epochs
    loglik: Any


def _noise():
    return ins.LCNoise(imu=ins.noise_preset("consumer"), init_att=np.array([0.01, 0.1]), init_vel=0.1, init_pos=1.0)


def _innovations(M=400, s_pos=2.0, s_vel=0.5, seed=0):
    """(M, 6) innovations with covariance diag(s_pos^2 r_p, s_vel^2 r_v) and their stated R (M, 6, 6)."""
    rng = np.random.default_rng(seed)
    r = np.concatenate([np.full(3, 0.02**2), np.full(3, 0.05**2)]) * rng.uniform(0.5, 2.0, (M, 6))
    s = np.concatenate([np.full(3, s_pos), np.full(3, s_vel)])
    nu = rng.standard_normal((M, 6)) * np.sqrt(r) * s
    return nu, r


def _run(nu, r):
    """A stand-in for the filter: innovations fixed, their covariance the noise's sigma factors times R."""
    M = nu.shape[0]

    def run(d, gate_probability, save):
        s = jnp.concatenate([jnp.broadcast_to(d.pos_sigma_scale, (3,)), jnp.broadcast_to(d.vel_sigma_scale, (3,))])
        var = jnp.asarray(r) * s**2
        ll = -0.5 * jnp.sum(jnp.asarray(nu) ** 2 / var + jnp.log(2 * jnp.pi * var))
        S = jnp.einsum("mi,ij->mij", var, jnp.eye(6))
        return _Result(_Epochs(np.arange(M), jnp.asarray(nu), S), ll)

    return run


def test_gnss_consistency_equals_an_independent_computation():
    nu, r = _innovations(M=300, s_pos=1.0, s_vel=1.0)
    mask = np.ones(nu.shape, bool)
    mask[5, 4] = False  # one velocity component not used: no velocity NIS there, 5 dof for the epoch
    nu[7, 1] = np.nan  # a non-finite innovation counts as not used
    res = _run(nu, r)(_noise(), None, None)
    nis = ins.gnss_nis(res, mask)
    w = nu**2 / r
    used = mask & np.isfinite(nu)
    p_ok = used[:, :3].all(-1)
    v_ok = used[:, 3:].all(-1)
    np.testing.assert_allclose(nis["pos"][p_ok], w[p_ok, :3].sum(-1), rtol=1e-12)
    np.testing.assert_allclose(nis["vel"][v_ok], w[v_ok, 3:].sum(-1), rtol=1e-12)
    assert np.isnan(nis["vel"][5]) and np.isnan(nis["pos"][7]) and nis["dof"][5] == 5 and nis["dof"][7] == 5
    np.testing.assert_allclose(nis["epoch"], np.where(used, w, 0.0).sum(-1), rtol=1e-12)
    c = ins.gnss_consistency(res, mask, gate_probability=0.999)
    assert c["n_epochs"] == 299 and c["n_vel_epochs"] == 299
    assert c["nis_per_dof"] == pytest.approx(w[p_ok, :3].sum(-1).mean() / 3, rel=1e-12)
    thr = {5: ins.chi2_quantile(0.999, 5), 6: ins.chi2_quantile(0.999, 6)}
    share = np.mean([e > thr[int(k)] for e, k in zip(nis["epoch"], nis["dof"])])
    assert c["share_above_gate"] == pytest.approx(share)
    # consistent noise: both means near 1, few epochs beyond the gate
    assert c["consistent"] and 0.8 < c["nis_per_dof"] < 1.25 and 0.8 < c["nis_vel_per_dof"] < 1.25


def test_calibration_finds_the_closed_form_sigma_factors():
    nu, r = _innovations()
    mask = np.ones(nu.shape, bool)
    names = ("pos_sigma_scale", "vel_sigma_scale")
    noise, rep = tune.calibrate_lc_noise(_run(nu, r), _noise(), mask, names, max_evals=30)
    w = nu**2 / r
    s_pos, s_vel = np.sqrt(w[:, :3].mean()), np.sqrt(w[:, 3:].mean())  # ML: s^2 = mean(nu^2 / r)
    assert rep["ran"] and "outside" in rep["reason"]
    assert rep["nis_before_per_dof"] == pytest.approx(s_pos**2, rel=1e-12)
    # L-BFGS stops at a relative loss change of 1e-4 (about 0.5 % in s here), well inside the estimate's
    # own sampling sigma of 1/sqrt(2 x 1200) = 2 %
    np.testing.assert_allclose([noise.pos_sigma_scale, noise.vel_sigma_scale], [s_pos, s_vel], rtol=1e-2)
    assert rep["after_si"]["pos_sigma_scale"] == pytest.approx(float(noise.pos_sigma_scale))
    assert 0.95 < rep["nis_after_per_dof"] < 1.05 and 0.95 < rep["nis_vel_after_per_dof"] < 1.05
    assert rep["loglik_after"] > rep["loglik_before"] and rep["n_epochs"] == nu.shape[0]
    # consistent noise is kept in "auto" mode; calibrate = true fits anyway; false runs nothing
    kept, rep2 = tune.calibrate_lc_noise(_run(nu, r), noise, mask, names)
    assert kept is noise and not rep2["ran"] and "consistent and kept" in rep2["reason"]
    _, rep3 = tune.calibrate_lc_noise(_run(nu, r), noise, mask, names, mode=True, max_evals=5)
    assert rep3["ran"] and rep3["reason"].startswith("calibrate = true")
    off, rep4 = tune.calibrate_lc_noise(_run(nu, r), _noise(), mask, names, mode=False)
    assert not rep4["ran"] and off.pos_sigma_scale == 1.0


def test_too_few_epochs_keep_the_noise_and_warn():
    nu, r = _innovations(M=ins.MIN_CALIBRATION_EPOCHS - 1)
    said = []
    noise, rep = tune.calibrate_lc_noise(
        _run(nu, r), _noise(), np.ones(nu.shape, bool), ("pos_sigma_scale",), progress=said.append
    )
    assert not rep["ran"] and "too few GNSS epochs" in rep["reason"] and said and said[0].startswith("warning")
    assert noise.pos_sigma_scale == 1.0


def test_noise_values_round_trip_and_bad_names():
    d = _noise()
    names = ("arw", "vrw", "pos_sigma_scale", "lever_arm")
    v = ins.calibration.noise_values(d, names, lever=np.array([0.1, 0.2, 0.3]))
    assert float(v["arw"]) == pytest.approx(float(d.imu.gyro_arw)) and v["lever_arm"].shape == (3,)
    d2, lev = ins.calibration.with_noise_values(d, {"arw": 2.0, "pos_sigma_scale": 3.0, "lever_arm": jnp.ones(3)})
    assert d2.imu.gyro_arw == 2.0 and d2.pos_sigma_scale == 3.0 and d2.imu.accel_vrw == d.imu.accel_vrw
    np.testing.assert_array_equal(lev, np.ones(3))
    with pytest.raises(ValueError, match=r"cannot tune \['bogus'\]"):
        ins.check_tunable(["bogus"], n_states=15)
    with pytest.raises(ValueError, match="18- and 21-state"):
        ins.check_tunable(["gyro_bias_instability"], n_states=15)
    with pytest.raises(ValueError, match="needs GNSS velocity updates"):
        ins.check_tunable(["vel_sigma_scale"], n_states=15, use_velocity=False)
    with pytest.raises(ValueError, match="mode must be 'auto', True or False, got 'on'"):
        tune.calibrate_lc_noise(lambda *a: None, d, np.ones((3, 6), bool), ["arw"], mode="on")
    with pytest.raises(ValueError, match="needs lever="):
        tune.fit_lc_noise(lambda d, lev: 0.0, d, ["lever_arm"])
    assert ins.calibration_params(21, True) == (
        "arw",
        "vrw",
        "pos_sigma_scale",
        "vel_sigma_scale",
        "gyro_bias_instability",
    )
