"""Maximum-likelihood noise fits of the loosely coupled INS/GNSS filter and its default self-calibration.

Both take the run as a function, so they serve any pipeline: ``loss(noise, lever) -> scalar`` for
:func:`fit_lc_noise`, ``run(noise, gate_probability, save) -> LCResult`` for :func:`calibrate_lc_noise`.
Gradients flow through the whole filter (forward or reverse mode, :func:`jaxnav.tune.value_and_grad`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from jaxnav.ins.calibration import (
    MIN_CALIBRATION_EPOCHS,
    NIS_BAND,
    NIS_GATE_SHARE_MAX,
    TUNABLE,
    LCNoise,
    check_names,
    consistency_report,
    consistency_words,
    gnss_consistency,
    noise_values,
    with_noise_values,
)
from jaxnav.tune._bijectors import Space
from jaxnav.tune._lbfgs import minimize_lbfgs


class LCNoiseFit(NamedTuple):
    """Result of :func:`fit_lc_noise`.

    Attributes:
      before, after: dict name -> value (SI; lists) at the start and the end.
      loglik_before, loglik_after: minus the loss at the start and at the end.
      n_evals: loss evaluations.  wall_time_s: host time, s (compilation included).
      noise: the fitted :class:`jaxnav.ins.LCNoise`.  lever: the fitted lever arm (3,) m (the given one
        where it was not fitted).  fitted_on: which data the loss used (the caller's words).
      n_epochs: how many epochs (the caller's count).
    """

    before: dict
    after: dict
    loglik_before: float
    loglik_after: float
    n_evals: int
    wall_time_s: float
    noise: LCNoise
    lever: np.ndarray | None
    fitted_on: str = ""
    n_epochs: int = 0


def fit_lc_noise(
    loss: Callable,
    noise: LCNoise,
    names,
    *,
    lever=None,
    max_evals: int = 25,
    mode: str = "reverse",
    fitted_on: str = "",
    n_epochs: int = 0,
) -> LCNoiseFit:
    """Fit the :data:`jaxnav.ins.calibration.TUNABLE` parameters ``names`` of ``noise`` by minimising ``loss``.

    L-BFGS (:func:`jaxnav.tune.minimize_lbfgs`) with gradients through the complete filter; densities and
    sigma factors on a log scale, the lever arm unconstrained.

    Args:
      loss: ``loss(noise, lever) -> scalar``, e.g. minus the GNSS innovation log-likelihood of
        :func:`jaxnav.ins.loosely_coupled` run with ``noise`` (its ``loglik``).
      noise: :class:`jaxnav.ins.LCNoise` to start from.  names: parameters to fit.
      lever: (3,) m lever arm (needed when ``"lever_arm"`` is fitted; passed through otherwise).
      max_evals: loss evaluations at most (static).  mode: "reverse" or "forward" gradients.
      fitted_on, n_epochs: the data the loss uses, recorded in the result.
    """
    check_names(names)
    if "lever_arm" in names and lever is None:
        raise ValueError("fitting 'lever_arm' needs lever= (3,) m to start from")
    p0 = noise_values(noise, names, lever)
    space = Space({n: TUNABLE[n][1] for n in names})
    t0 = time.perf_counter()
    res = minimize_lbfgs(lambda p: loss(*with_noise_values(noise, p, lever)), p0, space, max_evals=max_evals, mode=mode)
    fitted, lev = with_noise_values(noise, res.params, lever)
    return LCNoiseFit(
        before={n: np.asarray(v).tolist() for n, v in p0.items()},
        after={n: np.asarray(v).tolist() for n, v in res.params.items()},
        loglik_before=-float(np.asarray(res.losses)[0]),  # the first evaluation is at the start values
        loglik_after=-float(res.loss),
        n_evals=int(res.n_evals),
        wall_time_s=time.perf_counter() - t0,
        noise=fitted,
        lever=None if lev is None else np.asarray(lev),
        fitted_on=fitted_on,
        n_epochs=n_epochs,
    )


def calibrate_lc_noise(
    run: Callable,
    noise: LCNoise,
    mask,
    names,
    *,
    mode="auto",
    max_evals: int = 25,
    gate_probability: float | None = None,
    fitted_on: str = "GNSS position epochs the filter sees",
    progress: Callable | None = None,
) -> tuple:
    """Self-calibration of a run's noise: a NIS check of ``noise``, a maximum-likelihood fit where it fails.

    1. The filter runs with ``noise`` WITHOUT a working gate (an open one, probability 1, where the run has
       a gate: the final run's compiled program); :func:`jaxnav.ins.gnss_consistency` judges its GNSS
       position and velocity innovations.
    2. ``mode`` "auto": consistent noise is kept. Otherwise (or ``mode`` True) :func:`fit_lc_noise` fits
       ``names`` to the GNSS innovation log-likelihood of the ungated filter (L-BFGS, forward-mode
       gradients: a few parameters cost a few tangents, cheaper than reverse mode's tape), on the same
       epochs, and the check runs again. False: nothing runs.
    3. Fewer than :data:`jaxnav.ins.MIN_CALIBRATION_EPOCHS` GNSS position epochs: ``noise`` is kept and
       the measured NIS reported with a warning.

    Args:
      run: ``run(noise, gate_probability, save) -> LCResult``: the filter on the epochs it may see (a
        withheld epoch must be masked in it), with gate probability None (no gate) or a float, saving
        the outputs ``save`` (None: the run's own outputs, which must include "innovations" and
        "innov_covs"; the check then reuses the final run's compiled program).
      noise: :class:`jaxnav.ins.LCNoise`.  mask: (M, 6) bool GNSS mask of ``run``'s measurements.
      names: parameters to fit (:func:`jaxnav.ins.calibration_params`).  mode: "auto" | True | False.
      max_evals: loss evaluations of the fit.  gate_probability: the run's gate probability, or None.
      fitted_on: words for the epochs used, recorded in the report.
      progress: callable taking one line of text (stages and warnings), or None.
    Returns:
      (:class:`jaxnav.ins.LCNoise` to run with, report dict: mode, ran, reason, NIS per dof before (and
      after), parameters before/after (SI), the epochs fitted on and their number, evaluations, wall
      time, warning).
    """
    if not (mode is True or mode is False or mode == "auto"):
        raise ValueError(f"calibrate_lc_noise: mode must be 'auto', True or False, got {mode!r}")
    say = progress or (lambda *_: None)
    t0 = time.perf_counter()
    rep: dict = {
        "mode": mode,
        "ran": False,
        "nis_band_per_dof": list(NIS_BAND),
        "nis_gate_share_max": NIS_GATE_SHARE_MAX,
    }
    if mode is False:
        rep["reason"] = "calibrate = false: the configured noise is used as given"
        return noise, rep
    open_gate = None if gate_probability is None else 1.0
    before = gnss_consistency(run(noise, open_gate, None), mask, gate_probability=gate_probability)
    n = before["n_epochs"]
    rep.update(
        consistency_report(before, "before"),
        n_nis_epochs=n,
        n_nis_vel_epochs=before["n_vel_epochs"],
        min_epochs=MIN_CALIBRATION_EPOCHS,
    )
    if n < MIN_CALIBRATION_EPOCHS:
        rep["reason"] = (
            f"too few GNSS epochs to calibrate ({n} < {MIN_CALIBRATION_EPOCHS}): the configured noise is kept"
        )
        rep["warning"] = (
            f"only {n} GNSS position epochs, too few to check or calibrate the noise: GNSS position NIS per dof "
            f"{before['nis_per_dof']:.2f} (consistent: {NIS_BAND[0]:g}-{NIS_BAND[1]:g}); the configured noise is "
            "used, its uncertainties unchecked"
        )
        say(f"warning: {rep['warning']}")
        rep["wall_time_s"] = time.perf_counter() - t0
        return noise, rep
    why = consistency_words(before)[0]
    if mode == "auto" and before["consistent"]:
        rep["reason"] = f"{why}: the configured noise is consistent and kept"
        rep["wall_time_s"] = time.perf_counter() - t0
        return noise, rep
    names = tuple(names)
    rep["reason"] = f"calibrate = true; {why}" if mode is True else why
    say(
        f"calibrating {', '.join(names)} ({rep['reason']}): innovation likelihood on {n} {fitted_on}, ungated, "
        f"L-BFGS {max_evals} evaluations"
    )
    fit = fit_lc_noise(
        lambda d, _: -run(d, None, ("nav",)).loglik,
        noise,
        names,
        max_evals=max_evals,
        mode="forward",
        fitted_on=fitted_on,
        n_epochs=int(np.asarray(mask)[:, :3].any(-1).sum()),
    )
    after = gnss_consistency(run(fit.noise, open_gate, None), mask, gate_probability=gate_probability)
    rep.update(
        ran=True,
        params=list(names),
        loss="innovations (GNSS innovation log-likelihood of the forward filter, no gate)",
        before_si={k: float(v) for k, v in fit.before.items()},
        after_si={k: float(v) for k, v in fit.after.items()},
        loglik_before=fit.loglik_before,
        loglik_after=fit.loglik_after,
        **consistency_report(after, "after"),
        fitted_on=fitted_on,
        n_epochs=fit.n_epochs,
        n_evals=fit.n_evals,
    )
    if not after["consistent"]:
        bits = consistency_words(after)[1]
        rep["warning"] = (
            f"after calibration {' and '.join(bits)}: the uncertainties may still be wrong (errors the "
            "error model has no state for?)"
        )
        say(f"warning: {rep['warning']}")
    rep["wall_time_s"] = time.perf_counter() - t0
    return fit.noise, rep
