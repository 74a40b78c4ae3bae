"""S1 monitoring: network model, statistics, subsidence simulator, the S1 criterion, daily velocities, CLI."""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _paths import DATA_ROOT

from jaxnav import filters as jf
from jaxnav import io, sim
from jaxnav import monitoring as mon
from jaxnav.experiments import s1 as ex
from jaxnav.units import MM_PER_YEAR

DATA = DATA_ROOT / "gnss_daily_timeseries"


def test_network_model_is_block_diagonal_and_separable():
    """A 2-station network run equals two single-station runs (S1: stations stacked block-diagonally)."""
    S, T = 2, 120
    sig = jnp.array([2e-3, 2e-3, 4e-3])
    net = mon.network_model(S, 1.0, sigma=sig, accel_var=jnp.array([[1e-8] * 3, [4e-8] * 3]))
    one = jf.constant_velocity(1.0, sigma=sig, accel_var=1e-8)
    np.testing.assert_array_equal(net.F[:6, :6], one.F)
    np.testing.assert_array_equal(net.F[:6, 6:], 0.0)
    assert net.H.shape == (6, 12) and net.G.shape == (12, 6)
    zs = jax.random.normal(jax.random.PRNGKey(0), (T, 6)) * 3e-3 + jnp.arange(T)[:, None] * 1e-4
    zs = zs.at[10, 4].set(jnp.nan)
    x0, P0 = mon.initial_state(zs[0], sigma_pos=jnp.tile(sig, S), sigma_vel=1e-3)
    both = mon.forecast(net, x0, P0, zs)
    for s, q in ((0, 1e-8), (1, 4e-8)):
        m1 = jf.constant_velocity(1.0, sigma=sig, accel_var=q)
        x1, P1 = mon.initial_state(zs[0, 3 * s : 3 * s + 3], sigma_pos=sig, sigma_vel=1e-3)
        f1 = mon.forecast(m1, x1, P1, zs[:, 3 * s : 3 * s + 3])
        np.testing.assert_allclose(both.forecast[:, s], f1.forecast[:, 0], rtol=0, atol=1e-13)
        np.testing.assert_allclose(both.velocity_sigma[:, s], f1.velocity_sigma[:, 0], rtol=1e-10)
    assert np.isnan(both.deviation[10, 1, 1]) and np.isfinite(both.deviation[11]).all()
    with pytest.raises(ValueError, match=r"sigma has shape \(2,\)"):
        mon.network_model(2, 1.0, sigma=jnp.ones(2), accel_var=1.0)
    with pytest.raises(ValueError, match=r"zs has shape \(120, 5\)"):
        mon.forecast(net, x0, P0, zs[:, :5])


def test_period_statistics_against_numpy():
    rng = np.random.default_rng(1)
    dev = rng.normal(size=(250, 2, 3)) * 1e-3
    dev[7, 1, 2] = np.nan
    st = mon.period_statistics(dev, 100, thresholds=(0.5e-3, 0.4e-3, 1e-3))
    assert st.max_abs.shape == (2, 2, 3)
    for p in range(2):
        d = dev[100 * p : 100 * (p + 1)]
        a = np.abs(d)
        np.testing.assert_allclose(st.max_abs[p], np.nanmax(a, axis=0))
        np.testing.assert_allclose(st.mean_abs[p], np.nanmean(a, axis=0))
        under = np.where(np.isnan(a), np.nan, a < [0.5e-3, 0.4e-3, 1e-3])
        np.testing.assert_allclose(st.share_under[p], np.nanmean(under, axis=0))
        np.testing.assert_allclose(st.m_P[p], np.sqrt(np.mean(d[..., 0] ** 2 + d[..., 1] ** 2, axis=0)))  # S1 eq. (20)
        np.testing.assert_allclose(st.m_H[p], np.sqrt(np.nanmean(d[..., 2] ** 2, axis=0)))
    ip = mon.internal_precision(dev, 100)
    np.testing.assert_allclose(ip.sigma[1], np.std(dev[100:200], axis=0, ddof=1))  # S1 eqs. (21)-(22)
    np.testing.assert_allclose(ip.plane[1], np.hypot(*np.std(dev[100:200, :, :2], axis=0, ddof=1).T))
    np.testing.assert_allclose(mon.improvement(5.0, 4.0), 20.0)
    with pytest.raises(ValueError, match="shorter than one period"):
        mon.period_statistics(dev, 300)


