"""jaxnav.tune: bijectors, losses, the optax loop, ML noise identification, sweeps and sharding."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest
from _paths import ROOT

from jaxnav import filters as jf
from jaxnav import tune
from jaxnav.sim import simulate_linear

# --- bijectors -------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "name,vals",
    [
        ("unit", [1e-6, 0.254, 0.999]),
        ("positive", [1e-3, 1.0, 50.0]),
        ("log", [1e-8, 1.0, 1e6]),
        ("real", [-3.0, 0.0, 2.0]),
    ],
)
def test_bijector_round_trip(name, vals):
    b = tune.bijector(name)
    v = jnp.asarray(vals)
    np.testing.assert_allclose(b.forward(b.inverse(v)), v, rtol=1e-10)


def test_space_checks_domain_names_and_trainable():
    sp = tune.Space({"b": "unit", "q": "log"}, trainable=("b",))
    with pytest.raises(ValueError, match="outside the open domain"):
        sp.unconstrain({"b": 1.2, "q": 1.0})
    with pytest.raises(ValueError, match="do not match"):
        sp.unconstrain({"b": 0.2})
    with pytest.raises(ValueError, match="not parameters"):
        tune.Space({"b": "unit"}, trainable=("rho",))
    with pytest.raises(ValueError, match="unknown bijector"):
        tune.bijector("sigmoid")
    assert sp.mask() == {"b": 1.0, "q": 0.0}


# --- gradients and the optax loop -------------------------------------------------------------


def test_forward_and_reverse_value_and_grad_agree():
    def f(u):
        return jnp.sum(jnp.sin(u["a"]) * u["b"] ** 2) + jnp.exp(u["c"])

    u = {"a": jnp.array([0.3, -1.2]), "b": jnp.array([2.0, 0.5]), "c": jnp.array(0.1)}
    v1, g1 = tune.value_and_grad(f, "forward")(u)
    v2, g2 = tune.value_and_grad(f, "reverse")(u)
    assert v1 == pytest.approx(float(v2), rel=1e-14)
    for k in u:
        np.testing.assert_allclose(g1[k], g2[k], rtol=1e-12)
    # reverse-mode callers (optax's zoom line search) get the forward-mode gradient
    g3 = jax.grad(tune.forward_gradient(f))(u)
    for k in u:
        np.testing.assert_allclose(g3[k], g2[k], rtol=1e-12)


@pytest.mark.parametrize("opt", ["adam", "lbfgs"])
def test_minimize_finds_constrained_optimum_and_freezes_untrainable(opt):
    # minimum of (b - 0.3)^2 + (log s - log 2)^2 at b = 0.3, s = 2; c is frozen at 5
    def loss(p):
        return (p["b"] - 0.3) ** 2 + (jnp.log(p["s"]) - jnp.log(2.0)) ** 2 + (p["c"] - 1.0) ** 2

    sp = tune.Space({"b": "unit", "s": "log", "c": "positive"}, trainable=("b", "s"))
    optimizer = optax.adam(0.1) if opt == "adam" else optax.lbfgs()
    res = tune.minimize(
        loss, {"b": 0.9, "s": 0.1, "c": 5.0}, sp, optimizer=optimizer, steps=300 if opt == "adam" else 30
    )
    assert float(res.params["b"]) == pytest.approx(0.3, abs=1e-4)
    assert float(res.params["s"]) == pytest.approx(2.0, rel=1e-4)
    assert float(res.params["c"]) == pytest.approx(5.0, rel=1e-14)
    assert res.losses.shape == (300 if opt == "adam" else 30,)
    assert float(res.losses[0]) > float(res.loss)
    assert res.path["b"][0] == pytest.approx(0.9)
    if opt == "lbfgs":
        assert res.n_evals > 31  # the line search's evaluations are counted


@pytest.mark.parametrize("mode", ["forward", "reverse"])
def test_minimize_lbfgs_traces_the_loss_once_and_converges(mode):
    """The single-site L-BFGS: Rosenbrock's minimum, the frozen mask, one trace of the loss, the stop."""
    traces = []

    def loss(p):
        traces.append(1)
        return (1.0 - p["x"]) ** 2 + 100.0 * (p["y"] - p["x"] ** 2) ** 2 + (p["c"] - 1.0) ** 2

    sp = tune.Space({"x": "real", "y": "real", "c": "positive"}, trainable=("x", "y"))
    res = tune.minimize_lbfgs(loss, {"x": -1.2, "y": 1.0, "c": 3.0}, sp, max_evals=80, ftol=1e-14, mode=mode)
    assert len(traces) == 1  # optax.lbfgs in tune.minimize traces (and compiles) it three times
    assert float(res.params["x"]) == pytest.approx(1.0, abs=1e-6)
    assert float(res.params["y"]) == pytest.approx(1.0, abs=1e-6)
    assert float(res.params["c"]) == pytest.approx(3.0, rel=1e-14)
    assert float(res.loss) == pytest.approx(4.0, abs=1e-10)
    assert 20 < res.n_evals < 80  # stopped before the budget
    assert np.all(np.isinf(np.asarray(res.losses)[res.n_evals :]))
    assert np.all(np.isfinite(np.asarray(res.losses)[: res.n_evals]))
    with pytest.raises(ValueError, match="c1 < c2"):
        tune.minimize_lbfgs(loss, {"x": 0.0, "y": 0.0, "c": 1.0}, sp, c1=0.5, c2=0.1)


