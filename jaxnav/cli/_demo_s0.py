"""The S0 reproduction (what ``make demo`` runs): classic, attenuated- and fading-memory filters
in 18-state loosely coupled INS/GPS integration over vmapped Monte Carlo seeds.

Settings come from ``s0_experiment.toml`` beside this file (or ``--config``); the scenario is
:func:`jaxnav.sim.s0_scenario`. Writes ``results.json`` and figures into the output folder.
"""

from __future__ import annotations

import dataclasses
import json
import pathlib
import time
import tomllib

import jax
import jax.numpy as jnp
import numpy as np

import jaxnav
from jaxnav import filters as jf
from jaxnav import ins, sim
from jaxnav._montecarlo import run_chunked
from jaxnav.geodesy import meridian_radius, prime_vertical_radius
from jaxnav.ins.attitude import quat_conj, quat_mul, quat_to_rv
from jaxnav.ins.integration import LCParams, PVMeasurements, loosely_coupled

FILTERS = ("classic", "attenuated", "fading")
EXPERIMENT = pathlib.Path(__file__).with_name("s0_experiment.toml")
_SCHEMA = {
    "scenario": {"unsensed_velocity_steps": bool},
    "filter": {"n_states": int, "q_scale": float, "r_scale": float, "inflate_states": list, "b": float,
               "fading_window": int},
    "monte_carlo": {"seeds": int, "chunk": int},
    "sweep": {"b": list, "seeds": int},
    "published": {"classic": list, "attenuated": list, "fading": list},
}


def load_experiment(path=EXPERIMENT) -> dict:
    """Read and check an S0 experiment TOML; unknown or mistyped keys raise ValueError naming them."""
    path = pathlib.Path(path)
    try:
        d = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{path}: {exc}") from None
    for sec, v in d.items():
        if sec not in _SCHEMA:
            raise ValueError(f"{path}: unknown section [{sec}]; expected one of {sorted(_SCHEMA)}")
        for k, val in v.items():
            if k not in _SCHEMA[sec]:
                raise ValueError(f"{path}: unknown key {sec}.{k}; expected one of {sorted(_SCHEMA[sec])}")
            typ = _SCHEMA[sec][k]
            if typ is float and isinstance(val, int) and not isinstance(val, bool):
                val = float(val)
                v[k] = val
            if not isinstance(val, typ):
                raise ValueError(f"{path}: {sec}.{k} must be {typ.__name__}, got {val!r}")
            if typ is list and k == "inflate_states" and not all(isinstance(i, int) and i >= 0 for i in val):
                raise ValueError(f"{path}: {sec}.{k} must be a list of non-negative state indices, got {val!r}")
    for sec in _SCHEMA:
        if sec not in d:
            raise ValueError(f"{path}: missing section [{sec}]")
    return d


def scenario(exp: dict):
    """The S0 scenario with the experiment's mismatch applied."""
    cfg = sim.s0_scenario()
    if exp["scenario"]["unsensed_velocity_steps"]:
        segs = tuple(dataclasses.replace(s, sensed=False) if s.kind == "velocity_step" else s
                     for s in cfg.trajectory.segments)
        cfg = dataclasses.replace(cfg, trajectory=dataclasses.replace(cfg.trajectory, segments=segs))
    return cfg


def filter_params(cfg, exp: dict) -> LCParams:
    """P0 and Qc from the scenario's sigmas, scaled by the experiment's assumed-noise mismatch."""
    v3 = lambda x: np.broadcast_to(np.asarray(x, float), (3,))  # noqa: E731
    ie, g, a = cfg.initial_errors, cfg.gyro, cfg.accel
    lat, h = float(cfg.origin[0]), float(cfg.origin[2])
    RM, RN = float(meridian_radius(lat)) + h, float(prime_vertical_radius(lat)) + h
    pe = v3(ie.position)
    n = exp["filter"]["n_states"]
    p0 = [v3(ie.attitude) ** 2, v3(ie.velocity) ** 2,
          np.array([pe[1] / RM, pe[0] / (RN * np.cos(lat)), pe[2]]) ** 2, v3(g.bias_sigma) ** 2]
    if n == 18:
        p0.append(v3(g.markov_sigma) ** 2)
        Qc = ins.error_model_Qc(v3(g.white), v3(g.markov_sigma), v3(g.markov_tau), v3(a.white))
    else:
        Qc = ins.error_model_Qc15(v3(g.white), v3(a.white))
    p0.append(v3(a.bias_sigma) ** 2)
    return LCParams(P0=jnp.diag(jnp.asarray(np.concatenate(p0))), Qc=Qc * exp["filter"]["q_scale"],
                    tau_markov=jnp.asarray(v3(g.markov_tau)), R_scale=exp["filter"]["r_scale"])


def inflated_states(exp: dict):
    """The state indices the attenuated and fading rules inflate (None = all)."""
    return tuple(exp["filter"]["inflate_states"]) or None


def rules(exp: dict, b=None) -> dict:
    """The three filters' inflation rules (attenuated with ``b`` if given)."""
    f = exp["filter"]
    states = inflated_states(exp)
    return {"classic": None,
            "attenuated": jf.attenuated(f["b"] if b is None else b, states=states),
            "fading": jf.fading(window=f["fading_window"], states=states)}


