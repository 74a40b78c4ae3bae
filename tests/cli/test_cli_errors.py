"""Bad command lines, configs and files through ``jaxnav.cli.main(argv)`` (in process, fast): each
ends with exit status 2 and exactly one stderr line ``jaxnav CMD: ...`` naming the option, file
(and line) or config key, no traceback, and before any computation (no output written). Plus the
--debug and internal-error paths, strict JSON, and two real subprocess runs."""

from __future__ import annotations

import json
import math
import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest
from _paths import ROOT

from jaxnav.cli import main
from jaxnav.experiments.s0 import EXPERIMENT
from jaxnav.io import json_ready, write_json

EPOCHS = "point,time,x,y,h,B,L,H,sigma_x,sigma_y,sigma_h\n" + "".join(
    f"P{p},{2 * k},3631500.{k:04d},39486000.5,22.1,32.81,116.85,18.6,0.008,0.008,0.015\n"
    for p in range(2)
    for k in range(5)
)
CONTROL = "point,B,L,H,x,y,h\n" + "".join(
    f"K{i},{32.80 + 0.001 * i:.6f},{116.84 + 0.001 * i:.6f},18.0,{3631000 + 100 * i},{39486000 + 90 * i},21.5\n"
    for i in range(6)
)
TENV3 = (
    "site YYMMMDD yyyy.yyyy __MJD week d reflon _e0(m) __east(m) ____n0(m) _north(m) u0(m) ____up(m) _ant(m) "
    "sig_e(m) sig_n(m) sig_u(m) __corr_en __corr_eu __corr_nu _latitude(deg) _longitude(deg) __height(m)\n"
    + "".join(
        f"LHAS 95MAY{19 + k} {1995.3785 + k / 365.25:.4f} {49856 + k}  {801 + (5 + k) // 7} {(5 + k) % 7}   91.1    385  0.888603   "
        f"3282129  0.602585  3624  0.707878  0.0000 0.002231 0.001932 0.008643 -0.009728 -0.044382 "
        f"-0.198749  29.6573392384 -268.8960142076  3624.70788\n"
        for k in range(6)
    )
)


def _s0_config(tmp_path, name, old, new):
    text = EXPERIMENT.read_text()
    assert old in text
    f = tmp_path / name
    f.write_text(text.replace(old, new, 1))
    return f


def _tune_config(tmp_path, name, extra_or_replace):
    base = (ROOT / "jaxnav/experiments/configs/s0_b.toml").read_text()
    if isinstance(extra_or_replace, tuple):
        old, new = extra_or_replace
        assert old in base
        base = base.replace(old, new, 1)
    else:
        base += extra_or_replace
    f = tmp_path / name
    f.write_text(base)
    return f


