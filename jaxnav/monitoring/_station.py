"""Station velocities with coloured noise: outlier screening, daily grid, trajectory fit (host driver).

:func:`fit_station` takes a :class:`jaxnav.io.DailySeries` and returns a :class:`StationFit`:
velocities and their standard deviations under white + power-law (+ random-walk) noise, the
noise parameters with their box and at-bound flags, seasonal amplitudes, steps and the screened
outliers. The fit itself is :func:`jaxnav.monitoring.fit_component` (``vmap`` over the three
components); :func:`fit_series_batch` runs it over a batch of series in one ``vmap``.
"""

from __future__ import annotations

import datetime as _dt
import inspect
import math
from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxnav.monitoring._midas import midas_velocity
from jaxnav.monitoring._trajectory import (
    AT_BOUND_TOL,
    COMPONENTS,
    GAIN_LEFT_WARN,
    POSTSEISMIC_FORMS,
    NoiseFit,
    NoiseSpec,
    component_loglik,
    design_matrix,
    fit_component,
    noise_spec,
    powerlaw_amplitude,
    random_walk_amplitude,
    robust_scale,
    start_and_box,
)
from jaxnav.units import DAY, MM, YEAR

#: the daily grid is padded (masked epochs) to a multiple of this many days, so stations of
#: similar length share one compiled program
GRID_BUCKET = 512
_J2000 = _dt.datetime(2000, 1, 1, 12, 0, 0)


def iso_date(t) -> str:
    """s since J2000 -> ISO 8601 date of the day (UTC-like calendar day, as the daily series label it)."""
    return (_J2000 + _dt.timedelta(seconds=float(t))).date().isoformat()


def decimal_year(t):
    """s since J2000 -> decimal year (Julian years from 2000.0 at J2000)."""
    return 2000.0 + np.asarray(t, float) / YEAR


class Screening(NamedTuple):
    """Outlier screening of a daily series (per component).

    Attributes:
      keep: (N, 3) bool, epoch and component used.
      records: list of dicts, one per rejected value: index, date, decimal_year, component,
        reason ("sigma" | "residual"), value_m, sigma_m, residual_m (residual test only), threshold_m.
      counts: {"sigma": n, "residual": n, "missing": n} rejected values per reason ("missing":
        the file's nan values).
      sigma_limit_m: (3,) the formal-sigma limits used.  residual_limit_m: (3,) the last residual
        limits at the median formal sigma (each value's limit scales with its own sigma).
    """

    keep: jax.Array
    records: list
    counts: dict
    sigma_limit_m: jax.Array
    residual_limit_m: jax.Array


def _running_median(day, r, window_days):
    """Median of r over the epochs within +-window_days of each epoch (NaN ignored), (N,)."""
    T = int(day[-1]) + 1
    g = np.full(T + 2 * window_days, np.nan)
    g[day + window_days] = r
    win = np.lib.stride_tricks.sliding_window_view(g, 2 * window_days + 1)[day]
    with np.errstate(all="ignore"):
        import warnings as _w

        with _w.catch_warnings():
            _w.simplefilter("ignore", RuntimeWarning)
            return np.nanmedian(win, axis=1)


def _day_index(series):
    """Day of each epoch counted from the first (0, 1, ...).

    Times are rounded to whole days; for decimal-year files (SIO .neu, .col) the calendar reading
    of the decimal year (year + (day of year - 0.5) / days in that year) is used instead when it
    gives fewer epochs on one day (Julian years drift against the calendar by up to 0.75 day).
    """
    t = np.asarray(series.t, float)
    jul = np.round((t - t[0]) / DAY).astype(np.int64)
    if series.fmt == "tenv3":
        return jul
    yr = np.floor(np.asarray(series.year, float)).astype(int)
    ndays = np.where((yr % 4 == 0) & ((yr % 100 != 0) | (yr % 400 == 0)), 366, 365)
    doy0 = np.round((np.asarray(series.year) - yr) * ndays - 0.5).astype(np.int64)
    base = np.array([(_dt.date(int(y), 1, 1) - _dt.date(2000, 1, 1)).days for y in yr], np.int64)
    cal = base + doy0
    cal = cal - cal[0]

    def dups(d):
        return int(np.sum(np.diff(d) <= 0))

    return cal if dups(cal) < dups(jul) and np.all(np.diff(cal) >= 0) else jul


def series_span(series) -> tuple[float, float]:
    """(first, last) epoch of a daily series' day grid, s since J2000: the range a step must fall in.

    Args:
      series: :class:`jaxnav.io.DailySeries` (its ``t`` and, for decimal-year files, ``year``).
    """
    return float(series.t[0]), float(series.t[0]) + float(_day_index(series)[-1]) * DAY


def median_position(series):
    """Median latitude and longitude of a daily series' epochs that give both, rad (None if none does).

    Args:
      series: :class:`jaxnav.io.DailySeries` (its ``llh`` (N, 3): latitude, longitude rad, height m).
    Returns:
      (2,) [latitude, longitude] rad, or None.
    """
    llh = np.asarray(series.llh, float)
    ok = np.isfinite(llh[:, :2]).all(axis=1)
    return np.median(llh[ok, :2], axis=0) if ok.any() else None


def screen_outliers(
    series,
    *,
    steps=(),
    periods_days=(),
    sigma_factor: float = 5.0,
    sigma_max_m=None,
    residual_k: float = 5.0,
    window_days: int = 15,
    max_passes: int = 10,
    poly_degree: int = 1,
    postseismic=(),
) -> Screening:
    """Reject days with implausible formal sigmas and values far from the trajectory (per component).

    1. Sigma test: a component whose formal sigma exceeds ``sigma_factor`` x the median formal
       sigma of that component (or ``sigma_max_m`` when given) is rejected.
    2. Robust residual test, repeated until nothing changes: weighted least squares of the
       trajectory model (offset, rate, annual, semi-annual, ``steps``) on the kept values, minus
       the running median of those residuals over +-``window_days`` days (so the slow wander of
       flicker noise is not taken for outliers; only isolated departures are), divided by the
       value's formal sigma (days the file marks as noisier get wider limits); a value further
       than ``residual_k`` x 1.4826 x MAD of these from their median is rejected (the MAD scale is robust to
       the outliers themselves; 5 x is about 5 sigma for Gaussian residuals; Hector's
       removeoutliers uses 3 interquartile ranges of the plain residuals, about 4.7 sigma).

    Args:
      series: :class:`jaxnav.io.DailySeries`.  steps: step epochs, s since J2000.
      periods_days, poly_degree: further periodic terms and polynomial degree of the trajectory
        (:func:`design_matrix`).  postseismic: (epoch s, form, tau s) transients of the trajectory.
      sigma_factor, sigma_max_m, residual_k, window_days, max_passes: as above.
    Returns:
      :class:`Screening`.
    """
    if not (sigma_factor > 1.0 and residual_k > 0.0):
        raise ValueError(f"sigma_factor must be > 1 and residual_k > 0, got {sigma_factor}, {residual_k}")
    t = np.asarray(series.t, float)
    y = np.asarray(series.enu, float)
    sig = np.sqrt(np.asarray(np.diagonal(series.cov, axis1=-2, axis2=-1), float))
    present = np.isfinite(y)
    med = np.array([np.median(sig[present[:, c], c]) if present[:, c].any() else np.nan for c in range(3)])
    lim = med * sigma_factor if sigma_max_m is None else np.broadcast_to(np.asarray(sigma_max_m, float), (3,))
    bad_sig = present & (sig > lim[None, :])
    keep = present & ~bad_sig
    records = []
    for i, c in zip(*np.nonzero(bad_sig)):
        records.append(
            dict(
                index=int(i),
                date=iso_date(t[i]),
                decimal_year=float(decimal_year(t[i])),
                component=COMPONENTS[c],
                reason="sigma",
                value_m=float(y[i, c]),
                sigma_m=float(sig[i, c]),
                residual_m=None,
                threshold_m=float(lim[c]),
            )
        )
    A = (
        design_matrix(t, steps=steps, periods_days=periods_days, poly_degree=poly_degree, postseismic=postseismic).A
        if len(t) > 1
        else np.ones((len(t), 1))
    )
    day = _day_index(series)
    res_lim = np.full(3, np.nan)
    for c in range(3):
        for _ in range(max_passes):
            k = keep[:, c]
            if k.sum() <= A.shape[1] + 2:
                break
            w = 1.0 / sig[k, c]
            b = np.linalg.lstsq(A[k] * w[:, None], y[k, c] * w, rcond=None)[0]
            r = y[:, c] - A @ b
            hp = r - _running_median(day, np.where(k, r, np.nan), window_days)
            z = hp / sig[:, c]  # standardised by the formal sigma: noisier days have wider limits
            m = np.nanmedian(z[k])
            s = 1.4826 * np.nanmedian(np.abs(z[k] - m))
            res_lim[c] = residual_k * s * np.median(sig[k, c])
            out = k & (np.abs(z - m) > residual_k * s)
            if not out.any():
                break
            for i in np.flatnonzero(out):
                records.append(
                    dict(
                        index=int(i),
                        date=iso_date(t[i]),
                        decimal_year=float(decimal_year(t[i])),
                        component=COMPONENTS[c],
                        reason="residual",
                        value_m=float(y[i, c]),
                        sigma_m=float(sig[i, c]),
                        residual_m=float(hp[i] - m * sig[i, c]),
                        threshold_m=float(residual_k * s * sig[i, c]),
                    )
                )
            keep[:, c] &= ~out
    records.sort(key=lambda d: (d["index"], COMPONENTS.index(d["component"])))
    counts = {
        "sigma": int(bad_sig.sum()),
        "residual": sum(1 for d in records if d["reason"] == "residual"),
        "missing": int((~present).sum()),
    }
    return Screening(keep=keep, records=records, counts=counts, sigma_limit_m=lim, residual_limit_m=res_lim)


