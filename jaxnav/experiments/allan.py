"""``jaxnav allan IMU_FILE``: IMU noise densities from a static recording (Allan variance).

Reads the IMU log with the readers of ``jaxnav ins`` (:func:`jaxnav.io.read_imu`), puts the rates on a
uniform grid (:func:`jaxnav.ins.uniform_rates`), fits white noise, bias instability and rate
random walk per axis (:func:`jaxnav.ins.allan_noise_fit`) and writes a figure per sensor, a
``[noise]`` TOML section with the keys of :func:`jaxnav.io.load_ins_config` and ``results.json``.
"""

from __future__ import annotations

import pathlib

import numpy as np

from jaxnav import units
from jaxnav.ins import (
    allan_fit_datasheet,
    allan_noise_fit,
    static_check,
    uniform_rates,
)
from jaxnav.io import noise_toml, write_json


def run_allan(imu, out, *, source: str, start_s=None, end_s=None, tau_range=None, title=None) -> dict:
    """Fit the noise of a static IMU log and write ``allan_gyro.png``, ``allan_accel.png``, ``noise.toml``
    and ``results.json`` into ``out``.

    Args:
      imu: :class:`jaxnav.io.ImuLog`.  out: folder.  source: the file's name for the outputs.
      start_s, end_s: the stretch used, s after the first sample (None: all).
      tau_range: (lo, hi) s of the taus fitted (None: all).
    Returns:
      The summary written to ``results.json``.
    Raises:
      ValueError: a stretch with too few samples, or a log that is not static (the text says why).
    """
    from jaxnav.plot import plot_allan

    out = pathlib.Path(out)
    t = np.asarray(imu.t, float)
    rel = t - t[0]
    keep = np.ones(t.size, bool)
    if start_s is not None:
        keep &= rel >= start_s
    if end_s is not None:
        keep &= rel <= end_s
    if keep.sum() < 64:
        raise ValueError(
            f"{source}: only {int(keep.sum())} samples in the stretch "
            f"[{start_s or 0:g}, {end_s if end_s is not None else rel[-1]:g}] s; need >= 64"
        )
    sel = imu._replace(t=t[keep], f_b=np.asarray(imu.f_b)[keep], w_b=np.asarray(imu.w_b)[keep])
    bad = static_check(sel.w_b, sel.f_b)
    if bad:
        raise ValueError(f"{source}: not a static recording: {bad} (choose a still stretch with --start/--end)")
    dt, y = uniform_rates(sel.t, np.hstack([sel.w_b, sel.f_b]))
    fit_g = allan_noise_fit(y[:3], dt, tau_range=tau_range)
    fit_a = allan_noise_fit(y[3:], dt, tau_range=tau_range)
    toml = noise_toml(fit_g, fit_a, source=source)
    (out / "noise.toml").write_text(toml, encoding="utf-8")
    eg, ea = allan_fit_datasheet(fit_g, "gyro"), allan_fit_datasheet(fit_a, "accel")
    dur = float(sel.t[-1] - sel.t[0])
    name = title or source
    for sensor, fit, e, to, adev_unit, units3 in (
        ("gyro", fit_g, eg, units.rad_per_s_to_deg_per_hour, "deg/h", ("deg/sqrt(h)", "deg/h", "deg/h/sqrt(h)")),
        ("accelerometer", fit_a, ea, units.mps2_to_mg, "mg", ("m/s/sqrt(h)", "mg", "mg/sqrt(h)")),
    ):
        plot_allan(
            fit.taus,
            to(np.sqrt(fit.avar)),
            to(fit.avar_sigma / (2 * np.sqrt(fit.avar))),
            fit.fitted,
            to(fit.white),
            to(fit.bias_instability),
            to(fit.rate_rw),
            out / f"allan_{sensor[:5]}.png",
            title=f"{sensor} Allan deviation: {name} ({dur:.0f} s at {1 / dt:.0f} Hz)",
            adev_unit=adev_unit,
            white_label=_labels(e, 0, units3[0]),
            bi_label=_labels(e, 1, units3[1]),
            rrw_label=_labels(e, 2, units3[2]),
            resolved=fit.resolved,
            bounds=np.stack([to(fit.upper[..., j]) for j in range(3)], -1),
        )
    summary = {
        "input": {
            "file": source,
            "n_samples": int(keep.sum()),
            "n_uniform": int(y.shape[1]),
            "dt_s": dt,
            "duration_s": dur,
            "start_s": float(rel[keep][0]),
            "end_s": float(rel[keep][-1]),
            "tau_range_s": None if tau_range is None else [float(v) for v in tau_range],
        },
        "gyro": eg,
        "accel": ea,
        "method": "overlapping Allan variance at 2 taus per octave (>= 3 clusters); weighted least squares of "
        "N^2/tau + (2 ln2/pi) B^2 + K^2 tau/3 with the estimator's variance (IEEE Std 952 Annex C); "
        "sigmas treat the taus as independent and are a lower bound",
        "noise_toml": toml,
        "files": ["allan_gyro.png", "allan_accel.png", "noise.toml", "results.json"],
    }
    write_json(out / "results.json", summary)
    return summary


def _labels(e, j, unit):
    """Legend texts "value +- sigma unit" per axis (or "< upper (not resolved)") of term j (0 white, 1 BI, 2 RRW)."""
    head = ("vrw" if "vrw_m_per_s_per_sqrt_h" in e else "arw", "bias_instability", "rate_rw")[j]
    key = next(k for k in e if k.startswith(head + "_") and "_sigma" not in k and "_upper" not in k)
    tail = key[len(head) :]
    vals, sig, up = e[key], e[f"{head}_sigma{tail}"], e[f"{head}_upper_2sigma{tail}"]
    res = [r[j] for r in e["resolved_white_bi_rrw"]]
    return [
        f"{v:.3g} +- {s:.2g} {unit}" if r else f"< {u:.2g} {unit} (not resolved)"
        for v, s, u, r in zip(vals, sig, up, res)
    ]


def format_allan(summary: dict) -> str:
    """The command's summary: per sensor the fitted terms of each axis, then the TOML section."""
    lines = [
        f"{summary['input']['file']}: {summary['input']['duration_s']:.0f} s static, "
        f"dt {summary['input']['dt_s'] * 1e3:.3g} ms"
    ]
    for sensor, parts in (
        (
            "gyro",
            ((0, "ARW", "deg/sqrt(h)"), (1, "bias instability", "deg/h"), (2, "rate random walk", "deg/h/sqrt(h)")),
        ),
        ("accel", ((0, "VRW", "m/s/sqrt(h)"), (1, "bias instability", "mg"), (2, "rate random walk", "mg/sqrt(h)"))),
    ):
        for j, what, unit in parts:
            lines.append(f"  {sensor:5s} {what:17s} x/y/z: " + "; ".join(_labels(summary[sensor], j, unit)))
    return "\n".join(lines) + "\n\n" + summary["noise_toml"]
