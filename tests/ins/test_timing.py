"""IMU-GNSS time offset (issue 18): yaw rate vs GNSS course rate on a simulated car with turns."""

import math

import _car
import numpy as np
import pytest

from jaxnav import ins


def test_offset_recovered_to_10_ms():
    """Consumer gyro + road vibration, 10 Hz GNSS velocities (0.02 m/s noise); IMU stamps 0.15 s late."""
    t, w, f = _car.measured(5)
    tg, v, _ = _car.gnss(10.0)
    r = ins.estimate_time_offset(t + 0.15, w, tg, v, f_b=f)
    assert r.source == "velocity" and not r.at_bound
    assert abs(r.offset_s - (-0.15)) < 0.010, r
    assert abs(r.offset_s + 0.15) < 4 * r.sigma_s + 1e-3  # the reported sigma explains the error
    assert r.corr > 0.95 and r.n_epochs > 300 and r.turn_rate_rms > 0.1
    v_gap = v.copy()
    v_gap[250:262] = np.nan  # missing velocities (a reader's masked values) are left out
    r2 = ins.estimate_time_offset(t + 0.15, w, tg, v_gap, f_b=f)
    assert r2.source == "velocity" and r2.n_epochs < r.n_epochs and abs(r2.offset_s + 0.15) < 0.010
    # the other sign, and 1 Hz GNSS
    tg1, v1, _ = _car.gnss(1.0)
    r = ins.estimate_time_offset(t - 0.32, w, tg1, v1, f_b=f)
    assert abs(r.offset_s - 0.32) < 0.010, r


def test_exact_without_noise_and_from_positions():
    t, w, f = _car.measured(0, arw=0.0, vrw=0.0, vibration=False)
    tg, v, llh = _car.gnss(10.0, sigma_v=0.0)
    r = ins.estimate_time_offset(t + 0.15, w, tg, v, f_b=f)
    assert abs(r.offset_s + 0.15) < 1e-4 and r.corr > 0.999999
    r = ins.estimate_time_offset(t + 0.15, w, tg, None, llh=llh, up_b=(0, 0, 1))
    assert r.source == "position" and abs(r.offset_s + 0.15) < 1e-4


def test_bound_and_bad_input():
    t, w, f = _car.measured(1)
    tg, v, _ = _car.gnss(10.0)
    r = ins.estimate_time_offset(t + 0.8, w, tg, v, max_offset_s=0.5, step_s=0.01)
    assert r.at_bound  # the true offset -0.8 s lies outside the searched +-0.5 s
    with pytest.raises(ValueError, match="velocities v_enu or positions llh"):
        ins.estimate_time_offset(t, w, tg, None)
    with pytest.raises(ValueError, match="usable GNSS epochs"):
        ins.estimate_time_offset(t, w, tg, v, min_speed=50.0)
    with pytest.raises(ValueError, match=r"w_b \(N, 3\)"):
        ins.estimate_time_offset(t, w[:, :2], tg, v)
    with pytest.raises(ValueError, match="step_s"):
        ins.estimate_time_offset(t, w, tg, v, step_s=0.0)
    assert math.isfinite(r.sigma_s)


def test_search_time_offset_on_a_known_likelihood():
    """search_time_offset: cross-correlation first guess, likelihood grid + parabola and clock drift on an
    exactly quadratic log-likelihood (maximum at o = 0.153 s, sigma 4 ms; drift c = 0 or 60 ms)."""
    t, w, f = _car.measured(0, arw=0.0, vrw=0.0, vibration=False)
    tg, v, llh = _car.gnss(10.0, sigma_v=0.0)
    calls, lines = [], []

    def loglik(c_true):
        def ll(o, c):
            calls.append((o, c))
            return -0.5 * ((o - 0.153) / 0.004) ** 2 - 0.5 * ((c - c_true) / 0.01) ** 2

        return ll

    r = ins.search_time_offset(loglik(0.0), 0.5, t + 0.15, w, f, tg, llh, v, progress=lines.append)
    assert r["first_guess"].startswith("yaw rate") and abs(r["first_guess_s"] + 0.15) < 1e-3
    assert r["offset_s"] == pytest.approx(0.153, abs=1e-9) and r["sigma_s"] == pytest.approx(0.004, rel=1e-6)
    assert not r["at_search_edge"] and "0.5 s" in r["method"]
    assert r["grid_s"].size == r["loglik"].size and np.all(np.diff(r["grid_s"]) > 0)
    assert r["drift"]["change_s"] == pytest.approx(0.0, abs=1e-9) and not r["drift"]["significant"]
    assert len(calls) == len(set(calls))  # memoised: no trial clock run twice
    assert not [m for m in lines if m.startswith("warning")]
    # a drifting clock: flagged, with the warning passed on; no turns: the search starts from zero
    r = ins.search_time_offset(
        loglik(0.06), 0.5, t, np.zeros_like(w), f, tg, llh, v, progress=lines.append, widen_hint="widen it"
    )
    assert r["first_guess"].startswith("0 (cross-correlation not usable")
    assert r["drift"]["change_s"] == pytest.approx(0.06, abs=1e-6) and r["drift"]["significant"]
    assert any("changes over the run" in m for m in lines)
