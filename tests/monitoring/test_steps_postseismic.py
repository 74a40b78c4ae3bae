"""Known steps from files, post-seismic transients and the polynomial degree of the trajectory model."""

import json
import re

import jax
import numpy as np
import pytest

from jaxnav import io
from jaxnav import monitoring as mon
from jaxnav.units import DAY, MM, MM_PER_YEAR, YEAR

WHITE, FLICKER = 1.5 * MM, 3.0 * MM / YEAR**0.25  # white sigma; flicker amplitude (Hector's mm/yr^0.25)


def _noise(seed, n, rates_mm_yr):
    """(n, 3) m: rate + white + flicker noise (5 % of days missing), one component per key."""
    cols = [
        np.asarray(
            mon.simulate_powerlaw_series(
                jax.random.PRNGKey(seed + c),
                n,
                rate=r * MM_PER_YEAR,
                sigma_white=WHITE,
                amplitude=FLICKER,
                gap_fraction=0.05,
            )[0]
        )
        for c, r in enumerate(rates_mm_yr)
    ]
    return np.stack(cols, axis=1)


def _series(t, y, station="SIMU"):
    n = len(t)
    return io.DailySeries(
        station=station,
        path="simulated",
        fmt="tenv3",
        t=t,
        year=2000.0 + t / YEAR,
        enu=y,
        cov=np.tile(np.eye(3) * WHITE**2, (n, 1, 1)),
        origin=np.zeros(3),
        llh=np.full((n, 3), np.nan),
        reference_velocity=None,
        reference_velocity_sigma=None,
        n_masked=int(np.isnan(y).sum()),
        xyz=None,
        cov_xyz=None,
    )


def test_steps_file_formats_and_errors(tmp_path):
    f = tmp_path / "steps.txt"
    f.write_text(
        "# station date kind terms\n"
        "lhas 1995-08-23 equipment   # antenna\n"
        "\n"
        "ABCD, 2011.1920, earthquake, log:30, exp:estimate\n"
        "ABCD 2012-01-01 unknown\n"
        "P123  11MAR11  2  0.5  190.0  9.0  official20110311054624_0001\n"
        "P123  99DEC31  1  Antenna_Code_Changed\n"
    )
    ks = io.read_steps_file(f)
    assert [k.station for k in ks] == ["LHAS", "ABCD", "ABCD", "P123", "P123"]
    assert [k.kind for k in ks] == ["equipment", "earthquake", "unknown", "earthquake", "equipment"]
    assert ks[0].epoch == io.date_to_epoch("1995-08-23") and ks[0].origin == f"{f}:2"
    np.testing.assert_allclose(ks[1].epoch, 11.192 * YEAR)
    assert ks[1].postseismic == (("log", 30 * DAY), ("exp", None))
    assert ks[3].epoch == io.date_to_epoch("2011-03-11") and ks[4].epoch == io.date_to_epoch("1999-12-31")
    # the step applies from the daily solution of its date on (solutions are labelled at noon)
    assert io.date_to_epoch("2000-01-01") == -0.5 * DAY
    bad = {
        "LHAS 1995-08-23\n": "expected 'station date kind",
        "LHAS 1995-13-01 equipment\n": "not a calendar date",
        "LHAS 95/08/23 equipment\n": "cannot read the date",
        "LHAS 1995-08-23 antenna\n": "unknown step kind 'antenna'",
        "LHAS 1995-08-23 equipment log:30\n": "only earthquake steps take post-seismic terms",
        "LHAS 1995-08-23 earthquake power:30\n": "expected log:TAU_DAYS",
        "LHAS 1995-08-23 earthquake log:-3\n": "must be in (0, 1e5] days",
        "LHAS 1995-08-23 earthquake log:soon\n": "is not a number of days",
    }
    for k, (text, msg) in enumerate(bad.items()):
        g = tmp_path / f"bad{k}.txt"
        g.write_text("# header\n" + text)
        with pytest.raises(io.ReaderError, match=re.escape(msg)) as e:
            io.read_steps_file(g)
        assert e.value.line == 2 and str(e.value).startswith(f"{g}:2: "), str(e.value)
    (tmp_path / "empty.txt").write_text("# nothing\n")
    with pytest.raises(io.ReaderError, match="no step in the file"):
        io.read_steps_file(tmp_path / "empty.txt")