def test_ml_noise_scales_recovered_on_cv_batch():
    """Maximum likelihood recovers process and measurement noise scales (64 series x 500 epochs)."""
    zs = tune.simulate_cv_batch(jax.random.PRNGKey(11), 64, 500, sigma=0.003, q=1e-8)

    def loss(p):
        return tune.cv_nll(p, zs, sigma=0.003, q=1e-8)

    sp = tune.Space({"q_scale": "log", "r_scale": "log"})
    res = tune.minimize(loss, {"q_scale": 3.0, "r_scale": 0.3}, sp, optimizer=optax.lbfgs(), steps=12)
    assert float(res.params["q_scale"]) == pytest.approx(1.0, rel=0.10)
    assert float(res.params["r_scale"]) == pytest.approx(1.0, rel=0.10)
    assert float(res.loss) < float(res.losses[0])
    # at the optimum the gradient w.r.t. the log-scales vanishes
    _, g = tune.value_and_grad(lambda u: loss(sp.constrain(u)))(sp.unconstrain(res.params))
    assert max(abs(float(v)) for v in g.values()) < 1e-3


# --- losses -----------------------------------------------------------------------------------


def test_losses_on_a_consistent_filter():
    model = jf.constant_velocity(1.0, sigma=0.01, q=1e-6, ndim=1)
    x0, P0 = jnp.zeros(2), jnp.eye(2)

    def one(key):
        xs, zs = simulate_linear(key, model, x0, 400, P0=P0)
        res = jf.kalman_filter(model, x0, P0, zs, save=("means", "covs", "nis", "valid"))
        return tune.nees(res.means - xs, res.covs), res.nis, res.valid, tune.rms(res.means - xs)

    ne, nis, valid, r = jax.vmap(one)(jax.random.split(jax.random.PRNGKey(3), 64))
    assert np.mean(ne) == pytest.approx(2.0, rel=0.05)  # E NEES = n
    assert np.sum(nis) / np.sum(valid) == pytest.approx(1.0, rel=0.05)  # E NIS = m
    assert r.shape == (64, 2)
    e = jnp.ones((10, 3))
    np.testing.assert_allclose(tune.rms(e, mask=jnp.arange(10) < 5), 1.0)
    with pytest.raises(ValueError, match=r"\(T, d\)"):
        tune.rms(jnp.ones(5))
    with pytest.raises(ValueError, match="no saved 'nis'"):
        tune.nis_consistency(jf.kalman_filter(model, x0, P0, jnp.zeros((5, 1)), save=("means",)))


# --- sweeps -----------------------------------------------------------------------------------


def _cv_point(p, key):
    """NLL and position RMS of one CV series under scaled noise (a small sweep target)."""
    model = jf.constant_velocity(1.0, sigma=0.01, q=1e-6, ndim=1)
    xs, zs = simulate_linear(key, model, jnp.zeros(2), 200)
    m = jf.constant_velocity(1.0, sigma=0.01 * jnp.sqrt(p["r"]), q=1e-6 * p["q"], ndim=1)
    res = jf.kalman_filter(m, jnp.zeros(2), jnp.eye(2), zs, inflation=jf.attenuated(p["b"]), save=("means", "valid"))
    return {"nll": tune.innovation_nll(res), "rms": tune.rms(res.means - xs)[0]}


