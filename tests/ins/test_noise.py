"""Noise presets by grade and datasheet unit conversions (issue 18)."""

import math

import numpy as np
import pytest

from jaxnav import ins, units


def test_unit_helpers_against_hand_values():
    # 1 deg/sqrt(h) = (pi/180) rad / 60 sqrt(s)
    assert units.deg_per_sqrt_hour_to_rad_per_sqrt_s(1.0) == pytest.approx(math.pi / 180 / 60, rel=1e-15)
    assert units.mps_per_sqrt_hour_to_mps_per_sqrt_s(0.6) == pytest.approx(0.01, rel=1e-15)
    assert units.deg_per_hour_to_rad_per_s(3600.0) == pytest.approx(math.pi / 180, rel=1e-15)
    assert units.ug_to_mps2(1e6) == pytest.approx(9.80665)
    assert units.mg_to_mps2(1.0) == pytest.approx(9.80665e-3)
    assert units.ppm_to_ratio(250.0) == pytest.approx(2.5e-4)
    # a noise density in deg/s/sqrt(Hz) is an ARW: 1 deg/s/sqrt(Hz) = 60 deg/sqrt(h)
    assert units.DEG_PER_SEC_PER_SQRT_HZ == pytest.approx(units.deg_per_sqrt_hour_to_rad_per_sqrt_s(60.0))
    for f, g, x in (
        (units.deg_per_sqrt_hour_to_rad_per_sqrt_s, units.rad_per_sqrt_s_to_deg_per_sqrt_hour, 0.3),
        (units.mps_per_sqrt_hour_to_mps_per_sqrt_s, units.mps_per_sqrt_s_to_mps_per_sqrt_hour, 0.05),
        (units.deg_per_hour_to_rad_per_s, units.rad_per_s_to_deg_per_hour, 7.0),
        (units.mg_to_mps2, units.mps2_to_mg, 2.0),
        (units.ug_to_mps2, units.mps2_to_ug, 30.0),
        (units.ppm_to_ratio, units.ratio_to_ppm, 300.0),
    ):
        assert g(f(x)) == pytest.approx(x, rel=1e-14)


def test_presets_ordered_and_round_trip():
    grades = [ins.noise_preset(g) for g in ins.NOISE_GRADES]
    for field in (
        "gyro_arw",
        "accel_vrw",
        "gyro_bias_instability",
        "accel_bias_instability",
        "gyro_bias_initial",
        "accel_bias_initial",
        "gyro_sf",
        "accel_sf",
    ):
        vals = [getattr(n, field) for n in grades]
        assert all(a > b for a, b in zip(vals, vals[1:])), (field, vals)  # better grade, smaller figure
    nav = ins.noise_preset("navigation")
    ds = ins.imu_noise_to_datasheet(nav)
    assert ds["arw_deg_per_sqrt_h"] == pytest.approx(0.002)
    assert ds["gyro_bias_instability_deg_per_h"] == pytest.approx(0.005)
    back = ins.imu_noise_from_datasheet(**ds)
    np.testing.assert_allclose(np.array(back), np.array(nav), rtol=1e-12)
    # Groves (2013) ch. 4 orders: navigation-class gyro bias < 0.01 deg/h; consumer > 100 deg/h uncalibrated
    assert units.rad_per_s_to_deg_per_hour(nav.gyro_bias_initial) <= 0.01
    assert units.rad_per_s_to_deg_per_hour(ins.noise_preset("consumer").gyro_bias_initial) >= 100


def test_datasheet_checks():
    with pytest.raises(ValueError, match="unknown IMU grade 'mems'"):
        ins.noise_preset("mems")
    with pytest.raises(ValueError, match="arw_deg_per_sqrt_h"):
        ins.imu_noise_from_datasheet(arw_deg_per_sqrt_h=-1.0, vrw_mps_per_sqrt_h=0.1)
    with pytest.raises(ValueError, match="gyro_bias_tau_s"):
        ins.imu_noise_from_datasheet(arw_deg_per_sqrt_h=0.1, vrw_mps_per_sqrt_h=0.1, gyro_bias_tau_s=0.0)
    n = ins.imu_noise_from_datasheet(
        arw_deg_per_sqrt_h=0.1,
        vrw_mps_per_sqrt_h=0.1,
        gyro_bias_rw_deg_per_h_per_sqrt_h=1.0,
        accel_bias_rw_mps2_per_sqrt_h=0.06,
    )
    assert n.gyro_bias_rw == pytest.approx(math.radians(1) / 3600 / 60)
    assert n.accel_bias_rw == pytest.approx(0.001)