class DailyGrid(NamedTuple):
    """A series on its daily grid (missing days and rejected values masked).

    Attributes:
      t: (T,) s since J2000 of each grid day (first epoch + k days).
      y: (T, 3) m (NaN where not valid).  valid: (T, 3) bool.
      n_days: T without padding.  duplicates: file epochs that fell on an already used day (dropped).
    """

    t: jax.Array
    y: jax.Array
    valid: jax.Array
    n_days: int
    duplicates: int


def daily_grid(series, keep=None, *, bucket: int = GRID_BUCKET) -> DailyGrid:
    """Put a daily series on a regular daily grid (epochs rounded to the nearest day).

    Args:
      series: :class:`jaxnav.io.DailySeries`.  keep: optional (N, 3) bool of values to use.
      bucket: pad the grid with masked days to a multiple of this many days.
    """
    t = np.asarray(series.t, float)
    day = _day_index(series)
    n = int(day[-1]) + 1
    T = int(np.ceil(n / bucket) * bucket) if bucket else n
    y = np.full((T, 3), np.nan)
    ok = np.isfinite(series.enu) if keep is None else (np.asarray(keep, bool) & np.isfinite(series.enu))
    first = np.ones(len(day), bool)
    first[1:] = day[1:] != day[:-1]
    vals = np.where(ok, series.enu, np.nan)
    y[day[first]] = vals[first]
    return DailyGrid(t=t[0] + np.arange(T) * DAY, y=y, valid=np.isfinite(y), n_days=n, duplicates=int((~first).sum()))


def _start(scale, spec, random_walk, theta0=None):
    """(theta0, lo, hi) (..., 4) of :func:`start_and_box`, the start replaced by a given warm start
    ``theta0`` (clipped into the box) when there is one."""
    th0, lo, hi = start_and_box(np.asarray(scale), kappa=spec.kappa, random_walk=random_walk)
    if theta0 is not None:
        th0 = np.clip(np.broadcast_to(np.asarray(theta0, float), th0.shape), lo, hi)
    return th0, lo, hi


def _hinv_start(hinv0, batch_shape):
    """(..., 4, 4) starting inverse Hessians for :func:`fit_component`: NaN (its default start) where none is given."""
    if hinv0 is None:
        return np.full(tuple(batch_shape) + (4, 4), np.nan)
    return np.broadcast_to(np.asarray(hinv0, float), tuple(batch_shape) + (4, 4))


def fit_series_batch(
    y,
    valid,
    A,
    spec,
    scale,
    *,
    random_walk: bool = True,
    reml: bool = True,
    iterations: int = 40,
    chunk=None,
    workers=None,
    progress: bool = False,
    theta0=None,
    hinv0=None,
):
    """Fit many series at once: one ``jax.vmap`` of :func:`fit_component` over the leading axis.

    ``chunk`` (an int) runs the vmap over chunks of that many series (the last one padded, so one
    program serves all): the reverse pass keeps about 150 numbers per series and day, 4 MB per
    10-year series, so a few thousand series at once need chunks on a small machine. The chunks run
    in ``workers`` host threads at once (default: one per CPU core, at most :data:`MAX_DEFAULT_WORKERS`
    and one per chunk): a vmapped fit keeps one core busy, and JAX runs compiled programs from several
    threads in parallel (two chunks on two cores take half the time of one after the other). The
    memory is that of ``workers`` chunks, hence the cap on the default; pass ``workers`` for more. ``progress``: a progress line per finished chunk (:class:`jaxnav._progress.Progress`).

    Args:
      y: (B, T) m (any value where not valid).  valid: (B, T) bool.  A: (T, k) shared design.
      spec: :class:`NoiseSpec`.  scale: (B,) data scales, m (sets the start and the box).
      random_walk, reml, iterations: as in :func:`fit_component`.
      chunk: series per compiled call, or None (all in one).  workers: host threads (None: the CPU count).
      theta0, hinv0: None, or (B, 4) starts and (B, 4, 4) starting inverse Hessians (a warm start:
        the ``theta`` and ``hinv`` of a fit of the same series with fewer design terms) instead of
        the default start from ``scale``; theta0 is clipped into the box.
    Returns:
      :class:`NoiseFit` with a leading axis B.
    """
    th0, lo, hi = _start(scale, spec, random_walk, theta0)
    est = spec.kappa is None
    r, W, dg, Aj = jnp.asarray(spec.r), jnp.asarray(spec.W), jnp.asarray(spec.d_grid), jnp.asarray(A)
    one = lambda yy, vv, t0, l, h, H: fit_component(
        yy,
        vv,
        Aj,
        r,
        W,
        dg,
        t0,
        l,
        h,
        estimate_kappa=est,
        random_walk=random_walk,
        reml=reml,
        iterations=iterations,
        hinv0=H,
    )
    args = (
        jnp.where(jnp.asarray(valid), jnp.asarray(y), 0.0),
        jnp.asarray(valid),
        jnp.asarray(th0),
        jnp.asarray(lo),
        jnp.asarray(hi),
        jnp.asarray(_hinv_start(hinv0, th0.shape[:-1])),
    )
    if chunk is None:
        return jax.vmap(one)(*args)
    return _threaded_chunks(jax.jit(jax.vmap(one)), args, int(chunk), workers, progress)


#: most host threads :func:`fit_series_batch` starts by default (each holds a chunk's reverse pass in
#: memory: about 1 GB for 250 ten-year series)
MAX_DEFAULT_WORKERS = 4