def _files(tmp_path):
    """The files the cases name: good and bad inputs, an existing file to misuse as --out."""
    d = {}
    (tmp_path / "ep.csv").write_text(EPOCHS)
    d["ep"] = tmp_path / "ep.csv"
    (tmp_path / "cp_inf.csv").write_text(CONTROL.replace("K2,32.802000", "K2,inf"))
    d["cp_inf"] = tmp_path / "cp_inf.csv"
    (tmp_path / "ep_e9.csv").write_bytes(EPOCHS.encode().replace(b"P1,2,", b"P1\xe9,2,"))
    d["ep_e9"] = tmp_path / "ep_e9.csv"
    (tmp_path / "lev_nan.csv").write_text("point,height\nP0,nan\n")
    d["lev_nan"] = tmp_path / "lev_nan.csv"
    (tmp_path / "bad.tenv3").write_text(TENV3.replace("3282129  0.602585", "3282129  inf", 1))
    d["tenv3_inf"] = tmp_path / "bad.tenv3"
    (tmp_path / "lat.tenv3").write_text(TENV3.replace("29.6573392384", "129.6573392384", 1))
    d["tenv3_lat"] = tmp_path / "lat.tenv3"
    (tmp_path / "LHAS.tenv3").write_text(TENV3)
    d["tenv3_ok"] = tmp_path / "LHAS.tenv3"
    (tmp_path / "steps_bad.txt").write_text("# station date kind\nLHAS 2003-01-01 equipment\nLHAS 2004-01-01 antenna\n")
    d["steps_bad"] = tmp_path / "steps_bad.txt"
    (tmp_path / "a_file").write_text("not a folder")
    d["a_file"] = tmp_path / "a_file"
    d["b15"] = _s0_config(tmp_path, "b15.toml", "b = 0.254", "b = 1.5")
    d["bneg"] = _s0_config(tmp_path, "bneg.toml", "b = 0.254", "b = -0.1")
    d["seeds0"] = _s0_config(tmp_path, "seeds0.toml", "seeds = 32", "seeds = 0")
    d["unknown_key"] = _s0_config(tmp_path, "unk.toml", "fading_window = 10", "fading_window = 10\nfadng = 3")
    d["missing_key"] = _s0_config(tmp_path, "miss.toml", "fading_window = 10", "")
    d["syntax"] = _s0_config(tmp_path, "syntax.toml", "q_scale = 1.0", "q_scale = = 1.0")
    d["states"] = _s0_config(
        tmp_path, "states.toml", "inflate_states = [0, 1, 3, 4, 5, 6, 7, 8]", "inflate_states = [0, 99]"
    )
    d["nstates"] = _s0_config(tmp_path, "nstates.toml", "n_states = 18", "n_states = 17")
    d["qneg"] = _s0_config(tmp_path, "qneg.toml", "q_scale = 1.0", "q_scale = -1.0")
    d["bool_seeds"] = _s0_config(tmp_path, "bool.toml", "seeds = 32", "seeds = true")
    (tmp_path / "latin1.toml").write_bytes(EXPERIMENT.read_bytes().replace(b"# The S0", b"# The S0 \xe9", 1))
    d["latin1"] = tmp_path / "latin1.toml"
    d["t_seeds0"] = _tune_config(tmp_path, "t_seeds0.toml", ("seeds = 8", "seeds = 0"))
    d["t_init"] = _tune_config(tmp_path, "t_init.toml", ("init = 0.5", "init = 1.5"))
    d["t_num0"] = _tune_config(tmp_path, "t_num0.toml", ("num = 100", "num = 0"))
    d["t_steps0"] = _tune_config(tmp_path, "t_steps0.toml", ("steps = 12", "steps = 0"))
    d["t_lr"] = _tune_config(tmp_path, "t_lr.toml", ("learning_rate = 0.5", "learning_rate = -0.5"))
    d["t_mode"] = _tune_config(tmp_path, "t_mode.toml", ('mode = "forward"', 'mode = "sideways"'))
    d["t_unknown"] = _tune_config(tmp_path, "t_unk.toml", ("[tune]", "[tune]\nmomentum = 0.9"))
    d["t_param"] = _tune_config(tmp_path, "t_param.toml", ("[params.b]\ninit = 0.5", "[params.b]\ninit = true"))
    d["t_dur"] = _tune_config(tmp_path, "t_dur.toml", ("duration = 2000.0", "duration = -5.0"))
    ins = '[imu]\nfile = "imu.csv"\ntag = "imu.csv.tag"\n[gnss]\nfile = "sol.pos"\n[noise]\ngrade = "consumer"\n'
    (tmp_path / "ins_nofile.toml").write_text(ins)
    d["ins_nofile"] = tmp_path / "ins_nofile.toml"
    (tmp_path / "ins_badkey.toml").write_text(ins + "[evaluate]\noutage = 15\n")
    d["ins_badkey"] = tmp_path / "ins_badkey.toml"
    (tmp_path / "ins_pos.toml").write_text(
        ins.replace('file = "imu.csv"', f'file = "{d["a_file"]}"')
        .replace('tag = "imu.csv.tag"', f'tag = "{d["a_file"]}"')
        .replace('file = "sol.pos"', f'file = "{d["a_file"]}"')
    )
    d["ins_pos"] = tmp_path / "ins_pos.toml"
    (tmp_path / "ins_dir.toml").write_text(
        ins.replace('file = "imu.csv"', f'file = "{d["a_file"]}"')
        .replace('tag = "imu.csv.tag"', f'tag = "{d["a_file"]}"')
        .replace('file = "sol.pos"', f'file = "{tmp_path}"')
    )
    d["ins_dir"] = tmp_path / "ins_dir.toml"
    for name, sec, line in INS_RANGE_CASES:
        text = (
            ins.replace('grade = "consumer"\n', 'grade = "consumer"\n' + line + "\n")
            if sec == "noise"
            else ins + f"[{sec}]\n{line}\n"
        )
        (tmp_path / f"ins_{name}.toml").write_text(text)
        d[f"ins_{name}"] = tmp_path / f"ins_{name}.toml"
    for name, line in (
        ("rw15", "gyro_bias_rw_deg_per_h_per_sqrt_h = 0.1"),
        ("arw15", "accel_bias_rw_mg_per_sqrt_h = 0.01"),
        ("gbi15", "gyro_bias_instability_deg_per_h = 10.0"),
    ):
        (tmp_path / f"ins_{name}.toml").write_text(ins.replace('grade = "consumer"\n', f'grade = "consumer"\n{line}\n'))
        d[f"ins_{name}"] = tmp_path / f"ins_{name}.toml"
    from jaxnav.sim import _cadastral

    cad = (pathlib.Path(_cadastral.__file__).parent / "scenarios/cadastral.toml").read_text()
    for name, old, new in CADASTRAL_RANGE_CASES:
        assert old in cad, old
        (tmp_path / f"cad_{name}.toml").write_text(cad.replace(old, new, 1))
        d[f"cad_{name}"] = tmp_path / f"cad_{name}.toml"
    (tmp_path / "rtklibexplorer-gnss-imu").mkdir()  # a data set's own folder given where its parent belongs
    d["walkset"] = tmp_path / "rtklibexplorer-gnss-imu"
    (tmp_path / "cad_unsampled.toml").write_text(
        cad.replace("imu_rate_hz = 100.0", "imu_rate_hz = 10.0", 1).replace("accel_s = 2.0 ", "accel_s = 0.05 ", 1)
    )
    d["cad_unsampled"] = tmp_path / "cad_unsampled.toml"
    d["stops_bad"] = tmp_path / "stops.csv"
    d["stops_bad"].write_text("K0, known_coordinate, 0, 10, 132.0, 118.0, 10.0\n")
    return d


