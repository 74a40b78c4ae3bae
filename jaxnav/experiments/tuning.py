"""Sweeps and gradient tuning of the S0 filters and of CV noise scales from a config file
(what ``jaxnav sweep CONFIG --out DIR`` and ``jaxnav tune CONFIG --out DIR`` run).

A config is a TOML file (or the name of a shipped one: ``s0_b``, ``cv_noise``; see
``jaxnav/experiments/configs/``) with sections ``[problem]``, ``[params.NAME]`` (init, bijector,
trainable), ``[sweep]`` (grid axes) and ``[tune]`` (optimiser). :func:`run_sweep` and
:func:`run_tune` write ``results.json`` (values, losses, grid, wall times) and PNG figures;
:func:`format_sweep` / :func:`format_tune` give their one-line summaries.
"""

from __future__ import annotations

import csv
import logging
import pathlib
import time

import jax
import jax.numpy as jnp
import numpy as np
import optax

from jaxnav import filters as jf
from jaxnav import tune
from jaxnav.experiments.s0 import (
    EXPERIMENT,
    S0_FILTERS,
    S0_LOSSES,
    S0_PARAMS,
    S0Setup,
    load_experiment,
    s0_metrics,
)
from jaxnav.io import ConfigTable, load_toml, write_json
from jaxnav.sim import simulate_linear

_log = logging.getLogger(__name__)

#: the shipped sweep/tune configs (``s0_b``, ``cv_noise``)
CONFIGS = pathlib.Path(__file__).with_name("configs")
_POS = dict(lo=0.0, lo_open=True, hi=1e6)
#: keys of [problem] and [tune]: (kind of :meth:`jaxnav.io.ConfigTable.get`, bounds or choices)
_PROBLEM = {
    "kind": (str, dict(choices=("s0", "cv"))),
    "filter": (str, dict(choices=S0_FILTERS)),
    "loss": (str, dict(choices=S0_LOSSES)),
    "seeds": (int, dict(lo=1, hi=100_000)),
    "seed": (int, dict(lo=0, hi=2**32 - 1)),
    "duration": (float, _POS),
    "experiment": (str, {}),
    "series": (int, dict(lo=1, hi=100_000)),
    "epochs": (int, dict(lo=2, hi=10**6)),
    "sigma": (float, dict(lo=0.0, lo_open=True, hi=1e4)),
    "q": (float, _POS),
}
_OPTIMIZERS = ("adam", "sgd", "lbfgs", "lbfgs_wolfe")
_MODES = ("auto", "forward", "reverse")
_TUNE = {
    "optimizer": (str, dict(choices=_OPTIMIZERS)),
    "learning_rate": (float, _POS),
    "steps": (int, dict(lo=1, hi=10**6)),
    "mode": (str, dict(choices=_MODES)),
    "landscape": (int, dict(lo=0, hi=10**5)),
}
#: allowed values of each tunable parameter (bounds of :meth:`jaxnav.io.ConfigTable.get`)
_PARAM_RANGE = {
    "b": dict(lo=0.0, hi=1.0, hi_open=True),
    "q_scale": _POS,
    "r_scale": _POS,
    "S": dict(lo=1.0, hi=1e6),
    "rho": _POS,
    "tau": _POS,
}


def _keys(t: ConfigTable, schema: dict) -> dict:
    """The keys of ``schema`` given in table ``t``, checked; unknown keys refused."""
    t.expect(schema)
    return {k: t.get(k, kind, **bounds) for k, (kind, bounds) in schema.items() if t.has(k)}


