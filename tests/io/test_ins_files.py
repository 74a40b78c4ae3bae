"""The files a jaxnav ins config names (io.read_ins_*): read by format, each error naming file and config key."""

import numpy as np
import pytest
from _paths import DATA_ROOT

from jaxnav import io

WALK = DATA_ROOT / "rtklibexplorer-gnss-imu" / "walk_0827"
pytestmark = pytest.mark.skipif(not (WALK / "imu_1730.csv").exists(), reason=f"walk data not found at {WALK}")


@pytest.fixture(scope="module")
def cfg():
    return io.load_ins_config("walk_0827", variables={"JAXNAV_DATA": str(DATA_ROOT)})


def test_the_shipped_walk_reads(cfg):
    imu, pos = io.read_ins_inputs(cfg)
    assert np.asarray(imu.t).size > 20_000 and len(pos.t) == 536  # ~160 Hz IMU; the .pos README's 536 epochs
    assert abs(float(imu.t[0]) - float(pos.t[0])) < 5.0  # both GPST
    # no [evaluate] truth, [odometer] or [heading] section: nothing to read
    assert io.read_ins_truth(cfg) is None and io.read_ins_odometer(cfg) is None and io.read_ins_heading(cfg) is None


def test_a_missing_file_names_its_key(cfg, tmp_path):
    gone = tmp_path / "gone.pos"
    with pytest.raises(FileNotFoundError, match=r"gone\.pos: no such file \(.*walk_0827\.toml: gnss\.file\)"):
        io.read_ins_inputs(cfg._replace(gnss=cfg.gnss._replace(file=gone)))
    with pytest.raises(FileNotFoundError, match=r"a folder, not a file \(.*: imu\.file\)"):
        io.read_ins_inputs(cfg._replace(imu=cfg.imu._replace(file=tmp_path)))


def test_an_unreadable_line_names_file_and_line(cfg, tmp_path):
    bad = tmp_path / "bad.pos"
    bad.write_text("% header\n2025/08/28 17:30:39.749 40.0966916 -105.1471665 not-a-height 1 10\n")
    with pytest.raises(io.ReaderError, match=r"bad\.pos:2"):
        io.read_ins_inputs(cfg._replace(gnss=cfg.gnss._replace(file=bad)))