def _threaded_chunks(fn, args, chunk: int, workers, progress: bool, *, label="station fits", unit="series"):
    """``fn`` (vmapped over the leading axis of every array in ``args``) over chunks of ``chunk`` rows, the
    last padded with copies of its first row (one compiled size), in ``workers`` threads; concatenated."""
    import os
    from concurrent.futures import ThreadPoolExecutor

    from jaxnav._progress import Progress

    if chunk < 1:
        raise ValueError(f"chunk must be a positive number of series, got {chunk}")
    B = int(args[0].shape[0])
    starts = list(range(0, B, chunk))
    workers = min(int(workers or min(os.cpu_count() or 1, MAX_DEFAULT_WORKERS)), len(starts))
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")

    def run(s):
        part = [a[s : s + chunk] for a in args]
        n = int(part[0].shape[0])
        if n < chunk:
            part = [jnp.concatenate([p, jnp.broadcast_to(p[:1], (chunk - n, *p.shape[1:]))]) for p in part]
        return jax.tree_util.tree_map(lambda x: np.asarray(x)[:n], jax.block_until_ready(fn(*part)))

    with Progress(B, label, unit=unit, enabled=progress) as bar, ThreadPoolExecutor(workers) as ex:
        futures = [ex.submit(run, s) for s in starts]
        outs = []
        for s, f in zip(starts, futures):
            outs.append(f.result())
            bar.update(min(chunk, B - s))
    return jax.tree_util.tree_map(lambda *xs: jnp.asarray(np.concatenate(xs)), *outs)


class StationFit(NamedTuple):
    """Trajectory and noise of one station (host side, numpy, SI; (3,) arrays are east, north, up).

    Attributes:
      station, path, fmt: from the series.
      velocity: (3,) m/s.  velocity_sigma: (3,) m/s (GLS with the fitted coloured noise).
      velocity_sigma_white: (3,) m/s, the same trajectory model with white noise only (for contrast).
      offset: (3,) m at t_ref.  t_ref: s since J2000.
      annual_amplitude, semiannual_amplitude: (3,) m; *_sigma: (3,) m (linearised);
      annual_phase, semiannual_phase: (3,) rad, of A cos(2 pi h t/yr - phase) with t from J2000.
      steps: (S,) epochs, s.  step_sizes, step_sigmas: (3, S) m.  step_sources: (S,) "given" | "detected".
      white_sigma: (3,) m.  kappa: (3,) spectral index.  powerlaw_amplitude: (3,) m s^(kappa/4).
      random_walk: (3,) m/sqrt(s) (0 without a random walk).  noise: :class:`NoiseFit` (3 components).
      model: text naming the noise model.  warnings: list of str.  screening: :class:`Screening`.
      grid: :class:`DailyGrid`.  design_names: column names.  A: (T, k) design.
      gm_max_rel_error: of the Gauss-Markov approximation of the power-law covariance.
      step_gains: (S,) 2 ln L gain of each detected step at its detection (NaN for given steps).
      residual_trend: (3,) m/s, least-squares rate of the fit's residuals (:func:`residual_trend`).
      poly_degree: degree of the polynomial in time (:func:`polynomial_terms`).
      postseismic: tuple of :class:`PostseismicTerm`.
    """

    station: str
    path: str
    fmt: str
    velocity: jax.Array
    velocity_sigma: jax.Array
    velocity_sigma_white: jax.Array
    offset: jax.Array
    t_ref: float
    annual_amplitude: np.ndarray
    annual_amplitude_sigma: np.ndarray
    annual_phase: np.ndarray
    semiannual_amplitude: np.ndarray
    semiannual_amplitude_sigma: np.ndarray
    semiannual_phase: np.ndarray
    steps: jax.Array
    step_sizes: jax.Array
    step_sigmas: jax.Array
    step_sources: tuple
    white_sigma: jax.Array
    kappa: jax.Array
    powerlaw_amplitude: jax.Array
    random_walk: jax.Array
    noise: NoiseFit
    model: str
    warnings: list
    screening: Screening
    grid: DailyGrid
    design_names: tuple
    A: jax.Array
    gm_max_rel_error: float
    step_gains: jax.Array = ()
    residual_trend: jax.Array | None = None
    poly_degree: int = 1
    postseismic: tuple = ()


class PostseismicTerm(NamedTuple):
    """A post-seismic transient of a :class:`StationFit` (Bevis & Brown 2014; :func:`postseismic_column`).

    Attributes:
      epoch: t_eq, s since J2000.  form: "log" | "exp".  tau: time constant, s.
      estimated: whether tau was estimated (:func:`profile_tau`), else given.
      tau_range: (2,) s, the profile-likelihood interval of tau (2 Delta ln L <= 1, the noise held
        at its fitted values; (tau, tau) when given).  tau_at_edge: the best tau lies on an end of
        the searched grid (the data do not bound it).
      amplitude: (3,) m.  amplitude_sigma: (3,) m (GLS, conditional on tau).
    """

    epoch: float
    form: str
    tau: float
    estimated: bool
    tau_range: jax.Array
    tau_at_edge: bool
    amplitude: jax.Array
    amplitude_sigma: jax.Array


#: time constant a post-seismic term to be estimated starts from (screening, first noise fit), s
TAU_START = 30.0 * DAY
#: the searched grid of ln tau: 1 day .. 2 x the span, 10 points per decade
TAU_MIN = 1.0 * DAY
TAU_PER_DECADE = 10


@partial(jax.jit, static_argnames=("estimate_kappa", "random_walk"))
def _loglik_over_designs(theta, y, valid, As, r, W, d_grid, *, estimate_kappa, random_walk):
    """ML log-likelihood of one component at fixed noise for each design of a stack (G, T, k) -> (G,)."""
    return jax.vmap(
        lambda A: component_loglik(
            theta, y, valid, A, r, W, d_grid, estimate_kappa=estimate_kappa, random_walk=random_walk, reml=False
        )
    )(As)


def profile_tau(grid: DailyGrid, build, j: int, theta, spec, *, random_walk: bool, tau_max=None):
    """Time constant of post-seismic term ``j`` by its profile likelihood on a log grid, refined.

    For tau on a grid of ln tau (:data:`TAU_PER_DECADE` points per decade from :data:`TAU_MIN`
    to ``tau_max``, default twice the span) the design with that tau is fitted by generalised
    least squares under each component's noise ``theta`` (held fixed), and the ML log-likelihoods
    of the three components are summed (tau is one physical time constant for all three; the
    plain likelihood, since REML values of different designs are not comparable). A parabola
    in ln tau through the best grid point and its neighbours refines it; the interval is where
    2 (ln L_max - ln L) <= 1: on that parabola when it lies within one grid step of the best
    tau, else interpolated on the grid (a flat or skewed profile).

    Args:
      grid: :class:`DailyGrid`.  build: tau (s) -> (T, k) design with that tau for term j.
      j: the term.  theta: (3, 4) noise parameters.  spec: :class:`NoiseSpec`.
      random_walk: as in the fit.  tau_max: end of the grid, s.
    Returns:
      (tau s, (lo s, hi s), at_edge bool, ln tau grid (G,), summed ln L (G,)).
    """
    n = grid.n_days
    span = grid.t[n - 1] - grid.t[0]
    tau_max = 2.0 * span if tau_max is None else float(tau_max)
    G = max(int(np.ceil(np.log10(tau_max / TAU_MIN) * TAU_PER_DECADE)) + 1, 3)
    ln_tau = np.linspace(np.log(TAU_MIN), np.log(tau_max), G)
    As = jnp.asarray(np.stack([build(float(np.exp(lt))) for lt in ln_tau]))
    est = spec.kappa is None
    ll = np.zeros(G)
    for c in range(3):
        y = jnp.asarray(np.where(grid.valid[:, c], grid.y[:, c], 0.0))
        ll += np.asarray(
            _loglik_over_designs(
                jnp.asarray(theta[c]),
                y,
                jnp.asarray(grid.valid[:, c]),
                As,
                jnp.asarray(spec.r),
                jnp.asarray(spec.W),
                jnp.asarray(spec.d_grid),
                estimate_kappa=est,
                random_walk=random_walk,
            )
        )
    i = int(np.nanargmax(ll))
    at_edge = i in (0, G - 1)
    best = ln_tau[i]
    h = ln_tau[1] - ln_tau[0]
    half = np.inf
    if not at_edge:  # vertex of the parabola through the best point and its neighbours (uniform grid)
        v0, v1, v2 = ll[i - 1 : i + 2]
        curv = v2 - 2.0 * v1 + v0
        if curv < 0:
            best = float(np.clip(ln_tau[i] - 0.5 * h * (v2 - v0) / curv, ln_tau[i - 1], ln_tau[i + 1]))
            half = h / np.sqrt(-curv)  # 2 Delta ln L = 1 on the parabola: |ln tau - best| = h / sqrt(-curv)
    if half <= h:  # a sharp profile: the parabola's interval (finer than the grid)
        return (float(np.exp(best)), (float(np.exp(best - half)), float(np.exp(best + half))), at_edge, ln_tau, ll)
    llmax = float(ll[i])
    drop = 2.0 * (llmax - ll)

    def cross(k, step):
        while 0 <= k + step < G and drop[k + step] <= 1.0:
            k += step
        if not 0 <= k + step < G:
            return ln_tau[k]
        f = (1.0 - drop[k]) / max(drop[k + step] - drop[k], 1e-300)
        return ln_tau[k] + f * (ln_tau[k + step] - ln_tau[k])

    lo, hi = cross(i, -1), cross(i, 1)
    return float(np.exp(best)), (float(np.exp(min(lo, best))), float(np.exp(max(hi, best)))), at_edge, ln_tau, ll