def test_postseismic_columns_and_polynomial_design():
    """Bevis & Brown (2014) log and exp terms; powers of (t - t_ref) after the steps; the rate column unchanged."""
    t = np.arange(0.0, 1000.0) * DAY
    te, tau = 400.5 * DAY, 50 * DAY
    lg = mon.postseismic_column(t, te, "log", tau)
    ex = mon.postseismic_column(t, te, "exp", tau)
    assert np.all(lg[t < te] == 0) and np.all(ex[t < te] == 0)
    np.testing.assert_allclose(lg[500], np.log(1 + 99.5 / 50), rtol=1e-12)
    np.testing.assert_allclose(ex[500], 1 - np.exp(-99.5 / 50), rtol=1e-12)
    D1 = mon.design_matrix(t, steps=[te])
    D = mon.design_matrix(t, steps=[te], poly_degree=3, postseismic=[(te, "log", tau), (te, "exp", tau)])
    assert D.names[: len(D1.names)] == D1.names
    assert D.names[len(D1.names) :] == ("poly_2", "poly_3", "postseismic_0_log", "postseismic_1_exp")
    np.testing.assert_array_equal(D.A[:, : len(D1.names)], D1.A)
    np.testing.assert_allclose(D.A[:, D.names.index("poly_2")], ((t - D.t_ref) / YEAR) ** 2)
    with pytest.raises(ValueError, match="post-seismic form"):
        mon.postseismic_column(t, te, "power", tau)
    with pytest.raises(ValueError, match="outside the series"):
        mon.design_matrix(t, postseismic=[(t[-1] + DAY, "log", tau)])
    with pytest.raises(ValueError, match="poly_degree"):
        mon.design_matrix(t, poly_degree=0)


