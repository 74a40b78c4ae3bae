"""MIDAS robust trend (Blewitt et al. 2016) against a plain implementation written here; misfit warnings and
default step detection of jaxnav monitor on a shipped real series."""

import bisect
import json
import math

import jax
import numpy as np
import pytest
from _paths import DATA_ROOT

from jaxnav import io
from jaxnav import monitoring as mon
from jaxnav.units import DAY, MM, MM_PER_YEAR, YEAR

DATA = DATA_ROOT / "gnss_daily_timeseries"
FILES = ("LHAS.tenv3", "bjfsCleanUnf.neu", "UH01_GOM20_neu_cm.col", "MRHK_GOM20_neu_cm.col", "UHCR_GOM20_neu_cm.col")


def plain_midas(t, x, steps=(), tol=0.001):
    """MIDAS written out from the paper, loop by loop: a forward pass (each epoch with the epoch nearest one year
    later) and a backward pass (each epoch with the one nearest a year earlier), pairs within tol of a year and
    not straddling a step; median, 1.4826 MAD, 2-sigma trim, median, 3 x 1.2533 sigma / sqrt(N/4)."""
    t = [float(a) for a in t]
    x = [float(a) for a in x]
    ok = [math.isfinite(a) for a in x]
    t = [a for a, k in zip(t, ok) if k]
    x = [a for a, k in zip(x, ok) if k]
    n = len(t)

    def closest(target):
        k = bisect.bisect_left(t, target)
        near = [q for q in (k - 1, k) if 0 <= q < n]
        return min(near, key=lambda q: abs(t[q] - target)) if near else None

    def straddles(a, b):
        return any(a < s <= b for s in steps)

    slopes = []
    for i in range(n):  # forward
        j = closest(t[i] + 1.0)
        if j is not None and j > i and abs(t[j] - t[i] - 1.0) <= tol and not straddles(t[i], t[j]):
            slopes.append((x[j] - x[i]) / (t[j] - t[i]))
    for j in range(n - 1, -1, -1):  # backward
        i = closest(t[j] - 1.0)
        if i is not None and i < j and abs(t[j] - t[i] - 1.0) <= tol and not straddles(t[i], t[j]):
            slopes.append((x[j] - x[i]) / (t[j] - t[i]))
    v = np.array(slopes)
    m = np.median(v)
    s = 1.4826 * np.median(np.abs(v - m))
    v = v[np.abs(v - m) < 2 * s]
    m = np.median(v)
    s = 1.4826 * np.median(np.abs(v - m))
    return m, 3 * 1.2533 * s / math.sqrt(len(v) / 4)


def _years(series):
    return 2000.0 + np.asarray(series.t, float) / YEAR


@pytest.mark.parametrize("name", FILES)
def test_midas_equals_a_plain_implementation_on_the_real_series(name):
    """Rates and sigmas of the five shipped real series (every component) equal the loop implementation above
    to 0.01 mm/yr; LHAS also with its 1995 antenna-change step given."""
    s = io.read_daily(DATA / name)
    t = _years(s)
    cases = [()] + ([(1995.655,)] if name.startswith("LHAS") else [])
    for steps in cases:
        got = mon.midas_velocity(t, np.asarray(s.enu), steps)
        for c in range(3):
            v, sd = plain_midas(t, np.asarray(s.enu)[:, c], steps)
            assert abs(got.velocity[c] - v) / MM < 0.01 and abs(got.sigma[c] - sd) / MM < 0.01, (name, c, steps)
            assert got.pairs_kept[c] > 0.5 * got.pairs[c] > 100


def test_midas_recovers_a_known_rate_through_a_step_and_seasonal_terms():
    """A simulated 6-year series (rate 3 mm/yr, 5 mm annual, white + flicker noise, a 20 mm step): MIDAS with
    the step given is within 2 of its sigmas of 3 mm/yr, and so it is without the step (the straddling pairs'
    slopes are trimmed: the robustness Blewitt et al. 2016 designed it for)."""
    n = 2192
    y, _ = mon.simulate_powerlaw_series(
        jax.random.PRNGKey(3),
        n,
        rate=3 * MM_PER_YEAR,
        sigma_white=1.5 * MM,
        amplitude=2 * MM / YEAR**0.25,
        gap_fraction=0.1,
    )
    t = 2010.0 + np.arange(n) * DAY / YEAR
    y = np.asarray(y) + 5 * MM * np.cos(2 * np.pi * t) + 20 * MM * (t >= 2013.0)
    with_step = mon.midas_velocity(t, y, [2013.0])
    assert abs(with_step.velocity / MM - 3.0) < 2 * with_step.sigma / MM, with_step
    assert 0.05 < with_step.sigma / MM < 1.0
    no_step = mon.midas_velocity(t, y)
    assert abs(no_step.velocity / MM - 3.0) < 2 * no_step.sigma / MM, no_step
    assert no_step.pairs > with_step.pairs  # the pairs across the step


