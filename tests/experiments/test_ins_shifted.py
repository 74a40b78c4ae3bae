"""``[evaluate] shifts``: the outage protocol repeated with shifted starts, each shift a run of its own.

A short simulated car (110 s, 25 Hz IMU, 2 Hz RTK-level GNSS, no reference trajectory: scored against the
withheld fixes) with the noise calibration forced on. Checked: the ``evaluation.shifted_outages`` keys,
shift 0 equal to the unshifted protocol, and that nothing fitted for shift 1 saw the GNSS epochs shift 1
withholds: moving those fixes by 30 m leaves shift 1's calibrated noise as it was (while its scores,
taken on exactly those fixes, move by the 30 m).
"""

import json

import numpy as np
import pytest
from _recording import car_config, short_car_spec, write_car

EVALUATE = "first_s = 40.0\noutage_s = 15.0\ngap_s = 20.0\nend_margin_s = 5.0\nshifts = 2"


def test_shifted_outages_fitted_per_shift(tmp_path, capsys):
    from jaxnav.cli import main
    from jaxnav.experiments.ins_output import _densities_dict
    from jaxnav.experiments.ins_run import fit_and_run, shifted_config
    from jaxnav.ins import in_windows
    from jaxnav.io import load_ins_config, read_ins_inputs

    rec = write_car(tmp_path, spec=short_car_spec(), imu_rate=25.0, vibration=0.0)
    cfg_path = car_config(
        rec, tmp_path, time_offset=0.15, tune="calibrate = true\ncalibrate_steps = 3", evaluate=EVALUATE
    )
    out = tmp_path / "out"
    assert main(["ins", str(cfg_path), "--out", str(out), "-q"]) == 0
    assert "shifted outages: 2 schedules 17.5 s apart" in capsys.readouterr().out
    r = json.loads((out / "results.json").read_text())
    so = r["evaluation"]["shifted_outages"]
    assert so["shifts"] == 2 and so["shift_s"] == 17.5 and "withheld fixed-quality GNSS" in so["reference"]
    assert "shifted_outages.png" in r["files"] and "fitted again per shift" in r["tuning"]["shifted_outages"]
    for w in ("forward", "smoothed"):  # horizontal only without a reference trajectory
        assert set(so[w]) == {
            "n_outages",
            "n_unscored_outages",
            "rms_of_max_h_drift_m",
            "mean_of_max_h_drift_m",
            "max_of_max_h_drift_m",
        }
    rows, sh = so["per_outage"], so["per_shift"]
    assert so["n_outages"] == len(rows) >= 3 and [s["shift"] for s in sh] == [0, 1]
    # shift 0 is the unshifted protocol: the windows and numbers of `evaluation`
    s0 = [o for o in rows if o["shift"] == 0]
    ev = r["evaluation"]["windows"]
    assert [(o["gpst_start_s"], o["forward_max_h_m"], o["smoothed_max_h_m"]) for o in s0] == [
        (w["gpst_start_s"], w["forward_max_h_m"], w["smoothed_max_h_m"]) for w in ev
    ]
    assert sh[0]["noise"] == r["noise"] and sh[0]["noise_calibrated"] and sh[1]["noise_calibrated"]
    fwd = np.array([o["forward_max_h_m"] for o in rows])
    assert so["forward"]["rms_of_max_h_drift_m"] == pytest.approx(np.sqrt(np.mean(fwd**2)))
    assert so["forward"]["max_of_max_h_drift_m"] == pytest.approx(fwd.max())
    assert sh[1]["noise"] != sh[0]["noise"]  # shift 1 calibrated on its own epochs, not shift 0's

    # shift 1's withheld fixes moved 30 m north: shift 1's fits must not notice, its scores must
    cfg = load_ins_config(cfg_path)
    imu, pos = read_ins_inputs(cfg)
    w1 = np.array([[o["gpst_start_s"], o["gpst_end_s"]] for o in rows if o["shift"] == 1])
    moved = in_windows(pos.t, w1)
    assert moved.sum() >= 25
    pos_moved = pos._replace(lat=np.where(moved, np.asarray(pos.lat) + 30.0 / 6.37e6, pos.lat))
    fr = fit_and_run(shifted_config(cfg, 1), imu=imu, pos=pos_moved, calibrate=True)
    np.testing.assert_array_equal(fr.prep.outages, w1)
    got, ref = _densities_dict(fr.run.densities), sh[1]["noise"]
    assert got.keys() == ref.keys()
    for k in ref:
        assert got[k] == pytest.approx(ref[k], rel=1e-9, abs=0.0), k
    s1 = np.array([o["forward_max_h_m"] for o in rows if o["shift"] == 1])
    assert np.all(np.abs(fr.run.scores.fwd_max - s1) > 20.0)  # the scored fixes are the moved ones