#: (name, section, TOML line) of ``jaxnav ins`` config values outside their plausible range
INS_RANGE_CASES = [
    ("arw_huge", "noise", "arw_deg_per_sqrt_h = 1e300"),
    ("arw_1e6", "noise", "arw_deg_per_sqrt_h = 1e6"),
    ("vrw_tiny", "noise", "vrw_m_per_s_per_sqrt_h = 1e-300"),
    ("abias", "noise", "init_accel_bias_mg = 150000"),
    ("gbi", "noise", "gyro_bias_instability_deg_per_h = 1e9"),
    ("tau", "noise", "bias_correlation_time_s = 1e-9"),
    ("gbias", "noise", "init_gyro_bias_deg_per_s = 500.0"),
    ("scale", "noise", "init_gyro_scale_ppm = 1e9"),
    ("static", "alignment", "static_s = 1e-9"),
    ("zupt_rate", "constraints", "zupt_rate_hz = 1e9"),
    ("nhc_lever", "constraints", "nhc_lever_frd_m = [0, 0, 1e6]"),
    ("first", "evaluate", "first_s = 1e9"),
    ("outage", "evaluate", "outage_s = 1e6"),
]
#: (name, text in the shipped cadastral.toml, its replacement) outside the plausible ranges
CADASTRAL_RANGE_CASES = [
    ("rate0", "imu_rate_hz = 100.0", "imu_rate_hz = 0.0"),
    ("speed", "speed_mps = 1.2", "speed_mps = -1.2"),
    ("lat", "lat_deg = 32.06", "lat_deg = 132.06"),
    ("stop", "stop_s = 10.0", "stop_s = 1e9"),
    ("arw", "arw_deg_per_sqrt_h = 0.05", "arw_deg_per_sqrt_h = 1e300"),
    ("bias", "bias_mg = 0.3", "bias_mg = -0.3"),
    ("pipe", "outlier_k = 6.0", "outlier_k = 0.0"),
    ("pipe_key", "outlier_k = 6.0", "outlier_kk = 6.0"),
]

