"""S2 summaries of the RTK records: connection models, eq. (19) precisions, Table 3, per-point records, zones."""

import math

import jax.numpy as jnp
import numpy as np
import pytest

from jaxnav import geodesy as g
from jaxnav import survey
from jaxnav.survey import rtk
from jaxnav.units import ARCSEC


def _result(P=3, **fields):
    """An :class:`jaxnav.survey.RtkResult` of P points with NaN fields except those given."""
    base = {f: np.full((P, 3), np.nan) for f in rtk.RtkResult._fields}
    base.update(n=np.arange(P) + 10, **fields)
    return rtk.RtkResult(**base)


def test_connection_summary_recovers_the_similarity_and_the_surface():
    rng = np.random.default_rng(1)
    src = rng.uniform(-2000.0, 2000.0, (6, 2)) + np.array([3.9e6, 4.0e5])
    params = g.Similarity2D(t=jnp.array([120.0, -45.0]), theta=jnp.asarray(3.0 * ARCSEC), m=jnp.asarray(7e-6))
    dst = np.asarray(g.similarity2d(params, jnp.asarray(src)))
    zeta = 20.0 + 1e-5 * (src[:, 0] - 3.9e6) - 2e-5 * (src[:, 1] - 4.0e5)
    con = rtk.ConnectionModels(
        transform=g.estimate_similarity2d(src, dst),
        anomaly=g.fit_height_anomaly(src[:, 0], src[:, 1], zeta, kind="plane"),
    )
    s = survey.connection_summary(con)
    d, a = s["datum_transformation"], s["height_anomaly"]
    assert d["tx"] == pytest.approx(120.0, abs=1e-4) and d["ty"] == pytest.approx(-45.0, abs=1e-4)
    assert d["theta_arcsec"] == pytest.approx(3.0, abs=1e-6)
    assert d["m_ppm"] == pytest.approx(7.0, abs=1e-6)
    assert d["n_control"] == 6 and max(d["residual_rms_mm"]) < 1e-3 and d["sigma0_mm"] < 1e-3
    assert a["surface"] == "plane" and a["n_control"] == 6 and len(a["residuals_mm"]) == 6
    assert max(abs(v) for v in a["residuals_mm"]) < 1e-6
    assert survey.connection_summary(rtk.ConnectionModels(None, None)) == {}


def test_precision_summary_means_and_factors():
    filt = np.array([[3e-4, 4e-4, 1e-3], [6e-4, 8e-4, 3e-3], [np.nan, np.nan, np.nan]])
    res = _result(precision=filt, raw_precision=2 * filt, formal_precision=np.zeros((3, 3)))
    s = survey.precision_summary(res)
    assert s["filtered"]["plane_mm"] == pytest.approx(0.75, rel=1e-12)  # mean of 0.5 and 1.0 mm
    assert s["filtered"]["height_mm"] == pytest.approx(2.0, rel=1e-12)
    assert s["factor_conventional_over_filtered"]["plane"] == pytest.approx(2.0, rel=1e-12)
    assert s["factor_formal_over_filtered"]["height"] == 0.0
    zero = survey.precision_summary(_result(precision=np.zeros((3, 3)), raw_precision=filt, formal_precision=filt))
    assert math.isnan(zero["factor_conventional_over_filtered"]["plane"])


def test_levelling_summary_is_table3_in_cm_per_height_path():
    h_level = np.array([10.0, 20.0, 30.0, np.nan])
    xyh = np.zeros((4, 3))
    xyh[:, 2] = h_level + np.array([0.005, -0.012, 0.004, 0.0])
    raw = xyh.copy()
    raw[:, 2] += 0.02
    res = _result(P=4, xyh=xyh, raw_xyh=raw)  # terminal heights NaN: no such path
    s = survey.levelling_summary(res, h_level)
    assert list(s) == ["filtered", "conventional_H_anomaly"]
    f = s["filtered"]
    assert f["max_abs_cm"] == pytest.approx(1.2, abs=1e-9)
    assert f["mean_cm"] == pytest.approx(-0.1, abs=1e-9)
    assert f["thresholds_cm"] == pytest.approx([0.7, 1.0, 1.5])
    assert f["count_within"] == [2, 2, 3] and f["share_within"] == pytest.approx([2 / 3, 2 / 3, 1.0])
    assert s["conventional_H_anomaly"]["mean_cm"] == pytest.approx(1.9, abs=1e-9)
    assert survey.levelling_summary(res, np.full(4, np.nan)) == {}