def _amplitude(beta, cov, i):
    """Amplitude, its linearised sigma and phase of c cos + s sin from columns i, i+1."""
    c, s = beta[..., i], beta[..., i + 1]
    a = np.hypot(c, s)
    j = np.stack([c, s], axis=-1) / np.maximum(a, 1e-300)[..., None]
    sub = cov[..., i : i + 2, i : i + 2]
    var = np.einsum("...i,...ij,...j->...", j, sub, j)
    return a, np.sqrt(np.maximum(var, 0.0)), np.arctan2(s, c)


def _white_sigma(A, y, valid):
    """Rate sigma of the same design under white noise of the residual scatter (m/yr), per component."""
    out = []
    for c in range(y.shape[1]):
        k = valid[:, c]
        Ak = A[k]
        b = np.linalg.lstsq(Ak, y[k, c], rcond=None)[0]
        e = y[k, c] - Ak @ b
        s2 = e @ e / max(k.sum() - A.shape[1], 1)
        out.append(np.sqrt(s2 * np.linalg.inv(Ak.T @ Ak)[1, 1]))
    return np.array(out)


def step_penalty(grid: DailyGrid) -> float:
    """BIC penalty of one more step: 4 ln(n) (three step sizes and the epoch; n valid values, all components).

    Schwarz (1978): a model term is worth adding when it raises 2 ln L by more than ln(n) per
    parameter; for a 3-year daily series 4 ln(3300) = 32, for 10 years 4 ln(11000) = 37.
    """
    n = int(np.asarray(grid.valid)[: grid.n_days].sum())
    return 4.0 * float(np.log(max(n, 2)))


def _step_statistic(theta, y, valid, A, cand, r, W, d_grid, *, estimate_kappa, random_walk):
    """Twice the log-likelihood gain of a step at each candidate epoch, summed over the components.

    Per component the data and the design ``A`` are whitened by the component's noise
    (:func:`jaxnav.monitoring._trajectory._whitened`); with X~ = Q R and e~ the whitened residual
    (orthogonal to Q), the gain of the whitened step column s~ is (s~^T e~)^2 / (|s~|^2 - |Q^T s~|^2),
    whose sums :func:`jaxnav.monitoring._trajectory.step_scan_sums` accumulates in a second pass.
    Candidates the design already spans (a known step's epoch) get 0.

    Args:
      theta: (3, 4) noise parameters.  y: (3, T) m (0 where not valid).  valid: (3, T) bool.
      A: (T, k) design.  cand: (M,) int candidate epochs (grid indices).
    Returns:
      (M,) statistic.
    """
    from jaxnav.monitoring._trajectory import _whitened, step_scan_sums

    def one(th, yy, vv):
        yt, Xt, _ = _whitened(th, yy, vv, A, r, W, d_grid, estimate_kappa, random_walk)
        Q, _ = jnp.linalg.qr(Xt)
        e = yt - Q @ (Q.T @ yt)
        num, full, QtS = step_scan_sums(th, vv, cand, e, Q, r, W, d_grid, estimate_kappa, random_walk)
        den = full - jnp.sum(QtS * QtS, axis=0)
        ok = den > 1e-9 * jnp.maximum(full, 1e-300)
        return jnp.where(ok, num * num / jnp.where(ok, den, 1.0), 0.0)

    return jnp.sum(jax.vmap(one)(theta, y, valid), axis=0)


class ScanRequest(NamedTuple):
    """One station's step scan as the station driver asks for it (host side, numpy).

    Attributes:
      theta: (3, 4) fitted noise parameters.  y: (3, T) m (0 where not valid).  valid: (3, T) bool.
      A: (T, k) design.  cand: (M,) int candidate epochs.  spec: :class:`NoiseSpec`.
      random_walk: as in the fit.
    """

    theta: np.ndarray
    y: np.ndarray
    valid: np.ndarray
    A: np.ndarray
    cand: np.ndarray
    spec: NoiseSpec
    random_walk: bool


@partial(jax.jit, static_argnames=("estimate_kappa", "random_walk", "batched"))
def _scan_compiled(theta, y, valid, A, cand, r, W, d_grid, *, estimate_kappa, random_walk, batched):
    """:func:`_step_statistic` compiled, for one station or (``batched``) over a leading station axis."""
    fn = partial(_step_statistic, estimate_kappa=estimate_kappa, random_walk=random_walk)
    return (
        jax.vmap(fn)(theta, y, valid, A, cand, r, W, d_grid) if batched else fn(theta, y, valid, A, cand, r, W, d_grid)
    )


def _scan_request(req: ScanRequest):
    """The statistic (M,) of one scan request."""
    sp = req.spec
    return np.asarray(
        _scan_compiled(
            *(jnp.asarray(a) for a in (req.theta, req.y, req.valid, req.A, req.cand, sp.r, sp.W, sp.d_grid)),
            estimate_kappa=sp.kappa is None,
            random_walk=req.random_walk,
            batched=False,
        )
    )


def _detect_steps_program(grid: DailyGrid, A, fit, spec, *, random_walk: bool, spacing_days: int = 7, threshold=None):
    """:func:`detect_steps` as a generator: yields a :class:`ScanRequest` per scan, is sent its statistic."""
    n = grid.n_days
    cand = np.arange(30, n - 30, spacing_days)
    if cand.size == 0:
        return None
    base = dict(
        theta=np.asarray(fit.theta),
        y=np.where(grid.valid, grid.y, 0.0).T,
        valid=np.asarray(grid.valid).T,
        A=np.asarray(A),
        spec=spec,
        random_walk=random_walk,
    )
    stat = yield ScanRequest(cand=cand, **base)
    j = int(np.argmax(stat))
    if spacing_days > 1:  # refine to the day around the best candidate
        cand = np.arange(max(30, cand[j] - spacing_days + 1), min(n - 30, cand[j] + spacing_days))
        stat = yield ScanRequest(cand=cand, **base)
        j = int(np.argmax(stat))
    if stat[j] < (step_penalty(grid) if threshold is None else threshold):
        return None
    return float(grid.t[cand[j]]), float(stat[j])


