"""Gradients through the S0 INS/GNSS run w.r.t. b, rho and the noise scales; the tune/sweep CLI.

The full 2000 s check (b, rho, q_scale, r_scale against central differences) is part of
``benchmarks/bench_tune.py`` and recorded in ``benchmarks/RESULTS.md``; here the same on the
first 300 s of the S0 timeline (cruise, acceleration and the first unsensed velocity step).
"""

from __future__ import annotations

import pathlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxnav.cli import main
from jaxnav.experiments.s0 import S0Setup, load_experiment, s0_metrics
from jaxnav.experiments.tuning import load_config

NAMES = ("b", "rho", "q_scale", "r_scale")
THETA = np.array([0.254, 9.0, 1.3, 0.8])


@pytest.fixture(scope="module")
def setup():
    return S0Setup(load_experiment(), duration=300.0)


def _losses(setup, theta, remat=False):
    """[attenuated position RMS (b, q, r), fading position RMS (rho, q, r), attenuated innovation NLL].

    The noise scales are checked on the NLL, the loss one tunes them with: the position RMS moves
    by only ~1e-7 m per unit of q_scale, a sum of much larger per-epoch terms that cancel, which
    no central difference resolves to 1e-4.
    """
    b, rho, q, r = theta
    key = jax.random.PRNGKey(4)
    # both filters in one program (jf.switch): index 0 attenuated, 1 fading
    m = jax.vmap(
        lambda i: s0_metrics(
            setup,
            {"b": b, "rho": rho, "tau": 0.05, "q_scale": q, "r_scale": r, "filter_index": i},
            key,
            filter=("attenuated", "fading"),
            remat=remat,
        )
    )(jnp.arange(2))
    return jnp.stack([m["loss"][0], m["loss"][1], m["nll"][0]])


@pytest.fixture(scope="module")
def derivatives(setup):
    """One compiled call: the 4 tangents at THETA and the 8 perturbed primals (zero tangents)."""
    # relative steps: 1e-5 for b and rho; 1e-3 for the scales, whose derivative is small (the NLL
    # moves ~1e-5 per unit of q_scale) so that a 1e-5 step would be lost in rounding noise
    H = np.array([1e-5, 1e-5, 1e-3, 1e-3]) * np.abs(THETA)
    ths = np.concatenate([np.tile(THETA, (4, 1)), THETA + np.diag(H), THETA - np.diag(H)])
    tans = np.concatenate([np.eye(4), np.zeros((8, 4))])
    run = jax.jit(jax.vmap(lambda th, t: jax.jvp(lambda x: _losses(setup, x), (th,), (t,))))
    vals, dirs = (np.asarray(a) for a in run(jnp.asarray(ths), jnp.asarray(tans)))
    return vals, dirs, H


def test_gradients_through_the_ins_gnss_run_match_central_differences(derivatives):
    vals, dirs, H = derivatives
    assert np.all(np.isfinite(dirs[:4]))
    J = dirs[:4].T  # (3 losses, 4 parameters)
    fd = ((vals[4:8] - vals[8:12]) / (2 * H[:, None])).T
    np.testing.assert_allclose(vals[:4], np.broadcast_to(vals[0], (4, 3)), rtol=1e-14)
    for i, name in enumerate(NAMES):
        for r in {"b": [0], "rho": [1], "q_scale": [2], "r_scale": [2]}[name]:
            assert J[r, i] == pytest.approx(fd[r, i], rel=1e-4, abs=1e-9), (name, r, J[r, i], fd[r, i])
    # b only acts on the attenuated filter, rho only on the fading one
    assert J[1, 0] == 0.0 and J[0, 1] == 0.0


def test_reverse_mode_with_checkpointing_equals_forward_mode(setup, derivatives):
    # only the attenuated run: d(loss 0)/db involves nothing else, and the fading run would add
    # ~10 s of compilation (measured) for a zero contribution
    key = jax.random.PRNGKey(4)
    loss = lambda b: s0_metrics(
        setup,
        {"b": b, "q_scale": THETA[2], "r_scale": THETA[3]},
        key,
        filter="attenuated",
        remat=True,
    )["loss"]
    g_rev = float(jax.jit(jax.grad(loss))(THETA[0]))
    assert g_rev == pytest.approx(float(derivatives[1][0, 0]), rel=1e-9)


