"""S3 checks as library calls: AR standard-error coverage, preprocessing variances, RTK speed, stop records."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxnav import geodesy as g
from jaxnav import survey


def test_se_coverage_is_near_the_normal_shares():
    within1, within2 = survey.se_coverage(jax.random.PRNGKey(3), jnp.array([0.6, -0.3]), 1.0, 2000, 200)
    # 400 z values: binomial standard errors about 0.023 and 0.010
    assert within1 == pytest.approx(0.683, abs=0.08)
    assert within2 == pytest.approx(0.954, abs=0.04)


def test_preprocessing_variances_on_ar1_drift_plus_white_noise():
    n, dt, sw = 20000, 0.01, 0.01
    drift = np.asarray(survey.simulate_ar(jax.random.PRNGKey(0), jnp.array([0.999]), 1e-4, n))
    white = sw * np.asarray(jax.random.normal(jax.random.PRNGKey(1), (n,)))
    y = drift + white
    y[[100, 5000]] += 1.0  # two wild values
    r = survey.preprocessing_variances(jnp.asarray(y), jnp.asarray(drift), dt, 1e-3)
    assert r["var_raw"] == pytest.approx(float(np.var(y)), rel=1e-9)
    assert r["var_coloured_truth"] == pytest.approx(float(np.var(drift)), rel=1e-9)
    assert r["n_rejected"] == 2
    assert r["var_outliers_rejected"] == pytest.approx(float(np.var(drift + white)), rel=0.02)
    assert r["white_variance"] == pytest.approx(sw**2, rel=0.1)
    assert r["reduction_total"] == pytest.approx(r["var_raw"] / r["var_ar_kalman"], rel=1e-12)
    assert r["var_ar_kalman"] < 0.5 * r["var_outliers_rejected"]
    dec = r["decimated_1s"]
    assert dec["n"] == n // 100 and dec["block_s"] == 1.0
    assert dec["white_variance"] == pytest.approx(r["white_variance"] / 100, rel=1e-12)
    assert dec["var_error_raw_minus_drift"] == pytest.approx(sw**2 / 100, rel=0.2)  # white noise of 1 s means
    assert dec["var_error_ar_kalman_minus_drift"] < dec["var_error_raw_minus_drift"]
    assert set(r["stats_raw"]) == {"mean", "var", "skew", "kurt", "jb", "jb_p", "runs_z", "runs_p"}
    assert r["stats_clean"]["var"] == pytest.approx(r["var_outliers_rejected"], rel=1e-3)


def test_horizontal_speed_of_a_straight_track():
    t = np.arange(0.0, 20.0, 0.5)
    ref = np.array([0.6, 2.0, 50.0])
    enu = np.stack([1.5 * t, -2.0 * t, 0.3 * t], -1)  # 2.5 m/s horizontally, climbing
    pos = ref + np.asarray(g.enu_to_curvilinear(ref, jnp.asarray(enu)))
    np.testing.assert_allclose(survey.horizontal_speed(t, pos), 2.5, rtol=1e-5)


def test_stop_records():
    stops = survey.make_stop_list([1.0, 5.0], [3.0, 9.5], ["known_coordinate", "target"], name=["K1", "T1"])
    assert survey.stop_records(stops) == [
        {"name": "K1", "kind": "known_coordinate", "t_start": 1.0, "t_end": 3.0},
        {"name": "T1", "kind": "target", "t_start": 5.0, "t_end": 9.5},
    ]
