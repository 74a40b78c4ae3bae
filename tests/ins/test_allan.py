"""Allan variance noise identification: the estimator against allantools, the fit on simulated
white + flicker (bias instability) + rate random walk noise with known coefficients, the mapping to
ImuNoise, and ``jaxnav allan`` on a small simulated static file (its [noise] section loads as an
``jaxnav ins`` config; bad input ends with one line and exit 2)."""

from __future__ import annotations

import math

import allantools
import numpy as np
import pytest

from jaxnav import ins, units
from jaxnav.cli import main
from jaxnav.ins.allan import FLICKER_AVAR, GM_PEAK_ADEV, GM_PEAK_TAU, allan_ms
from jaxnav.io import load_ins_config


def _noise(rng, n, dt, white, flicker, rrw):
    """Rate samples: white noise of density ``white``, flicker of coefficient B = ``flicker`` (one-sided
    PSD B^2 / (pi f), i.e. the two-sided B^2 / (2 pi f) of IEEE Std 952, shaped in the frequency
    domain) and a rate random walk of density ``rrw`` (numpy only, independent of the library)."""
    f = np.fft.rfftfreq(n, dt)
    G = np.zeros_like(f)
    G[1:] = flicker**2 / (np.pi * f[1:])
    fl = np.fft.irfft(np.fft.rfft(rng.standard_normal(n)) * np.sqrt(G / (2 * dt)), n)
    return white / math.sqrt(dt) * rng.standard_normal(n) + fl + np.cumsum(rrw * math.sqrt(dt) * rng.standard_normal(n))


def test_adev_equals_allantools_and_uniform_grid_is_exact():
    rng = np.random.default_rng(4)
    dt = 0.01
    y = _noise(rng, 20_000, dt, 1e-3, 2e-4, 1e-4)
    ms = allan_ms(y.size)
    taus, ad = ins.allan_deviation(y, dt, ms)
    _, ad_ref, _, _ = allantools.oadev(y, rate=1 / dt, data_type="freq", taus=taus)
    np.testing.assert_allclose(np.asarray(ad), ad_ref, rtol=1e-9)
    # uniform tags: the resampling through the integral gives the samples back
    t = 100.0 + dt * np.arange(y.size)
    dt2, yu = ins.uniform_rates(t, y[:, None])
    assert dt2 == pytest.approx(dt)
    np.testing.assert_allclose(yu[0], y[1:], atol=1e-6 * np.abs(y).max())  # time-tag rounding only


# a gyro-like case: crossovers white/flicker at tau = 1 s, flicker/rate random walk at 30 s
N_W = 0.3
B_F = N_W / math.sqrt(FLICKER_AVAR)
K_R = math.sqrt(3 * FLICKER_AVAR) * B_F / math.sqrt(30.0)


def test_fit_recovers_white_bias_instability_and_rate_random_walk_within_10_percent():
    rng = np.random.default_rng(3)
    dt = 0.1
    y = np.stack([_noise(rng, 2**19, dt, N_W, B_F, K_R) for _ in range(3)])
    fit = ins.allan_noise_fit(y, dt)
    for got, sig, true in (
        (fit.white, fit.white_sigma, N_W),
        (fit.bias_instability, fit.bias_instability_sigma, B_F),
        (fit.rate_rw, fit.rate_rw_sigma, K_R),
    ):
        np.testing.assert_array_less(np.abs(got / true - 1.0), 0.10)
        assert np.all(sig > 0) and np.all(sig < 0.05 * true)
    assert fit.resolved.all()
    # the minimum of the fitted model: sqrt(3) N / K
    np.testing.assert_allclose(fit.tau_floor, math.sqrt(3) * fit.white / fit.rate_rw)
    # ImuNoise: white -> ARW/VRW, K -> bias random walk, B -> the Gauss-Markov with the same Allan peak
    n = ins.imu_noise_from_allan(fit, fit)
    np.testing.assert_allclose(n.gyro_arw, fit.white)
    np.testing.assert_allclose(n.accel_bias_rw, fit.rate_rw)
    gm = ins.allan.gauss_markov_avar(GM_PEAK_TAU * n.gyro_bias_tau[0], n.gyro_bias_instability[0], n.gyro_bias_tau[0])
    assert math.sqrt(gm) == pytest.approx(math.sqrt(FLICKER_AVAR) * fit.bias_instability[0], rel=1e-3)
    assert GM_PEAK_ADEV == pytest.approx(0.6174, abs=1e-3) and GM_PEAK_TAU == pytest.approx(1.8926, abs=1e-3)
    # a long recording (14.6 h): every term goes into the [noise] section, in the config's units
    from jaxnav.io import loads_toml, noise_toml

    fg, fa = ins.allan_noise_fit(y * 1e-4, dt), ins.allan_noise_fit(y * 1e-3, dt)  # rad/s, m/s^2
    sec = loads_toml(noise_toml(fg, fa, source="sim"))["noise"]
    assert sec["arw_deg_per_sqrt_h"] == pytest.approx(
        units.rad_per_sqrt_s_to_deg_per_sqrt_hour(fg.white.max()), rel=1e-3
    )
    assert sec["gyro_bias_rw_deg_per_h_per_sqrt_h"] == pytest.approx(
        units.rad_per_s_per_sqrt_s_to_deg_per_hour_per_sqrt_hour(fg.rate_rw.max()), rel=1e-3
    )
    assert sec["accel_bias_instability_mg"] == pytest.approx(
        units.mps2_to_mg(fa.bias_instability.max()) * math.sqrt(FLICKER_AVAR) / GM_PEAK_ADEV, rel=1e-3
    )
    assert sec["bias_correlation_time_s"] == pytest.approx(fg.tau_floor.max() / GM_PEAK_TAU, rel=1e-3)


