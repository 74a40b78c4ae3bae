"""What every command shares (issue 21): ``--version``, ``-q``/``-v`` through ``logging``, progress
without carriage returns off a terminal, ``--figure-format``, the provenance block and files list of
``results.json``, the rtk CSV's units/CRS header, strict unit-suffixed JSON. In process
through ``jaxnav.cli.main``, on the smallest inputs (a 2-point epoch log)."""

from __future__ import annotations

import io
import logging

import numpy as np
import pytest
from _outputs import check_provenance

import jaxnav
from jaxnav._progress import Progress
from jaxnav.cli import main

#: a 2-point epoch log, 5 epochs each, mm-level scatter (x, y, h and B, L, H)
EPOCHS = "point,time,x,y,h,B,L,H,sigma_x,sigma_y,sigma_h\n" + "".join(
    f"P{p},{2 * k},{3631500 + 0.004 * ((3 * k) % 5 - 2):.4f},{39486000.5 + 0.003 * ((2 * k) % 5 - 2):.4f},"
    f"{22.1 + 0.006 * ((4 * k) % 5 - 2):.4f},{32.81 + 1e-8 * ((3 * k) % 5 - 2):.10f},"
    f"{116.85 + 1e-8 * ((2 * k) % 5 - 2):.10f},{18.6 + 0.006 * ((4 * k) % 5 - 2):.4f},0.008,0.008,0.015\n"
    for p in range(2)
    for k in range(5)
)


def test_version(capsys):
    assert main(["--version"]) == 0
    assert capsys.readouterr().out == f"jaxnav {jaxnav.__version__}\n"
    assert main(["-q", "--version"]) == 0


@pytest.fixture(scope="module")
def epochs(tmp_path_factory):
    d = tmp_path_factory.mktemp("ep")
    (d / "ep.csv").write_text(EPOCHS)
    return d


@pytest.mark.parametrize("where", ["before", "after"])
def test_quiet_verbose_and_outputs_of_rtk(epochs, tmp_path, capsys, where):
    """Default: stage lines on stderr; -q: none (summary on stdout still); -v: debug lines too. The
    option works before and after the command. Also: rtk's results.json, rtk_results.json
    provenance, the CSV header and a PDF beside each PNG with --figure-format."""
    f = str(epochs / "ep.csv")
    runs = {}
    for flag in ("", "-q", "-v"):
        out = tmp_path / (flag.strip("-") or "default")
        opts = [flag] if flag else []
        argv = (opts + ["rtk", f, "--out", str(out)]) if where == "before" else (["rtk", f, "--out", str(out)] + opts)
        if flag == "-v":  # the formats as words (before the FILE) or as a comma list
            argv = (
                argv[:-3] + ["--figure-format", "pdf", "svg", f] + argv[-2:]
                if where == "before"
                else argv + ["--figure-format", "pdf,svg"]
            )
        if flag == "":  # a folder used before: its old results.json is replaced, its old files not listed
            out.mkdir()
            (out / "results.json").write_text('{"stale": true}')
            (out / "old.txt").write_text("x")
        assert main(argv) == 0
        cap = capsys.readouterr()
        runs[flag] = (cap.out, cap.err, out, argv)
    out_d, err_d, out0, argv0 = runs[""]
    res0 = check_provenance(out0, argv0, json_name="rtk_results.json")
    assert "stale" not in res0 and "old.txt" not in res0["files"] and res0["results_in"] == ["rtk_results.json"]
    assert "reading 1 file(s)" in err_d and "filtering 2 point(s)" in err_d and "debug:" not in err_d
    out_q, err_q, _, _ = runs["-q"]
    assert err_q == "" and "S2 pipeline: 2 points" in out_q  # the summary still shows
    out_v, err_v, out, argv = runs["-v"]
    assert "reading 1 file(s)" in err_v and "debug: " in err_v
    assert "\r" not in err_d + err_q + err_v
    # provenance in results.json and rtk_results.json; every file written listed
    res = check_provenance(out, argv, json_name="rtk_results.json")
    assert res["provenance"]["options"]["figure_formats"] == ["pdf", "svg"]
    assert {"rtk.png", "rtk.pdf", "rtk.svg", "rtk_results.csv", "rtk_results.json"} <= set(res["files"])
    # the CSV: # lines with CRS (PROJ), zone, height system, units; then unit-suffixed column names
    lines = (out / "rtk_results.csv").read_text().splitlines()
    head = [ln for ln in lines if ln.startswith("#")]
    assert lines[: len(head)] == head and len(lines) == len(head) + 1 + 2
    text = "\n".join(head)
    for needle in (
        "# crs: WGS-84 Gauss-Krueger",
        "+proj=tmerc",
        "+lon_0=117",
        "# zone: central meridian 117 deg",
        "# height system: WGS-84 ellipsoidal",
        "# time system: GPST",
        "# units: suffix _m metres",
    ):
        assert needle in text, needle
    cols = lines[len(head)].split(",")
    assert cols[:6] == ["point", "n_epochs", "x_m", "y_m", "h_m", "H_ellipsoidal_m"]
    assert all(c in ("point", "n_epochs") or c.endswith(("_m", "_mm", "_cm")) for c in cols), cols
    t = np.genfromtxt(
        out / "rtk_results.csv", delimiter=",", names=True, dtype=None, encoding="utf-8", skip_header=len(head)
    )
    assert t["n_epochs"].tolist() == [5, 5]


