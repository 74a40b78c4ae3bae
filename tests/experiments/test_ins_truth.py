"""``[evaluate] truth`` settings and files: every fault ends ``jaxnav ins`` with one line naming the
config key, or the truth file and line, before the filter runs (the end-to-end scoring of a simulated
car against its truth is in test_ins_simulated.py)."""

from __future__ import annotations

import pytest

from jaxnav.cli import main

HEAD = """[imu]
file = "imu.txt"
format = "kf-gins"
[gnss]
file = "gnss.txt"
format = "kf-gins"
[noise]
grade = "industrial"
[evaluate]
"""
TRUTH = "".join(f"2380 {345600 + 0.01 * k:.2f} 40.1 -105.2 1600.0 0.0 0.0 0.0 0.0 0.0 30.0\n" for k in range(10))


@pytest.fixture()
def folder(tmp_path):
    (tmp_path / "imu.txt").write_text("345600.01 0 0 0 0 0 -0.098\n")
    (tmp_path / "gnss.txt").write_text("345600.0 40.1 -105.2 1600.0 0.02 0.02 0.03\n")
    (tmp_path / "truth.nav").write_text(TRUTH)
    return tmp_path


@pytest.mark.parametrize(
    "evaluate, match",
    [
        ('truth = "missing.nav"\n', "missing.nav: no such file (%s: evaluate.truth)"),
        ('truth = "truth.nav"\ntruth_format = "nav"\n', "%s: evaluate.truth_format must be one of"),
        ('truth = "truth.nav"\ntruth_format = "csv"\n', "%s: evaluate.truth_columns is required"),
        ('truth_format = "kf-gins"\n', "%s: evaluate.truth_format is only used with truth = FILE"),
        (
            'truth = "truth.nav"\ntruth_columns = {t = 0}\n',
            "%s: evaluate.truth_columns is only used with truth_format = 'csv'",
        ),
        (
            'truth = "truth.nav"\ntruth_format = "csv"\ntruth_columns = {t = 0, speed = 1}\n',
            "%s: evaluate.truth_columns has unknown key 'speed'",
        ),
        (
            'truth = "truth.nav"\ntruth_format = "csv"\ntruth_columns = {t = 0, lat = 1, lon = 2, h = 3}\n'
            'truth_units = {angle = "grad"}\n',
            "%s: evaluate.truth_units angle = 'grad'",
        ),
        ('truth = "truth.nav"\ntruth_delimiter = ";;"\n', "%s: evaluate.truth_delimiter must be one character"),
        ("outages = false\n", "%s: evaluate.outages = false leaves nothing to evaluate"),
        ("truth = 3\n", "%s: evaluate.truth must be a string"),
    ],
)
def test_bad_truth_settings_named(folder, capsys, evaluate, match):
    cfg = folder / "run.toml"
    cfg.write_text(HEAD + evaluate)
    assert main(["ins", str(cfg), "--out", str(folder / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and (match % cfg) in err[0], err


def test_bad_truth_file_named_with_line(folder, capsys):
    lines = TRUTH.splitlines()
    lines[6] = lines[6].rsplit(" ", 1)[0]  # line 7 loses its yaw
    (folder / "truth_bad.nav").write_text("\n".join(lines) + "\n")
    cfg = folder / "run.toml"
    cfg.write_text(HEAD + 'truth = "truth_bad.nav"\n')
    assert main(["ins", str(cfg), "--out", str(folder / "o"), "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "truth_bad.nav:7: 10 fields, expected 11" in err[0], err
    # a CSV reference whose column map names a column the header lacks
    (folder / "ref.csv").write_text("t,lat,lon,h\n1,40.1,-105.2,1600\n")
    cfg.write_text(
        HEAD + 'truth = "ref.csv"\ntruth_format = "csv"\ntruth_columns = {t = "t", lat = "lat", lon = "lon", '
        'h = "height"}\n'
    )
    assert main(["ins", str(cfg), "--out", str(folder / "o"), "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "ref.csv:1: the header has no column 'height'" in err[0], err