def load_config(spec) -> dict:
    """Read and check a sweep/tune TOML (a path or a shipped name); errors name the file and key
    (:class:`jaxnav.io.ConfigError`, a ValueError)."""
    path = pathlib.Path(spec)
    if not path.exists() and (CONFIGS / f"{spec}.toml").exists():
        path = CONFIGS / f"{spec}.toml"
    if not path.exists():
        raise ValueError(f"{spec}: no such config file (shipped: {sorted(p.stem for p in CONFIGS.glob('*.toml'))})")
    doc = ConfigTable(load_toml(path), source=path)
    doc.expect(("problem", "params", "sweep", "tune"))
    pt = doc.table("problem", required=True)
    prob = _keys(pt, _PROBLEM)
    kind = pt.get("kind", str)
    if "experiment" in prob and not pathlib.Path(prob["experiment"]).is_file():
        pt.fail("experiment", f"= {prob['experiment']}: no such file")
    if kind == "s0":
        load_experiment(prob.get("experiment") or EXPERIMENT)  # its keys checked now, not after a compile
        prob.setdefault("filter", "attenuated")
        prob.setdefault("loss", "rms")
        prob.setdefault("seeds", 8)
        allowed = (
            set(S0_PARAMS[prob["filter"]]) | {"q_scale", "r_scale"} | ({"tau"} if prob["filter"] == "fading" else set())
        )
    else:
        prob.setdefault("loss", "nll")
        prob.setdefault("series", 64)
        prob.setdefault("epochs", 500)
        if prob["loss"] != "nll":
            pt.fail("loss", "must be 'nll' for kind = 'cv'")
        allowed = {"q_scale", "r_scale"}
    prob.setdefault("seed", 0)
    params_t = doc.table("params")
    if params_t is None or not params_t.data:
        doc.fail("params", "is required: sections [params.NAME] (at least one parameter)")
    params = {}
    for name in params_t.data:
        if name not in allowed:
            params_t.fail(name, f"does not apply to this problem; allowed parameters: {sorted(allowed)}")
        t = params_t.table(name)
        t.expect(("init", "bijector", "trainable"))
        init = t.get("init", float, **_PARAM_RANGE[name])
        p = {
            "init": init,
            "bijector": t.get("bijector", str, "unit" if name == "b" else "log"),
            "trainable": t.get("trainable", bool, True),
        }
        try:
            tune.bijector(p["bijector"])
        except (ValueError, TypeError) as exc:
            t.fail("bijector", f"{exc}")
        if p["bijector"] == "unit" and not 0.0 < init < 1.0:
            t.fail("init", f"= {init!r} must be in (0, 1) for bijector 'unit'")
        if p["bijector"] == "log" and not init > 0.0:
            t.fail("init", f"= {init!r} must be > 0 for bijector 'log'")
        params[name] = p
    if kind == "s0" and prob["filter"] not in ("classic", "fading"):
        need = S0_PARAMS[prob["filter"]]
        if not set(need) <= set(params):
            params_t.fail(None, f"lacks {need}: filter {prob['filter']} needs them")
    sw_t = doc.table("sweep") or ConfigTable({}, "sweep", source=path)
    sweep = {}
    for name in sw_t.data:
        if name == "chunk":
            sweep["chunk"] = sw_t.get("chunk", int, lo=1, hi=10**6)
            continue
        if name not in params:
            sw_t.fail(name, "is not a parameter: a sweep axis needs a [params.NAME] section")
        t = sw_t.table(name)
        t.expect(("start", "stop", "num", "log"))
        ax = {
            "start": t.get("start", float, **_PARAM_RANGE[name]),
            "stop": t.get("stop", float, **_PARAM_RANGE[name]),
            "num": t.get("num", int, lo=1, hi=10**6),
        }
        if t.has("log"):
            ax["log"] = t.get("log", bool)
        for end in ("start", "stop"):
            if ax.get("log") and not ax[end] > 0:
                t.fail(end, f"= {ax[end]!r} must be > 0 with log = true")
        sweep[name] = ax
    tn_t = doc.table("tune") or ConfigTable({}, "tune", source=path)
    tn = _keys(tn_t, _TUNE)
    tn.setdefault("optimizer", "adam")
    tn.setdefault("learning_rate", 0.1)
    tn.setdefault("steps", 50)
    tn.setdefault("mode", "auto")
    tn.setdefault("landscape", 0)
    return {"problem": prob, "params": params, "sweep": sweep, "tune": tn, "_path": str(path)}