def test_subsidence_simulator():
    cfg = sim.subsidence_config(3, w_max=0.05, time_constant=200.0, onset=100.0)
    assert cfg.w_max.shape == (3,) and cfg.horizontal.shape == (3, 2)
    t = jnp.arange(0.0, 1000.0)
    W, dW = sim.knothe(t, 0.05, 1 / 200.0, 100.0)
    np.testing.assert_allclose(W[600], 0.05 * (1 - np.exp(-2.5)), rtol=1e-12)
    np.testing.assert_allclose(dW[300], (W[301] - W[299]) / 2, rtol=1e-4)  # velocity = dW/dt
    assert W[100] == 0 and dW[100] == 0
    # noise: variance and correlation of white + station Gauss-Markov + common Gauss-Markov
    cfg = sim.subsidence_config(
        2,
        w_max=0.0,
        sigma_white=(1e-3,) * 3,
        sigma_corr=(2e-3,) * 3,
        tau_corr=50.0,
        sigma_common=(1e-3,) * 3,
        tau_common=500.0,
    )
    draw = jax.jit(jax.vmap(lambda k: sim.simulate_subsidence(k, cfg, 3000).noise))
    out = draw(jax.random.split(jax.random.PRNGKey(2), 12))
    n = np.asarray(out).reshape(12, 3000, 6)
    var = np.mean(n**2)
    np.testing.assert_allclose(var, 1e-6 + 4e-6 + 1e-6, rtol=0.1)
    lag = 50
    c = np.mean(n[:, lag:] * n[:, :-lag])
    np.testing.assert_allclose(c, 4e-6 * np.exp(-1) + 1e-6 * np.exp(-0.1), rtol=0.2)
    # the common mode correlates the stations
    cross = np.mean(n[:, :, :3] * n[:, :, 3:])
    np.testing.assert_allclose(cross, 1e-6, rtol=0.35)


@pytest.fixture(scope="module")
def s1_small():
    st = ex.S1Settings(n_periods=2, period=900, onset=(0.2, 0.5))
    return ex.run_s1_simulation(jax.random.PRNGKey(7), st, chunk=2, keep_series=0)


def test_s1_adaptive_beats_standard_under_mismatched_dynamics(s1_small):
    """Variance compensation: forecast RMS against the truth at least 1.5x better (S1 claims ~2x)."""
    r = s1_small
    std, ad = np.mean(r["forecast_rms"]["standard"]), np.mean(r["forecast_rms"]["adaptive"])
    assert std / ad >= 1.5, (std, ad)
    assert np.mean(r["episode_rms"]["standard"]) / np.mean(r["episode_rms"]["adaptive"]) >= 3.0
    assert r["status"]["standard"] == 0 and r["status"]["adaptive"] & ~8 == 0
    t = ex.s1_tables(r)
    assert t["forecast_ratio"]["height"] > 1.5
    for ax in "XYH":
        mx_s, mean_s, sh_s = t["table3_5"][ax]["standard"]
        mx_a, mean_a, sh_a = t["table3_5"][ax]["adaptive"]
        assert 0 <= sh_s <= 100 and mean_a <= mx_a
    text = ex.format_s1_tables(t)
    assert "Tables 3-5" in text and "Table 6" in text and "published" in text


def test_daily_velocity_bjfs_against_published_slopes():
    """Zero-PSD constant-velocity filter = weighted LS slope; BJFS agrees with SIO's published slopes."""
    b = mon.station_velocity(io.read_daily(DATA / "bjfsCleanUnf.neu"), psd_grid=None)
    np.testing.assert_allclose(b.velocity, b.ls_velocity, rtol=1e-7, atol=1e-6 * MM_PER_YEAR)
    assert np.all(b.sigma > 0) and np.all(b.sigma_ar1 >= b.sigma)
    # SIO's fitted slopes also carry annual terms; agreement within 2 published sigmas + 0.1 mm/yr
    assert np.all(np.abs(b.velocity - b.reference_velocity) < 2 * b.reference_sigma + 0.1 * MM_PER_YEAR)


