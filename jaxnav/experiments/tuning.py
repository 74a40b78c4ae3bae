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

from jaxnav.io import write_json
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
from jaxnav.io import load_toml
from jaxnav.sim import simulate_linear

_log = logging.getLogger(__name__)

#: the shipped sweep/tune configs (``s0_b``, ``cv_noise``)
CONFIGS = pathlib.Path(__file__).with_name("configs")
_PROBLEM = {"kind": str, "filter": str, "loss": str, "seeds": int, "seed": int, "duration": float,
            "experiment": str, "series": int, "epochs": int, "sigma": float, "q": float}
_TUNE = {"optimizer": str, "learning_rate": float, "steps": int, "mode": str, "landscape": int}
_OPTIMIZERS = ("adam", "sgd", "lbfgs", "lbfgs_wolfe")
_MODES = ("auto", "forward", "reverse")
#: allowed ranges (lo, hi, open ends "lo"/"hi"/"") of the problem and tune numbers
_PROBLEM_RANGE = {"seeds": (1, 100_000, ""), "series": (1, 100_000, ""), "epochs": (2, 10**6, ""),
                  "seed": (0, 2**32 - 1, ""), "duration": (0.0, 1e6, "lo"), "sigma": (0.0, 1e4, "lo"),
                  "q": (0.0, 1e6, "lo")}
_TUNE_RANGE = {"learning_rate": (0.0, 1e6, "lo"), "steps": (1, 10**6, ""), "landscape": (0, 10**5, "")}
#: allowed values of each tunable parameter (lo, hi, open ends)
_PARAM_RANGE = {"b": (0.0, 1.0, "hi"), "q_scale": (0.0, 1e6, "lo"), "r_scale": (0.0, 1e6, "lo"),
                "S": (1.0, 1e6, ""), "rho": (0.0, 1e6, "lo"), "tau": (0.0, 1e6, "lo")}


