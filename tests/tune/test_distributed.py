"""One study on 2 processes x 2 CPU devices (jax.distributed, gloo) equals the single-process study.

Two processes on 127.0.0.1 join through a small ``jaxnav sweep ... --coordinator --num-processes
--process-id`` (process 0 alone writes), then run a chunked Monte Carlo of a filter and a tuning loop (loss,
gradient, optax steps) whose Monte Carlo runs are sharded over the 4 devices of both processes
(``tests/tune/_multiprocess.py``).
The same studies run here in one process on one device; all agree to 1e-12. A hang fails fast:
the processes join within 60 s or fail, and the whole run is killed after ``DEADLINE_S``.
"""

from __future__ import annotations

import json
import os
import pathlib
import socket
import subprocess
import sys
import time

import numpy as np
import pytest

from jaxnav.cli import main

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))

HERE = pathlib.Path(__file__).resolve().parent
#: the whole 2-process run (imports, compilations, runs), s; far above a normal run, far below a hang's timeouts
DEADLINE_S = 600
CONFIG = """
[problem]
kind = "cv"
series = 4
epochs = 60
seed = 3

[params.q_scale]
init = 2.0

[params.r_scale]
init = 0.5

[sweep]
q_scale = { start = 0.5, stop = 2.0, num = 3, log = true }
r_scale = { start = 0.5, stop = 2.0, num = 2 }
chunk = 8
"""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _start(tmp_path, config):
    env = dict(
        os.environ,
        JAX_PLATFORMS="cpu",
        XLA_FLAGS=(os.environ.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=2").strip(),
    )
    for var in ("JAX_COORDINATOR_ADDRESS", "JAX_NUM_PROCESSES", "JAX_PROCESS_ID"):
        env.pop(var, None)
    port = str(_free_port())
    procs = []
    for i in range(2):  # output to files, not pipes: a full pipe would block a process
        with open(tmp_path / f"stdout_{i}.txt", "w") as out, open(tmp_path / f"stderr_{i}.txt", "w") as err:
            procs.append(
                subprocess.Popen(
                    [sys.executable, str(HERE / "_multiprocess.py"), str(tmp_path), str(i), "2", port, str(config)],
                    env=env,
                    stdout=out,
                    stderr=err,
                )
            )
    return procs


def _wait(procs, tmp_path, deadline):
    """Wait for both; kill both as soon as one fails or the deadline passes. Returns their stdout."""

    def tails():
        return "\n----\n".join((tmp_path / f"stderr_{i}.txt").read_text()[-2500:] for i in range(len(procs)))

    while any(p.poll() is None for p in procs):
        failed = [p for p in procs if p.poll() not in (None, 0)]
        if failed or time.monotonic() > deadline:
            for p in procs:
                if p.poll() is None:
                    p.kill()
                    p.wait()
            pytest.fail(
                ("a process failed" if failed else f"no result within {DEADLINE_S} s (a hang?)") + "\n" + tails()
            )
        time.sleep(0.2)
    assert all(p.returncode == 0 for p in procs), tails()
    return [(tmp_path / f"stdout_{i}.txt").read_text() for i in range(len(procs))]


def test_two_processes_equal_one_process(tmp_path):
    import _multiprocess as mp

    config = tmp_path / "cv_small.toml"
    config.write_text(CONFIG)
    deadline = time.monotonic() + DEADLINE_S
    procs = _start(tmp_path, config)
    try:
        # the reference, computed here (one process, one device) while the two processes run
        ref = mp.studies()
        assert main(["sweep", str(config), "--out", str(tmp_path / "single"), "--no-progress"]) == 0
    except BaseException:
        for p in procs:
            p.kill()
            p.wait()
        raise
    outs = _wait(procs, tmp_path, deadline)
    facts = [json.loads(o.strip().splitlines()[-1]) for o in outs]
    for i, f in enumerate(facts):
        assert f == {
            "cli_rc": 0,
            "process_index": i,
            "process_count": 2,
            "devices": 4,
            "local_devices": 2,
            "writer": i == 0,
        }

    # process 0 alone wrote the command's results; they equal the single-process command's
    assert sorted(os.listdir(tmp_path / "cli_1")) == []
    written = sorted(os.listdir(tmp_path / "cli_0"))
    assert "results.json" in written and "table.csv" in written and any(f.endswith(".png") for f in written)
    two = json.loads((tmp_path / "cli_0" / "results.json").read_text())
    one = json.loads((tmp_path / "single" / "results.json").read_text())
    assert (two["n_devices"], two["n_processes"], one["n_devices"], one["n_processes"]) == (4, 2, 1, 1)
    np.testing.assert_allclose(two["loss_per_run"], one["loss_per_run"], rtol=1e-12, atol=0)
    t2, t1 = (np.genfromtxt(tmp_path / d / "table.csv", delimiter=",", names=True) for d in ("cli_0", "single"))
    assert t2.dtype.names == t1.dtype.names and len(t2) == 6
    for name in t1.dtype.names:
        np.testing.assert_allclose(t2[name], t1[name], rtol=1e-12, atol=1e-15, err_msg=name)  # std of ~equal runs

    # every process returns the whole study, equal to the single-process one
    for i in range(2):
        got = np.load(tmp_path / f"process_{i}.npz")
        for name in ("mc_stats", "tune_params", "tune_losses", "tune_grad_norm", "tune_path"):
            assert got[name].shape == np.shape(ref[name]), name
            np.testing.assert_allclose(got[name], ref[name], rtol=1e-12, atol=0, err_msg=name)
    assert ref["mc_stats"].shape == (5, 9) and np.all(np.isfinite(ref["mc_stats"]))
    # the optimiser moved the parameters (the loop ran on both processes, the same steps)
    assert np.all(np.abs(np.log(ref["tune_params"] / np.array([3.0, 0.5]))) > 0.1)
    assert ref["tune_losses"][-1] < ref["tune_losses"][0]


@pytest.mark.parametrize(
    "argv,message",
    [
        (["--coordinator", "localhost"], "HOST:PORT"),
        (["--coordinator", "localhost:0"], "HOST:PORT"),
        (
            ["--coordinator", "127.0.0.1:1234", "--num-processes", "2", "--process-id", "2"],
            "process id must be in 0 .. 1",
        ),
        (["--num-processes", "0"], "must be in"),
        (["--process-id", "-1"], "must be in"),
    ],
)
def test_process_options_are_checked_before_any_work(tmp_path, capsys, argv, message):
    assert main(["sweep", "cv_noise", "--out", str(tmp_path / "o")] + argv) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()
