"""The demonstration runs end to end on small sizes and writes its table, JSON and figure."""

import pathlib

import jax
import numpy as np
import pytest
from _outputs import check_provenance

from jaxnav.cli import main
from jaxnav.experiments.s0 import EXPERIMENT, load_experiment
from jaxnav.tune import run_chunked


def test_demo_writes_results_and_figure(tmp_path, capsys):
    out = tmp_path / "demo"
    argv = ["demo-filters", "--out", str(out), "--seeds", "5", "--epochs", "300", "--no-progress"]
    assert main(argv) == 0
    res = check_provenance(out, argv)  # issue 21: version, commit, date, command, options, files written
    assert "filter_family.png" in res["files"]
    assert set(res["table"]) == {"classic", "attenuated", "fading", "variance_compensation"}
    assert res["settings"]["seeds"] == 5 and res["settings"]["b"] == 0.254
    t = res["table"]
    # the unmodelled burst hurts the classic filter most; every adaptive variant suppresses it
    for name in ("attenuated", "fading", "variance_compensation"):
        assert t[name]["pos_rms_during_mm"]["mean"] < 0.5 * t["classic"]["pos_rms_during_mm"]["mean"]
    assert (out / "filter_family.png").stat().st_size > 10_000
    printed = capsys.readouterr().out
    assert "classic" in printed and "fading" in printed


def test_run_chunked_pads_last_chunk_and_matches_vmap():
    keys = jax.random.split(jax.random.PRNGKey(0), 7)
    f = lambda k: {"a": jax.random.normal(k, (3,)), "b": jax.random.uniform(k)}
    got = run_chunked(f, keys, chunk=3, progress=False)
    ref = jax.vmap(f)(keys)
    np.testing.assert_array_equal(got["a"], ref["a"])
    np.testing.assert_array_equal(got["b"], ref["b"])


def test_s0_demo_writes_table_json_and_figures(tmp_path, capsys):
    """The S0 reproduction on 2 seeds and a 2-point b sweep (the full run is ``make demo``)."""
    out = tmp_path / "s0"
    argv = ["demo", "--out", str(out), "--seeds", "2", "--sweep-points", "2", "--no-progress"]
    assert main(argv) == 0
    res = check_provenance(out, argv, config=True)  # the shipped s0_experiment.toml and its contents
    assert res["provenance"]["config_file"].endswith("s0_experiment.toml") and "filter" in res["provenance"]["config"]
    assert set(res["filters"]) == {"classic", "attenuated", "fading"}
    for f in res["filters"].values():
        assert len(f["per_seed"]["pos_rms_m"]) == 2 and len(f["mean"]["vel_rms_mps"]) == 3
        assert len(f["published"]["pos_rms_m"]) == 3
    # the unmodelled sudden velocity changes hurt the classic filter; fading suppresses it
    assert res["filters"]["fading"]["mean_pos_rms_m"] < res["filters"]["classic"]["mean_pos_rms_m"]
    # no filter may lose the heading (inflating the heading error did: median errors of 30-55 deg)
    for name, f in res["filters"].items():
        assert max(max(r) for r in f["per_seed"]["att_rms_rad"]) < 0.02, name
    assert 0.254 in res["sweep"]["b"]
    for f in res["figures"]:
        assert pathlib.Path(f).stat().st_size > 10_000
    printed = capsys.readouterr().out
    assert "published" in printed and "b sweep" in printed
    assert "Why the columns differ from the published ones" in printed


def test_s0_table_says_why_it_differs_from_the_published_one():
    """Beside Table 1 (one run) the Monte Carlo mean differs by metres: the summary says why (one
    published run vs a mean over seeds; the paper's unstated model mismatch), without a run."""
    from jaxnav.experiments.s0 import FILTERS, format_s0

    per_seed = dict(pos_rms_m=[[1.0, 2.0, 3.0]] * 2, vel_rms_mps=[[0.1, 0.2, 0.3]] * 2, att_rms_rad=[[1e-3] * 3] * 2)
    res = dict(
        settings=dict(seeds=2, experiment=dict(published={f: [1.0] * 9 for f in FILTERS}, filter=dict(b=0.254))),
        filters={f: dict(per_seed=per_seed) for f in FILTERS},
        sweep=dict(b=[0.1, 0.254], mean_pos_rms_m=[2.0, 3.0], seeds=2),
    )
    text = format_s0(res)
    assert "one simulated run per filter" in text and "mean +- std over the seeds" in text
    assert "model mismatch it does not state" in text and "reproductions.md" in text


def test_experiment_file_errors_name_the_key(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(EXPERIMENT.read_text().replace("q_scale = 1.0", "q_scal = 1.0"))
    with pytest.raises(ValueError, match="unknown key filter.q_scal"):
        load_experiment(bad)
    bad.write_text(EXPERIMENT.read_text().replace("seeds = 32", 'seeds = "many"'))
    with pytest.raises(ValueError, match="monte_carlo.seeds must be an integer"):
        load_experiment(bad)


def test_data_dir_from_flag_or_environment(tmp_path, monkeypatch, capsys):
    """--data wins, else $JAXNAV_DATA; both name the folder that holds the sets (<root>/<set>), a relative
    one taken against the working directory; neither set: one clear line naming both; no cwd default."""
    from jaxnav.cli._common import CommandError, data_dir

    (tmp_path / "walkset").mkdir()
    monkeypatch.delenv("JAXNAV_DATA", raising=False)
    assert data_dir(str(tmp_path), "walkset") == tmp_path / "walkset"
    with pytest.raises(CommandError, match=r"walkset/walkset: no such data folder .*looks like the data set itself"):
        data_dir(str(tmp_path / "walkset"), "walkset")  # the set's own folder: never its parent, silently
    (tmp_path / "cwd").mkdir()
    monkeypatch.chdir(tmp_path / "cwd")
    assert data_dir("..", "walkset") == tmp_path / "walkset"
    monkeypatch.setenv("JAXNAV_DATA", "..")
    assert data_dir(None, "walkset") == tmp_path / "walkset"
    monkeypatch.delenv("JAXNAV_DATA")
    with pytest.raises(CommandError, match="--data.*JAXNAV_DATA"):
        data_dir(None, "walkset")
    assert data_dir(None, "walkset", required=False) is None
    monkeypatch.setenv("JAXNAV_DATA", str(tmp_path))
    assert data_dir(None, "walkset") == tmp_path / "walkset"
    assert data_dir(None, "other", required=False) is None
    with pytest.raises(CommandError, match="no such data folder"):
        data_dir(None, "other")


def test_cli_registry_has_every_command(capsys):
    """The ten commands of the README, each from its own module with register/run."""
    import importlib

    from jaxnav.cli import COMMANDS

    assert COMMANDS == ("demo", "demo_filters", "ins", "allan", "walk", "rtk", "cadastral", "monitor", "sweep", "tune")
    for name in COMMANDS:
        mod = importlib.import_module(f"jaxnav.cli.{name}")
        assert callable(mod.register) and callable(mod.run), name
    with pytest.raises(SystemExit):
        main(["--help"])
    printed = capsys.readouterr().out
    for name in ("demo", "demo-filters", "ins", "allan", "walk", "rtk", "cadastral", "monitor", "sweep", "tune"):
        assert f"    {name} " in printed, name
