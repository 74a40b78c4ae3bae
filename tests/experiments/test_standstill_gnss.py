"""Standstill detection of ``jaxnav ins`` on a simulated car cruising on a smooth road.

A car at constant speed with almost no vibration looks at rest to the IMU alone (constant specific
force, no rotation); the GNSS velocity says it moves, so no ZUPT may fall there, nor inside the GNSS
outages where nothing can check, while the two true stops (20 s at the start, 8 s in the middle)
must still get them.
"""

import numpy as np
import pytest
from _recording import car_config, write_car


@pytest.fixture(scope="module")
def car(tmp_path_factory):
    folder = tmp_path_factory.mktemp("smooth_car") / "data"
    rec = write_car(folder, vibration=0.02)
    # GNSS withheld on 60-80 s and 120-140 s, both while cruising: the IMU alone cannot check there
    p = car_config(rec, folder, time_offset=0.15, extra='[constraints]\nzupt = "auto"\n')
    return rec, p


@pytest.mark.parametrize("platform, velocity", [(None, True), ("car", True), ("rover", False)])
def test_no_zupt_while_cruising_and_zupt_at_stops(car, platform, velocity):
    """Default and car presets with the GNSS velocity; rover without it (speed from position differences)."""
    from jaxnav.experiments.ins_run import prepare
    from jaxnav.io import load_ins_config

    rec, p = car
    text = p.read_text()
    if platform is not None:
        text = text.replace("[run]\n", f'[run]\nplatform = "{platform}"\n')
    if not velocity:
        text = text.replace("[gnss]\n", "[gnss]\nuse_velocity = false\n")
    p = p.with_name(f"car_{platform}_{velocity}.toml")
    p.write_text(text)
    prep = prepare(load_ins_config(p), progress=lambda *a: None)
    t = prep.t - prep.t[0]
    speed = np.interp(t, np.asarray(rec.truth.t), np.linalg.norm(np.asarray(rec.truth.v_n), axis=1))
    st = np.asarray(prep.standstill)
    assert not np.any(st & (speed > 0.2)), f"ZUPT at speeds up to {speed[st].max():.1f} m/s"
    info = prep.standstill_info
    assert info["vetoed_samples"] > 0  # the IMU alone took the cruise for a stop
    assert info["unconfirmed_intervals"] >= 1  # and inside the outages
    # the stops: 0-20 s and the 8 s one (the middle of each, away from the start and stop transients)
    first, second = (t > 2.0) & (t < 18.0), (t > 82.0) & (t < 86.0)
    assert np.mean(st[first]) > 0.9 and np.mean(st[second]) > 0.9
    assert info["precision"] > 0.9 and info["recall"] > 0.8


def test_config_keys(car, tmp_path):
    from jaxnav.io import ConfigError, load_ins_config

    _, p = car
    cfg = load_ins_config(p)
    assert cfg.constraints.platform == "handheld" and cfg.constraints.detector_threshold == "auto"
    base = p.read_text()
    for old, new, key in (
        ("[run]\n", '[run]\nplatform = "boat"\n', "platform"),
        ('zupt = "auto"\n', 'zupt = "auto"\ndetector_threshold = "low"\n', "detector_threshold"),
        ('zupt = "auto"\n', 'zupt = "auto"\nzupt_gnss_k = -1.0\n', "zupt_gnss_k"),
    ):
        q = tmp_path / "bad.toml"
        q.write_text(base.replace(old, new))
        with pytest.raises(ConfigError, match=key):
            load_ins_config(q)


def test_slow_rover_default_preset(tmp_path):
    """A rover crawling at 0.3 m/s (no vibration) between stops: with the default preset no ZUPT while
    it moves, and its stops found."""
    import math

    from jaxnav import sim
    from jaxnav.experiments.ins_run import prepare
    from jaxnav.io import load_ins_config

    S = sim.Segment
    spec = sim.TrajectorySpec(
        lat=math.radians(40.1),
        lon=math.radians(-105.2),
        h=1600.0,
        heading=0.5,
        speed=0.0,
        segments=(
            S("rest", duration=20.0),
            S("accelerate", duration=3.0, dspeed=0.3),
            S("cruise", hold=20.0),
            S("accelerate", duration=3.0, dspeed=-0.3),
            S("rest", duration=10.0),
            S("accelerate", duration=3.0, dspeed=0.3),
            S("turn", duration=10.0, dheading=1.0),
            S("cruise", hold=10.0),
        ),
    )
    rec = write_car(tmp_path, vibration=0.0, spec=spec)
    p = car_config(rec, tmp_path, time_offset=0.15)
    text = p.read_text()
    text = text[: text.index("[evaluate]")].replace("min_speed_m_s = 3.0", "min_speed_m_s = 0.2")
    p.write_text(text + '[constraints]\nzupt = "auto"\n')
    prep = prepare(load_ins_config(p), progress=lambda *a: None)
    t = prep.t - prep.t[0]
    speed = np.interp(t, np.asarray(rec.truth.t), np.linalg.norm(np.asarray(rec.truth.v_n), axis=1))
    st = np.asarray(prep.standstill)
    assert not np.any(st & (speed > 0.15)), f"ZUPT at speeds up to {speed[st].max():.2f} m/s"
    assert np.mean(st[(t > 2.0) & (t < 18.0)]) > 0.9 and np.mean(st[(t > 48.0) & (t < 54.0)]) > 0.9