class Problem:
    """The config's problem: ``point(params, key) -> metrics dict`` and the keys of its runs."""

    def __init__(self, cfg):
        prob = cfg["problem"]
        self.cfg = cfg
        self.kind = prob["kind"]
        self.init = {k: float(v["init"]) for k, v in cfg["params"].items()}
        self.space = tune.Space(
            {k: v["bijector"] for k, v in cfg["params"].items()},
            trainable=tuple(k for k, v in cfg["params"].items() if v["trainable"]),
        )
        if self.kind == "s0":
            exp = load_experiment(prob.get("experiment") or EXPERIMENT)
            self.setup = S0Setup(exp, duration=prob.get("duration"))
            self.keys = jax.random.split(jax.random.PRNGKey(prob["seed"]), prob["seeds"])
            self.loss_name = {
                "rms": "mean position RMS, m",
                "nll": "innovation NLL per component",
                "nis": "NIS consistency (log ratio)^2",
            }[prob["loss"]]
            self.loss_column = {"rms": "loss_rms_m", "nll": "loss_nll_per_component", "nis": "loss_nis_log_ratio_sq"}[
                prob["loss"]
            ]
        else:
            self.keys = jax.random.split(jax.random.PRNGKey(prob["seed"]), prob["series"])
            self.loss_name = "innovation NLL per component"
            self.loss_column = "loss_nll_per_component"

    def point(self, params, key, remat=False):
        """Metrics of one run (one Monte Carlo seed / one series) at ``params``."""
        prob = self.cfg["problem"]
        if self.kind == "s0":
            return s0_metrics(self.setup, params, key, filter=prob["filter"], loss=prob["loss"], remat=remat)
        sigma, q, T = prob.get("sigma", 0.003), prob.get("q", 1e-8), prob["epochs"]
        model = jf.constant_velocity(1.0, sigma=sigma, q=q)
        zs = simulate_linear(key, model, jnp.zeros(6), T)[1]
        nll = tune.cv_nll(params, zs[None], sigma=sigma, q=q)
        return {"loss": nll, "nll": nll}

    def loss(self, params):
        """Mean loss over the runs (common random numbers), the runs sharded over all devices and processes."""
        remat = self.cfg["tune"]["mode"] == "reverse"
        return tune.monte_carlo_mean(lambda p, k: self.point(p, k, remat)["loss"], self.keys)(params)


def _axis(ax):
    if ax.get("log"):
        return np.geomspace(ax["start"], ax["stop"], int(ax["num"]))
    return np.linspace(ax["start"], ax["stop"], int(ax["num"]))


def _grid(P: Problem, axes: dict):
    full = {k: (axes[k] if k in axes else np.asarray([P.init[k]])) for k in P.init}
    return tune.grid(**full)


def csv_number(v):
    """A table cell: a float to 12 significant digits (a grid point 0.035 built as 0.01 + 5 * 0.005
    reads 0.035, not its float's repr 0.034999999999999996); anything else as it is."""
    return f"{v:.12g}" if isinstance(v, float) else v


