"""A coordinated-turn vehicle model on the real 1 Hz RTK car drive: EKF vs UKF, classic vs fading
vs IGG-III, filtered and smoothed, scored against the reference trajectory.

The data (``rtk_pos_matrtklib/kinematic`` of the shared data sets): ``rover_1Hz_rtk.pos`` (531 RTK
epochs of a 20-minute drive, 142 fixed and 389 float, with gaps of up to 56 s) and
``reference_1Hz.pos`` (the reference trajectory at every second). Everything here composes public
calls: :func:`jaxnav.io.read_pos`, :func:`jaxnav.geodesy.geodetic_to_enu`, the nonlinear filters
and smoothers and the plug-ins of :mod:`jaxnav.filters`, :func:`jaxnav.experiments.figures.plot_ct_drive`.

The model (:func:`jaxnav.filters.coordinated_turn`: state east, north m, speed m/s, heading rad from
east counter-clockwise, turn rate rad/s; 1 s steps on a 1 s grid, epochs without a solution are NaN
rows that the filters mask):

    e' = e + v cos(th) dt,  n' = n + v sin(th) dt,  v' = v,  th' = th + om dt,  om' = om,

with white acceleration (std ``accel_std``, m/s^2) and white turn-rate change (std ``turn_std``,
rad/s^2) as process noise, and the position measured with R_k from the solution's own E/N
covariance plus a floor (``sigma_floor``) for its optimistic fixed-epoch sigmas.
"""

from __future__ import annotations

import pathlib
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from jaxnav import filters as jf
from jaxnav.geodesy import geodetic_to_enu
from jaxnav.io import read_pos

ROVER = "rover_1Hz_rtk.pos"
REFERENCE = "reference_1Hz.pos"
#: the filters and plug-ins compared (:func:`plugin` gives the plug-ins' keywords)
FILTERS = ("EKF", "UKF")
PLUGINS = ("classic", "fading", "igg3")
UKF_ALPHA = 0.5  # well conditioned sigma points (see jaxnav.filters.unscented_kalman_filter)


class Drive(NamedTuple):
    """The drive on a 1 s grid, local ENU about the first reference epoch (m).

    Attributes:
      t: (T,) GPST, s since the GPS epoch.
      zs: (T, 2) rover east, north, m; NaN rows where the file has no epoch.
      R: (T, 2, 2) rover E/N covariance from the file, m^2 (identity where no epoch).
      q: (T,) int RTKLIB quality (1 fix, 2 float; 0 where no epoch).
      truth: (T, 2) reference east, north, m (NaN where the reference has no epoch).
      n_epochs: rover epochs read.
    """

    t: np.ndarray
    zs: np.ndarray
    R: np.ndarray
    q: np.ndarray
    truth: np.ndarray
    n_epochs: int


def load_drive(folder) -> Drive:
    """Read the rover and reference ``.pos`` files of ``folder`` onto one 1 s grid (host side).

    Args:
      folder: the ``rtk_pos_matrtklib/kinematic`` folder (``rover_1Hz_rtk.pos``, ``reference_1Hz.pos``).
    Returns:
      :class:`Drive`, from the first to the last rover epoch.
    """
    folder = pathlib.Path(folder)
    rov, ref = read_pos(folder / ROVER), read_pos(folder / REFERENCE)
    origin = (ref.lat[0], ref.lon[0], ref.h[0])
    t0 = rov.t[0]
    T = int(round(rov.t[-1] - t0)) + 1
    t = t0 + np.arange(T, dtype=np.float64)
    k = np.rint(rov.t - t0).astype(int)
    zs = np.full((T, 2), np.nan)
    zs[k] = np.stack(geodetic_to_enu(rov.lat, rov.lon, rov.h, *origin)[:2], axis=-1)
    R = np.tile(np.eye(2), (T, 1, 1))
    R[k] = rov.cov_enu[:, :2, :2]
    q = np.zeros(T, int)
    q[k] = rov.q
    truth = np.full((T, 2), np.nan)
    j = np.rint(ref.t - t0).astype(int)
    inside = (j >= 0) & (j < T)
    truth[j[inside]] = np.stack(geodetic_to_enu(ref.lat, ref.lon, ref.h, *origin)[:2], axis=-1)[inside]
    return Drive(t=t, zs=zs, R=R, q=q, truth=truth, n_epochs=int(rov.t.size))


DT = 1.0  # s, the grid step


def ct_model(R, *, accel_std=1.0, turn_std=0.1, pos_std=0.1) -> jf.NonlinearGaussian:
    """:func:`jaxnav.filters.coordinated_turn` on the drive's 1 s grid; R (2, 2) or (T, 2, 2) m^2."""
    return jf.coordinated_turn(DT, R, accel_std=accel_std, turn_std=turn_std, pos_std=pos_std)


def measurement_cov(drive: Drive, sigma_floor=0.1):
    """R_k (T, 2, 2), m^2: the file's E/N covariance plus sigma_floor^2 I (fixed-epoch sigmas are mm-level)."""
    return jnp.asarray(drive.R) + sigma_floor**2 * jnp.eye(2)