def test_grid_order_and_sweep_equals_loop_and_chunking():
    g = tune.grid(b=[0.0, 0.3], q=[0.5, 1.0, 2.0], r=[1.0])
    assert list(g["b"]) == [0.0, 0.0, 0.0, 0.3, 0.3, 0.3] and list(g["q"]) == [0.5, 1.0, 2.0] * 2
    keys = jax.random.split(jax.random.PRNGKey(0), 5)
    full = tune.sweep(_cv_point, g, keys, progress=False)
    chunked = tune.sweep(_cv_point, g, keys, chunk=4, progress=False)  # 30 pairs, last chunk padded
    assert full.values["nll"].shape == (6, 5) and chunked.chunk == 4
    np.testing.assert_array_equal(full.values["nll"], chunked.values["nll"])
    one = jax.jit(_cv_point)
    for gi in (0, 4):
        for ki in (0, 3):
            ref = one({k: jnp.asarray(v[gi]) for k, v in g.items()}, keys[ki])
            assert float(ref["rms"]) == pytest.approx(full.values["rms"][gi, ki], rel=1e-12)
    rows = tune.table(full)
    assert len(rows) == 6 and rows[4]["q"] == 1.0 and rows[4]["b"] == 0.3
    assert rows[4]["nll_mean"] == pytest.approx(full.values["nll"][4].mean())
    with pytest.raises(ValueError, match="one length G"):
        tune.sweep(_cv_point, {"b": [0.1, 0.2], "q": [1.0], "r": [1.0]}, keys, progress=False)


def test_chunked_sweep_memory_is_bounded():
    """XLA's memory estimate of a chunk call does not grow with the sweep; an unchunked one does."""
    keys = jax.random.split(jax.random.PRNGKey(1), 4)
    small = tune.grid(b=np.linspace(0, 0.5, 4), q=[1.0], r=[1.0])
    big = tune.grid(b=np.linspace(0, 0.5, 32), q=[1.0], r=[1.0])
    c_small = tune.sweep(_cv_point, small, keys, chunk=8, progress=False)
    c_big = tune.sweep(_cv_point, big, keys, chunk=8, progress=False)
    u_big = tune.sweep(_cv_point, big, keys, progress=False)
    assert c_small.peak_bytes > 0
    assert c_big.peak_bytes == c_small.peak_bytes
    assert u_big.peak_bytes > 8 * c_big.peak_bytes
    # the same runs batched differently: equal to rounding (XLA may fuse a batch of 8 and of 32 differently)
    np.testing.assert_allclose(c_big.values["nll"], u_big.values["nll"], rtol=1e-14, atol=0)


_SHARDED = textwrap.dedent("""
    import sys, json, numpy as np, jax
    import jaxnav; jaxnav.enable_x64()
    sys.path[:0] = [sys.argv[2], sys.argv[2] + "/tune"]
    from test_tune import _cv_point
    from jaxnav import tune
    g = tune.grid(b=np.linspace(0.0, 0.6, 6), q=[0.5, 2.0], r=[1.0])
    r = tune.sweep(_cv_point, g, jax.random.split(jax.random.PRNGKey(5), 3), chunk=8, progress=False)
    np.savez(sys.argv[1], nll=r.values["nll"], rms=r.values["rms"])
    print(json.dumps({"n_devices": r.n_devices, "chunk": r.chunk, "devices": len(jax.devices())}))
""")


def test_sweep_on_four_forced_host_devices_equals_one_device(tmp_path):
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=4", JAX_PLATFORMS="cpu")
    out = tmp_path / "sharded.npz"
    proc = subprocess.run(
        [sys.executable, "-c", _SHARDED, str(out), str(ROOT / "tests")],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    info = json.loads(proc.stdout.strip().splitlines()[-1])
    assert info["n_devices"] == 4 and info["chunk"] == 8
    g = tune.grid(b=np.linspace(0.0, 0.6, 6), q=[0.5, 2.0], r=[1.0])
    ref = tune.sweep(_cv_point, g, jax.random.split(jax.random.PRNGKey(5), 3), chunk=8, progress=False)
    assert ref.n_devices == 1
    sharded = np.load(out)
    np.testing.assert_allclose(sharded["nll"], ref.values["nll"], rtol=1e-12, atol=0)
    np.testing.assert_allclose(sharded["rms"], ref.values["rms"], rtol=1e-12, atol=0)