def _number(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _check_range(path, key, v, rng):
    """ValueError naming ``key`` unless ``v`` is a finite number inside ``rng`` = (lo, hi, open ends)."""
    lo, hi, opn = rng
    ok = _number(v) and v == v and (v > lo if "lo" in opn else v >= lo) and (v < hi if "hi" in opn else v <= hi)
    if not ok:
        _err(path, f"{key} = {v!r} is outside the allowed range {'(' if 'lo' in opn else '['}{lo:g}, {hi:g}"
                   f"{')' if 'hi' in opn else ']'}")


def _err(path, msg):
    raise ValueError(f"{path}: {msg}")


def load_config(spec) -> dict:
    """Read and check a sweep/tune TOML (a path or a shipped name); errors name the file and key."""
    path = pathlib.Path(spec)
    if not path.exists() and (CONFIGS / f"{spec}.toml").exists():
        path = CONFIGS / f"{spec}.toml"
    if not path.exists():
        raise ValueError(f"{spec}: no such config file (shipped: {sorted(p.stem for p in CONFIGS.glob('*.toml'))})")
    cfg = load_toml(path)
    for sec in cfg:
        if sec not in ("problem", "params", "sweep", "tune"):
            _err(path, f"unknown section [{sec}]; expected problem, params, sweep, tune")
    prob = cfg.get("problem") or _err(path, "missing section [problem]")
    if not isinstance(prob, dict):
        _err(path, f"problem must be a section [problem], got {prob!r}")
    for k, v in prob.items():
        if k not in _PROBLEM:
            _err(path, f"unknown key problem.{k}; expected one of {sorted(_PROBLEM)}")
        if _PROBLEM[k] is float and _number(v):
            prob[k] = float(v)
        elif not isinstance(prob[k], _PROBLEM[k]) or isinstance(v, bool):
            _err(path, f"problem.{k} must be {_PROBLEM[k].__name__}, got {v!r}")
        if k in _PROBLEM_RANGE:
            _check_range(path, f"problem.{k}", prob[k], _PROBLEM_RANGE[k])
    if "experiment" in prob and not pathlib.Path(prob["experiment"]).is_file():
        _err(path, f"problem.experiment: {prob['experiment']}: no such file")
    if prob.get("kind") == "s0":
        load_experiment(prob.get("experiment") or EXPERIMENT)  # its keys checked now, not after a compile
    kind = prob.get("kind")
    if kind == "s0":
        prob.setdefault("filter", "attenuated")
        prob.setdefault("loss", "rms")
        prob.setdefault("seeds", 8)
        if prob["filter"] not in S0_FILTERS:
            _err(path, f"problem.filter must be one of {S0_FILTERS}, got {prob['filter']!r}")
        if prob["loss"] not in S0_LOSSES:
            _err(path, f"problem.loss must be one of {S0_LOSSES}, got {prob['loss']!r}")
        allowed = set(S0_PARAMS[prob["filter"]]) | {"q_scale", "r_scale"} | (
            {"tau"} if prob["filter"] == "fading" else set())
    elif kind == "cv":
        prob.setdefault("loss", "nll")
        prob.setdefault("series", 64)
        prob.setdefault("epochs", 500)
        if prob["loss"] != "nll":
            _err(path, "problem.loss must be 'nll' for kind = 'cv'")
        allowed = {"q_scale", "r_scale"}
    else:
        _err(path, f"problem.kind must be 's0' or 'cv', got {kind!r}")
    prob.setdefault("seed", 0)
    params = cfg.get("params") or _err(path, "missing section [params.NAME] (at least one parameter)")
    if not isinstance(params, dict):
        _err(path, f"params must be sections [params.NAME], got {params!r}")
    for name, p in params.items():
        if not isinstance(p, dict):
            _err(path, f"params.{name} must be a section [params.{name}] with init = ..., got {p!r}")
        if name not in allowed:
            _err(path, f"parameter {name!r} does not apply to this problem; allowed: {sorted(allowed)}")
        if "init" not in p:
            _err(path, f"params.{name}.init is missing")
        unknown = set(p) - {"init", "bijector", "trainable"}
        if unknown:
            _err(path, f"unknown keys {sorted(unknown)} in [params.{name}]")
        p.setdefault("bijector", "unit" if name == "b" else "log")
        p.setdefault("trainable", True)
        if not isinstance(p["trainable"], bool):
            _err(path, f"params.{name}.trainable must be true or false, got {p['trainable']!r}")
        try:
            tune.bijector(p["bijector"])
        except (ValueError, TypeError) as exc:
            _err(path, f"params.{name}.bijector: {exc}")
        _check_range(path, f"params.{name}.init", p["init"], _PARAM_RANGE[name])
        if p["bijector"] == "unit" and not 0.0 < p["init"] < 1.0:
            _err(path, f"params.{name}.init = {p['init']!r} must be in (0, 1) for bijector 'unit'")
        if p["bijector"] == "log" and not p["init"] > 0.0:
            _err(path, f"params.{name}.init = {p['init']!r} must be > 0 for bijector 'log'")
    if kind == "s0" and prob["filter"] != "classic":
        need = S0_PARAMS[prob["filter"]]
        if prob["filter"] != "fading" and not set(need) <= set(params):
            _err(path, f"filter {prob['filter']} needs parameter(s) {need}")
    sw = cfg.setdefault("sweep", {})
    if not isinstance(sw, dict):
        _err(path, f"sweep must be a section [sweep], got {sw!r}")
    for name, ax in sw.items():
        if name == "chunk":
            _check_range(path, "sweep.chunk", ax, (1, 10**6, ""))
            if not isinstance(ax, int):
                _err(path, f"sweep.chunk must be an integer, got {ax!r}")
            continue
        if name not in params:
            _err(path, f"sweep axis {name!r} is not a parameter")
        if not (isinstance(ax, dict) and {"start", "stop", "num"} <= set(ax)):
            _err(path, f"sweep.{name} must be {{ start = , stop = , num = [, log = true] }}")
        unknown = set(ax) - {"start", "stop", "num", "log"}
        if unknown:
            _err(path, f"unknown keys {sorted(unknown)} in sweep.{name}; expected start, stop, num, log")
        if not isinstance(ax["num"], int) or isinstance(ax["num"], bool):
            _err(path, f"sweep.{name}.num must be an integer, got {ax['num']!r}")
        _check_range(path, f"sweep.{name}.num", ax["num"], (1, 10**6, ""))
        if not isinstance(ax.get("log", False), bool):
            _err(path, f"sweep.{name}.log must be true or false, got {ax['log']!r}")
        for end in ("start", "stop"):
            _check_range(path, f"sweep.{name}.{end}", ax[end], _PARAM_RANGE[name])
            if ax.get("log") and not ax[end] > 0:
                _err(path, f"sweep.{name}.{end} = {ax[end]!r} must be > 0 with log = true")
    tn = cfg.setdefault("tune", {})
    if not isinstance(tn, dict):
        _err(path, f"tune must be a section [tune], got {tn!r}")
    for k, v in tn.items():
        if k not in _TUNE:
            _err(path, f"unknown key tune.{k}; expected one of {sorted(_TUNE)}")
        if _TUNE[k] is float and _number(v):
            tn[k] = float(v)
        elif not isinstance(v, _TUNE[k]) or isinstance(v, bool):
            _err(path, f"tune.{k} must be {_TUNE[k].__name__}, got {v!r}")
        if k in _TUNE_RANGE:
            _check_range(path, f"tune.{k}", tn[k], _TUNE_RANGE[k])
    if tn.get("mode", "auto") not in _MODES:
        _err(path, f"tune.mode must be one of {_MODES}, got {tn['mode']!r}")
    tn.setdefault("optimizer", "adam")
    tn.setdefault("learning_rate", 0.1)
    tn.setdefault("steps", 50)
    tn.setdefault("mode", "auto")
    tn.setdefault("landscape", 0)
    if tn["optimizer"] not in _OPTIMIZERS:
        _err(path, f"tune.optimizer must be one of {_OPTIMIZERS}, got {tn['optimizer']!r}")
    cfg["_path"] = str(path)
    return cfg


class Problem:
    """The config's problem: ``point(params, key) -> metrics dict`` and the keys of its runs."""

    def __init__(self, cfg):
        prob = cfg["problem"]
        self.cfg = cfg
        self.kind = prob["kind"]
        self.init = {k: float(v["init"]) for k, v in cfg["params"].items()}
        self.space = tune.Space({k: v["bijector"] for k, v in cfg["params"].items()},
                                trainable=tuple(k for k, v in cfg["params"].items() if v["trainable"]))
        if self.kind == "s0":
            exp = load_experiment(prob.get("experiment") or EXPERIMENT)
            self.setup = S0Setup(exp, duration=prob.get("duration"))
            self.keys = jax.random.split(jax.random.PRNGKey(prob["seed"]), prob["seeds"])
            self.loss_name = {"rms": "mean position RMS, m", "nll": "innovation NLL per component",
                              "nis": "NIS consistency (log ratio)^2"}[prob["loss"]]
            self.loss_column = {"rms": "loss_rms_m", "nll": "loss_nll_per_component",
                                "nis": "loss_nis_log_ratio_sq"}[prob["loss"]]
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
    _log.info("sweep of %s: %d grid points x %d Monte Carlo runs", ", ".join(axes), len(next(iter(g.values()))),
              len(P.keys))
    res = tune.sweep(lambda p, k: P.point(p, k), g, P.keys, chunk=cfg["sweep"].get("chunk"), progress=progress,
                     desc="sweep")
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
        command="sweep", config=cfg["_path"], problem=cfg["problem"], loss_name=P.loss_name,
        grid={k: v for k, v in g.items()},
        axes=list(axes), loss_mean=mean, loss_std=loss.std(1), loss_per_run=loss,
        best={**{k: float(v[best]) for k, v in g.items()}, "loss": float(mean[best])},
        runs=len(P.keys), points=len(mean), chunk=res.chunk, n_devices=res.n_devices, n_processes=res.n_processes,
        peak_bytes_per_chunk=res.peak_bytes,
        wall_time_s=dict(total=time.perf_counter() - t0, sweep=res.wall_time_s, compile=res.compile_time_s),
        figures=[str(f) for f in figs], table=str(out / "table.csv"),
        table_columns=dict(parameters="dimensionless scale factors (as in the config)",
                           loss=f"{P.loss_column}_mean/_std/_min/_max over the Monte Carlo runs: {P.loss_name}"),
        jax_version=jax.__version__, devices=[str(d) for d in jax.devices()],
    )
    if "rms" in res.values:
        results["rms_best_mean"] = res.values["rms"][best].mean(0)
    if writer:
        write_json(out / "results.json", results)
    return results