#: (case id, argv with {name} placeholders for _files, strings the one stderr line must contain)
CASES = (
    [
        ("no command", [], ["jaxnav:", "command"]),
        ("unknown command", ["fly"], ["jaxnav:", "'fly'"]),
        ("unknown option", ["demo", "--frobnicate"], ["--frobnicate"]),
        ("demo seeds 0", ["demo", "--seeds", "0"], ["jaxnav demo:", "--seeds", "[1, 100000]", "got 0"]),
        ("demo seeds -1", ["demo", "--seeds", "-1"], ["--seeds", "got -1"]),
        ("demo seeds text", ["demo", "--seeds", "many"], ["--seeds", "'many'"]),
        ("demo seeds float", ["demo", "--seeds", "2.5"], ["--seeds", "'2.5'"]),
        ("demo sweep-points 0", ["demo", "--sweep-points", "0"], ["--sweep-points", ">= 1"]),
        ("demo config missing", ["demo", "--config", "{tmp}/nope.toml"], ["nope.toml", "no such file", "--config"]),
        ("demo config b=1.5", ["demo", "--config", "{b15}"], ["b15.toml", "filter.b = 1.5 must be < 1"]),
        ("demo config b=-0.1", ["demo", "--config", "{bneg}"], ["bneg.toml", "filter.b = -0.1"]),
        ("demo config seeds=0", ["demo", "--config", "{seeds0}"], ["seeds0.toml", "monte_carlo.seeds = 0"]),
        ("demo config unknown key", ["demo", "--config", "{unknown_key}"], ["unk.toml", "unknown key filter.fadng"]),
        (
            "demo config missing key",
            ["demo", "--config", "{missing_key}"],
            ["miss.toml", "filter.fading_window is required"],
        ),
        ("demo config syntax", ["demo", "--config", "{syntax}"], ["syntax.toml", "invalid TOML", "line"]),
        ("demo config states", ["demo", "--config", "{states}"], ["states.toml", "filter.inflate_states", "[0, 17]"]),
        (
            "demo config n_states",
            ["demo", "--config", "{nstates}"],
            ["nstates.toml", "filter.n_states must be one of [15, 18]"],
        ),
        ("demo config q_scale<0", ["demo", "--config", "{qneg}"], ["qneg.toml", "filter.q_scale = -1.0"]),
        (
            "demo config bool seeds",
            ["demo", "--config", "{bool_seeds}"],
            ["bool.toml", "monte_carlo.seeds must be an integer"],
        ),
        ("demo config latin-1", ["demo", "--config", "{latin1}"], ["latin1.toml:", "not UTF-8", "0xE9"]),
        ("demo out is a file", ["demo", "--out", "{a_file}"], ["a_file", "--out", "existing file"]),
        ("demo out under a file", ["demo", "--out", "{a_file}/sub"], ["a_file/sub", "cannot write the output folder"]),
        ("demo-filters b 1.5", ["demo-filters", "--b", "1.5"], ["jaxnav demo-filters:", "--b", "[0, 1)"]),
        ("demo-filters b -0.1", ["demo-filters", "--b", "-0.1"], ["--b", "got -0.1"]),
        ("demo-filters b nan", ["demo-filters", "--b", "nan"], ["--b", "finite"]),
        ("demo-filters b inf", ["demo-filters", "--b", "inf"], ["--b", "finite"]),
        ("demo-filters epochs 0", ["demo-filters", "--epochs", "0"], ["--epochs", "[100, 1e+06]"]),
        ("demo-filters seeds 0", ["demo-filters", "--seeds", "0"], ["--seeds"]),
        ("demo-filters out is a file", ["demo-filters", "--out", "{a_file}"], ["a_file", "existing file"]),
        ("ins config missing", ["ins", "{tmp}/nope.toml"], ["jaxnav ins:", "nope.toml", "no such config file"]),
        ("ins not shipped", ["ins", "no_such_name"], ["jaxnav ins:", "not a shipped config", "walk_0827"]),
        ("ins data file missing", ["ins", "{ins_nofile}", "--out", "{tmp}/o"], ["imu.csv", "no such file", "imu.file"]),
        ("ins unknown key", ["ins", "{ins_badkey}"], ["ins_badkey.toml", "unknown key evaluate.outage"]),
        ("ins unreadable files", ["ins", "{ins_pos}", "--out", "{tmp}/o"], ["a_file"]),
        ("ins gnss file is a folder", ["ins", "{ins_dir}", "--out", "{tmp}/o"], ["a folder, not a file", "gnss.file"]),
        # a density the chosen error model has no state for is refused, naming the state counts that use it
        (
            "ins bias rw with 15 states",
            ["ins", "{ins_rw15}", "--out", "{tmp}/o"],
            ["ins_rw15.toml", "noise.gyro_bias_rw_deg_per_h_per_sqrt_h is used only with states = 21", "states = 15"],
        ),
        (
            "ins accel bias rw with 15 states",
            ["ins", "{ins_arw15}", "--out", "{tmp}/o"],
            ["ins_arw15.toml", "noise.accel_bias_rw_mg_per_sqrt_h is used only with states = 21"],
        ),
        (
            "ins bias instability with 15 states",
            ["ins", "{ins_gbi15}", "--out", "{tmp}/o"],
            ["ins_gbi15.toml", "noise.gyro_bias_instability_deg_per_h is used only with states = 18 or 21"],
        ),
        ("rtk same file twice", ["rtk", "{ep}", "{ep}", "--out", "{tmp}/o"], ["point 'P0' also appears in"]),
        (
            "ins data folder missing",
            ["ins", "walk_0827", "--data", "{tmp}/no_data"],
            ["no_data", "no such data folder"],
        ),
        ("walk data missing", ["walk", "--data", "{tmp}/no_data"], ["jaxnav walk:", "no_data", "no such data folder"]),
        # --data is the folder that holds the data sets in every command, relative to the working directory,
        # and the message names the folder searched
        (
            "walk data relative",
            ["walk", "--data", "no_data"],
            ["{tmp}/no_data: no such data folder (--data = no_data)"],
        ),
        ("ins data relative", ["ins", "walk_0827", "--data", "no_data"], ["{tmp}/no_data: no such data folder"]),
        (
            "walk data is the set itself",
            ["walk", "--data", "{walkset}"],
            ["rtklibexplorer-gnss-imu/rtklibexplorer-gnss-imu: no such data folder", "looks like the data set itself"],
        ),
        (
            "walk data without the files",
            ["walk", "--data", "."],
            ["{tmp}/rtklibexplorer-gnss-imu/walk_0827/imu_1730.csv: no such file", "imu.file"],
        ),
        (
            "ins data without the files",
            ["ins", "walk_0827", "--data", "."],
            ["{tmp}/rtklibexplorer-gnss-imu/walk_0827/imu_1730.csv: no such file", "imu.file"],
        ),
        (
            "cadastral data is the set itself",
            ["cadastral", "--out", "{tmp}/c", "--data", "{walkset}"],
            ["looks like the data set itself"],
        ),
        ("rtk nothing", ["rtk"], ["jaxnav rtk:", "give FILES or --simulate"]),
        ("rtk missing file", ["rtk", "{tmp}/none.pos"], ["none.pos", "no such file"]),
        (
            "rtk control K2,inf",
            ["rtk", "{ep}", "--control", "{cp_inf}", "--out", "{tmp}/o"],
            ["cp_inf.csv:4:", "column 'B'", "'inf' is not a finite number"],
        ),
        (
            "rtk epoch log 0xE9",
            ["rtk", "{ep_e9}", "--out", "{tmp}/o"],
            ["ep_e9.csv:8:", "not UTF-8", "0xE9 at column 3"],
        ),
        (
            "rtk levelling nan",
            ["rtk", "{ep}", "--levelling", "{lev_nan}", "--out", "{tmp}/o"],
            ["lev_nan.csv:2:", "column 'height'", "not a finite number"],
        ),
        ("rtk control missing", ["rtk", "{ep}", "--control", "{tmp}/cp.csv"], ["cp.csv", "no such file", "--control"]),
        ("rtk step 0", ["rtk", "{ep}", "--step", "0"], ["--step", "(0, 86400]", "got 0"]),
        ("rtk window 0", ["rtk", "{ep}", "--window", "0"], ["--window", "[1, 1e+06]"]),
        ("rtk min-epochs > window", ["rtk", "{ep}", "--min-epochs", "90"], ["--min-epochs 90", "--window 60"]),
        ("rtk lon0 1000", ["rtk", "{ep}", "--lon0", "1000"], ["--lon0", "[-180, 360]"]),
        ("rtk zone width 4", ["rtk", "{ep}", "--zone-width", "4"], ["--zone-width", "invalid choice"]),
        ("rtk simulate -1", ["rtk", "--simulate", "-1"], ["--simulate", "got -1"]),
        ("rtk out is a file", ["rtk", "{ep}", "--out", "{a_file}"], ["a_file", "--out"]),
        ("monitor nothing", ["monitor"], ["jaxnav monitor:", "give daily series files"]),
        ("monitor missing file", ["monitor", "{tmp}/x.neu"], ["x.neu", "no such file"]),
        (
            "monitor tenv3 inf",
            ["monitor", "{tenv3_inf}", "--out", "{tmp}/o"],
            ["bad.tenv3:2:", "north = inf m", "not finite"],
        ),
        ("monitor tenv3 latitude", ["monitor", "{tenv3_lat}", "--out", "{tmp}/o"], ["lat.tenv3:2:", "latitude", "90"]),
        ("monitor unknown suffix", ["monitor", "{ep}", "--out", "{tmp}/o"], ["ep.csv", "unknown daily-series format"]),
        ("monitor period 0", ["monitor", "{tenv3_inf}", "--period", "0"], ["--period", ">= 1"]),
        ("monitor gross 2", ["monitor", "--simulate", "--gross", "2"], ["--gross", "[0, 1]"]),
        ("monitor stations 0", ["monitor", "--simulate", "--stations", "0"], ["--stations"]),
        ("monitor epochs 1", ["monitor", "--simulate", "--epochs", "1"], ["--epochs"]),
        ("monitor seed -1", ["monitor", "--simulate", "--seed", "-1"], ["--seed"]),
        ("monitor kappa 0", ["monitor", "{tenv3_inf}", "--kappa", "0"], ["--kappa 0", "(-2, 0)"]),
        ("monitor kappa word", ["monitor", "{tenv3_inf}", "--kappa", "pink"], ["--kappa", "'estimate'"]),
        ("monitor step no station", ["monitor", "{tenv3_inf}", "--step", "2003.5"], ["--step", "STATION:DATE"]),
        ("monitor step bad date", ["monitor", "{tenv3_inf}", "--step", "LHAS:2003-13-01"], ["--step", "2003-13-01"]),
        (
            "monitor step unknown station",
            ["monitor", "{tenv3_ok}", "--step", "XXXX:2010-01-01", "--out", "{tmp}/o"],
            ["--step XXXX", "no such station", "LHAS"],
        ),
        ("monitor files and simulate", ["monitor", "--simulate", "{tenv3_inf}"], ["not both"]),
        (
            "monitor steps file missing",
            ["monitor", "{tenv3_ok}", "--steps-file", "{tmp}/none.txt"],
            ["none.txt", "no such file", "--steps-file"],
        ),
        (
            "monitor steps file bad kind",
            ["monitor", "{tenv3_ok}", "--steps-file", "{steps_bad}", "--out", "{tmp}/o"],
            ["steps_bad.txt:3:", "unknown step kind 'antenna'"],
        ),
        (
            "monitor postseismic form",
            ["monitor", "{tenv3_ok}", "--postseismic", "LHAS:2003-01-01:power:30"],
            ["--postseismic LHAS:2003-01-01:power:30", "log:TAU_DAYS"],
        ),
        (
            "monitor postseismic fields",
            ["monitor", "{tenv3_ok}", "--postseismic", "LHAS:2003-01-01"],
            ["--postseismic expects STATION:DATE:FORM:TAU"],
        ),
        (
            "monitor postseismic unknown station",
            ["monitor", "{tenv3_ok}", "--postseismic", "XXXX:2010-01-01:log:30", "--out", "{tmp}/o"],
            ["--postseismic XXXX:2010-01-01:log:30", "no such station"],
        ),
        ("monitor poly degree 0", ["monitor", "{tenv3_ok}", "--poly-degree", "0"], ["--poly-degree"]),
        ("sweep missing config", ["sweep", "{tmp}/none.toml"], ["jaxnav sweep:", "none.toml", "no such config"]),
        ("sweep seeds 0", ["sweep", "{t_seeds0}"], ["t_seeds0.toml", "problem.seeds = 0"]),
        ("sweep init 1.5", ["sweep", "{t_init}"], ["t_init.toml", "params.b.init = 1.5"]),
        ("sweep num 0", ["sweep", "{t_num0}"], ["t_num0.toml", "sweep.b.num = 0"]),
        ("sweep duration < 0", ["sweep", "{t_dur}"], ["t_dur.toml", "problem.duration = -5.0"]),
        ("sweep bool init", ["sweep", "{t_param}"], ["t_param.toml", "params.b.init must be a number, got True"]),
        ("sweep out is a file", ["sweep", "s0_b", "--out", "{a_file}"], ["a_file", "existing file"]),
        ("sweep out under a file", ["sweep", "s0_b", "--out", "{a_file}/x"], ["cannot write the output folder"]),
        ("tune steps 0", ["tune", "{t_steps0}"], ["jaxnav tune:", "tune.steps = 0"]),
        ("tune learning rate < 0", ["tune", "{t_lr}"], ["tune.learning_rate = -0.5"]),
        ("tune mode", ["tune", "{t_mode}"], ["tune.mode must be one of"]),
        ("tune unknown key", ["tune", "{t_unknown}"], ["unknown key tune.momentum"]),
        ("tune out under a file", ["tune", "cv_noise", "--out", "{a_file}/x"], ["cannot write the output folder"]),
        ("cadastral seeds 0", ["cadastral", "--out", "{tmp}/c", "--seeds", "0"], ["jaxnav cadastral:", "--seeds"]),
        ("cadastral chunk 0", ["cadastral", "--out", "{tmp}/c", "--chunk", "0"], ["--chunk"]),
        ("cadastral legs 0", ["cadastral", "--out", "{tmp}/c", "--legs", "0"], ["--legs"]),
        (
            "cadastral legs without a target",
            ["cadastral", "--out", "{tmp}/c", "--legs", "2"],
            ["first 2 leg(s)", "at least 3 legs"],
        ),
        ("cadastral grade", ["cadastral", "--out", "{tmp}/c", "--grade", "navy"], ["--grade 'navy'", "tactical"]),
        (
            "cadastral config missing",
            ["cadastral", "--out", "{tmp}/c", "--config", "{tmp}/c.toml"],
            ["c.toml", "no such"],
        ),
        (
            "cadastral stops latitude",
            ["cadastral", "--out", "{tmp}/c", "--stops", "{stops_bad}"],
            ["stops.csv:1:", "lat_deg = 132"],
        ),
        ("cadastral out is a file", ["cadastral", "--out", "{a_file}"], ["a_file", "existing file"]),
        # a route the IMU rate cannot sample: refused when the config is read, naming the file (not mid-run)
        (
            "cadastral route not sampled",
            ["cadastral", "--out", "{tmp}/c", "--config", "{cad_unsampled}"],
            ["cad_unsampled.toml: survey and legs", "imu_rate_hz = 10"],
        ),
    ]
    + [
        (
            f"ins range {n}",
            ["ins", f"{{ins_{n}}}", "--out", "{tmp}/o"],
            [f"ins_{n}.toml", f"{sec}.{line.split(' =')[0]}", "plausible"],
        )
        for n, sec, line in INS_RANGE_CASES
    ]
    + [
        (
            f"cadastral range {n}",
            ["cadastral", "--out", "{tmp}/c", "--config", f"{{cad_{n}}}"],
            [f"cad_{n}.toml", new.split(" =")[0]],
        )
        for n, old, new in CADASTRAL_RANGE_CASES
    ]
)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("cli")
    d = _files(tmp)
    d["tmp"] = tmp
    return d


