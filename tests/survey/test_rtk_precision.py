"""Issue 19 (RTK half): static/moving segmentation and the precision of point means with
time-correlated epochs, checked on the real static .pos files of ../shared/data."""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _paths import DATA_ROOT

from jaxnav import geodesy as g
from jaxnav.io import read_pos
from jaxnav.survey import (
    autocovariance,
    autocovariance_masked,
    mean_variance_from_acov,
    motion_segments,
    pack_points,
    point_sigmas,
    windows_from_pos,
)

NAGOYA = DATA_ROOT / "rtk_pos_matrtklib" / "static" / "rover_rtk.pos"
DRIVE = DATA_ROOT / "rtk_pos_matrtklib" / "kinematic" / "rover_1Hz_rtk.pos"
SPIRENT = DATA_ROOT / "rtk_pos_instinct_simulated" / "Rover-static-2km-east_RTK_GPS-GAL_Forward_Continuous.pos"


def test_autocovariance_masked_equals_direct_sums():
    x = np.asarray(jax.random.normal(jax.random.PRNGKey(1), (50,)))
    full = np.ones(50, bool)
    np.testing.assert_allclose(
        autocovariance_masked(jnp.asarray(x), jnp.asarray(full), 5),
        autocovariance(jnp.asarray(x), 5),
        rtol=1e-12,
        atol=1e-14,
    )
    m = full.copy()
    m[[3, 4, 17, 40]] = False
    d = np.where(m, x - x[m].mean(), 0.0)
    ref = [np.sum(d[: 50 - k] * d[k:]) / m.sum() for k in range(6)]
    np.testing.assert_allclose(autocovariance_masked(jnp.asarray(x), jnp.asarray(m), 5), ref, rtol=1e-12, atol=1e-14)
    with pytest.raises(ValueError, match="max_lag=60"):
        autocovariance_masked(jnp.asarray(x), jnp.asarray(m), 60)


def test_mean_variance_of_ar1_equals_closed_form():
    """AR(1), gamma_k = phi^k / (1 - phi^2): Var(mean of n) = gamma_0/n [1 + 2 sum (1 - k/n) phi^k]."""
    phi, n = 0.9, 40
    gam = phi ** np.arange(n) / (1 - phi**2)
    k = np.arange(1, n)
    closed = gam[0] / n * (1 + 2 * np.sum((1 - k / n) * phi**k))
    v = mean_variance_from_acov(jnp.asarray(gam), jnp.arange(n), jnp.full(n, 1.0 / n))
    assert abs(float(v) / closed - 1) < 1e-12
    # a gap: the weights of absent samples are 0 and the lags are the grid indices
    idx = np.r_[0:10, 15:40]
    C = gam[np.abs(idx[:, None] - idx[None, :])]
    v2 = mean_variance_from_acov(jnp.asarray(gam), jnp.asarray(idx), jnp.full(idx.size, 1.0 / idx.size))
    assert abs(float(v2) - C.mean()) < 1e-12


def test_motion_segments_static_then_driving_on_real_files():
    """The real static rooftop file followed by the real car drive (shifted in time to follow it):
    the drive is excluded, the static half is one segment."""
    st, dr = read_pos(NAGOYA), read_pos(DRIVE)
    t = np.r_[st.t, dr.t - dr.t[0] + st.t[-1] + 1.0]
    lat, lon = np.r_[st.lat, dr.lat], np.r_[st.lon, dr.lon]
    seg = motion_segments(t, lat, lon)
    ns = st.t.size
    # the displacement test also flags the static epochs within window_s/2 = 5 s of the departure
    assert np.all(seg.segment[: ns - 5] == 0) and not seg.moving[: ns - 5].any() and seg.moving[ns - 5 : ns + 1].all()
    # the drive: every epoch but those of genuine stops is moving; what stays static is a stop of >= 20 s
    v_drive = seg.speed[ns + 1 :]
    assert seg.moving[ns:].mean() > 0.8 and np.nanmedian(v_drive) > 1.0
    for s in range(1, seg.n_segments):
        idx = np.flatnonzero(seg.segment == s)
        assert idx.min() >= ns and t[idx[-1]] - t[idx[0]] >= 20.0
        assert np.ptp(lat[idx]) * 6.371e6 < 0.2
    # a creeping antenna (2 cm/s, under the speed threshold) fails the displacement test
    tt = np.arange(200.0)
    creep = np.where(tt > 100, (tt - 100) * 0.02, 0.0) / 6.371e6
    sc = motion_segments(tt, np.radians(35.0) + creep, np.full(200, np.radians(137.0)))
    assert not sc.moving[:90].any() and sc.moving[110:].all()
    with pytest.raises(ValueError, match="one shape"):
        motion_segments(tt, tt[:-1], tt)