def test_fit_flags_a_term_the_record_cannot_resolve():
    rng = np.random.default_rng(0)
    y = rng.standard_normal((1, 4096)) * 0.01 / math.sqrt(0.01)  # white only
    fit = ins.allan_noise_fit(y, 0.01)
    assert fit.resolved[0, 0] and not fit.resolved[0, 2]
    assert fit.white[0] == pytest.approx(0.01, rel=0.05)
    assert fit.upper[0, 2] > 0
    with pytest.raises(ValueError, match="too few"):
        ins.allan_noise_fit(np.zeros((1, 2)), 0.01)
    with pytest.raises(ValueError, match="averaging times"):
        ins.allan_noise_fit(y, 0.01, tau_range=(1e3, 1e4))


ARW_DEG_SQRT_H, VRW_M_S_SQRT_H = 0.3, 0.05


def _static_file(path, n=30_000, dt=0.01, moving=False):
    """A static KF-GINS IMU file (FRD, z down): white noise of known ARW and VRW plus gravity."""
    rng = np.random.default_rng(1)
    arw = units.deg_per_sqrt_hour_to_rad_per_sqrt_s(ARW_DEG_SQRT_H)
    vrw = units.mps_per_sqrt_hour_to_mps_per_sqrt_s(VRW_M_S_SQRT_H)
    dth = arw * math.sqrt(dt) * rng.standard_normal((n, 3))
    dv = vrw * math.sqrt(dt) * rng.standard_normal((n, 3)) + np.array([0.0, 0.0, -units.G0]) * dt
    if moving:
        dth[:, 2] += 0.5 * dt * np.sin(np.arange(n) * dt)
    t = 345_600.0 + dt * np.arange(1, n + 1)
    np.savetxt(path, np.column_stack([t, dth, dv]), fmt=["%.4f"] + ["%.12e"] * 6)
    return path


def test_allan_command_writes_figures_results_and_a_noise_section_ins_accepts(tmp_path, capsys):
    f = _static_file(tmp_path / "static.txt")
    out = tmp_path / "out"
    assert main(["-q", "allan", str(f), "--format", "kf-gins", "--out", str(out)]) == 0
    for name in ("allan_gyro.png", "allan_accel.png", "noise.toml", "results.json"):
        assert (out / name).is_file(), name
    import json

    res = json.loads((out / "results.json").read_text())
    assert "provenance" in res
    assert res["gyro"]["arw_deg_per_sqrt_h"] == pytest.approx([ARW_DEG_SQRT_H] * 3, rel=0.05)
    assert res["accel"]["vrw_m_per_s_per_sqrt_h"] == pytest.approx([VRW_M_S_SQRT_H] * 3, rel=0.05)
    cfg = tmp_path / "run.toml"
    cfg.write_text(
        f'[imu]\nfile = "{f.name}"\nformat = "kf-gins"\n[gnss]\nfile = "g.txt"\nformat = "kf-gins"\n\n'
        + (out / "noise.toml").read_text()
    )
    c = load_ins_config(cfg)
    assert c.noise.arw == pytest.approx(units.deg_per_sqrt_hour_to_rad_per_sqrt_s(ARW_DEG_SQRT_H), rel=0.05)
    assert c.noise.vrw == pytest.approx(units.mps_per_sqrt_hour_to_mps_per_sqrt_s(VRW_M_S_SQRT_H), rel=0.05)
    assert c.noise.grade in ("consumer", "industrial")
    # 300 s cannot measure the bias terms: written commented out, the grade's values stand
    assert c.noise.gyro_bias_instability is None and c.noise.bias_correlation_time is None
    assert "# only 300 s of data" in (out / "noise.toml").read_text()
    assert "[noise]" in capsys.readouterr().out