def detect_steps(grid: DailyGrid, A, fit, spec, *, random_walk: bool, spacing_days: int = 7, threshold=None):
    """Best single step epoch under the fitted noise (likelihood-ratio scan), or None.

    For candidate epochs every ``spacing_days`` days (30 days from either end; then every day
    within ``spacing_days`` of the best of them), a step column is
    whitened with each component's fitted noise (the whitening is linear, so all candidates go
    through one ``vmap``) and the reduction of the weighted residual sum of squares
    (a~^T e~)^2 / (a~^T P a~) summed over the three components is computed (P the projector
    orthogonal to the whitened design): twice the log-likelihood gain of the step under the fitted
    noise. The largest gain is a step when it exceeds ``threshold``, by default the BIC penalty
    :func:`step_penalty` (32-37 for 3-10 year series; a chi-square with 3 degrees of freedom above
    30 leaves a false detection every few thousand station-years of pure coloured noise, on the
    conservative side because the scan picks the maximum over many epochs).

    Returns:
      (epoch s since J2000, statistic) or None.
    """
    return _run_program(
        _detect_steps_program(
            grid, A, fit, spec, random_walk=random_walk, spacing_days=spacing_days, threshold=threshold
        )
    )


def period_amplitudes(fit: StationFit) -> dict:
    """{"<P>d": (amplitude (3,) m, its linearised sigma (3,) m, phase (3,) rad)} of the further periodic terms."""
    out = {}
    for i, nm in enumerate(fit.design_names):
        if nm.startswith("period_") and nm.endswith("_cos"):
            out[nm[len("period_") : -len("_cos")]] = _amplitude(fit.noise.beta, fit.noise.beta_cov, i)
    return out


def polynomial_terms(fit: StationFit) -> dict:
    """{p: (coefficient (3,) m/s^p, its sigma (3,) m/s^p)} of the powers p >= 2 of (t - t_ref).

    The trajectory holds c_p ((t - t_ref) / yr)^p (:func:`design_matrix`); the acceleration at
    t_ref is 2 c_2 (p = 2 here: 2 x the coefficient is the acceleration, m/s^2).
    """
    out = {}
    for i, nm in enumerate(fit.design_names):
        if nm.startswith("poly_"):
            p = int(nm[len("poly_") :])
            out[p] = (fit.noise.beta[:, i] / YEAR**p, np.sqrt(fit.noise.beta_cov[:, i, i]) / YEAR**p)
    return out


def residual_trend(grid: DailyGrid, A, beta):
    """Ordinary least-squares rate of the residuals y - A beta per component (m/yr, (3,)).

    The generalised least-squares rate leaves the residuals with no trend the noise model cannot
    explain; the plain rate of the residuals differs from zero by well under the rate sigma when
    the trajectory model fits (both rates are unbiased, the ordinary one hardly less efficient
    under power-law noise), and by more where a step or transient is missing.

    Args:
      grid: :class:`DailyGrid`.  A: (T, k) design (column 1 the rate per yr).  beta: (3, k).
    """
    out = np.zeros(3)
    n = grid.n_days
    tt = (grid.t[:n] - grid.t[0]) / YEAR
    for c in range(3):
        k = grid.valid[:n, c]
        if k.sum() < 3:
            out[c] = np.nan
            continue
        e = grid.y[:n, c][k] - A[:n][k] @ beta[c]
        out[c] = np.polyfit(tt[k], e, 1)[0]
    return out


class FitRequest(NamedTuple):
    """One station's noise fit as the station driver asks for it (host side, numpy).

    Attributes:
      y: (3, T) m (any value where not valid).  valid: (3, T) bool.  A: (T, k) design.
      spec: :class:`NoiseSpec`.  scale: (3,) m, data scales (start and box).
      random_walk, reml, iterations: as in :func:`fit_component`.
      theta0, hinv0: None (start from ``scale``), or (3, 4) and (3, 4, 4): a warm start (the
        station's previous fit's ``theta`` and ``hinv``).
    """

    y: np.ndarray
    valid: np.ndarray
    A: np.ndarray
    spec: NoiseSpec
    scale: np.ndarray
    random_walk: bool
    reml: bool
    iterations: int
    theta0: np.ndarray | None = None
    hinv0: np.ndarray | None = None


def _fit_request(req: FitRequest):
    """The fit of one request: :func:`fit_series_batch` over its three components (numpy leaves)."""
    fit = fit_series_batch(
        req.y,
        req.valid,
        req.A,
        req.spec,
        req.scale,
        random_walk=req.random_walk,
        reml=req.reml,
        iterations=req.iterations,
        theta0=req.theta0,
        hinv0=req.hinv0,
    )
    return jax.tree_util.tree_map(np.asarray, fit)


def _run_request(req):
    """The answer to one request of a station program: a fit or a scan statistic."""
    return _fit_request(req) if isinstance(req, FitRequest) else _scan_request(req)


def _run_program(program):
    """Drive one station program (:func:`_fit_station_program`, :func:`_detect_steps_program`) to its end."""
    try:
        req = next(program)
        while True:
            req = program.send(_run_request(req))
    except StopIteration as stop:
        return stop.value


@partial(jax.jit, static_argnames=("estimate_kappa", "random_walk", "reml", "iterations"))
def _fit_stations_vmapped(
    y, valid, A, r, W, d_grid, theta0, lo, hi, hinv0, *, estimate_kappa, random_walk, reml, iterations
):
    """:func:`fit_component` over stations (leading axis: y, valid, theta0, lo, hi, hinv0 (S, 3, ...); A,
    r, W, d_grid (S, ...)) and, inside, over each station's three components (sharing its design and noise)."""

    def station(yy, vv, AA, rr, WW, dd, t0, l, h, H):
        def comp(y1, v1, t1, l1, h1, H1):
            return fit_component(
                y1,
                v1,
                AA,
                rr,
                WW,
                dd,
                t1,
                l1,
                h1,
                estimate_kappa=estimate_kappa,
                random_walk=random_walk,
                reml=reml,
                iterations=iterations,
                hinv0=H1,
            )

        return jax.vmap(comp)(yy, vv, t0, l, h, H)

    return jax.vmap(station)(y, valid, A, r, W, d_grid, theta0, lo, hi, hinv0)


def _request_key(req):
    """Requests with equal keys share one compiled batched call (array shapes and static choices)."""
    sp = req.spec
    shapes = (np.shape(sp.r), np.shape(sp.W), sp.kappa is None, req.random_walk)
    if isinstance(req, ScanRequest):
        return (req.y.shape, req.A.shape, req.cand.shape) + shapes
    return (req.y.shape, req.A.shape, req.reml, req.iterations) + shapes


#: series per compiled chunk of :func:`fit_stations` for ten-year daily series (about 1 GB of reverse
#: pass per chunk); shorter series get proportionally more stations per chunk
CHUNK_SERIES_DAYS = 250 * 3653


