"""Summaries of station records: velocity (mm/yr), one-day forecast statistics per filter, median position."""

from types import SimpleNamespace

import numpy as np
import pytest

from jaxnav import filters as jf
from jaxnav import monitoring as mon
from jaxnav.units import DEG, MM, MM_PER_YEAR


def _velocity(reference=True):
    v = np.array([1.0, -2.0, 0.5]) * MM_PER_YEAR
    return mon.StationVelocity(
        station="ABCD",
        n=100,
        span_years=3.5,
        velocity=v,
        sigma=np.full(3, 0.1 * MM_PER_YEAR),
        sigma_ar1=np.full(3, 0.3 * MM_PER_YEAR),
        ls_velocity=v * 1.01,
        ls_sigma=np.full(3, 0.1 * MM_PER_YEAR),
        reference_velocity=np.array([1.1, -2.1, 0.4]) * MM_PER_YEAR if reference else None,
        reference_sigma=np.full(3, 0.2 * MM_PER_YEAR) if reference else None,
        accel_psd=np.array([1e-30, 2e-30, 3e-30]),
        t=np.arange(100.0),
        smoothed_velocity=None,
        smoothed_sigma=None,
        loglik_grid=None,
        residuals=np.zeros((100, 3)),
    )


def test_velocity_summary_in_mm_per_yr():
    s = mon.velocity_summary(_velocity(), n_masked=4)
    assert (s["epochs"], s["span_years"], s["masked_values"]) == (100, 3.5, 4)
    assert s["velocity_mm_per_yr"] == pytest.approx({"east": 1.0, "north": -2.0, "up": 0.5}, rel=1e-12)
    assert s["ls_slope_mm_per_yr"]["north"] == pytest.approx(-2.02, rel=1e-12)
    assert s["sigma_ar1_mm_per_yr"]["up"] == pytest.approx(0.3, rel=1e-12)
    assert s["published_mm_per_yr"]["up"] == pytest.approx(0.4, rel=1e-12)
    assert s["published_sigma_mm_per_yr"]["east"] == pytest.approx(0.2, rel=1e-12)
    assert s["random_walk_psd_m2_per_s3"] == {"east": 1e-30, "north": 2e-30, "up": 3e-30}
    s0 = mon.velocity_summary(_velocity(reference=False)._replace(accel_psd=None))
    assert s0["published_mm_per_yr"] is None and s0["published_sigma_mm_per_yr"] is None
    assert s0["random_walk_psd_m2_per_s3"] is None


def test_forecast_summary_closed_form():
    N = 21  # periods of min(10, N - 1) = 10 epochs: two whole periods
    dev = np.zeros((N, 1, 3))
    dev[:10, 0] = [3 * MM, 4 * MM, 12 * MM]  # first period: every epoch above the east and up thresholds
    dev[10:20, 0] = [1 * MM, -1 * MM, 2 * MM]
    flags = np.zeros((N, 3), bool)
    flags[[2, 5]] = True
    fc = {
        "standard": SimpleNamespace(deviation=dev, status=2, noise=()),
        "robust": SimpleNamespace(deviation=dev, status=0, noise=_robust_info(flags)),
    }
    s = mon.forecast_summary(fc, 10)
    st = s["standard"]
    assert st["m_P_mm"] == pytest.approx([5.0, np.sqrt(2.0)], rel=1e-12)
    assert st["m_H_mm"] == pytest.approx([12.0, 2.0], rel=1e-12)
    np.testing.assert_allclose(st["max_abs_mm"], [[3.0, 4.0, 12.0], [1.0, 1.0, 2.0]], rtol=1e-12)
    assert st["share_under_3_3_10mm"] == [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]]
    assert st["status"] == 2 and "outliers_flagged" not in st
    assert s["robust"]["outliers_flagged"] == 6  # 2 epochs x 3 components
    assert mon.DAILY_THRESHOLDS_ENU == pytest.approx((3 * MM, 3 * MM, 10 * MM))


def _robust_info(rejected):
    fields = {f: None for f in jf.RobustInfo._fields}
    fields["rejected"] = rejected
    return jf.RobustInfo(**fields)


def test_median_position():
    llh = np.array([[10.0, 20.0, 1.0], [11.0, np.nan, 1.0], [12.0, 22.0, 1.0], [14.0, 21.0, 1.0]]) * DEG
    pos = mon.median_position(SimpleNamespace(llh=llh))
    np.testing.assert_allclose(pos, np.array([12.0, 21.0]) * DEG, rtol=1e-15)
    assert mon.median_position(SimpleNamespace(llh=np.full((3, 3), np.nan))) is None