def _config(tmp_path, kind):
    if kind == "s0":
        text = """
[problem]
kind = "s0"
filter = "attenuated"
seeds = 2
duration = 150.0
[params.b]
init = 0.5
[sweep]
b = { start = 0.05, stop = 0.65, num = 3 }
[tune]
optimizer = "adam"
learning_rate = 0.5
steps = 2
landscape = 3
"""
    else:
        text = """
[problem]
kind = "cv"
series = 8
epochs = 200
[params.q_scale]
init = 2.0
[params.r_scale]
init = 0.5
[sweep]
q_scale = { start = 0.5, stop = 2.0, num = 3, log = true }
r_scale = { start = 0.5, stop = 2.0, num = 2, log = true }
[tune]
steps = 60
"""
        if kind == "cv_wolfe":
            text = text.replace("steps = 60", 'optimizer = "lbfgs_wolfe"\nsteps = 25')
    p = tmp_path / f"{kind}.toml"
    p.write_text(text)
    return p


@pytest.mark.parametrize("kind", ["s0", "cv", "cv_wolfe"])
def test_sweep_and_tune_cli_write_results_and_figures(tmp_path, kind, capsys):
    """Both commands on the CV problem; the sweep on a 150 s S0 problem (its tune path is the same
    code with the S0 loss, exercised by notebook 05 and benchmarks/bench_tune.py)."""
    cfg = _config(tmp_path, kind)
    from _outputs import check_provenance

    argv = ["sweep", str(cfg), "--out", str(tmp_path / "sw"), "--no-progress"]
    assert main(argv) == 0
    sw = check_provenance(tmp_path / "sw", argv, config=True)
    assert "table.csv" in sw["files"] and "params" in sw["provenance"]["config"]
    G = 3 if kind == "s0" else 6
    assert len(sw["loss_mean"]) == G and np.asarray(sw["loss_per_run"]).shape == (G, sw["runs"])
    assert sw["best"]["loss"] == pytest.approx(min(sw["loss_mean"]))
    assert (tmp_path / "sw" / "table.csv").read_text().count("\n") == G + 1
    figures = list(sw["figures"])
    if kind == "s0":
        assert np.asarray(sw["rms_best_mean"]).shape == (9,)
    else:
        argv = ["tune", str(cfg), "--out", str(tmp_path / "tu"), "--no-progress"]
        assert main(argv) == 0
        tu = check_provenance(tmp_path / "tu", argv, config=True)
        assert tu["loss_final"] < tu["loss_init"]
        assert set(tu["tuned"]) == set(tu["init"]) and tu["wall_time_s"]["tune"] > 0
        assert np.asarray(tu["loss_per_run"]["tuned"]).shape == (8,)
        assert np.all(np.isfinite(np.asarray(tu["losses"]))) and tu["loss_evaluations"] >= len(tu["losses"])
        figures += tu["figures"]
        assert "tune:" in capsys.readouterr().out
    for f in figures:
        assert pathlib.Path(f).stat().st_size > 10_000


def test_config_errors_name_file_and_key(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text('[problem]\nkind = "s0"\nfilter = "attenuated"\n[params.rho]\ninit = 3.0\n')
    with pytest.raises(ValueError, match=r"bad.toml: params.rho does not apply"):
        load_config(p)
    p.write_text('[problem]\nkind = "s0"\nloss = "mse"\n[params.b]\ninit = 0.3\n')
    with pytest.raises(ValueError, match=r"bad.toml: problem.loss must be one of"):
        load_config(p)
    p.write_text('[problem]\nkind = "cv"\n[params.q_scale]\ninit = 1.0\n[sweep]\nr_scale = {start=1, stop=2, num=2}\n')
    with pytest.raises(ValueError, match=r"sweep.r_scale is not a parameter"):
        load_config(p)
    with pytest.raises(ValueError, match="no such config file"):
        load_config(tmp_path / "missing.toml")


def test_load_toml_errors_name_file_and_line(tmp_path):
    """One TOML reader for every config: syntax errors name the file and line, a missing file its path."""
    from jaxnav.io import load_toml

    p = tmp_path / "broken.toml"
    p.write_text('[problem]\nkind = "cv"\nseed = \n')
    with pytest.raises(ValueError, match=r"broken.toml: invalid TOML: .*line 3"):
        load_toml(p)
    with pytest.raises(FileNotFoundError, match="missing.toml"):
        load_toml(tmp_path / "missing.toml")
    with pytest.raises(ValueError, match=r"broken.toml: invalid TOML"):
        load_config(p)