def run_sweep(config, out, *, progress=True) -> dict:
    """Sweep the config's grid x Monte Carlo runs; write results.json, table.csv and figures into ``out``.

    Returns:
      The results dict written to ``results.json`` (grid, per-run and mean losses, best point).
    """
    t0 = time.perf_counter()
    cfg = load_config(config)
    out = pathlib.Path(out)
    writer = tune.is_writer()  # several processes: all compute, process 0 writes
    if writer:
        out.mkdir(parents=True, exist_ok=True)  # before the computation: an unusable folder fails now
    P = Problem(cfg)
    axes = {k: _axis(v) for k, v in cfg["sweep"].items() if k != "chunk"}
    if not axes:
        raise ValueError(f"{cfg['_path']}: [sweep] has no axes")
    g = _grid(P, axes)
    _log.info(
        "sweep of %s: %d grid points x %d Monte Carlo runs", ", ".join(axes), len(next(iter(g.values()))), len(P.keys)
    )
    res = tune.sweep(
        lambda p, k: P.point(p, k), g, P.keys, chunk=cfg["sweep"].get("chunk"), progress=progress, desc="sweep"
    )
    loss = res.values["loss"]  # (G, K)
    mean = loss.mean(1)
    best = int(np.argmin(mean))
    figs = []
    if writer:
        # columns: the parameters (dimensionless scale factors), then the loss's mean/std/min/max over the
        # Monte Carlo runs, its name carrying its unit (loss_rms_m: m; the likelihood losses are pure numbers)
        rows = tune.table(res, lambda v: {P.loss_column: v["loss"]})
        with open(out / "table.csv", "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows([{k: csv_number(v) for k, v in r.items()} for r in rows])
        from jaxnav.plot import plot_sweep

        figs = plot_sweep(out, grid=g, axes=list(axes), loss=loss, loss_name=P.loss_name, init=P.init)
    results = dict(
        command="sweep",
        config=cfg["_path"],
        problem=cfg["problem"],
        loss_name=P.loss_name,
        grid={k: v for k, v in g.items()},
        axes=list(axes),
        loss_mean=mean,
        loss_std=loss.std(1),
        loss_per_run=loss,
        best={**{k: float(v[best]) for k, v in g.items()}, "loss": float(mean[best])},
        runs=len(P.keys),
        points=len(mean),
        chunk=res.chunk,
        n_devices=res.n_devices,
        n_processes=res.n_processes,
        peak_bytes_per_chunk=res.peak_bytes,
        wall_time_s=dict(total=time.perf_counter() - t0, sweep=res.wall_time_s, compile=res.compile_time_s),
        figures=[str(f) for f in figs],
        table=str(out / "table.csv"),
        table_columns=dict(
            parameters="dimensionless scale factors (as in the config)",
            loss=f"{P.loss_column}_mean/_std/_min/_max over the Monte Carlo runs: {P.loss_name}",
        ),
        jax_version=jax.__version__,
        devices=[str(d) for d in jax.devices()],
    )
    if "rms" in res.values:
        results["rms_best_mean"] = res.values["rms"][best].mean(0)
    if writer:
        write_json(out / "results.json", results)
    return results


def format_sweep(results: dict) -> str:
    """One line: the size and wall time of :func:`run_sweep`'s sweep and its best point."""
    b, w = results["best"], results["wall_time_s"]
    return (
        f"sweep: {results['points']} points x {results['runs']} runs in {w['sweep']:.1f} s "
        f"({w['compile']:.1f} s compile, {results['n_devices']} device(s), chunk {results['chunk']}); "
        f"best "
        + ", ".join(f"{k} = {v:.4g}" for k, v in b.items() if k != "loss")
        + f": {results['loss_name']} {b['loss']:.4f}"
    )


def _optimizer(tn):
    if tn["optimizer"] == "adam":
        return optax.adam(tn["learning_rate"])
    if tn["optimizer"] == "sgd":
        return optax.sgd(tn["learning_rate"])
    return optax.lbfgs()


def run_tune(config, out, *, progress=True) -> dict:
    """Tune the config's parameters by gradient descent (optax in lax.scan); write results.json and figures.

    Returns:
      The results dict written to ``results.json`` (initial and tuned values, loss path).
    """
    t0 = time.perf_counter()
    cfg = load_config(config)
    out = pathlib.Path(out)
    writer = tune.is_writer()  # several processes: all compute (the same parameters), process 0 writes
    if writer:
        out.mkdir(parents=True, exist_ok=True)  # before the computation: an unusable folder fails now
    P = Problem(cfg)
    tn = cfg["tune"]
    _log.info(
        "tuning %s of %s: %s, %d %s over %d Monte Carlo runs (one compiled lax.scan: no progress until it returns)",
        ", ".join(P.init),
        cfg["problem"].get("kind", "?"),
        tn["optimizer"],
        tn["steps"],
        "loss evaluations" if tn["optimizer"] == "lbfgs_wolfe" else "steps",
        len(P.keys),
    )
    if tn["optimizer"] == "lbfgs_wolfe":  # steps = evaluation budget; the loss is compiled once
        res = tune.minimize_lbfgs(P.loss, P.init, P.space, max_evals=tn["steps"], mode=tn["mode"])
        done = np.isfinite(np.asarray(res.losses))
        res = res._replace(
            losses=np.asarray(res.losses)[done],
            grad_norm=np.asarray(res.grad_norm)[done],
            path={k: np.asarray(v)[done] for k, v in res.path.items()},
        )
    else:
        res = tune.minimize(P.loss, P.init, P.space, optimizer=_optimizer(tn), steps=tn["steps"], mode=tn["mode"])
    t_tune = time.perf_counter() - t0
    final = {k: float(v) for k, v in res.params.items()}
    _log.info(
        "tuned in %.1f s (compilation included): %s; %s %.4g -> %.4g",
        t_tune,
        ", ".join(f"{k} {float(P.init[k]):.4g} -> {v:.4g}" for k, v in final.items()),
        P.loss_name,
        float(res.losses[0]),
        float(res.loss),
    )
    landscape = None
    if tn["landscape"] and len(P.init) == 1:
        (name,) = P.init
        ax = cfg["sweep"].get(name)
        vals = _axis(dict(ax, num=tn["landscape"])) if ax else None
        if vals is not None:
            sw = tune.sweep(
                lambda p, k: P.point(p, k),
                {name: vals},
                P.keys,
                chunk=cfg["sweep"].get("chunk"),
                progress=progress,
                desc="landscape",
            )
            landscape = dict(values=vals, loss=sw.values["loss"].mean(1), wall_time_s=sw.wall_time_s)
    # Monte Carlo distribution of the per-run loss at the start and at the tuned values (a 2-point sweep)
    _log.info("scoring the start and the tuned values over %d Monte Carlo runs", len(P.keys))
    ends = tune.sweep(
        lambda p, k: P.point(p, k)["loss"],
        {k: [P.init[k], final[k]] for k in P.init},
        P.keys,
        chunk=cfg["sweep"].get("chunk"),
        progress=False,
    ).values
    start_runs, final_runs = ends[0], ends[1]
    figs = []
    if writer:
        from jaxnav.plot import plot_tune

        figs = plot_tune(
            out,
            path={k: np.asarray(v) for k, v in res.path.items()},
            losses=np.asarray(res.losses),
            final=final,
            final_loss=float(res.loss),
            landscape=landscape,
            loss_name=P.loss_name,
            start_runs=start_runs,
            final_runs=final_runs,
        )
    results = dict(
        command="tune",
        config=cfg["_path"],
        problem=cfg["problem"],
        loss_name=P.loss_name,
        init=P.init,
        tuned=final,
        loss_init=float(res.losses[0]),
        loss_final=float(res.loss),
        losses=np.asarray(res.losses),
        path={k: np.asarray(v) for k, v in res.path.items()},
        grad_norm=np.asarray(res.grad_norm),
        optimizer=dict(tn),
        loss_evaluations=int(res.n_evals),
        runs=len(P.keys),
        loss_per_run=dict(init=start_runs, tuned=final_runs),
        landscape=landscape,
        wall_time_s=dict(tune=t_tune, total=time.perf_counter() - t0),
        figures=[str(f) for f in figs],
        jax_version=jax.__version__,
        n_processes=jax.process_count(),
        n_devices=len(jax.devices()),
    )
    if writer:
        write_json(out / "results.json", results)
    return results


def format_tune(results: dict) -> str:
    """One line: optimiser, steps, wall time and the parameters and loss before and after :func:`run_tune`."""
    tn, init = results["optimizer"], results["init"]
    return (
        f"tune: {tn['optimizer']} x {tn['steps']} steps ({tn['mode']} mode) over {results['runs']} runs in "
        f"{results['wall_time_s']['tune']:.1f} s: "
        + ", ".join(f"{k} {init[k]:.4g} -> {v:.4g}" for k, v in results["tuned"].items())
        + f"; {results['loss_name']} {results['loss_init']:.4f} -> {results['loss_final']:.4f}"
    )