def _points(path, step, window, min_epochs, lon0):
    """Windows of a static file -> (names, GK epochs (P, T, 3), mask, grid, segment labels)."""
    w = windows_from_pos(read_pos(path), step=step, window=window, min_epochs=min_epochs)
    names, ser = pack_points(w["point"], w["t"], w["lat"], w["lon"], w["H"], w["sigma"], mask=w["mask"])
    x, y = g.gauss_kruger(ser.lat, ser.lon, lon0=lon0)
    z = np.stack([np.asarray(x), np.asarray(y), np.asarray(ser.H)], -1)
    grid = np.zeros(ser.mask.shape, np.int64)
    seg = []
    for i, n in enumerate(names):
        gi = w["grid"][w["point"] == n]
        grid[i, : gi.size], grid[i, gi.size :] = gi, gi[-1]
        seg.append(w["segment"][w["point"] == n][0])
    return names, z, np.asarray(ser.mask), grid, np.array(seg)


def _claimed_vs_actual(z, mask, sig):
    """Per component: actual scatter of the point means (ddof 1) and the rms claimed sigma, m."""
    means = np.array([z[p][mask[p]].mean(0) for p in range(z.shape[0])])
    return means.std(0, ddof=1), np.sqrt(np.mean(sig**2, axis=0))


