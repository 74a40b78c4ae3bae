"""Network products of jaxnav monitor: the velocity table, the velocity map, further periodic terms."""

import csv

import numpy as np
import pytest

from jaxnav import monitoring as mon
from jaxnav.units import DAY, MM, YEAR


def _record(v, lat):
    enu = ("east", "north", "up")
    return dict(
        velocity_mm_per_yr=dict(zip(enu, v)),
        velocity_sigma_mm_per_yr=dict(zip(enu, (0.5, 0.6, 1.5))),
        midas_velocity_mm_per_yr=dict(zip(enu, v)),
        midas_velocity_sigma_mm_per_yr=dict(zip(enu, (0.3,) * 3)),
        latitude_deg=lat,
        longitude_deg=None if lat is None else 91.1,
        first_day="2000-01-01",
        last_day="2009-12-31",
        span_years=10.0,
        steps=[{}],
        model='white + power-law, "REML"',
        file="/x/a.tenv3",
    )


def test_velocity_table_has_units_header_and_one_row_per_station(tmp_path):
    """velocities.csv: '#' lines naming units and frame, then a header row and one row per station; a station
    without coordinates has empty latitude/longitude cells."""
    from jaxnav.io import write_velocity_table

    recs = {"AAAA": _record((45.4, 16.3, 0.2), 29.65), "BBBB": _record((-1.0, 1.2, -17.1), None)}
    p = write_velocity_table(tmp_path / "velocities.csv", recs, command="jaxnav m")
    text = p.read_text().splitlines()
    head = [ln for ln in text if ln.startswith("#")]
    assert any("mm/yr" in ln for ln in head) and any("reference frame" in ln for ln in head)
    rows = list(csv.DictReader(ln for ln in text if not ln.startswith("#")))
    assert [r["station"] for r in rows] == ["AAAA", "BBBB"]
    assert float(rows[0]["ve_mm_per_yr"]) == 45.4 and float(rows[0]["latitude_deg"]) == 29.65
    assert rows[1]["latitude_deg"] == "" and rows[1]["steps"] == "1" and "REML" in rows[1]["noise_model"]


def test_velocity_map_draws_stations_with_coordinates(tmp_path):
    from jaxnav.plot import plot_velocity_map

    fig = plot_velocity_map(
        [
            dict(name="A", lat_deg=29.7, lon_deg=91.1, ve=45.0, vn=16.0, se=1.3, sn=1.0),
            dict(name="B", lat_deg=39.6, lon_deg=115.9, ve=30.0, vn=-10.0, se=0.3, sn=0.7, corr_en=0.4),
            dict(name="C", lat_deg=float("nan"), lon_deg=0.0, ve=1.0, vn=1.0, se=1.0, sn=1.0),
        ],
        tmp_path / "map.png",
    )
    names = {t.get_text() for t in fig.axes[0].texts}
    assert {"A", "B"} <= names and "C" not in names and any("mm/yr" in n for n in names)
    assert (tmp_path / "map.png").stat().st_size > 10_000


def test_extra_period_columns_recover_a_draconitic_term():
    """design_matrix(periods_days=(351.6,)): cos/sin columns that recover a 3 mm draconitic term by least squares
    beside the annual ones (6 years, noise-free)."""
    t = 10 * YEAR + np.arange(2192) * DAY
    D = mon.design_matrix(t, periods_days=(351.6,))
    assert D.names[6:8] == ("period_351.6d_cos", "period_351.6d_sin")
    y = 3 * MM * np.cos(2 * np.pi * t / (351.6 * DAY) - 0.7) + 2 * MM * np.cos(2 * np.pi * t / YEAR)
    b = np.linalg.lstsq(D.A, y, rcond=None)[0]
    assert abs(np.hypot(b[6], b[7]) - 3 * MM) < 1e-9 and abs(np.arctan2(b[7], b[6]) - 0.7) < 1e-6
    with pytest.raises(ValueError, match="periods_days"):
        mon.design_matrix(t, periods_days=(0.0,))