@pytest.mark.parametrize(
    "argv_tail, match",
    [
        (["--format", "csv"], "--columns"),
        (["--format", "kf-gins", "--columns", "t=0"], "only used with --format csv"),
        (["--format", "kf-gins", "--start", "10", "--end", "5"], "--end"),
        (["--format", "kf-gins", "--start", "299.9"], "samples in the stretch"),
    ],
)
def test_allan_command_bad_options(tmp_path, capsys, argv_tail, match):
    f = _static_file(tmp_path / "static.txt", n=30_000)
    assert main(["-q", "allan", str(f), "--out", str(tmp_path / "o"), *argv_tail]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("jaxnav allan") and match in err[0], err


def test_allan_command_bad_files(tmp_path, capsys):
    assert main(["allan", str(tmp_path / "nope.txt"), "--format", "kf-gins", "--out", str(tmp_path / "o")]) == 2
    assert "nope.txt: no such file" in capsys.readouterr().err
    moving = _static_file(tmp_path / "moving.txt", n=5_000, moving=True)
    assert main(["allan", str(moving), "--format", "kf-gins", "--out", str(tmp_path / "o")]) == 2
    assert "not a static recording" in capsys.readouterr().err
    bad = tmp_path / "bad.txt"
    bad.write_text("345600.01 0 0 0 0 0 -0.098\n345600.02 0 x 0 0 0 -0.098\n")
    assert main(["allan", str(bad), "--format", "kf-gins", "--out", str(tmp_path / "o")]) == 2
    assert "bad.txt:2" in capsys.readouterr().err


def test_allan_command_reads_a_csv_with_a_column_map(tmp_path):
    """``--format csv --columns --units``: rates in deg/s and g, header names; the same ARW comes back."""
    rng = np.random.default_rng(2)
    n, dt = 20_000, 0.01
    arw = units.deg_per_sqrt_hour_to_rad_per_sqrt_s(ARW_DEG_SQRT_H)
    w = np.degrees(arw / math.sqrt(dt) * rng.standard_normal((n, 3)))  # deg/s
    a = 0.001 * rng.standard_normal((n, 3)) + np.array([0.0, 0.0, 1.0])  # g
    f = tmp_path / "imu.csv"
    np.savetxt(
        f,
        np.column_stack([dt * np.arange(n), w, a]),
        delimiter=",",
        header="time,wx,wy,wz,ax,ay,az",
        comments="",
        fmt="%.9g",
    )
    out = tmp_path / "out"
    assert (
        main(
            [
                "-q",
                "allan",
                str(f),
                "--format",
                "csv",
                "--columns",
                "t=time,gx=wx,gy=wy,gz=wz,ax=ax,ay=ay,az=az",
                "--units",
                "t=s,gyro=deg/s,accel=g",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    import json

    res = json.loads((out / "results.json").read_text())
    assert res["gyro"]["arw_deg_per_sqrt_h"] == pytest.approx([ARW_DEG_SQRT_H] * 3, rel=0.05)


def test_static_check_nearest_grade_and_datasheet_record():
    """static_check names the failing test (gravity, gyro or accelerometer spread); nearest_grade picks the preset
    nearest in log ARW; allan_fit_datasheet gives per-axis lists in datasheet units."""
    rng = np.random.default_rng(1)
    w = 1e-4 * rng.standard_normal((1000, 3))
    f = np.array([0.0, 0.0, units.G0]) + 1e-3 * rng.standard_normal((1000, 3))
    assert ins.static_check(w, f) is None
    assert "mean specific force" in ins.static_check(w, f / units.G0)
    assert "angular rate varies" in ins.static_check(w + np.linspace(0, 1, 1000)[:, None], f)
    assert "specific force varies" in ins.static_check(w, f + 2.0 * np.sin(np.arange(1000))[:, None])
    for g in ins.NOISE_GRADES:
        assert ins.nearest_grade(float(ins.noise_preset(g).gyro_arw) * 1.1) == g
    fit = ins.allan_noise_fit(0.01 * rng.standard_normal((3, 4096)), 0.01)
    e = ins.allan_fit_datasheet(fit, "gyro")
    np.testing.assert_allclose(e["arw_deg_per_sqrt_h"], units.rad_per_sqrt_s_to_deg_per_sqrt_hour(fit.white))
    assert len(e["adev_deg_per_h"]) == 3 and "vrw_m_per_s_per_sqrt_h" in ins.allan_fit_datasheet(fit, "accel")
