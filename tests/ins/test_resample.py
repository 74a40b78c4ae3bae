"""Aiding readings onto the IMU samples: linear with gap rules, and nearest sample within one interval."""

import numpy as np

from jaxnav import ins


def test_interpolate_on_samples_gaps_and_edges():
    t_imu = np.arange(0.0, 10.0, 0.5)
    t_read = np.array([1.0, 2.0, 3.0, 4.0, 9.0])
    v = np.array([1.0, 2.0, np.nan, 4.0, 9.0])
    out = ins.interpolate_on_samples(t_read, v, t_imu, max_gap_factor=3.0)
    assert np.isnan(out[t_imu < 1.0]).all() and out[t_imu == 1.5][0] == 1.5
    assert out[t_imu == 2.5][0] == 2.5  # across the missing reading: a 2 s gap, within 3 x the median 1 s
    assert np.isnan(out[t_imu == 6.0][0])  # across the 5 s gap
    assert np.isnan(out[t_imu == 9.5][0])  # after the last reading


def test_nearest_samples():
    t_imu = np.arange(0.0, 1.0, 0.1)
    j, ok = ins.nearest_samples(np.array([0.14, 0.46, 5.0]), t_imu)
    assert j[:2].tolist() == [1, 5] and ok.tolist() == [True, True, False]