@pytest.mark.parametrize("case,argv,needles", CASES, ids=[c[0] for c in CASES])
def test_bad_input_is_one_line_exit_2(case, argv, needles, files, capsys, monkeypatch):
    monkeypatch.delenv("JAXNAV_DATA", raising=False)
    monkeypatch.chdir(files["tmp"])  # default --out folders land in the temporary folder
    before = set(files["tmp"].rglob("*"))
    # -q: no stage lines ("reading ...", INFO on stderr), so the error is the only line; without it
    # the error is the last line, after the stages that ran
    rc = main(["-q"] + [a.format(**files) for a in argv])
    out, err = capsys.readouterr()
    assert rc == 2, (case, rc, err)
    assert err.endswith("\n") and err.count("\n") == 1, err  # exactly one line
    assert err.startswith("jaxnav"), err
    assert "Traceback" not in err and "internal error" not in err, err
    assert "np.str_" not in err and "np.float64" not in err, err  # values, not numpy reprs
    for s in needles:
        assert s.format(**files) in err, (s, err)
    created = {p for p in set(files["tmp"].rglob("*")) - before if p.is_file()}
    assert not created, created  # nothing computed or written


def test_debug_shows_the_traceback(files, capsys):
    with pytest.raises(ValueError, match=r"b15\.toml: filter\.b = 1\.5"):
        main(["--debug", "demo", "--config", str(files["b15"])])
    from jaxnav.cli._common import CommandError

    with pytest.raises(CommandError, match="none.csv: no such file"):  # --debug after the command works too
        main(["rtk", str(files["ep"]), "--control", str(files["tmp"] / "none.csv"), "--debug"])


