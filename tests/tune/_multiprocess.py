"""The small studies of test_distributed.py, run by 2 processes x 2 devices and by the test itself.

As a script (one process of the study): ``python _multiprocess.py OUT PROCESS_ID NUM_PROCESSES PORT CONFIG``
joins the study through a ``jaxnav sweep`` of CONFIG on the command line (``--coordinator 127.0.0.1:PORT
--num-processes N --process-id I``, writing into ``OUT/cli_I``), then runs :func:`studies` on the
joined processes and saves the arrays to ``OUT/process_I.npz`` and a JSON line of facts on stdout.
"""

from __future__ import annotations

import json
import pathlib
import sys

import jax
import jax.numpy as jnp
import numpy as np
import optax

import jaxnav

jaxnav.enable_x64()

from jaxnav import filters as jf
from jaxnav import tune
from jaxnav.sim import simulate_linear


def cv_point(p, key):
    """NLL and position RMS of one 1-D constant-velocity series (200 epochs) under scaled noise."""
    model = jf.constant_velocity(1.0, sigma=0.01, q=1e-6, ndim=1)
    xs, zs = simulate_linear(key, model, jnp.zeros(2), 200)
    m = jf.constant_velocity(1.0, sigma=0.01 * jnp.sqrt(p["r"]), q=1e-6 * p["q"], ndim=1)
    res = jf.kalman_filter(
        m, jnp.zeros(2), jnp.eye(2), zs, inflation=jf.attenuated(p.get("b", 0.0)), save=("means", "valid")
    )
    return {"nll": tune.innovation_nll(res), "rms": tune.rms(res.means - xs)[0]}


def studies() -> dict:
    """A Monte Carlo of 5 runs in chunks of 4 (2 chunks, the second padded; each run a (9,) vector of
    statistics of an attenuated-memory filter, b = 0.254) and tuning over 6 sharded runs: the loss,
    its gradient (its norm each step) and 8 adam steps in one program.

    (The sweep is the ``jaxnav sweep`` run of :func:`main`. The chunked run's sharding does not depend
    on the filter inside; the S0 INS/GPS filter runs chunked (``tune.sweep``) in test_demo.py's S0 demo.)
    """
    out = {}

    def mc_point(k):
        r = cv_point({"q": jnp.asarray(1.0), "r": jnp.asarray(1.0), "b": jnp.asarray(0.254)}, k)
        return jnp.concatenate([jnp.stack([r["nll"], r["rms"]]), jnp.full(7, r["rms"] ** 2)])

    out["mc_stats"] = tune.run_chunked(mc_point, jax.random.split(jax.random.PRNGKey(2019), 5), chunk=4, progress=False)

    loss = tune.monte_carlo_mean(lambda p, k: cv_point(p, k)["nll"], jax.random.split(jax.random.PRNGKey(9), 6))
    p0 = {"q": jnp.asarray(3.0), "r": jnp.asarray(0.5)}
    res = tune.minimize(
        loss, p0, tune.Space({"q": "log", "r": "log"}), optimizer=optax.adam(0.05), steps=8, mode="forward"
    )
    out["tune_params"] = np.asarray([res.params["q"], res.params["r"]])
    out["tune_losses"] = np.asarray(res.losses)
    out["tune_grad_norm"] = np.asarray(res.grad_norm)
    out["tune_path"] = np.stack([np.asarray(res.path["q"]), np.asarray(res.path["r"])])
    return out


def main(argv):
    out, pid, nproc, port, config = pathlib.Path(argv[0]), int(argv[1]), int(argv[2]), argv[3], argv[4]
    from jaxnav.cli import main as cli

    rc = cli(
        [
            "sweep",
            config,
            "--out",
            str(out / f"cli_{pid}"),
            "--no-progress",
            "--coordinator",
            f"127.0.0.1:{port}",
            "--num-processes",
            str(nproc),
            "--process-id",
            str(pid),
            "--join-timeout",
            "60",
        ]
    )
    facts = {
        "cli_rc": rc,
        "process_index": jax.process_index(),
        "process_count": jax.process_count(),
        "devices": len(jax.devices()),
        "local_devices": jax.local_device_count(),
        "writer": tune.is_writer(),
    }
    res = studies()
    np.savez(out / f"process_{pid}.npz", **res)
    print(json.dumps(facts), flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