def _fit_requests(reqs, *, chunk, workers, progress, label):
    """Fits of requests that share a :func:`_request_key`, in chunked ``vmap`` calls; a list of numpy
    :class:`NoiseFit` (leading axis the three components), one per request."""
    r0 = reqs[0]
    th0, lo, hi = zip(*(_start(q.scale, q.spec, q.random_walk, q.theta0) for q in reqs))
    args = (
        jnp.asarray(np.stack([np.where(q.valid, q.y, 0.0) for q in reqs])),
        jnp.asarray(np.stack([q.valid for q in reqs])),
        jnp.asarray(np.stack([q.A for q in reqs])),
        jnp.asarray(np.stack([q.spec.r for q in reqs])),
        jnp.asarray(np.stack([q.spec.W for q in reqs])),
        jnp.asarray(np.stack([q.spec.d_grid for q in reqs]).astype(float)),
        jnp.asarray(np.stack(th0)),
        jnp.asarray(np.stack(lo)),
        jnp.asarray(np.stack(hi)),
        jnp.asarray(np.stack([_hinv_start(q.hinv0, (3,)) for q in reqs])),
    )
    n = len(reqs)
    per_chunk = int(chunk) if chunk else max(1, CHUNK_SERIES_DAYS // (3 * r0.y.shape[1]))
    per_chunk = min(per_chunk, 1 << (n - 1).bit_length())  # a small batch: padded to a power of two, not to a chunk
    fn = partial(
        _fit_stations_vmapped,
        estimate_kappa=r0.spec.kappa is None,
        random_walk=r0.random_walk,
        reml=r0.reml,
        iterations=r0.iterations,
    )
    fits = _threaded_chunks(fn, args, per_chunk, workers, progress, label=label, unit="station")
    fits = jax.tree_util.tree_map(np.asarray, fits)
    return [jax.tree_util.tree_map(lambda x, i=i: x[i], fits) for i in range(n)]


def _scan_requests(reqs, *, chunk, progress, label):
    """Statistics of scan requests that share a :func:`_request_key`, in chunked ``vmap`` calls (one
    host thread: the scans run one after the other); a list of (M,) arrays, one per request."""
    r0 = reqs[0]
    sp = [q.spec for q in reqs]
    args = (
        jnp.asarray(np.stack([q.theta for q in reqs])),
        jnp.asarray(np.stack([q.y for q in reqs])),
        jnp.asarray(np.stack([q.valid for q in reqs])),
        jnp.asarray(np.stack([q.A for q in reqs])),
        jnp.asarray(np.stack([q.cand for q in reqs])),
        jnp.asarray(np.stack([p.r for p in sp])),
        jnp.asarray(np.stack([p.W for p in sp])),
        jnp.asarray(np.stack([p.d_grid for p in sp]).astype(float)),
    )
    n = len(reqs)
    per_chunk = int(chunk) if chunk else max(1, CHUNK_SERIES_DAYS // (3 * r0.y.shape[1]))
    per_chunk = min(per_chunk, 1 << (n - 1).bit_length())
    fn = partial(_scan_compiled, estimate_kappa=r0.spec.kappa is None, random_walk=r0.random_walk, batched=True)
    stats = np.asarray(_threaded_chunks(fn, args, per_chunk, 1, progress, label=label, unit="station"))
    return list(stats)


def fit_stations(series, *, steps=None, postseismic=None, chunk=None, workers=None, progress: bool = False, **options):
    """:func:`fit_station` of many stations, their noise fits and step scans batched: the same
    results, one compiled ``vmap`` per step of the stations' programs instead of one station after the other.

    Every station runs :func:`fit_station`'s program (screening, design, noise fit, step scans,
    refit after a detected step); each time, the driver collects what all unfinished stations ask
    for, a noise fit (:class:`FitRequest`) or a step scan (:class:`ScanRequest`, coarse or fine),
    runs the requests of equal shapes (grid length, design size, candidates, noise terms) in chunked
    ``vmap`` calls (fits in ``workers`` host threads, scans in one), and sends each station its
    answer. A station that gains a step asks for a refit; the others finish. A network with 0-4
    steps per station needs 3 steps (fit, coarse scan, fine scan) per step found plus 3, each
    cheaper than the last as stations finish.

    Args:
      series: sequence of :class:`jaxnav.io.DailySeries`.
      steps: None, or one sequence of known step epochs (s since J2000) per station.
      postseismic: None, or one sequence of post-seismic terms per station (as in :func:`fit_station`).
      chunk: stations per compiled call (default: about 250 ten-year series' worth).
      workers: host threads for the fits (default: the CPU count, at most :data:`MAX_DEFAULT_WORKERS`).
        Memory grows faster than the thread count: 100 ten-year stations with the random walk peak at
        2.1 GB with one thread and 5.7 GB with two (1.23x faster; benchmarks/RESULTS.md).
      progress: progress lines per batched call (:class:`jaxnav._progress.Progress`).
      options: the further keyword options of :func:`fit_station`, the same for every station.
    Returns:
      list of :class:`StationFit`, in the order of ``series``; equal to :func:`fit_station` of each
      station up to rounding (the batch runs the same program in another vmap nesting).
    Raises:
      ValueError: as :func:`fit_station` (the station named), or ``steps``/``postseismic`` of another
        length than ``series``.
    """
    import logging
    import time

    series = list(series)
    n = len(series)
    per = {}
    for name, val in (("steps", steps), ("postseismic", postseismic)):
        per[name] = [()] * n if val is None else list(val)
        if len(per[name]) != n:
            raise ValueError(f"{name}: {len(per[name])} entries for {n} stations (one per station, or None)")
    programs = []
    for s, st, ps in zip(series, per["steps"], per["postseismic"]):
        bound = inspect.signature(fit_station).bind(s, steps=st, postseismic=ps, **options)  # TypeError: unknown option
        bound.apply_defaults()
        programs.append(_fit_station_program(bound.arguments))
    log = logging.getLogger(__name__)
    done = [None] * n
    pending = {}

    def advance(i, answer=None, first=False):
        try:
            pending[i] = next(programs[i]) if first else programs[i].send(answer)
        except StopIteration as stop:
            done[i] = stop.value
            pending.pop(i, None)

    for i in range(n):  # screening and the first design
        advance(i, first=True)
    rounds = 0
    while pending:
        rounds += 1
        t0 = time.perf_counter()
        groups = {}
        for i, req in pending.items():
            groups.setdefault((type(req).__name__, _request_key(req)), []).append(i)
        answers = {}
        n_fit = n_scan = 0
        for (kind, _), idx in groups.items():
            reqs = [pending[i] for i in idx]
            if kind == "FitRequest":
                n_fit += len(idx)
                got = _fit_requests(
                    reqs, chunk=chunk, workers=workers, progress=progress, label=f"station fits, step {rounds}"
                )
            else:
                n_scan += len(idx)
                got = _scan_requests(reqs, chunk=chunk, progress=progress, label=f"step scans, step {rounds}")
            answers.update(zip(idx, got))
        for i in list(pending):
            advance(i, answers[i])
        log.info(
            "step %d: %d station fit(s) and %d step scan(s) in %.1f s (%d compiled shape(s)); %d station(s) continue",
            rounds,
            n_fit,
            n_scan,
            time.perf_counter() - t0,
            len(groups),
            len(pending),
        )
    return done


def fit_station(
    series,
    *,
    steps=(),
    detect: int = 0,
    kappa=-1.0,
    random_walk: bool = True,
    reml: bool = True,
    screen: bool = True,
    sigma_factor: float = 5.0,
    residual_k: float = 5.0,
    per_decade: float = 1.5,
    iterations: int = 40,
    periods_days=(),
    warn_steps=None,
    poly_degree: int = 1,
    postseismic=(),
) -> StationFit:
    """Velocity, its uncertainty under coloured noise, seasonal terms, steps and outliers of one station.

    Args:
      series: :class:`jaxnav.io.DailySeries`.
      steps: known step epochs (antenna changes), s since J2000.
      detect: detect up to this many further steps (:func:`detect_steps`, refitting after each).
      kappa: spectral index of the power-law noise (-1 flicker), or None to estimate it.
      random_walk: include the random-walk term.  reml: restricted ML (Hector's default) or ML.
      screen: run :func:`screen_outliers` first (else only the file's nan values are left out).
      sigma_factor, residual_k: screening thresholds.  per_decade: Gauss-Markov terms per decade.
      iterations: BFGS iterations of the first noise fit; a refit (after a detected step or a new
        post-seismic tau) starts from the fit before it (its parameters and inverse Hessian) and
        takes :func:`refit_iterations` of them (half).
      periods_days: further periodic terms, days (:func:`jaxnav.monitoring.design_matrix`).
      warn_steps: after the last fit, scan once more and warn when one more step would beat the
        BIC penalty (a misfit); default: when ``detect`` > 0.
      poly_degree: degree of the polynomial in time (1: offset and rate; 2 adds an acceleration);
        the rate is always the velocity at the reference epoch t_ref (mid-span).
      postseismic: post-seismic transients, each (epoch s since J2000, "log" | "exp", tau s or
        None to estimate it by :func:`profile_tau`, started at :data:`TAU_START`, alternated with
        the noise fit until tau moves by less than 2 %, at most 3 profiles). The coseismic step at
        the same epoch is not implied: give it in ``steps``.
    Returns:
      :class:`StationFit` (amplitudes of the further periods: :func:`period_amplitudes`; the
      polynomial: :func:`polynomial_terms`; the transients: ``postseismic``).
    Raises:
      ValueError: a series shorter than 60 days or with fewer valid days than model terms + 10, a
        step or post-seismic epoch outside the series.
    """
    return _run_program(_fit_station_program(locals()))


def refit_iterations(iterations: int) -> int:
    """BFGS steps of a warm-started refit (after a detected step or a new post-seismic tau): half of ``iterations``.

    A step column changes the noise estimate little, and BFGS started at the previous optimum with
    its inverse Hessian converges in a few steps: on eight simulated ten-year stations with white +
    flicker + random walk (24 components), 20 warm steps reach the cold 40-step fit's ln L_R within
    1e-4 and its rate sigmas within 0.1 % (benchmarks/RESULTS.md).
    """
    return max(1, int(iterations) // 2)


#: :func:`fit_station`'s parameter names, in order
_FIT_STATION_ARGS = tuple(inspect.signature(fit_station).parameters)


def _fit_station_program(args: dict):
    """:func:`fit_station` as a generator: yields a :class:`FitRequest` per noise fit and a
    :class:`ScanRequest` per step scan, is sent the answer (a :class:`NoiseFit` with numpy leaves and
    a leading axis of three components, or the scan statistic), returns the :class:`StationFit`.

    Args:
      args: :func:`fit_station`'s arguments by name, every one given (``inspect.BoundArguments.arguments``).
    """
    (
        series,
        steps,
        detect,
        kappa,
        random_walk,
        reml,
        screen,
        sigma_factor,
        residual_k,
        per_decade,
        iterations,
        periods_days,
        warn_steps,
        poly_degree,
        postseismic,
    ) = (args[name] for name in _FIT_STATION_ARGS)
    steps = [float(s) for s in np.atleast_1d(np.asarray(steps, float))]
    post = []
    for item in postseismic:
        te, form, tau = item
        if form not in POSTSEISMIC_FORMS:
            raise ValueError(f"{series.station}: post-seismic form {form!r} (expected one of {POSTSEISMIC_FORMS})")
        if tau is not None and not (np.isfinite(tau) and tau > 0):
            raise ValueError(f"{series.station}: post-seismic time constant {tau} s must be > 0")
        post.append((float(te), form, tau))
    estimate_tau = [j for j, (_, _, tau) in enumerate(post) if tau is None]
    taus = [TAU_START if tau is None else float(tau) for _, _, tau in post]
    tau_info = {j: ((taus[j], taus[j]), False) for j in range(len(post))}
    sources = ["given"] * len(steps)
    gains = [np.nan] * len(steps)
    t = np.asarray(series.t, float)
    if len(t) < 2 or (t[-1] - t[0]) / DAY < 60:
        raise ValueError(
            f"{series.station}: the series spans {(t[-1] - t[0]) / DAY if len(t) > 1 else 0:.0f} days; "
            "a trajectory with seasonal terms needs at least 60"
        )
    scr = (
        screen_outliers(
            series,
            steps=steps,
            periods_days=periods_days,
            sigma_factor=sigma_factor,
            residual_k=residual_k,
            poly_degree=poly_degree,
            postseismic=[(te, f, tau) for (te, f, _), tau in zip(post, taus)],
        )
        if screen
        else Screening(
            keep=np.isfinite(series.enu),
            records=[],
            counts={"sigma": 0, "residual": 0, "missing": int((~np.isfinite(series.enu)).sum())},
            sigma_limit_m=np.full(3, np.nan),
            residual_limit_m=np.full(3, np.nan),
        )
    )
    grid = daily_grid(series, scr.keep)
    spec = noise_spec(grid.n_days, kappa=kappa, per_decade=per_decade)
    warnings = []
    t_ref = 0.5 * (grid.t[0] + grid.t[grid.n_days - 1])
    for te, _, _ in post:
        if not grid.t[0] < te < grid.t[grid.n_days - 1]:
            raise ValueError(
                f"{series.station}: post-seismic epoch {decimal_year(te):.4f} is outside the series "
                f"({decimal_year(grid.t[0]):.4f} .. {decimal_year(grid.t[grid.n_days - 1]):.4f})"
            )

    def design(step_list, tau_list):
        return design_matrix(
            grid.t,
            steps=sorted(step_list),
            t_ref=t_ref,
            periods_days=periods_days,
            poly_degree=poly_degree,
            postseismic=[(te, f, tau) for (te, f, _), tau in zip(post, tau_list)],
        )

    tau_passes = 0
    fit = None
    while True:
        for ts in steps:
            if not grid.t[0] < ts <= grid.t[grid.n_days - 1]:
                raise ValueError(
                    f"{series.station}: step epoch {decimal_year(ts):.4f} is outside the series "
                    f"({decimal_year(grid.t[0]):.4f} .. {decimal_year(grid.t[grid.n_days - 1]):.4f})"
                )
        D = design(steps, taus)
        A = D.A
        nvalid = grid.valid.sum(axis=0)
        if np.any(nvalid < A.shape[1] + 10):
            raise ValueError(
                f"{series.station}: {nvalid.tolist()} valid days per component, fewer than the "
                f"{A.shape[1]} model terms + 10"
            )
        scale = []
        for c in range(3):
            k = grid.valid[:, c]
            b = np.linalg.lstsq(A[k], grid.y[k, c], rcond=None)[0]
            scale.append(max(float(robust_scale(grid.y[k, c] - A[k] @ b)), 1e-6))
        warm = fit is not None  # a refit after a step or a new tau starts from the fit before it
        fit = yield FitRequest(
            grid.y.T,
            grid.valid.T,
            A,
            spec,
            np.array(scale),
            random_walk,
            reml,
            refit_iterations(iterations) if warm else iterations,
            theta0=fit.theta if warm else None,
            hinv0=fit.hinv if warm else None,
        )
        if estimate_tau and tau_passes < 3:  # profile each estimated tau under the noise just fitted
            tau_passes += 1
            moved = False
            for j in estimate_tau:

                def build(tau, j=j):
                    return design(steps, [tau if k == j else taus[k] for k in range(len(taus))]).A

                tau_new, rng, edge, _, _ = profile_tau(grid, build, j, fit.theta, spec, random_walk=random_walk)
                tau_info[j] = (rng, edge)
                if abs(np.log(tau_new / taus[j])) > 0.02:
                    taus[j], moved = tau_new, True
            if moved:
                continue
        limit = detect <= sum(s == "detected" for s in sources)
        if limit and not (detect > 0 if warn_steps is None else warn_steps):
            break
        found = yield from _detect_steps_program(grid, A, fit, spec, random_walk=random_walk)
        if found is None:
            break
        if limit:
            warnings.append(
                f"a further step at {iso_date(found[0])} would raise 2 ln L by {found[1]:.0f}, more "
                f"than the BIC penalty {step_penalty(grid):.0f}; not added (detection limit {detect}): "
                "the model misfits"
            )
            break
        steps.append(found[0])
        tau_passes = 0
        sources.append("detected")
        gains.append(found[1])
        warnings.append(
            f"step detected at {iso_date(found[0])} (2 ln L gain {found[1]:.0f} > BIC penalty {step_penalty(grid):.0f})"
        )
    order = np.argsort(steps) if steps else np.array([], int)
    steps_sorted = np.array(steps)[order] if steps else np.zeros(0)
    sources = tuple(np.array(sources)[order].tolist()) if steps else ()
    gains = np.array(gains, float)[order] if steps else np.zeros(0)
    beta, cov = fit.beta, fit.beta_cov
    names = D.names
    ia = names.index("annual_cos")
    a1, a1s, p1 = _amplitude(beta, cov, ia)
    a2, a2s, p2 = _amplitude(beta, cov, ia + 2)
    js = [names.index(f"step_{j}") for j in range(len(steps))]  # the design's steps are sorted
    lab = ("white sigma", "power-law sigma", "random-walk sigma", "spectral index")
    for c, comp in enumerate(COMPONENTS):
        for j in range(4):
            if not fit.free[c, j]:
                continue
            edge = "upper" if fit.at_upper[c, j] else ("lower" if fit.at_lower[c, j] else None)
            if edge is None:
                continue
            lo, hi = fit.lo[c, j], fit.hi[c, j]
            if j == 3:
                bounds = f"[{lo:.3f}, {hi:.3f}]"
            elif j == 2:
                f = np.sqrt(365.25) * 1e3  # per-day step (m) -> mm/sqrt(yr)
                bounds = f"[{np.exp(lo) * f:.3g}, {np.exp(hi) * f:.3g}] mm/sqrt(yr)"
            elif j == 1:
                d = -0.5 * fit.theta[c, 3]
                f = 365.25 ** (d / 2) * 1e3
                bounds = f"[{np.exp(lo) * f:.3g}, {np.exp(hi) * f:.3g}] mm/yr^{d / 2:.2f}"
            else:
                bounds = f"[{np.exp(lo) * 1e3:.3g}, {np.exp(hi) * 1e3:.3g}] mm"
            if j == 2 and edge == "lower":
                warnings.append(
                    f"{comp}: random walk at the lower bound of its box {bounds}: not resolved "
                    f"by these data (effectively zero)"
                )
            else:
                warnings.append(
                    f"{comp}: {lab[j]} estimate at the {edge} bound of its box {bounds} "
                    f"(within {AT_BOUND_TOL} in ln units): the estimate is limited by the box"
                )
    terms = []
    for j, (te, form, tau) in enumerate(post):
        i = names.index(f"postseismic_{j}_{form}")
        rng, edge = tau_info[j]
        if edge:
            warnings.append(
                f"post-seismic {form} term after {iso_date(te)}: the best time constant lies at the end of "
                f"the searched range ({taus[j] / DAY:.3g} days): not resolved by these data"
            )
        terms.append(
            PostseismicTerm(
                epoch=te,
                form=form,
                tau=taus[j],
                estimated=tau is None,
                tau_range=np.array(rng, float),
                tau_at_edge=bool(edge),
                amplitude=beta[:, i],
                amplitude_sigma=np.sqrt(cov[:, i, i]),
            )
        )
    left = np.asarray(fit.gain_left)
    for c in np.flatnonzero(left > GAIN_LEFT_WARN):
        warnings.append(
            f"{COMPONENTS[c]}: noise fit not converged after {int(fit.iterations[c])} accepted BFGS steps "
            f"(a further step would raise ln L_R by {left[c]:.2g}): rates and sigmas may be off; raise iterations"
        )
    r_rate = residual_trend(grid, A, beta)
    kap = fit.theta[:, 3]
    model = (
        "white + power-law (GGM, 1-phi = 6.9e-6, kappa "
        + ("estimated" if kappa is None else f"{kappa:g}")
        + ")"
        + (" + random walk" if random_walk else "")
        + f", {'REML' if reml else 'ML'}"
    )
    return StationFit(
        station=series.station,
        path=series.path,
        fmt=series.fmt,
        velocity=beta[:, 1] / YEAR,
        velocity_sigma=np.sqrt(cov[:, 1, 1]) / YEAR,
        velocity_sigma_white=_white_sigma(A, np.where(grid.valid, grid.y, 0.0), grid.valid) / YEAR,
        offset=beta[:, 0],
        t_ref=D.t_ref,
        annual_amplitude=a1,
        annual_amplitude_sigma=a1s,
        annual_phase=p1,
        semiannual_amplitude=a2,
        semiannual_amplitude_sigma=a2s,
        semiannual_phase=p2,
        steps=steps_sorted,
        step_sizes=beta[:, js] if js else np.zeros((3, 0)),
        step_sigmas=np.sqrt(cov[:, js, js]) if js else np.zeros((3, 0)),
        step_sources=sources,
        white_sigma=np.exp(fit.theta[:, 0]),
        kappa=kap,
        powerlaw_amplitude=powerlaw_amplitude(fit.theta),
        random_walk=random_walk_amplitude(fit.theta) if random_walk else np.zeros(3),
        noise=fit,
        model=model,
        warnings=warnings,
        screening=scr,
        grid=grid,
        design_names=names,
        A=A,
        gm_max_rel_error=spec.max_rel_error,
        step_gains=gains,
        residual_trend=r_rate / YEAR,
        poly_degree=int(poly_degree),
        postseismic=tuple(terms),
    )


def midas_check(fit: StationFit):
    """MIDAS rates (Blewitt et al. 2016) of a fitted station's screened daily values, checked against the fit.

    Where the fit has post-seismic terms, MIDAS (whose model is a rate and steps) runs on the
    values less the fitted transients, so that the comparison tests the rest of the model.

    Args:
      fit: :class:`StationFit` (its grid, steps, design and rates).
    Returns:
      (:class:`jaxnav.monitoring.MidasVelocity`: rates and sigmas (3,) m/yr with the fit's steps;
      warnings): a warning per component where MIDAS and the model rate differ by more than their combined sigma sqrt(s_midas^2 + s_fit^2), and where
      the ordinary least-squares rate of the residuals exceeds 3 MIDAS sigmas (a misfit that an
      inflated random walk would hide from the model's own sigma).
    """
    g = fit.grid
    t_yr = decimal_year(g.t[: g.n_days])
    y = np.where(g.valid, g.y, np.nan)[: g.n_days]
    for i, nm in enumerate(fit.design_names):  # MIDAS has no transient: it sees the series less the fitted ones
        if nm.startswith("postseismic_"):
            y = y - np.outer(fit.A[: g.n_days, i], np.asarray(fit.noise.beta)[:, i])
    m = midas_velocity(t_yr, y, decimal_year(fit.steps))
    v_fit, s_fit = fit.velocity * YEAR, fit.velocity_sigma * YEAR
    warnings = []
    for c, comp in enumerate(COMPONENTS):
        d, s = m.velocity[c] - v_fit[c], math.hypot(m.sigma[c], s_fit[c])
        if np.isfinite(d) and abs(d) > s:
            warnings.append(
                f"{comp}: MIDAS rate {m.velocity[c] / MM:+.2f} +- {m.sigma[c] / MM:.2f} mm/yr differs from "
                f"the model rate {v_fit[c] / MM:+.2f} +- {s_fit[c] / MM:.2f} mm/yr by more than their "
                "combined sigma: a step, transient or outliers the model misses?"
            )
    span = (g.n_days - 1) / 365.25
    for c, comp in enumerate(COMPONENTS):
        r = float(fit.residual_trend[c] * YEAR)
        if np.isfinite(r) and np.isfinite(m.sigma[c]) and abs(r) > 3.0 * m.sigma[c]:
            warnings.append(
                f"{comp}: the residuals keep a trend of {r / MM:+.2f} mm/yr ({r * span / MM:+.0f} mm over "
                f"{span:.1f} yr), more than 3 x the MIDAS rate sigma {m.sigma[c] / MM:.2f} mm/yr: the "
                "model misfits (a missed step or transient, absorbed by the noise model?)"
            )
    return m, warnings