def _measurements(cfg, gnss, t):
    v3 = lambda x: np.broadcast_to(np.asarray(x, float), (3,))  # noqa: E731
    M = t.shape[0]
    R = np.diag(np.concatenate([v3(cfg.gnss.pos_sigma) ** 2, v3(cfg.gnss.vel_sigma) ** 2]))
    return PVMeasurements(t=t, pos=gnss.pos, vel=gnss.vel, R=jnp.broadcast_to(R, (M, 6, 6)),
                          mask=jnp.broadcast_to(gnss.valid[:, None], (M, 6)), lever=jnp.zeros((M, 3)))


class _Setup:
    def __init__(self, exp):
        self.exp = exp
        self.cfg = scenario(exp)
        self.truth = sim.make_trajectory(self.cfg)
        self.t_imu = np.asarray(self.truth.t[1:])
        g0 = sim.simulate(self.cfg, jax.random.PRNGKey(0), trajectory=self.truth).gnss
        self.t_gnss, self.gidx = np.asarray(g0.t), np.asarray(g0.index)
        self.params = filter_params(self.cfg, exp)
        lat = self.truth.pos[self.gidx, 0]
        self.RM, self.RN, self.lat = meridian_radius(lat), prime_vertical_radius(lat), lat

    def run(self, key, inflation, save=("nav",)):
        r = sim.simulate(self.cfg, key, trajectory=self.truth)
        meas = _measurements(self.cfg, r.gnss, self.t_gnss)
        return loosely_coupled(r.nav0, self.t_imu, r.imu.dtheta, r.imu.dv, meas, self.params, dt_imu=self.cfg.dt,
                               n_states=self.exp["filter"]["n_states"], inflation=inflation, save=save)

    def errors(self, res):
        d = res.epochs.nav.pos - self.truth.pos[self.gidx]
        pe = jnp.stack([d[:, 1] * self.RN * jnp.cos(self.lat), d[:, 0] * self.RM, d[:, 2]], -1)
        return pe, res.epochs.nav.v_n - self.truth.v_n[self.gidx]

    def attitude_errors(self, res):
        """(M, 3) attitude error rotation vectors (ENU, rad): C_est C_true^T = exp([phi x])."""
        dq = jax.vmap(quat_mul)(res.epochs.nav.q_bn, jax.vmap(quat_conj)(self.truth.q_bn[self.gidx]))
        return jax.vmap(quat_to_rv)(dq)

    def rms(self, key, inflation):
        """(9,) per-run RMS: position E, N, U (m), velocity E, N, U (m/s), attitude E, N, U (rad)."""
        res = self.run(key, inflation)
        pe, ve = self.errors(res)
        ae = self.attitude_errors(res)
        return jnp.concatenate([jnp.sqrt(jnp.mean(pe**2, 0)), jnp.sqrt(jnp.mean(ve**2, 0)),
                                jnp.sqrt(jnp.mean(ae**2, 0))])


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
    rms, timing = {}, {}
    for name, rule in rules(exp).items():
        t0 = time.perf_counter()
        rms[name] = run_chunked(lambda k, r=rule: S.rms(k, r), keys, chunk=exp["monte_carlo"]["chunk"],
                                desc=f"S0 {name}", progress=progress)
        timing[name] = time.perf_counter() - t0

    # b sweep: vmapped over the b grid and a few seeds
    bs = np.asarray(exp["sweep"]["b"], float)
    if sweep_points is not None:
        bs = bs[:sweep_points]
    if not np.any(np.isclose(bs, exp["filter"]["b"])):
        bs = np.sort(np.append(bs, exp["filter"]["b"]))
    skeys = keys[: exp["sweep"]["seeds"]]
    t0 = time.perf_counter()
    states = inflated_states(exp)
    sweep_fn = jax.jit(jax.vmap(lambda b: jax.vmap(lambda k: S.rms(k, jf.attenuated(b, states=states)))(skeys)))
    from tqdm.auto import tqdm

    sweep = []
    for b in tqdm(bs, desc="b sweep", disable=not progress):
        sweep.append(np.asarray(sweep_fn(jnp.asarray([b]))[0]))
    sweep = np.stack(sweep)  # (B, seeds, 9)
    timing["sweep"] = time.perf_counter() - t0

    # one seed in detail for the figures
    detail = {}
    for name, rule in rules(exp).items():
        res = S.run(keys[0], rule, save=("nav", "covs", "factors"))
        pe, ve = S.errors(res)
        cov = np.asarray(res.epochs.covs)
        sig_p = np.sqrt(np.stack([cov[:, 7, 7] * np.asarray(S.RN * jnp.cos(S.lat)) ** 2,
                                  cov[:, 6, 6] * np.asarray(S.RM) ** 2, cov[:, 8, 8]], -1))
        sig_v = np.sqrt(np.stack([cov[:, 3, 3], cov[:, 4, 4], cov[:, 5, 5]], -1))
        detail[name] = dict(pos_err=np.asarray(pe), vel_err=np.asarray(ve), sig_pos=sig_p, sig_vel=sig_v,
                            factors=np.asarray(res.epochs.factors))

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