def test_postseismic_log_transient_recovered_with_estimated_tau():
    """Seven years of white + flicker noise with an earthquake halfway: a 5 mm step and a logarithmic
    transient (20, -12, 30 mm; tau 60 days). With tau estimated, each amplitude is within 10 % of the
    truth, each rate within its sigma, and tau's interval covers 60 days."""
    n = 2557
    t = 10 * YEAR + np.arange(n) * DAY
    te = t[n // 2] - 0.5 * DAY
    amp, rate = np.array([20.0, -12.0, 30.0]) * MM, np.array([3.0, -2.0, 1.0])
    transient = amp * mon.postseismic_column(t, te, "log", 60 * DAY)[:, None]
    y = _noise(11, n, rate) + transient + 5 * MM * (t >= te)[:, None]
    fit = mon.fit_station(_series(t, y), steps=[te], postseismic=[(te, "log", None)], random_walk=False)
    (p,) = fit.postseismic
    assert p.estimated and p.form == "log" and not p.tau_at_edge
    np.testing.assert_allclose(p.amplitude, amp, rtol=0.10)
    assert np.all(p.amplitude_sigma < 0.05 * np.abs(amp))
    assert p.tau_range[0] <= 60 * DAY <= p.tau_range[1] and p.tau_range[1] / p.tau_range[0] < 1.5, p.tau_range / DAY
    v, sd = fit.velocity / MM_PER_YEAR, fit.velocity_sigma / MM_PER_YEAR
    assert np.all(np.abs(v - rate) < sd), (v, sd)
    assert fit.step_sizes.shape == (3, 1)
    assert np.all(np.abs(fit.step_sizes[:, 0] / MM - 5.0) < 3 * fit.step_sigmas[:, 0] / MM)


def test_poly_degree_two_recovers_an_acceleration():
    """Seven years, white + flicker and a step, an east acceleration of 3 mm/yr^2: recovered within 2 sigma
    (and the rate, the velocity at mid-span, within 2 sigma); north and up, with none, within 2 sigma of
    zero. (The same length and number of model terms as the post-seismic case: one compilation.)"""
    n = 2557
    t = 10 * YEAR + np.arange(n) * DAY
    rate = np.array([2.0, -1.0, 0.5])
    tm = 0.5 * (t[0] + t[-1])
    acc = np.array([3.0, 0.0, 0.0]) * MM / YEAR**2
    ts = t[n // 2] - 0.5 * DAY
    y = _noise(21, n, rate) + 0.5 * acc * (t - tm)[:, None] ** 2 + 4 * MM * (t >= ts)[:, None]
    fit = mon.fit_station(_series(t, y), steps=[ts], poly_degree=2, random_walk=False)
    c2, s2 = mon.polynomial_terms(fit)[2]
    a, sa = 2 * c2, 2 * s2
    assert np.all(np.abs(a - acc) < 2 * sa), (a * YEAR**2 / MM, sa * YEAR**2 / MM)
    assert np.all(sa * YEAR**2 / MM < 1.0)
    np.testing.assert_allclose(fit.t_ref, tm)
    v, sd = fit.velocity / MM_PER_YEAR, fit.velocity_sigma / MM_PER_YEAR
    assert np.all(np.abs(v - rate) < 2 * sd), (v, sd)


def test_cli_steps_file_postseismic_and_poly_degree(tmp_path, capsys):
    """jaxnav monitor with a steps file: the earthquake's step and log term (given tau) in the model, its
    amplitude near the truth; a step of another station and one before the series warned about and listed;
    --poly-degree 2 reports the acceleration."""
    from jaxnav.cli import main

    n = 731
    years = 2010.0 + np.arange(n) / 365.25
    t = (years - 2000.0) * YEAR
    te = io.date_to_epoch("2011-01-02")
    amp = np.array([15.0, -8.0, 20.0]) * MM
    y = (
        _noise(31, n, [4.0, 1.0, -2.0])
        + amp * mon.postseismic_column(t, te, "log", 40 * DAY)[:, None]
        + 8 * MM * (t >= te)[:, None]
    )
    rows = [
        f"{yr:.4f} {y[i, 1] / MM:.3f} {y[i, 0] / MM:.3f} {y[i, 2] / MM:.3f} 1.5 1.5 1.5"
        for i, yr in enumerate(years)
        if np.all(np.isfinite(y[i]))
    ]
    (tmp_path / "SIMA_sim.col").write_text(
        "Decimal-Year NS(mm) EW(mm) UD(mm) sigma-NS(mm) sigma-EW(mm) sigma-UD(mm)\n" + "\n".join(rows) + "\n"
    )
    (tmp_path / "steps.txt").write_text(
        "SIMA 2011-01-02 earthquake log:40\nSIMA 2001-01-01 equipment\nXXXX 2011-01-02 earthquake\n"
    )
    out = tmp_path / "o"
    assert (
        main(
            [
                "monitor",
                str(tmp_path / "SIMA_sim.col"),
                "--steps-file",
                str(tmp_path / "steps.txt"),
                "--poly-degree",
                "2",
                "--no-detect-steps",
                "--no-random-walk",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    text = capsys.readouterr().out
    res = json.loads((out / "monitor.json").read_text())
    assert res["settings"]["poly_degree"] == 2 and res["settings"]["steps_files"] == [str(tmp_path / "steps.txt")]
    (um,) = res["known_steps"]["unmatched_stations"]
    assert um["station"] == "XXXX" and um["given_by"] == f"{tmp_path / 'steps.txt'}:3"
    assert "known step of XXXX at 2011-01-02" in text
    st = res["stations"]["SIMA"]
    (step,) = st["steps"]
    assert step["date"] == "2011-01-02" and step["kind"] == "earthquake" and step["source"] == "given"
    (ps,) = st["postseismic"]
    assert ps["form"] == "log" and ps["tau_days"] == 40.0 and not ps["tau_estimated"]
    for c, comp in enumerate(("east", "north", "up")):
        tol = max(0.15 * abs(amp[c] / MM), 3 * ps["amplitude_sigma_mm"][comp])
        assert abs(ps["amplitude_mm"][comp] - amp[c] / MM) < tol, (comp, ps["amplitude_mm"][comp])
    assert [o["date"] for o in st["known_steps_outside_series"]] == ["2001-01-01"]
    assert any("2001-01-01" in w and "outside the series" in w for w in st["warnings"])
    pol = st["polynomial"]
    assert pol["degree"] == 2 and pol["rate_is_the_velocity_at"] == "reference_epoch"
    assert set(pol["acceleration_mm_per_yr2"]) == {"east", "north", "up"}
    assert "post-seismic log after 2011-01-02, tau 40 d (given)" in text and "acceleration mm/yr^2" in text


def test_known_steps_on_one_day_merge():
    """A --step and a file's earthquake on the same day are one step: the more specific kind, the terms of
    both (one per form, an option's before a file's), all origins; other days stay apart, in time order."""
    from jaxnav.io import merge_known_steps

    d = io.date_to_epoch("2011-03-11")
    ks = [
        io.KnownStep("ABCD", d + 0.3 * DAY, "earthquake", (("log", 30 * DAY),), "f.txt:4"),
        io.KnownStep("ABCD", d, "unknown", (), "--step"),
        io.KnownStep("ABCD", d + 0.1 * DAY, "earthquake", (("log", None), ("exp", None)), "--postseismic x"),
        io.KnownStep("ABCD", d - 40 * DAY, "equipment", (), "f.txt:2"),
    ]
    m = merge_known_steps(ks)
    assert [k.kind for k in m] == ["equipment", "earthquake"]
    assert m[1].epoch == d and m[1].postseismic == (("log", None), ("exp", None))
    assert m[1].origin == "--step; --postseismic x; f.txt:4"
