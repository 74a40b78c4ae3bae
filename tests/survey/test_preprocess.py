"""S3 step 1: wild values, zero-phase low-pass, statistics, and the preprocessing pipeline."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.signal
import scipy.stats
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxnav.survey import (
    PreprocessParams,
    ar_kalman,
    butter2_lowpass,
    preprocess_imu,
    reject_outliers,
    running_median,
    select_ar_order,
    series_stats,
    white_noise_variance,
    zero_phase_lowpass,
)


@pytest.mark.parametrize("fc,fs", [(20.0, 100.0), (5.0, 160.0), (40.0, 100.0)])
def test_butterworth_equals_scipy(fc, fs):
    b, a = butter2_lowpass(fc, fs)
    bs, as_ = scipy.signal.butter(2, fc, fs=fs)
    np.testing.assert_allclose(np.asarray(b), bs, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(np.asarray(a), as_, rtol=1e-12, atol=1e-15)


def test_zero_phase_lowpass_equals_scipy_filtfilt():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(700, 3)).cumsum(0) + rng.normal(size=(700, 3))
    for fc in (2.0, 20.0):
        b, a = scipy.signal.butter(2, fc, fs=100.0)
        ref = scipy.signal.filtfilt(b, a, x, axis=0)
        np.testing.assert_allclose(np.asarray(zero_phase_lowpass(x, 0.01, fc)), ref, rtol=0, atol=1e-10)
    np.testing.assert_allclose(
        np.asarray(zero_phase_lowpass(x[:, 0], 0.01, 5.0)),
        scipy.signal.filtfilt(*scipy.signal.butter(2, 5.0, fs=100.0), x[:, 0]),
        atol=1e-10,
    )


def test_lowpass_unit_dc_gain_and_zero_phase():
    t = np.arange(2000) * 0.01
    np.testing.assert_allclose(np.asarray(zero_phase_lowpass(np.full(2000, 3.7), 0.01, 10.0)), 3.7, atol=1e-12)
    s = np.sin(2 * np.pi * 0.5 * t)
    y = np.asarray(zero_phase_lowpass(s, 0.01, 20.0))
    inner = slice(200, 1800)
    # 0.5 Hz through a 20 Hz Butterworth pair: gain |H|^2 = 1 / (1 + (f/fc)^4), no lag
    np.testing.assert_allclose(y[inner], s[inner] / (1 + (0.5 / 20.0) ** 4), atol=1e-6)
    with pytest.raises(ValueError, match="more than 9"):
        zero_phase_lowpass(np.ones(5), 0.01, 10.0)


def test_running_median_matches_numpy():
    rng = np.random.default_rng(1)
    x = rng.normal(size=50)
    ref = np.array([np.median(x[max(0, i - 2) : i + 3]) if 2 <= i < 48 else np.nan for i in range(50)])
    got = np.asarray(running_median(x, 2))
    np.testing.assert_allclose(got[2:48], ref[2:48])


def test_reject_outliers_finds_spikes_keeps_steps():
    rng = np.random.default_rng(2)
    N = 4000
    x = 0.01 * rng.normal(size=N)
    x[2000:] += 1.0  # a step (a real manoeuvre) must survive
    x[1000:1200] += np.linspace(0, 0.5, 200)  # and a ramp
    spikes = rng.choice(np.r_[100:1990, 2010:3900], 20, replace=False)
    x_sp = x.copy()
    x_sp[spikes] += rng.choice([-1, 1], 20) * 0.5
    r = reject_outliers(x_sp, 6.0)
    flagged = np.flatnonzero(np.asarray(r.flags))
    assert set(spikes) <= set(flagged)
    assert len(flagged) - len(spikes) <= 4  # false alarms: ~ 2 * norm.sf(6) * N plus edges, tiny
    assert int(r.n_rejected) == len(flagged)
    np.testing.assert_allclose(np.asarray(r.clean)[spikes], np.asarray(running_median(x_sp, 2))[spikes])
    assert not np.asarray(r.flags)[1995:2005].any()


@settings(max_examples=25, deadline=None)
@given(shift=st.floats(-1e3, 1e3), scale=st.floats(0.1, 10.0), seed=st.integers(0, 1000))
def test_reject_outliers_equivariant(shift, scale, seed):
    """Flags do not change under x -> a x + c (robust scale and median are equivariant)."""
    rng = np.random.default_rng(seed)
    x = rng.standard_t(3, size=600)
    r0 = reject_outliers(x, 6.0)
    r1 = reject_outliers(scale * x + shift, 6.0)
    np.testing.assert_array_equal(np.asarray(r0.flags), np.asarray(r1.flags))
    unflagged = ~np.asarray(r0.flags)
    np.testing.assert_array_equal(np.asarray(r0.clean)[unflagged], x[unflagged])


def test_series_stats_against_scipy_and_runs_loop():
    rng = np.random.default_rng(3)
    x = rng.gamma(2.0, size=1000)
    s = series_stats(x)
    assert abs(float(s.skew) - scipy.stats.skew(x)) < 1e-10
    assert abs(float(s.kurt) - scipy.stats.kurtosis(x)) < 1e-10
    jb = scipy.stats.jarque_bera(x)
    assert abs(float(s.jb) - jb.statistic) < 1e-8 and abs(float(s.jb_p) - jb.pvalue) < 1e-10
    assert abs(float(s.var) - np.var(x, ddof=1)) < 1e-10
    # runs test written out: drop values equal to the median, count sign changes
    med = np.median(x)
    y = x[x != med]
    sgn = y > med
    runs = 1 + np.sum(sgn[1:] != sgn[:-1])
    n1, n2 = sgn.sum(), (~sgn).sum()
    mu = 2 * n1 * n2 / (n1 + n2) + 1
    var = 2 * n1 * n2 * (2 * n1 * n2 - n1 - n2) / ((n1 + n2) ** 2 * (n1 + n2 - 1))
    assert float(s.runs) == runs
    assert abs(float(s.runs_z) - (runs - mu) / np.sqrt(var)) < 1e-10
    # white Gaussian noise: normal and stationary; a random walk fails the run test
    w = np.asarray(jax.random.normal(jax.random.PRNGKey(0), (1000,)))
    sw = series_stats(w)
    assert sw.jb_p > 0.001 and sw.runs_p > 0.001
    assert series_stats(np.cumsum(w)).runs_p < 1e-6
    s2 = series_stats(np.stack([w, np.cumsum(w)], 1))
    assert s2.runs_z.shape == (2,)


@pytest.fixture(scope="module")
def calib():
    from jaxnav.sim import cadastral_scenarios, calibration_record

    scn = cadastral_scenarios()[0]["consumer"]
    return scn, calibration_record(scn, jax.random.PRNGKey(4), 20000)


def test_preprocessing_reduces_residual_error_variance(calib):
    """Static record, true signal constant: wild values, then the AR(p) Kalman filter, lower the error variance."""
    scn, rec = calib
    y = rec.gyro[:, 1]
    raw = float(jnp.var(y))
    clean = reject_outliers(y, 6.0, 1e-4)
    assert int(clean.n_rejected) >= int(jnp.sum(jnp.abs(y - rec.gyro_coloured[:, 1]) > 0.05))
    c = clean.clean
    sel = select_ar_order(c, 6)
    kf = ar_kalman(c, sel.fit.phi, sel.fit.sigma2, white_noise_variance(c))
    v_clean, v_kf = float(jnp.var(c)), float(jnp.var(kf.error))
    assert v_clean < 0.5 * raw
    assert v_kf < 0.5 * v_clean
    # what is left is mostly the correlated error (bias + Gauss-Markov), which class 1 estimates
    assert float(jnp.var(kf.error - rec.gyro_coloured[:, 1])) < 0.5 * float(jnp.var(c - rec.gyro_coloured[:, 1]))


def test_preprocess_imu_pipeline(calib):
    scn, rec = calib
    dt = scn.dt
    out = preprocess_imu(rec.gyro[:6000] * dt, rec.accel[:6000] * dt, dt, PreprocessParams(cutoff_hz=10.0))
    assert out.dtheta.shape == (6000, 3)
    assert int(out.n_rejected) >= 1
    # unit DC gain: the mean increment (what drives the navigation error) is kept
    np.testing.assert_allclose(
        np.asarray(out.dtheta.mean(0)), np.asarray((rec.gyro_coloured[:6000] * dt).mean(0)), rtol=0.2, atol=2e-7
    )
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        preprocess_imu(jnp.zeros((10, 2)), jnp.zeros((10, 2)), dt)
