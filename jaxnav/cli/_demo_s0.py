"""The S0 reproduction (what ``make demo`` runs): classic, attenuated- and fading-memory filters
in 18-state loosely coupled INS/GPS integration over vmapped Monte Carlo seeds.

Settings come from ``jaxnav/tune/s0_experiment.toml`` (or ``--config``); the scenario is
:func:`jaxnav.sim.s0_scenario`. Writes ``results.json`` and figures into the output folder.
"""

from __future__ import annotations

import json
import pathlib
import time

import jax
import jax.numpy as jnp
import numpy as np

import jaxnav
from jaxnav import filters as jf
from jaxnav import tune
from jaxnav.tune._s0 import (  # noqa: F401  (re-exported: notebooks and tests use them from here)
    EXPERIMENT,
    FILTERS,
    S0Setup,
    filter_params,
    inflated_states,
    load_experiment,
    rules,
    scenario,
)
from jaxnav.tune._s0 import S0Setup as _Setup  # noqa: F401


def run_s0_demo(out="out/demo", *, seeds=None, config=None, sweep_points=None, progress=True) -> dict:
    """Run the S0 reproduction; print the Table-1-style table; write results.json and figures.

    Args:
      out: output folder.  seeds: Monte Carlo seeds (default from the experiment file, 32).
      config: experiment TOML (default ``s0_experiment.toml``).
      sweep_points: use only the first n b values of the sweep (tests); default all.
    Returns:
      The results dictionary.
    """
    jaxnav.enable_x64()
    t_all = time.perf_counter()
    exp = load_experiment(config or EXPERIMENT)
    seeds = exp["monte_carlo"]["seeds"] if seeds is None else int(seeds)
    outdir = pathlib.Path(out)
    outdir.mkdir(parents=True, exist_ok=True)
    S = _Setup(exp)
    keys = jax.random.split(jax.random.PRNGKey(2019), seeds)
    chunk = exp["monte_carlo"]["chunk"]
    states = inflated_states(exp)

    def summary(res):
        """Per-run RMS (9,) and the per-epoch errors and 1-sigma bands used by the figures."""
        pe, ve = S.errors(res)
        ae = S.attitude_errors(res)
        cov = res.epochs.covs
        sig_p = jnp.sqrt(jnp.stack([cov[:, 7, 7] * (S.RN * jnp.cos(S.lat)) ** 2, cov[:, 6, 6] * S.RM**2,
                                    cov[:, 8, 8]], -1))
        sig_v = jnp.sqrt(jnp.stack([cov[:, 3, 3], cov[:, 4, 4], cov[:, 5, 5]], -1))
        r = jnp.concatenate([jnp.sqrt(jnp.mean(pe**2, 0)), jnp.sqrt(jnp.mean(ve**2, 0)),
                             jnp.sqrt(jnp.mean(ae**2, 0))])
        return dict(rms=r, pos_err=pe, vel_err=ve, sig_pos=sig_p, sig_vel=sig_v, factors=res.epochs.factors)

    save = ("nav", "covs", "factors")

    def s0_run(p, key):
        """One run of the filter ``p["rule"]``: 0 attenuated with ``p["b"]`` (b = 0 is the classic filter
        exactly: S_k = 1, S0 eq. (11)), 1 fading. One compiled program serves all three filters and the
        b sweep (``jf.switch``)."""
        rule = jf.switch(p["rule"], [jf.attenuated(p["b"], states=states), rules(exp)["fading"]])
        return summary(S.run(key, rule, save=save))

    timing = {}
    t0 = time.perf_counter()
    three = tune.sweep(s0_run, {"b": np.asarray([0.0, exp["filter"]["b"], 0.0]), "rule": np.asarray([0.0, 0.0, 1.0])},
                       keys, chunk=chunk, desc="S0 classic, attenuated, fading", progress=progress)
    timing["filters"] = time.perf_counter() - t0
    timing["compile"] = three.compile_time_s
    runs = {name: {k: v[i] for k, v in three.values.items()} for i, name in enumerate(("classic", "attenuated",
                                                                                       "fading"))}
    rms = {name: runs[name]["rms"] for name in FILTERS}

    # b sweep: the same compiled function over the b grid and a few seeds
    bs = np.asarray(exp["sweep"]["b"], float)
    if sweep_points is not None:
        bs = bs[:sweep_points]
    if not np.any(np.isclose(bs, exp["filter"]["b"])):
        bs = np.sort(np.append(bs, exp["filter"]["b"]))
    skeys = keys[: exp["sweep"]["seeds"]]
    t0 = time.perf_counter()
    sweep = tune.sweep(s0_run, {"b": bs, "rule": np.zeros_like(bs)}, skeys, chunk=chunk, desc="b sweep",
                       progress=progress).values["rms"]  # (B, seeds, 9)
    timing["sweep"] = time.perf_counter() - t0

    # the first seed in detail for the figures
    detail = {name: {k: runs[name][k][0] for k in ("pos_err", "vel_err", "sig_pos", "sig_vel", "factors")}
              for name in FILTERS}

    pub = exp["published"]
    table = {}
    for name in FILTERS:
        r = rms[name]
        table[name] = dict(
            per_seed=dict(pos_rms_m=r[:, :3].tolist(), vel_rms_mps=r[:, 3:6].tolist(), att_rms_rad=r[:, 6:].tolist()),
            mean=dict(pos_rms_m=r[:, :3].mean(0).tolist(), vel_rms_mps=r[:, 3:6].mean(0).tolist(),
                      att_rms_rad=r[:, 6:].mean(0).tolist()),
            std=dict(pos_rms_m=r[:, :3].std(0).tolist(), vel_rms_mps=r[:, 3:6].std(0).tolist(),
                     att_rms_rad=r[:, 6:].std(0).tolist()),
            mean_pos_rms_m=float(r[:, :3].mean()),
            published=dict(pos_rms_m=pub[name][:3], vel_rms_mps=pub[name][3:]),
        )
    lines = [f"S0 INS/GPS, 2000 s, IMU 100 Hz, GPS 1 Hz, {seeds} seeds (mean +- std of the per-run RMS; "
             f"published = Table 1, one run)",
             f"{'filter':<12}{'':<10}" + "".join(f"{h:>16}" for h in ("pos E m", "pos N m", "pos U m", "vel E m/s",
                                                                         "vel N m/s", "vel U m/s", "att E deg",
                                                                         "att N deg", "att U deg"))]
    for name in FILTERS:
        r = np.concatenate([rms[name][:, :6], np.degrees(rms[name][:, 6:])], axis=1)
        lines.append(f"{name:<12}{'jaxnav':<10}" + "".join(f"{m:>9.3f} +-{s:<5.3f}" for m, s in zip(r.mean(0), r.std(0))))
        lines.append(f"{'':<12}{'published':<10}" + "".join(f"{v:>16.3f}" for v in pub[name]))
    best = int(np.argmin(sweep[:, :, :3].mean(axis=(1, 2))))
    lines.append(f"b sweep ({len(bs)} values x {len(skeys)} seeds, mean position RMS): best b = {bs[best]:.3f} "
                 f"({sweep[best, :, :3].mean():.3f} m); b = {exp['filter']['b']} gives "
                 f"{sweep[np.argmin(np.abs(bs - exp['filter']['b'])), :, :3].mean():.3f} m")
    text = "\n".join(lines)
    print(text)

    from jaxnav.plot import plot_s0

    figs = plot_s0(outdir, truth=S.truth, gidx=S.gidx, t=S.t_gnss, detail=detail, sweep_b=bs,
                   sweep_rms=sweep[:, :, :3].mean(axis=(1, 2)), b_paper=exp["filter"]["b"])
    wall = time.perf_counter() - t_all
    results = dict(
        settings=dict(seeds=seeds, experiment=exp, duration_s=S.cfg.duration, imu_rate_hz=S.cfg.imu_rate_hz,
                      gps_rate_hz=S.cfg.gnss.rate_hz),
        filters=table,
        sweep=dict(b=bs.tolist(), seeds=len(skeys), mean_pos_rms_m=sweep[:, :, :3].mean(axis=(1, 2)).tolist(),
                   best_b=float(bs[best])),
        wall_time_s=dict(total=wall, **timing), figures=[str(f) for f in figs],
        jax_version=jax.__version__, devices=[str(d) for d in jax.devices()],
    )
    (outdir / "results.json").write_text(json.dumps(results, indent=1))
    print(f"\nwrote {outdir / 'results.json'} and {len(figs)} figures to {outdir} ({wall:.0f} s in all)")
    return results