def test_internal_error_says_so_and_points_to_debug(monkeypatch, capsys):
    import jaxnav.cli.walk as walk

    def broken(args):
        raise TypeError("unsupported operand type(s)")

    monkeypatch.setattr(walk, "run", broken)
    rc = main(["walk", "--data", "."])
    err = capsys.readouterr().err
    assert rc == 3 and err.count("\n") == 1
    assert "internal error: TypeError: unsupported operand" in err and "--debug" in err
    with pytest.raises(TypeError):
        main(["walk", "--data", ".", "--debug"])


def test_json_is_strict_with_null_reasons(tmp_path):
    data = {
        "rms": float("nan"),
        "per_seed": np.array([1.0, np.inf, np.nan]),
        "inner": {"x": -math.inf, "ok": 2},
        "n": np.int64(3),
        "flag": np.bool_(True),
        "ok": [1.5],
    }
    p = write_json(tmp_path / "r.json", data)

    def no_constants(name):
        raise AssertionError(f"{name} token in JSON")

    back = json.loads(p.read_text(), parse_constant=no_constants)
    assert back["rms"] is None and back["rms_null_reason"].startswith("not computed (nan)")
    assert back["per_seed"] == [1.0, None, None] and back["per_seed_null_reason"].startswith("2 of 3 values not finite")
    assert (
        back["inner"]["x"] is None
        and back["inner"]["x_null_reason"].startswith("infinite (-inf)")
        and back["inner"]["ok"] == 2
    )
    assert back["n"] == 3 and back["flag"] is True and back["ok"] == [1.5] and "ok_null_reason" not in back
    assert json_ready({"a": 1.0})[1] == {}
    given = json_ready({"rms": float("nan"), "rms_null_reason": "no fixed epoch in the window"})[0]
    assert given == {"rms": None, "rms_null_reason": "no fixed epoch in the window"}
    assert '"nan"' not in p.read_text()  # no bare kind as a reason


