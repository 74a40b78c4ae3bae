"""The filter-family demonstration (``jaxnav demo-filters``; S0, S1 and S2 filters side by side).

A 3-D constant-velocity monitoring series (S1/S2 model, 1 Hz, 3 mm noise) with an acceleration
burst mid-series that the filter's model does not expect (the onset of subsidence). Classic,
attenuated-memory (S0 eqs. (11)-(12)), fading-memory (S0 eqs. (13)-(17)) and variance-
compensation (S1 eqs. (12)-(19)) filters run side by side over vmapped Monte Carlo seeds.
"""

from __future__ import annotations

import pathlib
import time

import jax
import jax.numpy as jnp
import numpy as np

from jaxnav import filters as jf
from jaxnav.io import write_json
from jaxnav.sim import simulate_cv_scenario
from jaxnav.tune import is_writer, run_chunked
from jaxnav.units import MM

SIGMA = 3.0 * MM  # measurement noise, m
ACCEL_STD = 2e-5  # process acceleration std per epoch, m/s^2 (what the filter's model assumes)
CHANGE_ACCEL = (3e-4, -2e-4, -6e-4)  # unmodelled acceleration burst, m/s^2
CHANGE_START, CHANGE_LEN = 0.45, 0.08  # fractions of the series


def _filters(b):
    """The four filters' keyword arguments of :func:`jaxnav.filters.kalman_filter`."""
    return {
        "classic": dict(),
        "attenuated": dict(inflation=jf.attenuated(b)),
        "fading": dict(inflation=jf.fading(window=10)),
        # horizon 10: S1's i-step residuals; floor_rel 1: compensate missing variance only
        "variance_compensation": dict(estimator=jf.variance_compensation(window=30, horizon=10, floor_rel=1.0)),
    }


def _one(key, epochs, b):
    """One seed: simulate the series and run every filter; position error, forecast deviation (m), factors."""
    sc = simulate_cv_scenario(
        key,
        T=epochs,
        sigma=SIGMA,
        accel_std=ACCEL_STD,
        change_start=CHANGE_START,
        change_len=CHANGE_LEN,
        change_accel=CHANGE_ACCEL,
    )
    model = jf.constant_velocity(1.0, sigma=SIGMA, accel_var=ACCEL_STD**2)
    x0 = jnp.concatenate([sc.zs[0], jnp.zeros(3)])
    P0 = jnp.diag(jnp.array([SIGMA**2] * 3 + [1e-6] * 3))
    out = {}
    for name, kw in _filters(b).items():
        r = jf.kalman_filter(model, x0, P0, sc.zs, save=("means", "pred_means", "factors", "noise"), **kw)
        err = r.means[:, :3] - sc.x_true[:, :3]
        fc = r.pred_means[:, :3] - sc.zs  # forecast X(k/k-1) minus the measurement (S1)
        out[name] = dict(
            err=err,
            fc=fc,
            factors=r.factors,
            q=r.noise.q if name == "variance_compensation" else jnp.zeros((epochs, 3)),
            status=r.status,
        )
    return out, sc


def _rms(a, axis):
    return np.sqrt(np.mean(a**2, axis=axis))


def run_filter_family(out="out/demo", seeds=64, epochs=1200, b=0.254, progress=True) -> dict:
    """Run the demonstration; write ``results.json`` and ``filter_family.png`` to ``out``.

    Args:
      out: output folder (created).  seeds: Monte Carlo seeds (vmapped).  epochs: epochs per
        series (1 Hz).  b: attenuation factor (S0 eq. (11)).  progress: show the progress bar.
    Returns:
      The results dict (also written as JSON): per filter the mean and std over seeds of the 3-D
      position RMS (mm) before, during and after the burst and of the forecast deviation (mm).
    """
    outdir = pathlib.Path(out)
    writer = is_writer()  # several processes: all compute, process 0 writes
    if writer:
        outdir.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    keys = jax.random.split(jax.random.PRNGKey(2026), seeds)
    res = run_chunked(lambda k: _one(k, epochs, b)[0], keys, chunk=16, desc="filters x seeds", progress=progress)
    wall = time.perf_counter() - t0
    _, sc0 = _one(keys[0], epochs, b)
    change = np.asarray(sc0.change)
    i0, i1 = int(np.argmax(change)), int(np.argmax(change)) + int(change.sum())
    segments = {"before": slice(20, i0), "during": slice(i0, i1), "after": slice(i1, epochs), "all": slice(20, epochs)}

    table = {}
    order = list(_filters(b))
    res = {name: res[name] for name in order}
    for name, r in res.items():
        row = {}
        for seg, sl in segments.items():
            pos3d = _rms(np.linalg.norm(r["err"][:, sl], axis=-1), axis=1) / MM  # per seed, mm
            row[f"pos_rms_{seg}_mm"] = dict(mean=float(pos3d.mean()), std=float(pos3d.std()))
        fc = _rms(np.linalg.norm(r["fc"][:, 20:], axis=-1), axis=1) / MM
        row["forecast_rms_mm"] = dict(mean=float(fc.mean()), std=float(fc.std()))
        row["max_factor"] = float(np.max(r["factors"]))
        row["status"] = int(np.bitwise_or.reduce(r["status"]))
        table[name] = row

    fig_path = outdir / "filter_family.png"
    if writer:
        from jaxnav.experiments.figures import plot_filter_family

        plot_filter_family(
            {k: {kk: v[0] for kk, v in r.items()} for k, r in res.items()}, np.asarray(sc0.t), (i0, i1), fig_path, b=b
        )
    results = dict(
        settings=dict(
            seeds=seeds,
            epochs=epochs,
            b=b,
            sigma_m=SIGMA,
            accel_std_mps2=ACCEL_STD,
            change_accel_mps2=list(CHANGE_ACCEL),
            change_epochs=[i0, i1],
            fading_window=10,
            vc_window=30,
            vc_horizon=10,
            vc_floor_rel=1.0,
        ),
        table=table,
        wall_time_s=wall,
        jax_version=jax.__version__,
        devices=[str(d) for d in jax.devices()],
    )
    if writer:
        write_json(outdir / "results.json", results, indent=2)
    return results


def format_filter_family(results: dict) -> str:
    """The table of :func:`run_filter_family`: mean +- std over seeds of the 3-D RMS, mm."""
    st = results["settings"]
    i0, i1 = st["change_epochs"]
    hdr = f"{'filter':<22}" + "".join(
        f"{h:>18}" for h in ("pos before mm", "pos during mm", "pos after mm", "pos all mm", "forecast mm")
    )
    lines = [
        f"Constant-velocity series, {st['epochs']} epochs at 1 Hz, sigma {st['sigma_m'] / MM:.0f} mm, "
        f"unmodelled acceleration burst at epochs {i0}-{i1}; {st['seeds']} seeds (mean +- std of 3-D RMS)",
        hdr,
        "-" * len(hdr),
    ]
    for name, row in results["table"].items():
        cells = [row[f"pos_rms_{s}_mm"] for s in ("before", "during", "after", "all")] + [row["forecast_rms_mm"]]
        lines.append(f"{name:<22}" + "".join(f"{c['mean']:>10.2f} +-{c['std']:>5.2f}" for c in cells))
    return "\n".join(lines)