def test_progress_plain_lines_without_carriage_returns():
    s = io.StringIO()
    with Progress(100, "sweep", unit="run", stream=s, tty=False) as p:
        for _ in range(50):
            p.update(2)
    lines = s.getvalue().splitlines()
    assert "\r" not in s.getvalue() and 10 <= len(lines) <= 12  # the first update, every 10 %, the end
    assert lines[-1].startswith("sweep: 100/100 runs (100 %")
    s2 = io.StringIO()
    with Progress(3, "x", stream=s2, tty=False, enabled=False) as p:
        p.update(3)
    assert s2.getvalue() == ""


def test_progress_estimates_the_time_left_after_the_first_chunk(monkeypatch):
    """A long sweep says how long it will take: after the first chunk at that chunk's rate (which may
    include compiling), then from the rate after it; the last line has none."""
    import jaxnav._progress as prog

    clock = iter([0.0, 30.0, 35.0, 40.0, 45.0, 50.0])
    monkeypatch.setattr(prog.time, "monotonic", lambda: next(clock))
    s = io.StringIO()
    with Progress(100, "sweep", unit="run", stream=s, tty=False) as p:
        for _ in range(5):
            p.update(20)
    lines = s.getvalue().splitlines()
    assert lines[0] == "sweep: 20/100 runs (20 %, 30 s, about 120 s left at the first chunk's rate)"
    assert lines[1] == "sweep: 40/100 runs (40 %, 35 s, about 15 s left)"  # 5 s per 20 runs once compiled
    assert lines[-1] == "sweep: 100/100 runs (100 %, 50 s)"


def test_progress_silent_when_the_logger_is_quiet():
    log = logging.getLogger("jaxnav")
    old = log.level
    log.setLevel(logging.WARNING)
    try:
        s = io.StringIO()
        with Progress(5, "x", stream=s, tty=False) as p:
            p.update(5)
        assert s.getvalue() == ""
    finally:
        log.setLevel(old)


def test_progress_bar_on_a_terminal():
    s = io.StringIO()
    with Progress(4, "bar", stream=s, tty=True) as p:
        p.update(4)
    assert "\r" in s.getvalue() and "4/4" in s.getvalue()  # tqdm


def test_figure_format_is_checked(capsys):
    assert main(["rtk", "x.csv", "--figure-format", "gif"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "gif" in err and "png, pdf, svg" in err


def test_every_command_has_its_own_default_folder():
    import argparse

    from jaxnav.cli import _modules

    defaults = {}
    sub = argparse.ArgumentParser().add_subparsers()
    for mod in _modules():
        p = mod.register(sub)
        defaults[p.prog.split()[-1]] = p.get_default("out")
    assert defaults.pop("ins") is None  # out/ins/<config name>, chosen after reading the config
    assert defaults == {c: f"out/{c}" for c in defaults}, defaults