def _run(args, tmp_path):
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    env.pop("JAXNAV_DATA", None)
    return subprocess.run(
        [sys.executable, "-m", "jaxnav", *args], capture_output=True, text=True, cwd=tmp_path, env=env, timeout=120
    )


def test_subprocess_bad_seeds_and_bad_control_file(files):
    r = _run(["demo", "--seeds", "0"], files["tmp"])
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "--seeds" in r.stderr and "Traceback" not in r.stderr
    # the error is the last stderr line, after the stage line of the reading; with -q it is the only one
    msg = f"jaxnav rtk: {files['cp_inf']}:4: column 'B': 'inf' is not a finite number\n"
    r = _run(
        ["rtk", str(files["ep"]), "--control", str(files["cp_inf"]), "--out", str(files["tmp"] / "s")], files["tmp"]
    )
    assert r.returncode == 2 and r.stderr == "reading 1 file(s): ep.csv\n" + msg, r.stderr
    r = _run(
        ["rtk", "-q", str(files["ep"]), "--control", str(files["cp_inf"]), "--out", str(files["tmp"] / "s")],
        files["tmp"],
    )
    assert r.returncode == 2 and r.stderr == msg, r.stderr


def test_monitor_masks_and_reports_a_nan_east_value(tmp_path, capsys):
    """A ``nan`` east value in a real tenv3 file: exit 0, counted in monitor.json and the printout,
    finite velocities and LS slope, strict JSON."""
    from _paths import DATA_ROOT

    src = DATA_ROOT / "gnss_daily_timeseries/LHAS.tenv3"
    if not src.exists():
        pytest.skip("shared data not present")
    lines = src.read_text().splitlines()[:400]
    w = lines[50].split()
    w[8] = "nan"  # east fraction
    lines[50] = " ".join(w)
    f = tmp_path / "LHAS.tenv3"
    f.write_text("\n".join(lines) + "\n")
    assert main(["monitor", str(f), "--out", str(tmp_path / "o"), "--period", "100"]) == 0
    printed = capsys.readouterr().out
    assert "1 position value(s) given as nan" in printed
    assert "PL mm/yr^-k/4" in printed  # the power-law amplitude column carries its unit

    def no_constants(name):
        raise AssertionError(f"{name} token in monitor.json")

    st = json.loads((tmp_path / "o/monitor.json").read_text(), parse_constant=no_constants)["stations"]["LHAS"]
    assert st["masked_values"] == 1 and st["days_used"]["east"] == st["days_used"]["north"] - 1
    vals = list(st["velocity_mm_per_yr"].values()) + list(st["velocity_sigma_mm_per_yr"].values())
    assert all(v is not None and math.isfinite(v) for v in vals)


def test_a_value_error_from_inside_numpy_is_internal(monkeypatch, capsys):
    """Only jaxnav's own checks make exit status 2; a ValueError raised inside numpy is a bug (3)."""
    import jaxnav.cli.walk as walk

    monkeypatch.setattr(walk, "run", lambda args: np.ones(3) + np.ones(4))
    assert main(["walk", "--data", "."]) == 3
    assert "internal error: ValueError: operands could not be broadcast" in capsys.readouterr().err


def test_config_ranges_are_documented_beside_their_keys():
    """Every range of the ``ins`` and cadastral configs appears in the docs as ``| `key` | lo | hi |``."""
    from jaxnav.io import INS_CONFIG_RANGES as INS
    from jaxnav.sim._cadastral import RANGES as CAD

    for doc, ranges in (("docs/guide/ins.md", INS), ("docs/api/survey.md", CAD)):
        text = (ROOT / doc).read_text()
        for k, (lo, hi) in ranges.items():
            assert f"| `{k}` | {lo:g} | {hi:g} |" in text, (doc, k)


