"""The navigation-solution writers of jaxnav.io: the .pos reads back through read_pos, the CSV carries its
units header and every column, GeoJSON and KML hold one line per track."""

import csv
import json
import math

import numpy as np
import pytest

from jaxnav import io


def _solution(M=5):
    t = 1.4e9 + np.arange(M, dtype=float)
    pos = np.stack(
        [np.radians(30.5) + 1e-7 * np.arange(M), np.radians(114.3) + 2e-7 * np.arange(M), 20.0 + 0.1 * np.arange(M)], -1
    )
    v = np.tile([1.0, 2.0, -0.1], (M, 1))
    rpy = np.tile(np.radians([1.0, -2.0, 359.0]), (M, 1))
    return io.NavSolution(
        t=t,
        pos=pos,
        v_enu=v,
        rpy=rpy,
        sig_pos_enu=np.tile([0.01, 0.02, 0.03], (M, 1)),
        sig_vel=np.tile([0.001, 0.002, 0.003], (M, 1)),
        sig_att=np.tile(np.radians([0.1, 0.2, 0.3]), (M, 1)),
        gnss_used=np.arange(M) % 2 == 0,
        quality=np.where(np.arange(M) % 2 == 0, 1, 0),
    )


def test_pos_reads_back(tmp_path):
    sol = _solution()
    p = io.write_pos(tmp_path / "a.pos", sol, comments=[("program", "test"), ("config", "x.toml")])
    assert p.read_text().startswith("% program   : test\n% config    : x.toml\n% Q ")
    r = io.read_pos(p)
    np.testing.assert_allclose(r.t, sol.t, atol=1e-3)
    np.testing.assert_allclose(r.lat, sol.pos[:, 0], atol=1e-10)
    np.testing.assert_allclose(r.h, sol.pos[:, 2], atol=1e-4)
    np.testing.assert_array_equal(r.q, sol.quality)
    np.testing.assert_allclose(r.v_enu, sol.v_enu, atol=1e-5)
    np.testing.assert_allclose(np.sqrt(np.diagonal(r.cov_enu, axis1=1, axis2=2)), sol.sig_pos_enu, atol=1e-4)


def test_trajectory_csv_columns_and_degrees(tmp_path):
    sol = _solution()
    p = io.write_trajectory_csv(tmp_path / "t.csv", sol, title="my run")
    lines = p.read_text().splitlines()
    assert lines[0].startswith("# my run; time GPST") and lines[3].startswith("# units: gpst_s [s]")
    rows = list(csv.DictReader(lines[4:]))
    assert list(rows[0]) == [n for n, _ in io.TRAJECTORY_COLUMNS] and len(rows) == 5
    assert float(rows[0]["heading_deg"]) == pytest.approx(359.0) and float(rows[0]["roll_deg"]) == pytest.approx(1.0)
    assert float(rows[0]["sigma_heading_deg"]) == pytest.approx(0.3) and rows[1]["gnss_used"] == "0"
    assert rows[0]["gpst_iso"] == io.gpst_iso(sol.t[0]) and len(rows[0]["gpst_iso"]) == 23


def test_shapes_checked(tmp_path):
    with pytest.raises(ValueError, match=r"rpy has shape \(4, 3\), expected \(5, 3\)"):
        io.write_pos(tmp_path / "b.pos", _solution()._replace(rpy=np.zeros((4, 3))))


def test_geojson_and_kml_tracks(tmp_path):
    sol = _solution()
    tracks = [
        io.Track("a", sol.pos, color="ff0000ff", width=2, clamp_to_ground=True),
        io.Track("b", sol.pos[:2], {"gpst_start_s": 1.0}),
    ]
    g = json.loads(io.write_geojson(tmp_path / "t.geojson", tracks).read_text())
    assert [f["properties"] for f in g["features"]] == [{"name": "a"}, {"name": "b", "gpst_start_s": 1.0}]
    lon, lat, h = g["features"][0]["geometry"]["coordinates"][0]
    assert (lon, lat) == pytest.approx((114.3, 30.5)) and h == pytest.approx(20.0)
    k = io.write_kml(tmp_path / "t.kml", tracks, name="doc").read_text()
    assert k.count("<LineString") == 2 and "clampToGround" in k and "<name>doc</name>" in k
    assert math.isclose(float(k.split("<coordinates>")[1].split(",")[0]), 114.3)