def fixed_runs(q, half_width=5):
    """Epochs (T,) bool with no float (or worse) solution within +/- half_width s and a fixed one in reach.

    The stretches of the drive where the rover is at cm level: scored for the gross-error test.
    """
    q = np.asarray(q)
    w = np.ones(2 * half_width + 1, int)
    not_fixed = np.convolve((q > 1).astype(int), w, mode="same")
    fixed = np.convolve((q == 1).astype(int), w, mode="same")
    return (not_fixed == 0) & (fixed > 0)


def inject_outliers(zs, candidates, n=6, low=20.0, high=50.0, seed=0):
    """Add n gross errors of low-high m in random directions at random epochs among candidates (host side).

    Args:
      zs: (T, 2) positions, m.  candidates: (T,) bool, the epochs that may receive an outlier.
      n: number of outliers.  low, high: their size range, m.  seed: numpy generator seed.
    Returns:
      (zs with the outliers (T, 2), the epoch indices (n,)).
    """
    rng = np.random.default_rng(seed)
    zs = np.array(zs, dtype=np.float64)
    k = np.sort(rng.choice(np.flatnonzero(candidates), size=n, replace=False))
    ang = rng.uniform(0.0, 2.0 * np.pi, n)
    mag = rng.uniform(low, high, n)
    zs[k] += np.stack([mag * np.cos(ang), mag * np.sin(ang)], axis=-1)
    return zs, k


def plugin(name):
    """The filter keywords of a variant: classic, fading (window 5) or IGG-III (k0 2, k1 4.5)."""
    return {"classic": {}, "fading": {"inflation": jf.fading(window=5)}, "igg3": {"estimator": jf.igg3()}}[name]


def initial_state(zs):
    """x0 (5,) at the first measured position, at rest, heading east; P0 (5, 5) wide on speed and heading."""
    z0 = zs[np.flatnonzero(np.isfinite(zs[:, 0]))[0]]
    x0 = jnp.array([z0[0], z0[1], 0.0, 0.0, 0.0])
    P0 = jnp.diag(jnp.array([1.0, 1.0, 4.0, np.pi**2, 0.1**2]))
    return x0, P0


def run_variants(model, zs, kinds=FILTERS, plugins=PLUGINS):
    """Filter and smooth zs with every (filter, plug-in) pair.

    Returns:
      {(kind, plugin): {"filtered": (T, 5), "smoothed": (T, 5), "n_masked": int, "status": int}}.
    """
    zs = jnp.asarray(zs)
    x0, P0 = initial_state(np.asarray(zs))
    out = {}
    for kind in kinds:
        for name in plugins:
            if kind == "EKF":
                r = jf.extended_kalman_filter(model, x0, P0, zs, **plugin(name))
                s = jf.extended_rts_smoother(model, r)
            else:
                r = jf.unscented_kalman_filter(model, x0, P0, zs, alpha=UKF_ALPHA, **plugin(name))
                s = jf.unscented_rts_smoother(model, r, alpha=UKF_ALPHA)
            out[(kind, name)] = {
                "filtered": np.asarray(r.means),
                "smoothed": np.asarray(s.means),
                "n_masked": int(r.n_nonfinite),
                "status": int(r.status),
            }
    return out


def horizontal_errors(means, truth):
    """Horizontal error (T,), m, of means (T, >= 2) against truth (T, 2) (NaN where truth is missing)."""
    d = np.asarray(means)[:, :2] - np.asarray(truth)
    return np.hypot(d[:, 0], d[:, 1])


def scores(err, where=None):
    """(RMS, max) of the finite errors (where: optional boolean selection), m."""
    e = np.asarray(err)
    keep = np.isfinite(e) if where is None else np.isfinite(e) & where
    return float(np.sqrt(np.mean(e[keep] ** 2))), float(np.max(e[keep]))


def turning(truth, threshold=np.radians(5.0), min_speed=1.0):
    """Epochs (T,) bool where the reference turns faster than threshold rad/s at min_speed m/s or more."""
    d = np.gradient(np.asarray(truth), axis=0)
    speed = np.hypot(d[:, 0], d[:, 1])
    heading = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    rate = np.abs(np.gradient(heading))
    return (np.nan_to_num(rate) > threshold) & (np.nan_to_num(speed) >= min_speed)


STIFF = {"accel_std": 0.1, "turn_std": 0.005}  # a model that expects near-straight, steady driving


