"""``jaxnav ins`` calibrates its noise by default: consistent uncertainties from a grade preset alone.

A simulated car (110 s, 25 Hz IMU, 2 Hz RTK-level GNSS, two 15 s outages, known truth) whose IMU
white noise is 4x the consumer preset's: the preset alone is overconfident (GNSS position NIS per
dof above its band, the outage errors far outside the solution's 3 sigma); the default
``calibrate = "auto"`` fits ARW, VRW and the GNSS sigma factor on the epochs the filter sees and
ends consistent. The same car with the preset's own noise keeps the preset (only the NIS check runs).
"""

import math

import numpy as np
import pytest
from _recording import car_config, short_car_spec, write_car, write_truth_nav

CONSUMER_ARW = math.radians(0.5) / 60  # rad/sqrt(s), the consumer preset's 0.5 deg/sqrt(h)
CONSUMER_VRW = 0.1 / 60  # m/s/sqrt(s), the consumer preset's 0.1 m/s/sqrt(h)
EVALUATE = "first_s = 40.0\noutage_s = 15.0\ngap_s = 20.0\nend_margin_s = 5.0"


def _car(folder, factor, vel_factor=1.0):
    """The short car with IMU white noise ``factor`` times the consumer preset's and GNSS velocity noise
    ``vel_factor`` times the sigma its file states (0.03 m/s); its config (consumer preset)."""
    rec = write_car(
        folder,
        spec=short_car_spec(),
        imu_rate=25.0,
        vibration=0.0,
        vel_sigma=vel_factor * 0.03,
        vel_sigma_stated=0.03,
        gyro_white=factor * CONSUMER_ARW,
        accel_white=factor * CONSUMER_VRW,
        gyro_bias=math.radians(100.0) / 3600,
        accel_bias=10e-3 * 9.81,
    )
    write_truth_nav(rec, folder / "truth.nav", step=5)
    cfg = car_config(
        rec,
        folder,
        time_offset=0.15,
        noise='grade = "consumer"',
        tune='calibrate = "auto"\ncalibrate_steps = 8',
        evaluate=EVALUATE,
        evaluate_extra='truth = "truth.nav"',
    )
    return rec, cfg


def test_overconfident_preset_is_calibrated_to_consistency(tmp_path):
    from jaxnav.cli import main

    _, cfg = _car(tmp_path / "data", 4.0)
    out = tmp_path / "out"
    assert main(["ins", str(cfg), "--out", str(out), "-q"]) == 0
    import json

    r = json.loads((out / "results.json").read_text())
    c = r["calibration"]
    assert c["mode"] == "auto" and c["ran"] and "outside" in c["reason"]
    lo, hi = c["nis_band_per_dof"]
    assert c["nis_before_per_dof"] > hi and lo <= c["nis_after_per_dof"] <= hi
    # the check's open gate rejected nothing: every GNSS epoch the filter sees has its NIS
    assert c["n_nis_epochs"] == r["gnss"]["n_epochs_used"]
    # fitted on the GNSS epochs the filter sees, never the withheld ones
    assert c["n_epochs"] == r["gnss"]["n_epochs_used"] and r["gnss"]["n_withheld"] > 40
    assert "outside the [evaluate] outages" in c["fitted_on"]
    # the white-noise densities grow towards the simulated 4x
    assert c["after_display"]["arw"] > 2.0 * c["before_display"]["arw"]
    assert c["after_display"]["vrw"] > 1.2 * c["before_display"]["vrw"]
    assert c["display_units"]["arw"] == "deg/sqrt(h)" and c["before_si"]["arw"] == pytest.approx(CONSUMER_ARW)
    # consistent: the truth inside the solution's 3 sigma (the preset alone, calibrate = false: 82 %
    # overall, 69 % in the outages, NEES 23 and 43), sigmas not inflated beyond the errors (NEES of 3
    # expected; a 100 % coverage of two correlated outages is no evidence of over-caution, a NEES far
    # below 3 would be), and the gate keeps (nearly) every GNSS epoch (the preset alone: 18 % gated)
    f = r["evaluation"]["truth"]["forward"]
    assert f["outages"]["share_pos_within_3_sigma"] >= 0.90 and f["all"]["share_pos_within_3_sigma"] >= 0.90
    assert 1.0 <= f["all"]["nees_pos_mean"] <= 6.0 and 1.0 <= f["outages"]["nees_pos_mean"] <= 9.0
    assert r["gnss"]["gated_share"] < 0.05 and "gate_warning" not in c
    assert r["tuning"]["fitted"]["noise calibration"]["n_epochs"] == c["n_epochs"]
    # one outage schedule (the default [evaluate] shifts = 1): no shifted-outage block, no figure
    assert "shifted_outages" not in r["evaluation"] and "shifted_outages.png" not in r["files"]


