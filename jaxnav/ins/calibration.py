"""The noise of a loosely coupled run and its consistency with the GNSS innovations (NIS).

:class:`LCNoise` groups what a user may tune in a run (IMU densities, initial sigmas, factors on the
GNSS sigmas) as array leaves; :func:`gnss_nis` and :func:`gnss_consistency` test a run's noise
against its own GNSS innovations: the mean normalised innovation squared per degree of freedom is 1
for a consistent filter (Bar-Shalom, Li & Kirubarajan, *Estimation with Applications to Tracking and
Navigation*, 2001, section 5.4). The maximum-likelihood fit that repairs an inconsistent noise is
:func:`jaxnav.tune.calibrate_lc_noise` (it needs the optimiser of :mod:`jaxnav.tune`).
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from jaxnav.ins.integration import chi2_quantile
from jaxnav.ins.noise import ImuNoise

#: band of the mean GNSS position (and velocity) NIS per degree of freedom inside which the noise counts as
#: consistent: a factor 1.25 either way in innovation variance. Thousands of time-correlated epochs make
#: the chi-square band of the mean far too narrow to use; a wider band ([0.5, 2]) leaves a run with 4x
#: its IMU noise uncalibrated (docs/guide/ins.md, "Noise self-calibration").
NIS_BAND = (0.8, 1.25)
#: largest share of GNSS epochs whose NIS exceeds the gate's chi-square quantile for consistent noise
NIS_GATE_SHARE_MAX = 0.01
#: fewest GNSS position epochs a run must see for its noise to be checked and calibrated
MIN_CALIBRATION_EPOCHS = 50
#: gated share of the GNSS epochs above which a run warns
GATED_SHARE_WARN = 0.05


class LCNoise(NamedTuple):
    """The noise of a loosely coupled run (SI; array leaves, so ``vmap`` and ``grad`` reach every field).

    Attributes:
      imu: :class:`jaxnav.ins.ImuNoise`; which of its densities enter the filter depends on the error
        model (:meth:`jaxnav.ins.ErrorModel.Qc`).
      init_att: (2,) initial attitude 1-sigma, rad: roll/pitch, heading.  init_vel: initial velocity
        1-sigma, m/s.  init_pos: initial position 1-sigma, m.
      pos_sigma_scale: factor on the GNSS position sigmas.  vel_sigma_scale: factor on the GNSS velocity
        sigmas (:func:`scale_gnss_sigmas`).
    """

    imu: ImuNoise
    init_att: ArrayLike
    init_vel: ArrayLike
    init_pos: ArrayLike
    pos_sigma_scale: ArrayLike = 1.0
    vel_sigma_scale: ArrayLike = 1.0


#: tunable parameter name -> (:class:`LCNoise` or :class:`ImuNoise` field, or "lever_arm"; bijector of
#: :mod:`jaxnav.tune`)
TUNABLE = {
    "arw": ("gyro_arw", "log"),
    "vrw": ("accel_vrw", "log"),
    "gyro_bias_instability": ("gyro_bias_instability", "log"),
    "pos_sigma_scale": ("pos_sigma_scale", "log"),
    "vel_sigma_scale": ("vel_sigma_scale", "log"),
    "lever_arm": ("lever_arm", "real"),
}


def noise_values(noise: LCNoise, names, lever=None) -> dict:
    """The current values of the :data:`TUNABLE` parameters ``names`` of ``noise`` (``lever_arm``: ``lever`` (3,) m)."""
    out = {}
    for n in names:
        field = TUNABLE[n][0]
        if field == "lever_arm":
            out[n] = jnp.asarray(lever, float)
        else:
            out[n] = jnp.asarray(getattr(noise.imu if field in ImuNoise._fields else noise, field), float)
    return out


def with_noise_values(noise: LCNoise, values: dict, lever=None):
    """(:class:`LCNoise`, lever) with the :data:`TUNABLE` parameters in ``values`` replaced; differentiable."""
    fields = {TUNABLE[n][0]: v for n, v in values.items() if TUNABLE[n][0] != "lever_arm"}
    noise = noise._replace(
        imu=noise.imu._replace(**{f: v for f, v in fields.items() if f in ImuNoise._fields}),
        **{f: v for f, v in fields.items() if f not in ImuNoise._fields},
    )
    return noise, values.get("lever_arm", lever)


def check_names(names) -> None:
    """Raise ``ValueError`` naming the parameters of ``names`` that are not :data:`TUNABLE`."""
    unknown = [n for n in names if n not in TUNABLE]
    if unknown:
        raise ValueError(f"cannot tune {unknown}; tunable: {sorted(TUNABLE)}")


def check_tunable(names, *, n_states: int, use_velocity: bool = True) -> None:
    """Raise ``ValueError`` naming the parameters of ``names`` a run with ``n_states`` error states (and GNSS
    velocity updates or not) cannot tune."""
    check_names(names)
    if "gyro_bias_instability" in names and n_states not in (18, 21):
        raise ValueError(
            f"gyro_bias_instability is a parameter of the 18- and 21-state error models, not of {n_states} states"
        )
    if "vel_sigma_scale" in names and not use_velocity:
        raise ValueError("vel_sigma_scale scales the GNSS velocity sigmas: it needs GNSS velocity updates")


def calibration_params(n_states: int, use_velocity: bool) -> tuple:
    """The densities a default calibration fits: ARW, VRW and the GNSS position sigma factor, the GNSS
    velocity sigma factor where the run uses GNSS velocity, and the gyro bias instability where the error
    model has a state for it (``n_states`` 18 or 21)."""
    vel = ("vel_sigma_scale",) if use_velocity else ()
    extra = ("gyro_bias_instability",) if n_states in (18, 21) else ()
    return ("arw", "vrw", "pos_sigma_scale", *vel, *extra)


def scale_gnss_sigmas(meas, pos_sigma_scale, vel_sigma_scale):
    """GNSS measurements (:class:`jaxnav.ins.PVMeasurements`) with R -> D R D, D = diag(pos_sigma_scale x 3,
    vel_sigma_scale x 3): the sigmas scaled, their correlations kept. Differentiable in both factors."""
    s = jnp.concatenate([jnp.broadcast_to(pos_sigma_scale, (3,)), jnp.broadcast_to(vel_sigma_scale, (3,))])
    return meas._replace(R=jnp.asarray(meas.R) * (s[:, None] * s[None, :]))


def _block_nis(nu, S, use):
    """nu' S^-1 nu over the components ``use`` (K, m) bool of (K, m) innovations with (K, m, m) covariances;
    the others are left out (their rows and columns replaced by the identity, their innovations by 0)."""
    u = use[..., :, None] & use[..., None, :]
    eye = np.broadcast_to(np.eye(S.shape[-1]), S.shape)
    Sm = np.where(u, S, eye)
    L = np.linalg.cholesky(Sm)
    w = np.linalg.solve(L, np.where(use, nu, 0.0)[..., None])[..., 0]
    return np.sum(w * w, -1)


def gnss_nis(res, mask) -> dict:
    """NIS of the GNSS innovations per GNSS epoch: position, velocity and the whole epoch (the gate's statistic).

    Args:
      res: :class:`jaxnav.ins.LCResult` saved with "innovations", "innov_covs" (rows 0-2 of each epoch's
        stacked measurement are the GNSS position components, m, rows 3-5 the velocity, m/s).
      mask: (M, 6) bool GNSS mask (PVMeasurements).
    Returns:
      dict of (M,) arrays: ``pos`` (3 dof; NaN unless the three position components were used), ``vel``
      (3 dof; NaN unless the three velocity components were used), ``epoch`` (nu' S^-1 nu over every GNSS
      component used at the epoch, as :class:`jaxnav.ins.LCGate` computes it; NaN where none) and ``dof``
      (its number of components, 0 where none).
    """
    ep = res.epochs
    row = np.asarray(ep.gnss_row)
    g = np.nonzero(row >= 0)[0]
    nu = np.asarray(ep.innovations, float)[g, :6]
    S = np.asarray(ep.innov_covs, float)[g, :6, :6]
    M = np.asarray(mask).shape[0]
    used = np.asarray(mask, bool)[row[g], :6] & np.isfinite(nu)
    out = {k: np.full(M, np.nan) for k in ("pos", "vel", "epoch")}
    out["dof"] = np.zeros(M, int)
    for key, sl in (("pos", slice(0, 3)), ("vel", slice(3, 6))):
        ok = used[:, sl].all(-1)
        if ok.any():
            out[key][row[g][ok]] = _block_nis(nu[ok][:, sl], S[ok][:, sl, sl], used[ok][:, sl])
    k = used.sum(-1)
    ok = k > 0
    if ok.any():
        out["epoch"][row[g][ok]] = _block_nis(nu[ok], S[ok], used[ok])
        out["dof"][row[g][ok]] = k[ok]
    return out


def position_nis(res, mask) -> np.ndarray:
    """(M,) NIS of the GNSS position innovations per GNSS epoch (3 dof; NaN where the three position
    components were not all used); arguments as :func:`gnss_nis`."""
    return gnss_nis(res, mask)["pos"]


def gnss_consistency(res, mask, *, gate_probability: float | None = None) -> dict:
    """Whether a run's noise explains its GNSS innovations: mean NIS per degree of freedom and the share of
    epochs beyond the gate.

    Consistent: the mean position NIS per dof inside :data:`NIS_BAND`, the mean velocity NIS per dof too
    (where the run used GNSS velocity), and at most :data:`NIS_GATE_SHARE_MAX` of the epochs beyond the
    chi-square quantile of ``gate_probability`` (0.9999 without one): the whole epoch's NIS against the
    quantile for its number of components (as the gate judges it), and the position and velocity NIS each
    against the 3-dof quantile (a block's outliers can hide in the 6-dof epoch NIS). Pass a run made
    without the gate (or with an open one): gated epochs carry no update to judge.

    Args:
      res: :class:`jaxnav.ins.LCResult` saved with "innovations" and "innov_covs".  mask: (M, 6) bool GNSS
        mask.  gate_probability: the run's chi-square gate probability, or None.
    Returns:
      dict: ``nis_per_dof`` (mean position NIS / 3), ``nis_median_per_dof`` (median position NIS / 2.366,
      the chi-square(3) median; robust to outliers), ``n_epochs`` (epochs with a position NIS),
      ``nis_vel_per_dof``, ``nis_vel_median_per_dof``, ``n_vel_epochs`` (the same for the velocity; NaN
      and 0 without GNSS velocity), ``share_above_gate``, ``share_pos_above_gate``,
      ``share_vel_above_gate`` (0 without GNSS velocity), ``consistent`` (bool), ``loglik`` (the run's).
    """
    nis = gnss_nis(res, mask)
    p, v, e, k = nis["pos"], nis["vel"], nis["epoch"], nis["dof"]
    ok, okv, oke = np.isfinite(p), np.isfinite(v), np.isfinite(e)
    n, nv = int(ok.sum()), int(okv.sum())
    prob = gate_probability if gate_probability is not None else 0.9999
    thr = np.array([np.inf] + [chi2_quantile(prob, j) for j in range(1, 7)])
    mean = float(np.mean(p[ok]) / 3.0) if n else float("nan")
    mean_v = float(np.mean(v[okv]) / 3.0) if nv else float("nan")
    share = float(np.mean(e[oke] > thr[k[oke]])) if oke.any() else float("nan")
    share_p = float(np.mean(p[ok] > thr[3])) if n else float("nan")
    share_v = float(np.mean(v[okv] > thr[3])) if nv else 0.0
    lo, hi = NIS_BAND
    return {
        "nis_per_dof": mean,
        "nis_median_per_dof": float(np.median(p[ok]) / 2.366) if n else float("nan"),
        "n_epochs": n,
        "nis_vel_per_dof": mean_v,
        "nis_vel_median_per_dof": float(np.median(v[okv]) / 2.366) if nv else float("nan"),
        "n_vel_epochs": nv,
        "share_above_gate": share,
        "share_pos_above_gate": share_p,
        "share_vel_above_gate": share_v,
        "consistent": bool(
            n
            and lo <= mean <= hi
            and (nv == 0 or lo <= mean_v <= hi)
            and max(share, share_p, share_v) <= NIS_GATE_SHARE_MAX
        ),
        "loglik": float(res.loglik),
    }


def consistency_words(check: dict) -> tuple:
    """(what a :func:`gnss_consistency` result measured, the list of what fails) as short phrases."""
    lo, hi = NIS_BAND
    said, bad = [], []
    for what, key in (("position", "nis_per_dof"), ("velocity", "nis_vel_per_dof")):
        x = check[key]
        if what == "velocity" and not check["n_vel_epochs"]:
            continue
        inside = lo <= x <= hi
        said.append(f"GNSS {what} NIS per dof {x:.2f} {'inside' if inside else 'outside'} {lo:g}-{hi:g}")
        if not inside:
            bad.append(f"the GNSS {what} NIS per dof is {x:.2f}, outside {lo:g}-{hi:g}")
    for what, key in (("", "share_above_gate"), (" by the position NIS", "share_pos_above_gate")) + (
        ((" by the velocity NIS", "share_vel_above_gate"),) if check["n_vel_epochs"] else ()
    ):
        sh = check[key]
        if sh > NIS_GATE_SHARE_MAX:
            said.append(f"{100 * sh:.1f} % of the epochs beyond the gate{what}")
            bad.append(
                f"{100 * sh:.1f} % of the GNSS epochs are beyond the gate{what} (at most "
                f"{100 * NIS_GATE_SHARE_MAX:g} % for consistent noise)"
            )
    return ", ".join(said), bad


def consistency_report(check: dict, when: str) -> dict:
    """The NIS figures of a :func:`gnss_consistency` result as report keys tagged ``when`` ("before", "after")."""
    return {
        f"nis_{when}_per_dof": check["nis_per_dof"],
        f"nis_median_{when}_per_dof": check["nis_median_per_dof"],
        f"nis_vel_{when}_per_dof": check["nis_vel_per_dof"],
        f"nis_vel_median_{when}_per_dof": check["nis_vel_median_per_dof"],
        f"share_above_gate_{when}": check["share_above_gate"],
        f"share_pos_above_gate_{when}": check["share_pos_above_gate"],
        f"share_vel_above_gate_{when}": check["share_vel_above_gate"],
    }