def test_a_value_error_deep_in_the_computation_is_not_an_input_error(monkeypatch, capsys, tmp_path):
    """A plain ValueError raised by jaxnav code after ``jaxnav ins`` has checked its input and started
    computing (here: from inside the processing) exits 3 saying how long it ran, not 2 ("fix your
    input"); a ReaderError at that stage still exits 2."""
    import jaxnav.experiments.ins_output as ins_output
    from jaxnav.io import load_ins_config

    def broken(cfg, out, **kw):  # a check inside jaxnav's own code, met with internal data
        from jaxnav.sim._cadastral import short_survey

        short_survey(None, 0)

    cfg = load_ins_config(ROOT / "jaxnav/experiments/configs/ins/walk_0827.toml", variables={"JAXNAV_DATA": "."})
    monkeypatch.setattr(ins_output, "process", broken)
    import jaxnav.cli.ins as ins_cli
    import jaxnav.cli.walk as walk

    monkeypatch.setattr(walk, "run", lambda args: ins_cli.run_config(args, cfg, tmp_path / "o"))
    assert main(["-q", "walk", "--data", "."]) == 3
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "into the computation" in err and "n_legs must be >= 1" in err and "--debug" in err

    def unreadable(cfg, out, **kw):
        from jaxnav import io

        io.read_daily("series.xyz")

    monkeypatch.setattr(ins_output, "process", unreadable)
    assert main(["-q", "walk", "--data", "."]) == 2
    assert capsys.readouterr().err.startswith("jaxnav walk: series.xyz: unknown daily-series format")


@pytest.mark.parametrize("key,value", [("first_s", "1e5"), ("outage_s", "3000.0")])
def test_evaluate_windows_that_withhold_nothing_are_refused(key, value, tmp_path, capsys):
    """``[evaluate]`` settings that leave no outage window inside the recording are a config error
    naming the file and the keys (exit 2), not a run that reports "0 withheld" and a null evaluation."""
    from _paths import DATA_ROOT

    if not (DATA_ROOT / "rtklibexplorer-gnss-imu/walk_0827/imu_1730.csv").exists():
        pytest.skip("shared data not present")
    text = (ROOT / "jaxnav/experiments/configs/ins/walk_0827.toml").read_text()
    old = {"first_s": "first_s = 40.0", "outage_s": "outage_s = 15.0"}[key]
    assert old in text
    f = tmp_path / "late.toml"
    f.write_text(text.replace(old, f"{key} = {value}", 1))
    rc = main(["-q", "ins", str(f), "--data", str(DATA_ROOT), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1, err
    assert "late.toml: evaluate.first_s" in err and "nothing would be withheld" in err


def test_summaries_print_words_and_short_numbers():
    """A status is printed with its flag names; a sweep table cell reads 0.035, not 0.034999999999999996."""
    from jaxnav._status import GNSS_GATED, NONFINITE_MEASUREMENT, status_words
    from jaxnav.experiments.tuning import csv_number

    assert status_words(65536) == "65536 (GNSS_GATED)" and status_words(0) == "0 (ok)"
    assert status_words(np.array([GNSS_GATED, NONFINITE_MEASUREMENT])) == "65537 (NONFINITE_MEASUREMENT | GNSS_GATED)"
    assert (
        csv_number(0.034999999999999996) == "0.035"
        and csv_number(3) == 3
        and csv_number(1.2345678901234567e-9) == "1.23456789012e-09"
    )


@pytest.mark.parametrize("how", ["walk --data", "ins --data", "ins JAXNAV_DATA"])
def test_data_means_the_folder_of_the_data_sets_relative_to_the_cwd(how, tmp_path, monkeypatch):
    """`jaxnav walk --data D`, `jaxnav ins walk_0827 --data D` and `JAXNAV_DATA=D jaxnav ins walk_0827`
    read the same files, D relative to the working directory (never to the config's folder or D's parent)."""
    from _paths import DATA_ROOT

    import jaxnav.cli.ins as ins_cli

    work = tmp_path / "a" / "b"
    work.mkdir(parents=True)
    monkeypatch.chdir(work)
    rel = os.path.relpath(DATA_ROOT, work)
    seen = []
    monkeypatch.setattr(ins_cli, "run_config", lambda args, cfg, out, tune=False: seen.append(cfg) or 0)
    monkeypatch.delenv("JAXNAV_DATA", raising=False)
    if how == "walk --data":
        argv = ["-q", "walk", "--data", rel]
    elif how == "ins --data":
        argv = ["-q", "ins", "walk_0827", "--data", rel]
    else:
        monkeypatch.setenv("JAXNAV_DATA", rel)
        argv = ["-q", "ins", "walk_0827"]
    assert main(argv) == 0
    walk = DATA_ROOT / "rtklibexplorer-gnss-imu" / "walk_0827"
    assert seen[0].imu.file.resolve() == (walk / "imu_1730.csv").resolve()
    assert seen[0].gnss.file.resolve() == (walk / "gnss_1730_sf.pos").resolve()