def test_cli_monitor_files(tmp_path):
    """jaxnav monitor FILE --out DIR --s1: labelled velocities with coloured-noise sigmas (near SIO's
    published slopes), noise, seasonal terms, outliers, the station figure; and S1's adaptive-filter
    results (filter = weighted LS = SIO's slopes, forecast statistics) under s1_adaptive_filter."""
    from jaxnav.cli import main

    argv = ["monitor", str(DATA / "bjfsCleanUnf.neu"), "--out", str(tmp_path), "--s1"]
    assert main(argv) == 0
    from _outputs import check_provenance

    assert "BJFS_fit.png" in check_provenance(tmp_path, argv, json_name="monitor.json")["files"]
    res = json.loads((tmp_path / "monitor.json").read_text())
    st = res["stations"]["BJFS"]
    v, sd = st["velocity_mm_per_yr"], st["velocity_sigma_mm_per_yr"]
    assert set(v) == set(sd) == {"east", "north", "up"}
    pub = [-10.5, 30.4, 2.4]  # SIO's header slopes n, e, u (mm/yr)
    for comp, p in zip(("north", "east", "up"), pub):
        assert abs(v[comp] - p) < 2.0 * sd[comp] + 0.2, (comp, v[comp], p)
        assert sd[comp] > 4.0 * st["velocity_sigma_white_noise_only_mm_per_yr"][comp]
        n = st["noise"][comp]
        assert n["spectral_index"] == -1.0 and n["white_mm"] > 0 and n["powerlaw_amplitude"] > 0
        assert n["powerlaw_amplitude_unit"] == "mm/yr^0.250" and "white_mm" in n["bounds"]
        assert st["seasonal"][comp]["annual_amplitude_mm"] >= 0
    assert st["seasonal"]["up"]["annual_amplitude_mm"] > 5.0  # BJFS's large annual height cycle
    assert st["outliers"]["count"] == len(st["outliers"]["list"]) == sum(st["outliers"]["by_reason"].values())
    assert (tmp_path / "BJFS_fit.png").stat().st_size > 10_000
    s1 = st["s1_adaptive_filter"]
    enu = ("east", "north", "up")  # labelled components, no bare triplets (issue 21)
    assert all(set(s1[k]) == set(enu) for k in ("velocity_mm_per_yr", "ls_slope_mm_per_yr", "published_mm_per_yr"))
    vel, ls, pub = (
        [s1[k][c] for c in enu] for k in ("velocity_mm_per_yr", "ls_slope_mm_per_yr", "published_mm_per_yr")
    )
    np.testing.assert_allclose(vel, ls, rtol=1e-6)
    np.testing.assert_allclose(vel, pub, atol=0.25)
    assert s1["random_walk_psd_m2_per_s3"]["east"] > mon.PSD_GRID[0]  # the ML random walk is not the smallest
    assert set(s1["forecast_statistics"]) == {"standard", "adaptive"}
    assert len(s1["forecast_statistics"]["adaptive"]["m_P_mm"]) == len(np.arange(s1["epochs"] - 1)) // 365
    assert (tmp_path / "s1/velocity_BJFS.png").stat().st_size > 10_000
    assert main(["monitor", "--out", str(tmp_path)]) == 2  # no files, no --simulate: one-line usage error


def test_weighted_slope_mrhk_subsides():
    """MRHK (Houston) subsides about 17 mm/yr (data README: ~12.7 cm in ~7 years)."""
    s = io.read_daily(DATA / "MRHK_GOM20_neu_cm.col")
    v, sd = mon.weighted_slope(s.t, s.enu, np.sqrt(np.diagonal(s.cov, axis1=1, axis2=2)))
    assert -18.5 < v[2] / MM_PER_YEAR < -16.0 and np.all(sd > 0)
