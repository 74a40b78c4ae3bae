"""``--tune`` with ``[evaluate]`` fits only on the GNSS epochs the filter sees.

The withheld fixes (inside the evaluation outages) are moved by 30 m: the fitted noise densities and
lever arm must not change, so the scores after tuning come from data the tuning never saw.
"""

import numpy as np
from _recording import car_config, write_car


def test_withheld_fixes_do_not_move_the_fit(tmp_path):
    from jaxnav.experiments.ins_run import prepare, tune_noise
    from jaxnav.io import load_ins_config

    rec = write_car(tmp_path)
    cfg = load_ins_config(car_config(rec, tmp_path, time_offset=0.15))
    prep = prepare(cfg, progress=None)
    w = np.asarray(prep.withheld)
    assert w.sum() > 20
    pos = np.asarray(prep.meas.pos).copy()
    pos[w, 0] += 30.0 / 6.4e6  # 30 m north
    moved = prep._replace(meas=prep.meas._replace(pos=pos))
    names = ["arw", "vrw", "lever_arm"]
    a = tune_noise(prep, names, max_evals=5)
    b = tune_noise(moved, names, max_evals=5)
    for n in names:
        np.testing.assert_allclose(b.after[n], a.after[n], rtol=1e-9, atol=1e-12)
    assert a.n_epochs == int((np.asarray(prep.meas.mask)[:, :3].any(-1)).sum())
    assert "outside the [evaluate] outages" in a.fitted_on
    assert any(not np.allclose(a.after[n], a.before[n], rtol=1e-6) for n in names)  # the fit moved at all
