"""The S0 experiment (Tan, Wu, Kang 2019) as a reusable problem: scenario, filter settings, runs.

``s0_experiment.toml`` beside this file holds the model mismatch and filter settings of the
reproduction (``jaxnav demo``); the scenario is :func:`jaxnav.sim.s0_scenario`. :class:`S0Setup`
simulates one Monte Carlo run from a PRNG key and runs the 18-state loosely coupled filter with
any inflation rule; the tuning tools (:mod:`jaxnav.tune`) and the demo share it.
"""

from __future__ import annotations

import dataclasses
import pathlib
import tomllib

import jax
import jax.numpy as jnp
import numpy as np

from jaxnav import filters as jf
from jaxnav import ins, sim
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


def cut_timeline(cfg, duration: float):
    """The scenario ``cfg`` keeping only the trajectory segments that end by ``duration`` (s)."""
    segs, t = [], 0.0
    for seg in cfg.trajectory.segments:
        if t + seg.duration + seg.hold > duration + 1e-9:
            break
        segs.append(seg)
        t += seg.duration + seg.hold
    if not segs:
        raise ValueError(f"duration {duration} s is shorter than the first trajectory segment")
    return dataclasses.replace(cfg, duration=float(duration),
                               trajectory=dataclasses.replace(cfg.trajectory, segments=tuple(segs)))


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


class S0Setup:
    """One S0 experiment: truth trajectory, GNSS epochs and filter parameters, built once (host side).

    Args:
      exp: experiment dict from :func:`load_experiment`.
      duration: optional shorter timeline, s: the whole trajectory segments (change + hold) that
        end by then are kept (short runs for tests and notebooks); default the full 2000 s.
    """

    def __init__(self, exp, duration=None):
        self.exp = exp
        self.cfg = scenario(exp) if duration is None else cut_timeline(scenario(exp), duration)
        self.truth = sim.make_trajectory(self.cfg)
        self.t_imu = np.asarray(self.truth.t[1:])
        g0 = sim.simulate(self.cfg, jax.random.PRNGKey(0), trajectory=self.truth).gnss
        self.t_gnss, self.gidx = np.asarray(g0.t), np.asarray(g0.index)
        self.params = filter_params(self.cfg, exp)
        lat = self.truth.pos[self.gidx, 0]
        self.RM, self.RN, self.lat = meridian_radius(lat), prime_vertical_radius(lat), lat

    def run(self, key, inflation, save=("nav",), *, q_scale=1.0, r_scale=1.0, remat=False):
        """Simulate the run of ``key`` and filter it (pure in key, the rule's leaves and the scales).

        Args:
          key: PRNG key of the Monte Carlo run.  inflation: rule of :mod:`jaxnav.filters` or None.
          save: per-epoch outputs.  q_scale, r_scale: factors on the experiment's Qc and R (array
            leaves, differentiable).  remat: checkpoint each epoch (reverse-mode gradients).
        """
        r = sim.simulate(self.cfg, key, trajectory=self.truth)
        meas = _measurements(self.cfg, r.gnss, self.t_gnss)
        params = self.params._replace(Qc=self.params.Qc * q_scale, R_scale=self.params.R_scale * r_scale)
        return loosely_coupled(r.nav0, self.t_imu, r.imu.dtheta, r.imu.dv, meas, params, dt_imu=self.cfg.dt,
                               n_states=self.exp["filter"]["n_states"], inflation=inflation, save=save, remat=remat)

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