def _sigmas(P=2):
    return rtk.PointSigmas(
        sigma=np.array([[1e-3, 2e-3, 2e-3], [np.nan, 1e-3, 1e-3]])[:P],
        sigma_naive=np.array([[5e-4, 1e-3, 1e-3], [5e-4, 5e-4, 5e-4]])[:P],
        n_eff=np.full((P, 3), 4.0),
        lag1=np.full((P, 3), 0.5),
        segment_epochs=np.array([60, 60])[:P],
        segment_points=np.array([2, 2])[:P],
        method=rtk.SIGMA_METHOD,
    )


def test_point_records_and_sigma_summary():
    xyh = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])
    res = _result(P=2, xyh=xyh, precision=np.full((2, 3), 2e-4), raw_precision=np.full((2, 3), 3e-4))
    t = np.array([[100.0, 101.0, 102.0], [5.0, 6.0, 7.0]])
    mask = np.array([[False, True, True], [False, False, False]])
    recs = survey.point_records(["A", "B"], res, _sigmas(), t, mask, np.array(["s1", "s1"]))
    a, b = recs
    assert (a["name"], a["n_epochs"], a["t_start"], a["t_end"]) == ("A", 10, 101.0, 102.0)
    assert b["t_start"] is None and b["t_end"] is None
    assert (a["x_m"], a["y_m"], a["h_m"]) == (1.0, 2.0, 3.0)
    assert a["sigma_y_m"] == 2e-3 and a["sigma_naive_x_m"] == 5e-4 and a["sigma_method"] == rtk.SIGMA_METHOD
    assert a["precision_mm"] == pytest.approx([0.2] * 3) and a["raw_precision_mm"] == pytest.approx([0.3] * 3)
    assert a["segment"] == "s1" and a["segment_points"] == 2 and a["lag1_autocorrelation"] == [0.5] * 3
    s = survey.sigma_summary(_sigmas())  # point B has a NaN sigma: left out
    assert s["corrected"] == pytest.approx([1.0, 2.0, 2.0]) and s["naive"] == pytest.approx([0.5, 1.0, 1.0])
    s2 = survey.sigma_summary(_sigmas()._replace(sigma=np.array([[1e-3, 2e-3, 2e-3], [3e-3, 1e-3, 1e-3]])))
    assert s2["corrected"][0] == pytest.approx(math.sqrt(5.0), rel=1e-12)  # rms of 1 and 3 mm
    assert survey.sigma_summary(_sigmas()._replace(sigma=np.full((2, 3), np.nan)))["corrected"] is None


def test_central_meridians_and_unusable_epochs():
    lon = np.deg2rad(np.array([[117.2, 117.3, 150.0], [120.9, 121.0, 121.1]]))
    mask = np.array([[True, True, False], [True, True, True]])
    series = rtk.RtkSeries(
        t=np.zeros((2, 3)),
        lat=np.zeros((2, 3)),
        lon=lon,
        H=np.zeros((2, 3)),
        sigma=np.ones((2, 3, 3)),
        mask=mask,
        h_terminal=np.zeros((2, 3)),
        xy_terminal=np.zeros((2, 3, 2)),
    )
    np.testing.assert_allclose(np.rad2deg(survey.central_meridians(series, 3)), [117.0, 120.0], atol=1e-9)
    np.testing.assert_allclose(np.rad2deg(survey.central_meridians(series, 6)), [117.0, 123.0], atol=1e-9)
    sigma = np.ones((5, 3))
    sigma[3, 1] = np.nan
    n = survey.unusable_epochs(
        np.array([True, False, True, True, True]),
        np.array([0.1, 0.1, np.nan, 0.1, 0.1]),
        np.zeros(5),
        np.array([1.0, 1.0, 1.0, 1.0, np.inf]),
        sigma,
    )
    assert n == 4
