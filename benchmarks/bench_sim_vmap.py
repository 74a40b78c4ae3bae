"""The S0 simulator under ``jit(vmap)`` over many keys: time and peak memory of the full-size batch.

A script, not a test (tests/sim/test_sim.py checks the same program on 16 keys). For B keys it
simulates the full S0 scenario (200 000 IMU samples at 100 Hz, 3 axes) and keeps the measured
velocity increments, a (B, 200000, 3) float64 array (1.2 GB at B = 256); it prints the compile and
run times, the process's peak resident memory and the same statistical checks as the test (the
keys differ; the mean over keys of dv minus the ideal increments stays within 6 sigma of its noise).

    .venv/bin/python benchmarks/bench_sim_vmap.py              # B = 256
    .venv/bin/python benchmarks/bench_sim_vmap.py --keys 64
"""

from __future__ import annotations

import argparse
import math
import pathlib
import resource
import sys
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import jax
from _harness import cpu_model, loadavg

import jaxnav

jaxnav.enable_x64()

import jax.numpy as jnp
import numpy as np

from jaxnav import sim, units


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--keys", type=int, default=256, help="batch size B (default 256)")
    a = p.parse_args(argv)
    B = a.keys
    print(f"# {cpu_model()}, jax {jax.__version__}, load {loadavg()[0]:.1f}")
    cfg = sim.s0_scenario()
    tr = sim.make_trajectory(cfg)
    keys = jax.random.split(jax.random.key(0), B)
    run = jax.jit(jax.vmap(lambda k: sim.simulate(cfg, k, trajectory=tr).imu.dv))
    t0 = time.perf_counter()
    compiled = run.lower(keys).compile()
    t1 = time.perf_counter()
    dv = jax.block_until_ready(compiled(keys))
    t2 = time.perf_counter()
    n = int(np.shape(dv)[1])
    e0 = np.asarray(dv[0, :1000] - tr.dv[:1000])
    e1 = np.asarray(dv[1, :1000] - tr.dv[:1000])
    resid = np.asarray(jnp.mean(dv[:, 5000:5100] - tr.dv[5000:5100], axis=0))
    bound = 6 * math.hypot(cfg.noise.accel_vrw[0] * math.sqrt(0.01), 0.1 * units.MG * 0.01) / math.sqrt(B)
    peak_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024**2
    print(f"B = {B} keys x {n} samples x 3: output {dv.nbytes / 1e9:.2f} GB")
    print(f"compile {t1 - t0:.1f} s, run {t2 - t1:.1f} s, peak RSS {peak_gb:.2f} GB, load {loadavg()[0]:.1f}")
    ok = (not np.allclose(e0, e1)) and np.abs(resid).max() < bound
    print(f"keys differ and mean residual {np.abs(resid).max():.3g} < 6 sigma {bound:.3g}: {'ok' if ok else 'FAILED'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