@pytest.mark.parametrize("window,lo,hi", [(60, 1 / 1.5, 1.5), (15, 1 / 1.5, 1.5)])
def test_claimed_precision_matches_scatter_on_real_static_point(window, lo, hi):
    """The real Nagoya rooftop file (5 min, 1 Hz, all fixed), epochs at 2 s (S2): 2-minute points
    (60 epochs; 3 points: 60, 60, 31 epochs) and 30-s points (10 points). The claimed precision
    (acf_ess_segment) agrees with the actual scatter of the point means within a factor 1.5
    (2-minute points: pooled over the components, there being 2 degrees of freedom a component;
    30-s points: every component); the independent-epoch sigma is 2-5x optimistic."""
    names, z, mask, grid, seg = _points(NAGOYA, 2.0, window, window // 2, np.radians(138.0))
    ps = point_sigmas(z, mask, grid, seg)
    assert ps.method == "acf_ess_segment" and set(ps.segment_points) == {len(names)}
    actual, claimed = _claimed_vs_actual(z, mask, ps.sigma)
    _, naive = _claimed_vs_actual(z, mask, ps.sigma_naive)
    pooled = float(np.sqrt(np.mean((actual / claimed) ** 2)))
    print(
        f"\n{len(names)} points of {window} epochs: actual {actual * 1e3} mm, claimed {claimed * 1e3} mm, "
        f"naive {naive * 1e3} mm; pooled actual/claimed {pooled:.2f}"
    )
    assert lo < pooled < hi
    if window == 15:
        assert np.all((actual / claimed > lo) & (actual / claimed < hi))
    assert float(np.sqrt(np.mean((actual / naive) ** 2))) > 2.5
    assert np.all(ps.sigma >= ps.sigma_naive * 0.8)  # the floor is the segment's gamma(0)/n


def test_claimed_precision_on_spirent_static_point():
    """The Spirent-simulated static rover (10 min, 20 float epochs masked in the first point):
    four 2-minute points; pooled actual/claimed within 1.5."""
    names, z, mask, grid, seg = _points(SPIRENT, 2.0, 60, 30, np.radians(9.0))
    ps = point_sigmas(z, mask, grid, seg)
    actual, claimed = _claimed_vs_actual(z, mask, ps.sigma)
    pooled = float(np.sqrt(np.mean((actual / claimed) ** 2)))
    assert len(names) == 5 and 1 / 1.5 < pooled < 1.5


def _static_then_drive(path):
    """A .pos file: the real static rooftop records, then the real car drive's records moved in time
    to start 2 s after them (a static half and a driving half, as a user's u-blox file)."""
    import datetime as dt

    st = NAGOYA.read_text().splitlines()
    drive = [ln for ln in DRIVE.read_text().splitlines() if ln.strip() and not ln.startswith("%")]
    last = dt.datetime.strptime(" ".join(st[-1].split()[:2]), "%Y/%m/%d %H:%M:%S.%f")
    t0 = dt.datetime.strptime(" ".join(drive[0].split()[:2]), "%Y/%m/%d %H:%M:%S.%f")
    out = list(st)
    for ln in drive:
        w = ln.split()
        t = dt.datetime.strptime(f"{w[0]} {w[1]}", "%Y/%m/%d %H:%M:%S.%f") - t0 + last + dt.timedelta(seconds=2)
        out.append(t.strftime("%Y/%m/%d %H:%M:%S.%f")[:-3] + "   " + "   ".join(w[2:]))
    path.write_text("\n".join(out) + "\n")
    return path


def test_cli_excludes_the_driving_half(tmp_path, capsys):
    """``jaxnav rtk`` on a static half + driving half: points only where the antenna stood, the
    moving epochs counted in the JSON and said in the summary line."""
    from jaxnav.cli import main

    f = _static_then_drive(tmp_path / "static_then_drive.pos")
    assert main(["rtk", str(f), "--out", str(tmp_path / "o")]) == 0
    text = capsys.readouterr().out
    s = json.loads((tmp_path / "o" / "rtk_results.json").read_text())
    # the static half: 297 of 301 epochs pass (the last ones are within 5 s of the departure) -> 149 at 2 s
    # -> 60, 60 (+29 < 30)
    assert s["n_points"] == 2 and [p["name"] for p in s["points"]] == [f"static_then_drive#{k}" for k in (1, 2)]
    assert 500 < s["excluded_moving_epochs"] < 531 and s["motion_test"]["files"][0]["n_epochs"] == 832
    moving, short = s["excluded_moving_epochs"], s["excluded_short_static_epochs"]
    # worded so that it cannot read as "everything excluded", and the points' coordinates printed
    assert f"{832 - moving - short} of 832 epochs kept as static" in text and f"left out: {moving} moving" in text
    assert "EXCLUDED" not in text
    for p in s["points"]:
        assert f"{p['name']}: x {p['x_m']:.4f} m, y {p['y_m']:.4f} m, h {p['h_m']:.4f} m" in text
    assert all(p["t_end"] <= "2024-06-24T08:25:00.000" for p in s["points"])
    # without the test, 4 of 7 points are formed while driving (a user's "17 of 38")
    w = windows_from_pos(read_pos(f), motion=None, fixed_only=False)
    assert len(set(w["point"])) == 7 and w["n_moving"] == 0


def test_cli_on_a_drive_only_file_says_why_nothing_is_left(tmp_path, capsys):
    from jaxnav.cli import main

    assert main(["rtk", str(DRIVE), "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    # the stage line of the reading, then the one-line error (-q: the error alone)
    assert err[0].startswith("reading 1 file(s)") and len(err) == 2
    assert "no window of 30 epochs" in err[1] and "506 moving" in err[1]


def test_sampling_grid_given_and_derived():
    """Given epoch indices are kept (padded with the last); -1 ones are derived from the median time step."""
    from jaxnav.survey import sampling_grid

    t = np.array([[0.0, 1.0, 2.0, 0.0], [10.0, 12.0, 16.0, 18.0]])
    mask = np.array([[True, True, True, False], [True, True, True, True]])
    point = np.array(["a", "a", "a", "b", "b", "b", "b"])
    grid = np.array([5, 6, 8, -1, -1, -1, -1])
    got = sampling_grid(t, mask, ["a", "b"], point, grid)
    np.testing.assert_array_equal(got, [[5, 6, 8, 8], [0, 1, 3, 4]])