def test_midas_bad_shapes():
    with pytest.raises(ValueError, match=r"\(3,\).*\(4,\)"):
        mon.midas_velocity(np.arange(3.0), np.zeros(4))


@pytest.fixture(scope="module")
def lhas_start(tmp_path_factory):
    """The first 3 years of LHAS (its 1995 antenna change inside)."""
    lines = (DATA / "LHAS.tenv3").read_text().splitlines()
    p = tmp_path_factory.mktemp("lhas") / "LHAS.tenv3"
    p.write_text("\n".join(lines[: 1 + 1000]) + "\n")
    return p


def test_monitor_detects_the_lhas_1995_step_by_default(lhas_start, tmp_path):
    """jaxnav monitor on 3 years of LHAS: by default the 1995-08-23 antenna change (about -59 mm up) is found
    to the day by the BIC criterion, and MIDAS sits beside the model rate in monitor.json."""
    from jaxnav.cli import main

    assert main(["monitor", str(lhas_start), "--out", str(tmp_path), "--no-progress"]) == 0
    st = json.loads((tmp_path / "monitor.json").read_text())["stations"]["LHAS"]
    det = [d for d in st["steps"] if d["source"] == "detected"]
    assert len(det) == 1 and det[0]["gain_2lnL"] > 4 * math.log(3 * 900), det
    assert det[0]["date"] == "1995-08-23" and -70 < det[0]["size_mm"]["up"] < -45, det
    for k in ("midas_velocity_mm_per_yr", "midas_velocity_sigma_mm_per_yr"):
        assert set(st[k]) == {"east", "north", "up"} and all(v is not None for v in st[k].values())
    assert abs(st["midas_velocity_mm_per_yr"]["up"] - st["velocity_mm_per_yr"]["up"]) < 3.0


def test_misfit_warnings_name_a_step_the_model_left_out():
    """midas_check on a 4-year series (2 mm/yr) with a 30 mm up step the model left out. A least-squares rate
    that absorbed the step (about 14 mm/yr) differs from MIDAS (given the step) by more than the combined sigma;
    a model line pulled the other way (-3 +- 6 mm/yr, as an inflated random walk allows) is within the combined
    sigma but leaves a trend in the residuals: each case warns once, in the up component only."""
    from types import SimpleNamespace

    n = 1461
    rng = np.random.default_rng(5)
    t = 10 * YEAR + np.arange(n) * DAY
    y = rng.normal(0, 2 * MM, (n, 3)) + (2 * MM_PER_YEAR) * (t - t[0])[:, None]
    y[:, 2] += 30 * MM * (np.arange(n) >= 700)
    grid = mon.DailyGrid(t=t, y=y, valid=np.ones((n, 3), bool), n_days=n, duplicates=0)
    A = mon.design_matrix(t).A
    beta = np.stack([np.linalg.lstsq(A, y[:, c], rcond=None)[0] for c in range(3)])
    for rate_up, sig_up, start in ((None, 5.0, "up: MIDAS rate"), (-3.0, 6.0, "up: the residuals keep a trend")):
        b = beta.copy()
        if rate_up is not None:
            b[2, 1] = rate_up * MM
        sig = np.array([1.0, 1.0, sig_up]) * MM_PER_YEAR
        fit = SimpleNamespace(
            grid=grid,
            steps=np.array([t[700]]),
            velocity=b[:, 1] / YEAR,
            velocity_sigma=sig,
            design_names=("offset", "rate"),
            A=A,
            residual_trend=mon.residual_trend(grid, A, b) / YEAR,
        )
        m, warn = mon.midas_check(fit)
        assert np.all(np.abs(m.velocity / MM - 2.0) < 2 * m.sigma / MM), m
        assert len(warn) == 1 and warn[0].startswith(start), warn