def format_sweep(results: dict) -> str:
    """One line: the size and wall time of :func:`run_sweep`'s sweep and its best point."""
    b, w = results["best"], results["wall_time_s"]
    return (f"sweep: {results['points']} points x {results['runs']} runs in {w['sweep']:.1f} s "
            f"({w['compile']:.1f} s compile, {results['n_devices']} device(s), chunk {results['chunk']}); "
            f"best " + ", ".join(f"{k} = {v:.4g}" for k, v in b.items() if k != "loss")
            + f": {results['loss_name']} {b['loss']:.4f}")


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
    _log.info("tuning %s of %s: %s, %d %s over %d Monte Carlo runs (one compiled lax.scan: no progress until it "
              "returns)", ", ".join(P.init), cfg["problem"].get("kind", "?"), tn["optimizer"], tn["steps"],
              "loss evaluations" if tn["optimizer"] == "lbfgs_wolfe" else "steps", len(P.keys))
    if tn["optimizer"] == "lbfgs_wolfe":  # steps = evaluation budget; the loss is compiled once
        res = tune.minimize_lbfgs(P.loss, P.init, P.space, max_evals=tn["steps"], mode=tn["mode"])
        done = np.isfinite(np.asarray(res.losses))
        res = res._replace(losses=np.asarray(res.losses)[done], grad_norm=np.asarray(res.grad_norm)[done],
                           path={k: np.asarray(v)[done] for k, v in res.path.items()})
    else:
        res = tune.minimize(P.loss, P.init, P.space, optimizer=_optimizer(tn), steps=tn["steps"], mode=tn["mode"])
    t_tune = time.perf_counter() - t0
    final = {k: float(v) for k, v in res.params.items()}
    _log.info("tuned in %.1f s (compilation included): %s; %s %.4g -> %.4g", t_tune,
              ", ".join(f"{k} {float(P.init[k]):.4g} -> {v:.4g}" for k, v in final.items()), P.loss_name,
              float(res.losses[0]), float(res.loss))
    landscape = None
    if tn["landscape"] and len(P.init) == 1:
        (name,) = P.init
        ax = cfg["sweep"].get(name)
        vals = _axis(dict(ax, num=tn["landscape"])) if ax else None
        if vals is not None:
            sw = tune.sweep(lambda p, k: P.point(p, k), {name: vals}, P.keys, chunk=cfg["sweep"].get("chunk"),
                            progress=progress, desc="landscape")
            landscape = dict(values=vals, loss=sw.values["loss"].mean(1), wall_time_s=sw.wall_time_s)
    # Monte Carlo distribution of the per-run loss at the start and at the tuned values (a 2-point sweep)
    _log.info("scoring the start and the tuned values over %d Monte Carlo runs", len(P.keys))
    ends = tune.sweep(lambda p, k: P.point(p, k)["loss"], {k: [P.init[k], final[k]] for k in P.init}, P.keys,
                      chunk=cfg["sweep"].get("chunk"), progress=False).values
    start_runs, final_runs = ends[0], ends[1]
    figs = []
    if writer:
        from jaxnav.plot import plot_tune

        figs = plot_tune(out, path={k: np.asarray(v) for k, v in res.path.items()}, losses=np.asarray(res.losses),
                         final=final, final_loss=float(res.loss), landscape=landscape, loss_name=P.loss_name,
                         start_runs=start_runs, final_runs=final_runs)
    results = dict(
        command="tune", config=cfg["_path"], problem=cfg["problem"], loss_name=P.loss_name, init=P.init,
        tuned=final,
        loss_init=float(res.losses[0]), loss_final=float(res.loss), losses=np.asarray(res.losses),
        path={k: np.asarray(v) for k, v in res.path.items()}, grad_norm=np.asarray(res.grad_norm),
        optimizer=dict(tn), loss_evaluations=int(res.n_evals), runs=len(P.keys),
        loss_per_run=dict(init=start_runs, tuned=final_runs),
        landscape=landscape, wall_time_s=dict(tune=t_tune, total=time.perf_counter() - t0),
        figures=[str(f) for f in figs], jax_version=jax.__version__, n_processes=jax.process_count(),
        n_devices=len(jax.devices()),
    )
    if writer:
        write_json(out / "results.json", results)
    return results


def format_tune(results: dict) -> str:
    """One line: optimiser, steps, wall time and the parameters and loss before and after :func:`run_tune`."""
    tn, init = results["optimizer"], results["init"]
    return (f"tune: {tn['optimizer']} x {tn['steps']} steps ({tn['mode']} mode) over {results['runs']} runs in "
            f"{results['wall_time_s']['tune']:.1f} s: "
            + ", ".join(f"{k} {init[k]:.4g} -> {v:.4g}" for k, v in results["tuned"].items())
            + f"; {results['loss_name']} {results['loss_init']:.4f} -> {results['loss_final']:.4f}")
