"""Station velocities with coloured noise (issue 19): power-law covariance as a Gauss-Markov sum,
whitening = jaxnav's Kalman filter, rates and sigmas beside Hector on a real series, coverage of the
95 % rate interval on simulated power-law series, the PBO .pos reader, outlier screening."""

import datetime as dt

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _paths import DATA_ROOT
from reference.hector_run import hector_available, hector_covariance_row, run_hector

from jaxnav import filters as jf
from jaxnav import io
from jaxnav import monitoring as mon
from jaxnav.monitoring._trajectory import _whitened
from jaxnav.units import DAY, MM, MM_PER_YEAR, YEAR

DATA = DATA_ROOT / "gnss_daily_timeseries"


def test_ggm_autocovariance_equals_hectors_and_the_gauss_markov_sum_approximates_it():
    """gamma(k) of the flicker GGM (1-phi = 6.9e-6) against Hector's own first covariance row, and
    the sum of 8 first-order Gauss-Markov processes within 0.3 % of it over 10 years of lags."""
    g = mon.ggm_autocovariance(0.5)
    if hector_available():
        h = hector_covariance_row(4000, 0.5, 6.9e-6)
        np.testing.assert_allclose(g[:4000], h, rtol=1e-6)
    gm = mon.gauss_markov_sum(0.5, 3653)
    k = np.arange(3653)
    approx = (gm.r[None, :] ** k[:, None]) @ gm.w
    assert len(gm.r) <= 9 and np.all(gm.w > 0)
    assert np.max(np.abs(approx / g[:3653] - 1.0)) == pytest.approx(gm.max_rel_error) and gm.max_rel_error < 3e-3