def test_preset_that_fits_is_kept_and_few_epochs_warn(tmp_path):
    from jaxnav.experiments.ins_run import calibrate_noise, prepare
    from jaxnav.ins import MIN_CALIBRATION_EPOCHS
    from jaxnav.io import load_ins_config

    _, cfg = _car(tmp_path, 1.0)
    prep = prepare(load_ins_config(cfg), progress=None)
    d, c = calibrate_noise(prep)
    assert c["mode"] == "auto" and not c["ran"] and "inside" in c["reason"]
    lo, hi = c["nis_band_per_dof"]
    assert lo <= c["nis_before_per_dof"] <= hi and c["n_nis_epochs"] > MIN_CALIBRATION_EPOCHS
    assert d is prep.densities
    # too few GNSS epochs: the preset is kept, with the measured NIS in the report
    mask = np.asarray(prep.meas.mask).copy()
    seen = np.nonzero(mask[:, :3].any(-1))[0]
    mask[seen[MIN_CALIBRATION_EPOCHS - 10 :]] = False
    few = prep._replace(meas=prep.meas._replace(mask=mask))
    msgs = []
    d, c = calibrate_noise(few, True, progress=msgs.append)
    assert not c["ran"] and "too few GNSS epochs" in c["reason"] and c["n_nis_epochs"] == MIN_CALIBRATION_EPOCHS - 10
    assert np.isfinite(c["nis_before_per_dof"]) and d is prep.densities
    assert "too few to check or calibrate" in c["warning"] and any("warning" in m for m in msgs)
    # calibrate = false: nothing runs
    d, c = calibrate_noise(prep, False)
    assert not c["ran"] and "nis_before_per_dof" not in c


def test_velocity_noise_beyond_its_sigmas_is_calibrated(tmp_path):
    """GNSS velocity noise 2x the sigmas of the file: the gate (position and velocity together) rejects
    10 % of the GNSS epochs of the preset; the check sees the velocity NIS (3.6 per dof) and the
    calibration fits the velocity sigma factor, after which both NIS are in the band and the gate keeps
    (nearly) every epoch. Before the velocity sigma factor existed (check and fit on position only) the
    calibration ran (position NIS per dof 1.41) but ended with 1.38 and a warning, velocity NIS per dof
    3.5, and its run gated 9.6 % of the GNSS epochs."""
    from jaxnav.experiments.ins_run import calibrate_noise, prepare, run_filter
    from jaxnav.io import load_ins_config

    _, cfg = _car(tmp_path, 1.0, vel_factor=2.0)
    prep = prepare(load_ins_config(cfg), progress=None)
    n_used = int(np.count_nonzero(np.asarray(prep.meas.mask)[:, :3].any(-1)))
    d, c = calibrate_noise(prep)
    lo, hi = c["nis_band_per_dof"]
    assert c["ran"] and "vel_sigma_scale" in c["params"] and "velocity NIS per dof" in c["reason"]
    assert c["nis_vel_before_per_dof"] > 2.0 * hi and c["n_nis_vel_epochs"] == c["n_nis_epochs"]
    assert c["share_above_gate_before"] > 0.05
    assert lo <= c["nis_vel_after_per_dof"] <= hi and lo <= c["nis_after_per_dof"] <= hi
    assert c["share_above_gate_after"] <= c["nis_gate_share_max"] and "warning" not in c
    assert 1.5 < c["after_si"]["vel_sigma_scale"] < 3.0 and c["display_units"]["vel_sigma_scale"] == "1"
    # the gated run: the preset rejects many GNSS epochs, the calibrated noise (nearly) none
    assert int(run_filter(prep).n_gated) / n_used > 0.05
    assert int(run_filter(prep, d).n_gated) / n_used < 0.05


class _Called(BaseException):
    """Raised by the stand-in for the processing (not an Exception: the command lets it through)."""


@pytest.mark.parametrize("argv, expected", [([], None), (["--no-calibrate"], False)])
def test_no_calibrate_option_reaches_the_run(tmp_path, monkeypatch, argv, expected):
    """``--no-calibrate`` overrides ``[tune] calibrate`` with false; without it the config decides (None)."""
    import jaxnav.experiments.ins_output as ins_output
    from jaxnav.cli import main

    for f in ("imu.txt", "gnss.txt"):
        (tmp_path / f).write_text("0\n")
    cfg = tmp_path / "c.toml"
    cfg.write_text('[imu]\nfile = "imu.txt"\nformat = "kf-gins"\n[gnss]\nfile = "gnss.txt"\nformat = "kf-gins"\n')

    def process(cfg, out, *, tune=False, calibrate=None, **kw):
        raise _Called(calibrate)

    monkeypatch.setattr(ins_output, "process", process)
    with pytest.raises(_Called) as e:
        main(["-q", "ins", str(cfg), "--out", str(tmp_path / "o"), *argv])
    assert e.value.args[0] is expected