def run_ct_drive(
    folder,
    out: str | None = None,
    *,
    kinds=FILTERS,
    plugins=PLUGINS,
    n_outliers=6,
    seed=0,
    sigma_floor=0.1,
    stiff=STIFF,
    **model_kw,
) -> dict:
    """The whole comparison on the drive.

    1. Every (filter, plug-in) pair, filtered and smoothed, with :func:`ct_model` (``model_kw``).
    2. Manoeuvres: the EKF, classic vs fading, with a stiff model (``stiff``: turns unmodelled),
       scored in the turns of the reference.
    3. Gross errors: ``n_outliers`` errors of 20-50 m injected into the fixed runs
       (:func:`fixed_runs`), the EKF classic vs IGG-III, scored over the fixed runs.

    Args:
      folder: the ``kinematic`` data folder.  out: optional folder for ``ct_drive.png``.
      kinds, plugins: the filters and plug-ins of part 1.  n_outliers, seed: part 3.
      sigma_floor: m, added to the file's sigmas.  stiff: :func:`ct_model` keywords of part 2.
      model_kw: :func:`ct_model` keywords of parts 1 and 3.
    Returns:
      dict with "drive" (:class:`Drive`), "raw" ((T,) m, the rover's own error), "measured",
      "turns", "fixed_runs" ((T,) bool), "errors" {(kind, plugin, "filtered"/"smoothed"): (T,) m},
      "manoeuvre_errors" {("EKF", "classic"/"fading", stage): (T,) m}, "outlier_errors"
      {("EKF", "classic"/"igg3", stage): (T,) m}, "outlier_epochs", "n_masked" (NaN elements
      masked per run), "status" {(kind, plugin): int}, "figure" (path or None).
    """
    drive = load_drive(folder)
    R = measurement_cov(drive, sigma_floor)
    model = ct_model(R, **model_kw)
    truth = drive.truth

    def errs(res):
        return {
            (k, p, st): horizontal_errors(v[st], truth) for (k, p), v in res.items() for st in ("filtered", "smoothed")
        }

    res = run_variants(model, drive.zs, kinds, plugins)
    stiff_res = run_variants(ct_model(R, **stiff), drive.zs, ("EKF",), ("classic", "fading"))
    runs = fixed_runs(drive.q)
    zo, ko = inject_outliers(drive.zs, runs & (drive.q == 1), n_outliers, seed=seed)
    bad = run_variants(model, zo, ("EKF",), ("classic", "igg3"))
    result = {
        "drive": drive,
        "raw": horizontal_errors(drive.zs, truth),
        "measured": np.isfinite(drive.zs[:, 0]),
        "turns": turning(truth),
        "fixed_runs": runs,
        "errors": errs(res),
        "manoeuvre_errors": errs(stiff_res),
        "outlier_errors": errs(bad),
        "outlier_epochs": ko,
        "n_masked": next(iter(res.values()))["n_masked"],
        "status": {k: v["status"] for k, v in res.items()},
        "figure": None,
    }
    if out is not None:
        from jaxnav.experiments.figures import plot_ct_drive

        outdir = pathlib.Path(out)
        outdir.mkdir(parents=True, exist_ok=True)
        result["figure"] = outdir / "ct_drive.png"
        plot_ct_drive(result, result["figure"])
    return result


def format_ct_drive(result) -> str:
    """Markdown tables (m) of a :func:`run_ct_drive` result: all variants; manoeuvres; gross errors."""
    meas, turns, runs = result["measured"], result["turns"], result["fixed_runs"]
    raw = result["raw"]
    f2 = lambda v: f"{v[0]:.2f} / {v[1]:.2f}"
    lines = [
        "| filter | plug-in | filtered, all epochs | smoothed, all epochs | filtered, measured epochs | "
        "smoothed, measured epochs |",
        "|---|---|---|---|---|---|",
        f"| rover RTK itself | | | | {f2(scores(raw, meas))} | |",
    ]
    e = result["errors"]
    for k, p, st in e:
        if st == "filtered":
            lines.append(
                f"| {k} | {p} | {f2(scores(e[(k, p, 'filtered')]))} | {f2(scores(e[(k, p, 'smoothed')]))} | "
                f"{f2(scores(e[(k, p, 'filtered')], meas))} | {f2(scores(e[(k, p, 'smoothed')], meas))} |"
            )
    lines += [
        "",
        "| stiff model, EKF | filtered, in turns | smoothed, in turns | filtered, all epochs |",
        "|---|---|---|---|",
    ]
    m = result["manoeuvre_errors"]
    for p in ("classic", "fading"):
        lines.append(
            f"| {p} | {f2(scores(m[('EKF', p, 'filtered')], turns))} | "
            f"{f2(scores(m[('EKF', p, 'smoothed')], turns))} | {f2(scores(m[('EKF', p, 'filtered')]))} |"
        )
    lines += [
        "",
        f"| {len(result['outlier_epochs'])} outliers of 20-50 m in the fixed runs, EKF | "
        "filtered, fixed runs | smoothed, fixed runs | filtered, all epochs |",
        "|---|---|---|---|",
    ]
    o = result["outlier_errors"]
    clean = result["errors"]
    if ("EKF", "classic", "filtered") in clean:
        lines.append(
            f"| classic, no outliers | {f2(scores(clean[('EKF', 'classic', 'filtered')], runs))} | "
            f"{f2(scores(clean[('EKF', 'classic', 'smoothed')], runs))} | "
            f"{f2(scores(clean[('EKF', 'classic', 'filtered')]))} |"
        )
    for p in ("classic", "igg3"):
        lines.append(
            f"| {p} | {f2(scores(o[('EKF', p, 'filtered')], runs))} | "
            f"{f2(scores(o[('EKF', p, 'smoothed')], runs))} | {f2(scores(o[('EKF', p, 'filtered')]))} |"
        )
    return "\n".join(lines)