def test_whitening_is_jaxnavs_kalman_filter_with_gaps():
    """The specialised whitening scan equals jaxnav.filters.kalman_filter on the same state-space
    model: innovations / sqrt(S) and sum ln S, with missing days masked."""
    T = 300
    spec = mon.noise_spec(T)
    theta = jnp.array([np.log(2e-3), np.log(1e-3), np.log(1e-4), -1.0])
    y = jax.random.normal(jax.random.PRNGKey(1), (T,)) * 3e-3
    valid = jax.random.uniform(jax.random.PRNGKey(2), (T,)) > 0.2
    A = jnp.asarray(mon.design_matrix(np.arange(T) * DAY).A)
    yt, At, lds = _whitened(
        theta, y, valid, A, jnp.asarray(spec.r), jnp.asarray(spec.W), jnp.asarray(spec.d_grid), False, True
    )
    model, P0 = mon.noise_state_space(theta, jnp.asarray(spec.r), jnp.asarray(spec.W), jnp.asarray(spec.d_grid))
    x0 = jnp.zeros(P0.shape[0])
    for col, ref in ((y, yt), (A[:, 1], At[:, 1])):
        r = jf.kalman_filter(model, x0, P0, jnp.where(valid, col, jnp.nan)[:, None])
        S = r.innov_covs[:, 0, 0]
        np.testing.assert_allclose(jnp.where(valid, r.innovations[:, 0] / jnp.sqrt(S), 0.0), ref, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(jnp.sum(jnp.where(valid, jnp.log(S), 0.0)), lds, rtol=1e-12)


@pytest.fixture(scope="module")
def lhas():
    """LHAS (NGL tenv3), its first 3500 days (the program compiled for BJFS's grid serves it too)."""
    s = io.read_daily(DATA / "LHAS.tenv3")
    n = int(np.searchsorted(s.t, s.t[0] + 3499.5 * DAY))
    return s._replace(t=s.t[:n], year=s.year[:n], enu=s.enu[:n], cov=s.cov[:n], llh=s.llh[:n])


@pytest.mark.skipif(not hector_available(), reason="hector-ts not installed (pip install -e '.[test]')")
def test_rates_and_sigmas_agree_with_hector_on_a_real_series(lhas):
    """White + flicker on a real NGL series (LHAS, 9.6 years, gaps): jaxnav's REML rate within
    0.1 mm/yr and its sigma within 20 % of Hector's on the same cleaned days and model (measured:
    within 0.005 mm/yr and 1 %), and the coloured-noise sigma is many times the white-noise one."""
    fit = mon.fit_station(lhas, random_walk=False)
    g = fit.grid
    assert fit.warnings == [] and np.all(fit.noise.grad_norm < 1e-3)
    for c in (0, 2):  # east and up (the noisiest)
        v = g.valid[:, c]
        h = run_hector(g.t[v], g.y[v, c])
        rate, sd = fit.velocity[c] / MM_PER_YEAR, fit.velocity_sigma[c] / MM_PER_YEAR
        assert abs(rate - h["trend"]) < 0.1, (c, rate, h["trend"])
        assert abs(sd / h["trend_sigma"] - 1.0) < 0.2, (c, sd, h["trend_sigma"])
        assert abs(fit.white_sigma[c] / MM / h["NoiseModel"]["White"]["sigma"] - 1.0) < 0.1
        amp = fit.powerlaw_amplitude[c] * YEAR**0.25 / MM
        assert abs(amp / h["NoiseModel"]["FlickerGGM"]["sigma"] - 1.0) < 0.1
        assert sd > 5.0 * fit.velocity_sigma_white[c] / MM_PER_YEAR


def test_95_percent_rate_interval_covers_the_truth_in_simulated_flicker_series():
    """40 simulated 3-year series (white 2 mm + flicker 6 mm/yr^0.25, 10 % missing days, known rate):
    the rate errors over their coloured-noise sigmas have a spread near 1 (0.7 .. 1.4) and the 95 %
    interval covers the truth in >= 34 of 40 (a binomial 95 % leaves fewer than 34 with probability
    2e-3); the white-noise sigmas are too small by far (spread > 3). The 500-series version is
    benchmarks/bench_monitoring.py."""
    B, n = 40, 1096
    rate = 3.0 * MM_PER_YEAR
    keys = jax.random.split(jax.random.PRNGKey(19), B)
    sim = jax.vmap(
        lambda k: mon.simulate_powerlaw_series(
            k, n, rate=rate, sigma_white=2 * MM, amplitude=6 * MM / YEAR**0.25, kappa=-1.0, gap_fraction=0.1
        )
    )
    y, t = sim(keys)
    y = np.asarray(y)
    valid = np.isfinite(y)
    D = mon.design_matrix(np.asarray(t[0]))
    spec = mon.noise_spec(n)
    fit = mon.fit_series_batch(np.nan_to_num(y), valid, D.A, spec, np.full(B, 4 * MM), random_walk=False)
    est = np.asarray(fit.beta[:, 1]) / YEAR
    sd = np.sqrt(np.asarray(fit.beta_cov[:, 1, 1])) / YEAR
    z = (est - rate) / sd
    assert 0.7 < np.std(z) < 1.4, np.std(z)
    assert np.sum(np.abs(z) <= 1.96) >= 34, np.sum(np.abs(z) <= 1.96)
    sd_white = (
        np.array(
            [
                np.sqrt(
                    np.linalg.lstsq(D.A[v], y[i, v], rcond=None)[1][0]
                    / (v.sum() - 6)
                    * np.linalg.inv(D.A[v].T @ D.A[v])[1, 1]
                )
                for i, v in enumerate(valid)
            ]
        )
        / YEAR
    )
    assert np.std((est - rate) / sd_white) > 3.0


def _pbo_text(s, station="LHAS"):
    """A PBO .pos (format 1.1) with the local offsets of a DailySeries (header as documented by GAGE)."""
    head = [
        "PBO Station Position Time Series. Reference Frame : IGS14",
        "Format Version: 1.1.0",
        f"4-character ID: {station}",
        "Station name : test",
        "Start Field Description",
        "dN Difference in North component from NEU reference position, meters",
        "End Field Description",
        "*YYYYMMDD HHMMSS JJJJJ.JJJJ X Y Z Sx Sy Sz Rxy Rxz Ryz NLat Elong Height dN dE dU Sn Se Su Rne Rnu Reu Soln",
    ]
    rows = []
    for i in range(len(s.t)):
        mjd = s.t[i] / 86400.0 + 51544.5
        d = dt.datetime(2000, 1, 1, 12) + dt.timedelta(seconds=float(s.t[i]))
        c = s.cov[i]
        sg = np.sqrt(np.diag(c))
        e, n_, u = s.enu[i]
        rows.append(
            f" {d:%Y%m%d} {d:%H%M%S} {mjd:.4f} -1.0e6 5.0e6 3.0e6 0.002 0.003 0.004 0.1 -0.2 0.3 "
            f"29.657 91.104 3624.7 {n_:.5f} {e:.5f} {u:.5f} {sg[1]:.5f} {sg[0]:.5f} {sg[2]:.5f} "
            f"{c[0, 1] / sg[0] / sg[1]:.3f} {c[1, 2] / sg[1] / sg[2]:.3f} {c[0, 2] / sg[0] / sg[2]:.3f} final"
        )
    return "\n".join(head + rows) + "\n"


def test_pbo_pos_reader_keeps_enu_full_covariance_and_ecef(tmp_path, lhas):
    """A PBO .pos written from LHAS's values reads back as the same ENU series (fields reordered from
    dN dE dU, correlations Rne Rnu Reu), with the ECEF covariance kept; an RTKLIB .pos is refused."""
    s = lhas._replace(t=lhas.t[:50], year=lhas.year[:50], enu=lhas.enu[:50], cov=lhas.cov[:50])
    f = tmp_path / "LHAS.pos"
    f.write_text(_pbo_text(s))
    r = io.read_daily(f)
    assert r.fmt == "pbo" and r.station == "LHAS" and r.enu.shape == (50, 3)
    np.testing.assert_allclose(r.t, s.t, atol=10.0)
    np.testing.assert_allclose(r.enu, s.enu, atol=6e-6)
    sr, ss = np.sqrt(np.diagonal(r.cov, axis1=1, axis2=2)), np.sqrt(np.diagonal(s.cov, axis1=1, axis2=2))
    np.testing.assert_allclose(sr, ss, atol=6e-6)  # sigmas written with 5 decimals (m)
    np.testing.assert_allclose(
        r.cov / sr[:, :, None] / sr[:, None, :], s.cov / ss[:, :, None] / ss[:, None, :], atol=6e-4
    )  # correlations with 3
    assert r.cov_xyz.shape == (50, 3, 3) and r.cov_xyz[0, 0, 1] == pytest.approx(0.1 * 0.002 * 0.003)
    bad = tmp_path / "rover.pos"
    bad.write_text("% program   : RTKLIB\n% GPST latitude(deg)\n")
    with pytest.raises(io.ReaderError, match="rover.pos:1: not an EarthScope/PBO"):
        io.read_daily(bad)
    lines = _pbo_text(s).splitlines()
    lines[12] = lines[12].replace("final", "").rsplit(" ", 3)[0]
    f.write_text("\n".join(lines) + "\n")
    with pytest.raises(io.ReaderError, match="LHAS.pos:13: expected 25 fields"):
        io.read_daily(f)


def test_screening_lists_days_with_huge_sigmas_and_isolated_spikes(lhas):
    """Planted: 3 days with 2 m formal sigmas and 2 spikes of 60 mm (up) are rejected, counted and
    listed with their reasons; the slow flicker wander is not taken for outliers (few others)."""
    s = lhas._replace(enu=lhas.enu.copy(), cov=lhas.cov.copy())
    for i in (100, 900, 2000):
        s.cov[i] = np.diag([4.0, 4.0, 4.0])
    s.enu[1500, 2] += 0.06
    s.enu[2500, 2] -= 0.06
    scr = mon.screen_outliers(s)
    sig = {(d["index"], d["component"]) for d in scr.records if d["reason"] == "sigma"}
    res = {(d["index"], d["component"]) for d in scr.records if d["reason"] == "residual"}
    assert sig == {(i, c) for i in (100, 900, 2000) for c in mon.COMPONENTS}
    assert {(1500, "up"), (2500, "up")} <= res
    assert scr.counts["sigma"] == 9 and scr.counts["residual"] == len(res) < 0.03 * len(s.t)
    assert not scr.keep[100].any() and not scr.keep[1500, 2] and scr.keep[1500, 0]


def test_step_detection_finds_a_planted_step_and_nothing_in_pure_noise():
    """detect_steps (likelihood-ratio scan under the noise model) on a simulated 3-year flicker series:
    a planted 8 mm step (all components) is found within a week; without it nothing passes the threshold."""
    from types import SimpleNamespace

    n = 1024
    y = _station_series(7, n).enu
    t = np.arange(n) * DAY + 10 * YEAR
    spec = mon.noise_spec(n)
    A = mon.design_matrix(t).A
    theta = np.tile([np.log(2 * MM), np.log(4 * MM * DAY**0.25 / YEAR**0.25), np.log(1e-9), -1.0], (3, 1))
    fit = SimpleNamespace(theta=theta)
    for planted in (True, False):
        yy = y + (8 * MM * (np.arange(n) >= 600))[:, None] if planted else y
        grid = mon.DailyGrid(t=t, y=yy, valid=np.isfinite(yy), n_days=n, duplicates=0)
        found = mon.detect_steps(grid, A, fit, spec, random_walk=False)
        if planted:
            assert found is not None and abs(found[0] - t[600]) <= 7 * DAY, found
        else:
            assert found is None, found


def test_chunked_threaded_batch_equals_one_vmap():
    """fit_series_batch with chunk (the last chunk padded) in two host threads gives the fits of one vmap."""
    B, n = 5, 300
    keys = jax.random.split(jax.random.PRNGKey(3), B)
    sim = jax.vmap(
        lambda k: mon.simulate_powerlaw_series(
            k, n, rate=3.0 * MM_PER_YEAR, sigma_white=2 * MM, amplitude=6 * MM / YEAR**0.25, gap_fraction=0.1
        )
    )
    y, t = sim(keys)
    y = np.asarray(y)
    valid = np.isfinite(y)
    D = mon.design_matrix(np.asarray(t[0]))
    spec = mon.noise_spec(n)
    args = (np.nan_to_num(y), valid, D.A, spec, np.full(B, 4 * MM))
    one = mon.fit_series_batch(*args, random_walk=False, iterations=15)
    chunked = mon.fit_series_batch(*args, random_walk=False, iterations=15, chunk=2, workers=2)
    assert chunked.theta.shape == one.theta.shape == (B, 4)
    np.testing.assert_allclose(chunked.theta, one.theta, rtol=0, atol=1e-9)
    np.testing.assert_allclose(chunked.beta, one.beta, rtol=1e-9, atol=1e-15)
    with pytest.raises(ValueError, match="chunk must be a positive"):
        mon.fit_series_batch(*args, random_walk=False, chunk=0)


def _station_series(seed, n, step_day=None, step_mm=0.0):
    keys = jax.random.split(jax.random.PRNGKey(seed), 3)
    y = np.stack(
        [
            np.asarray(
                mon.simulate_powerlaw_series(
                    k, n, rate=2 * MM_PER_YEAR, sigma_white=2 * MM, amplitude=4 * MM / YEAR**0.25, gap_fraction=0.05
                )[0]
            )
            for k in keys
        ],
        axis=1,
    )
    if step_day is not None:
        y[step_day:] += step_mm * MM
    t = np.arange(n) * DAY + 10 * YEAR
    return io.DailySeries(
        station=f"S{seed}",
        path="simulated",
        fmt="tenv3",
        t=t,
        year=2000.0 + t / YEAR,
        enu=y,
        cov=np.tile(np.eye(3) * (2 * MM) ** 2, (n, 1, 1)),
        origin=np.zeros(3),
        llh=np.full((n, 3), np.nan),
        n_masked=int(np.isnan(y).sum()),
    )


def test_warm_started_refit_reaches_the_cold_fit_in_half_the_iterations():
    """A refit after a step is added, started from the fit without it (theta and the BFGS inverse
    Hessian, as fit_station's refits are), reaches the cold 40-iteration fit within
    refit_iterations(40) = 20 steps: ln L_R, rates and rate sigmas equal; white + flicker + random walk."""
    from jaxnav.monitoring._station import refit_iterations
    from jaxnav.monitoring._trajectory import robust_scale

    n, day = 900, 500
    ser = _station_series(11, n, step_day=day, step_mm=12.0)
    grid = mon.daily_grid(ser, np.isfinite(ser.enu))
    spec = mon.noise_spec(grid.n_days)
    A0 = mon.design_matrix(grid.t).A
    A1 = mon.design_matrix(grid.t, steps=[float(grid.t[day])]).A

    def scale(A):
        out = []
        for c in range(3):
            k = grid.valid[:, c]
            b = np.linalg.lstsq(A[k], grid.y[k, c], rcond=None)[0]
            out.append(float(robust_scale(grid.y[k, c] - A[k] @ b)))
        return np.array(out)

    y, v = grid.y.T, grid.valid.T
    before = mon.fit_series_batch(y, v, A0, spec, scale(A0))
    cold = mon.fit_series_batch(y, v, A1, spec, scale(A1))
    k = refit_iterations(40)
    warm = mon.fit_series_batch(y, v, A1, spec, scale(A1), iterations=k, theta0=before.theta, hinv0=before.hinv)
    assert k == 20 and np.all(np.asarray(cold.grad_norm) < 1e-2)
    np.testing.assert_allclose(warm.loglik_reml, cold.loglik_reml, rtol=0, atol=1e-3)
    rate_sigma = np.sqrt(np.asarray(cold.beta_cov)[:, 1, 1])
    np.testing.assert_allclose(warm.beta[:, 1], cold.beta[:, 1], rtol=0, atol=0.01 * rate_sigma.min())
    np.testing.assert_allclose(np.sqrt(np.asarray(warm.beta_cov)[:, 1, 1]), rate_sigma, rtol=0.01)


def test_a_fit_stopped_short_of_its_optimum_says_so():
    """Two BFGS steps leave the noise fit short of its optimum: the predicted rise of ln L_R
    (NoiseFit.gain_left) exceeds GAIN_LEFT_WARN and the station's warnings name the components; the
    default iterations leave nothing to gain and no such warning."""
    from jaxnav.monitoring._trajectory import GAIN_LEFT_WARN

    ser = _station_series(5, 500)
    short = mon.fit_station(ser, random_walk=False, iterations=2)
    assert np.any(short.noise.gain_left > GAIN_LEFT_WARN)
    flagged = [w for w in short.warnings if "not converged" in w]
    assert len(flagged) == int(np.sum(short.noise.gain_left > GAIN_LEFT_WARN)) and flagged
    full = mon.fit_station(ser, random_walk=False)
    assert np.all(full.noise.gain_left < 1e-4) and not any("not converged" in w for w in full.warnings)


def test_fit_stations_equals_fit_station_of_each_station():
    """fit_stations (the fits of all stations batched per round, stations advanced in threads) gives
    fit_station's results station by station: two grid lengths (two compiled shapes), a known step,
    a detected one (a second round for that station only), a station with nothing to add."""
    ser = [
        _station_series(1, 700, step_day=350, step_mm=15.0),  # detected
        _station_series(2, 700),
        _station_series(3, 450, step_day=200, step_mm=10.0),  # given
    ]
    given = [[], [], [float(ser[2].t[200])]]
    opts = dict(detect=2, random_walk=False, iterations=20)
    one = [mon.fit_station(s, steps=st, **opts) for s, st in zip(ser, given)]
    many = mon.fit_stations(ser, steps=given, chunk=2, workers=2, **opts)
    assert [len(f.steps) for f in many] == [len(f.steps) for f in one] == [1, 0, 1]
    assert many[0].step_sources == ("detected",) and many[2].step_sources == ("given",)
    assert np.all(many[0].noise.iterations <= 10)  # the refit after the detected step: warm, 20 // 2 steps
    for a, b in zip(one, many):
        assert a.station == b.station and a.warnings == b.warnings
        np.testing.assert_allclose(b.steps, a.steps, rtol=0, atol=1e-6)
        np.testing.assert_allclose(b.velocity, a.velocity, rtol=0, atol=1e-6 * np.max(a.velocity_sigma))
        np.testing.assert_allclose(b.velocity_sigma, a.velocity_sigma, rtol=1e-6)
        np.testing.assert_allclose(b.step_sizes, a.step_sizes, rtol=0, atol=1e-9)
    with pytest.raises(ValueError, match="steps: 1 entries for 3 stations"):
        mon.fit_stations(ser, steps=[[]], **opts)
    with pytest.raises(TypeError, match="detekt"):
        mon.fit_stations(ser, detekt=2)


def test_step_statistic_equals_the_projection_of_whitened_step_columns():
    """The scan's statistic from on-the-fly sums (s~^T e~, |s~|^2, Q^T s~) equals the textbook one:
    whiten [design, step columns] with the fitted noise, project out the design by QR in NumPy,
    (s~_p^T e~)^2 / |s~_p|^2 per candidate, summed over components; a known step's epoch scores 0."""
    from jaxnav.monitoring._station import _step_statistic

    n = 400
    ser = _station_series(5, n, step_day=150, step_mm=6.0)
    y = np.where(np.isfinite(ser.enu), ser.enu, 0.0).T
    valid = np.isfinite(ser.enu).T
    t = np.asarray(ser.t)
    A = mon.design_matrix(t, steps=[t[300]], t_ref=t[n // 2]).A  # a known step at day 300
    spec = mon.noise_spec(n)
    theta = np.array([[np.log(2 * MM), np.log(4 * MM * DAY**0.25 / YEAR**0.25), np.log(1e-4 * MM), -1.0]] * 3)
    theta[1, 0] += 0.3
    cand = np.array([30, 100, 149, 150, 151, 250, 300, 369])
    got = np.asarray(
        _step_statistic(theta, y, valid, A, cand, spec.r, spec.W, spec.d_grid, estimate_kappa=False, random_walk=True)
    )
    S = (np.arange(n)[:, None] >= cand[None, :]).astype(float)
    want = np.zeros(cand.size)
    for c in range(3):
        yt, At, _ = _whitened(
            theta[c], y[c], valid[c], np.concatenate([A, S], 1), spec.r, spec.W, spec.d_grid, False, True
        )
        yt, At = np.asarray(yt), np.asarray(At)
        Q, _ = np.linalg.qr(At[:, : A.shape[1]])
        e = yt - Q @ (Q.T @ yt)
        Sp = At[:, A.shape[1] :] - Q @ (Q.T @ At[:, A.shape[1] :])
        den = np.sum(Sp * Sp, axis=0)
        want += np.where(den > 1e-9 * np.sum(At[:, A.shape[1] :] ** 2, axis=0), (Sp.T @ e) ** 2 / den, 0.0)
    assert want[3] > 30 and want[6] == 0.0  # the planted step stands out; the known one adds nothing
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9)
