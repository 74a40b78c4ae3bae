"""S2: Kalman filtering of CORS-RTK point series to improve a mobile terminal's accuracy.

Per point (S2 "Procedure"), for many points in one ``vmap``-ed, jitted call (points with
different epoch counts are padded to a common length and masked):

1. project each epoch's WGS-84 (B, L) to Gauss-Krüger (x north, y east) and keep the ellipsoidal H;
2. filter the 3-D series (x, y, H) with the constant-velocity model of S1
   (:func:`jaxnav.filters.kalman_filter`, optionally followed by :func:`jaxnav.filters.rts_smoother`),
   started from the post-processing initial values of S2 eqs. (11)-(17) (:func:`initial_values`);
3. transform each filtered epoch into the reference frame with the connection survey's
   4-parameter plane similarity and convert H to a normal height with the fitted height-anomaly
   surface (:mod:`jaxnav.geodesy`);
4. average the transformed epochs and evaluate the internal precision of the mean, S2 eqs. (18)-(19).

The same transforms applied to the unfiltered epochs give the *conventional* result (plain
averaging) that the paper compares against; the terminal's own fitted heights h (the second height
path) are averaged as well, and :func:`compare_levelling` forms the paper's Table 3.

Host side, before and after the pipeline): :func:`motion_segments` splits a ``.pos``
series into static segments and moving epochs (:class:`MotionParams`), :func:`windows_from_pos`
cuts points inside static segments only, and :func:`point_sigmas` states the precision of each
point's mean with time-correlated epochs (``sigma_method = "acf_ess_segment"``: the effective
sample size from the segment's sample autocovariance) beside eq. (19), which takes the epochs as
independent.
"""

from __future__ import annotations

import math
from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxnav.filters import LinearGaussian, kalman_filter, rts_smoother
from jaxnav.geodesy import (
    WGS84,
    Ellipsoid,
    HeightAnomalyModel,
    HelmertFit,
    Similarity2D,
    gauss_kruger,
    height_anomaly,
    similarity2d,
    zone_central_meridian,
)
from jaxnav.units import ARCSEC, CM, MM


class RtkSeries(NamedTuple):
    """Epoch series of P points padded to T epochs (S2 "Input"); SI units.

    Attributes:
      t: (P, T) epoch times, s (padding repeats the last valid time).
      lat, lon: (P, T) WGS-84 latitude and longitude, rad.  H: (P, T) ellipsoidal height, m.
      sigma: (P, T, 3) standard errors of x (north), y (east), H, m.
      mask: (P, T) bool, True for real epochs (padding and rejected epochs are False).
      h_terminal: (P, T) the terminal's own fitted (normal) height, m (NaN if unknown).
      xy_terminal: (P, T, 2) the terminal's own local plane coordinates, m (NaN if unknown).
    """

    t: jax.Array
    lat: jax.Array
    lon: jax.Array
    H: jax.Array
    sigma: jax.Array
    mask: jax.Array
    h_terminal: jax.Array
    xy_terminal: jax.Array


class InitialValues(NamedTuple):
    """S2 post-processing initial values of one point (eqs. (11)-(17)).

    Attributes:
      x0: (6,) [xi0 (3,) m, lambda0 (3,) m/s].  P0: (6, 6) diag(D_xi0, D_lambda0).
      D_omega: (3, 3) acceleration (process-noise) covariance, m^2/s^4.
      dt: mean sampling interval, s.  n: number of valid epochs.
    """

    x0: jax.Array
    P0: jax.Array
    D_omega: jax.Array
    dt: jax.Array
    n: jax.Array


class RtkResult(NamedTuple):
    """Per-point results of :func:`process_points` (P points, T epochs).

    Attributes:
      n: (P,) valid epochs.
      xyh: (P, 3) filtered result: reference-frame x, y and normal height (H + anomaly path), m.
      precision: (P, 3) its internal precision (standard error of the mean, eq. (19)), m.
      H: (P,) filtered mean ellipsoidal height, m.
      raw_xyh: (P, 3) conventional result: the same transforms on the unfiltered epochs, averaged, m.
      raw_precision: (P, 3) its internal precision from the scatter of the epochs (eq. (19)), m.
      formal_precision: (P, 3) precision of the plain mean propagated from the terminal's reported
        per-epoch standard errors, sqrt(sum sigma_i^2) / n, m (see Notes of :func:`process_points`).
      terminal_xyh: (P, 3) the terminal's own x, y and fitted height h, averaged, m (NaN if unknown).
      terminal_precision: (P, 3) its internal precision, m.
      epochs: (P, T, 3) filtered epochs in the reference frame (x, y, normal height), m.
      raw_epochs: (P, T, 3) unfiltered epochs in the reference frame, m.
      gk: (P, T, 3) the filter's measurements: WGS-84 Gauss-Krüger x, y and H, m.
      init: :class:`InitialValues` batched over points.
      n_skipped: (P,) epochs without a measurement update (padding, masked and non-finite epochs).
      n_nonfinite: (P,) epochs given as valid whose x, y, H or sigma was NaN/inf (masked, counted).
      status: (P,) filter status flags.
    """

    n: jax.Array
    xyh: jax.Array
    precision: jax.Array
    H: jax.Array
    raw_xyh: jax.Array
    raw_precision: jax.Array
    formal_precision: jax.Array
    terminal_xyh: jax.Array
    terminal_precision: jax.Array
    epochs: jax.Array
    raw_epochs: jax.Array
    gk: jax.Array
    init: InitialValues
    n_skipped: jax.Array
    n_nonfinite: jax.Array
    status: jax.Array


def initial_values(t, z, sigma, mask) -> InitialValues:
    """S2 post-processing initial values of one point, eqs. (11)-(17), over the valid epochs.

    * xi0 = mean of the n epoch positions; lambda0 = mean change between adjacent epochs per unit
      time, (z_last - z_first) / (t_last - t_first) (eqs. (11)-(12); the sum of adjacent
      differences telescopes, and dividing by the elapsed time also covers uneven sampling);
    * D_xi0 = diag(mean sigma)^2 per axis (eq. (14)); D_lambda0 = 2 dt^-2 D_xi0 (15);
      P0 = diag(D_xi0, D_lambda0) (16); D_Omega = 4 dt^-4 D_xi0 (17), dt the mean interval.

    Args:
      t: (T,) s.  z: (T, 3) positions, m.  sigma: (T, 3) standard errors, m.  mask: (T,) bool.
    Returns:
      :class:`InitialValues`.
    """
    m = mask.astype(z.dtype)
    n = jnp.sum(m)
    xi0 = jnp.sum(jnp.where(mask[:, None], z, 0.0), axis=0) / n
    first = jnp.argmax(mask)
    last = t.shape[0] - 1 - jnp.argmax(mask[::-1])
    span = t[last] - t[first]
    safe_span = jnp.where(span > 0, span, 1.0)
    lam0 = jnp.where(span > 0, (z[last] - z[first]) / safe_span, 0.0)
    dt = jnp.where(n > 1, safe_span / jnp.maximum(n - 1.0, 1.0), 1.0)
    msig = jnp.sum(jnp.where(mask[:, None], sigma, 0.0), axis=0) / n
    D_xi0 = msig**2
    D_lam0 = 2.0 * D_xi0 / dt**2
    return InitialValues(
        x0=jnp.concatenate([xi0, lam0]),
        P0=jnp.diag(jnp.concatenate([D_xi0, D_lam0])),
        D_omega=jnp.diag(4.0 * D_xi0 / dt**4),
        dt=dt,
        n=n,
    )


def cv_series_model(t, sigma, mask, D_omega, *, center_offset=False) -> LinearGaussian:
    """Time-varying constant-velocity model of one point's series (S1 eqs. (3)-(6), S2 eq. (7)).

    F_k = [[I, dt_k I], [0, I]], G_k = [[dt_k^2/2 I], [dt_k I]], dt_k = t_k - t_{k-1} (dt_0 = 0: the
    initial values refer to the first epoch), Q = D_Omega, R_k = diag(sigma_k^2). Observation
    matrix B_k = [I, c (t_k - t_c) I] with t_c the central time of the valid epochs: c = 0 (the
    default) gives B = [I 0] as in S1, c = 1 the literal S2 eq. (7).

    Args:
      t: (T,) s.  sigma: (T, 3) m.  mask: (T,) bool.  D_omega: (3, 3) m^2/s^4.
      center_offset: c above, bool or 0/1 (an array leaf: both variants share one compilation).
    Returns:
      :class:`jaxnav.filters.LinearGaussian` with (T, ...) leaves F, H, G, R.
    """
    # masked (padded, rejected) epochs hold the state; a valid epoch after masked ones spans the
    # whole gap since the previous valid epoch
    last_valid_t = jax.lax.associative_scan(jnp.maximum, jnp.where(mask, t, -jnp.inf))
    prev_valid_t = jnp.concatenate([jnp.full(1, -jnp.inf), last_valid_t[:-1]])
    dts = jnp.where(mask & jnp.isfinite(prev_valid_t), t - prev_valid_t, 0.0)
    I3 = jnp.eye(3)
    Z3 = jnp.zeros((3, 3))
    F = jax.vmap(lambda d: jnp.block([[I3, d * I3], [Z3, I3]]))(dts)
    G = jax.vmap(lambda d: jnp.concatenate([0.5 * d * d * I3, d * I3], axis=0))(dts)
    R = jax.vmap(jnp.diag)(jnp.where(mask[:, None], sigma, 1.0) ** 2)
    c = jnp.asarray(center_offset, t.dtype)
    tc = jnp.sum(jnp.where(mask, t, 0.0)) / jnp.sum(mask)
    H = jax.vmap(lambda d: jnp.concatenate([I3, c * d * I3], axis=1))(jnp.where(mask, t - tc, 0.0))
    return LinearGaussian(F=F, H=H, Q=D_omega, R=R, G=G)


def _masked_mean_precision(v, mask):
    """Mean over valid epochs and its standard error sqrt(sum (v - mean)^2 / (n (n - 1))) (S2 eqs. (18)-(19))."""
    m = mask[:, None]
    n = jnp.sum(mask)
    mean = jnp.sum(jnp.where(m, v, 0.0), axis=0) / n
    ss = jnp.sum(jnp.where(m, (v - mean) ** 2, 0.0), axis=0)
    return mean, jnp.sqrt(ss / (n * (n - 1.0)))


def _to_reference(gk, transform, anomaly):
    """WGS-84 GK (x, y, H) epochs -> reference-frame (x, y, normal height) (S2 step 3)."""
    xy = gk[..., :2]
    zeta = 0.0 if anomaly is None else height_anomaly(anomaly, xy[..., 0], xy[..., 1])
    xy_ref = xy if transform is None else similarity2d(transform, xy)
    return jnp.concatenate([xy_ref, (gk[..., 2] - zeta)[..., None]], axis=-1)


def _one_point(
    t,
    lat,
    lon,
    H,
    sigma,
    mask,
    h_term,
    xy_term,
    lon0,
    q_scale,
    *,
    transform,
    anomaly,
    ellipsoid,
    smoother,
    center_offset,
):
    x, y = gauss_kruger(lat, lon, lon0=lon0, ellipsoid=ellipsoid)
    z = jnp.stack([x, y, H], axis=-1)
    finite = jnp.all(jnp.isfinite(z), axis=-1) & jnp.all(jnp.isfinite(sigma), axis=-1)
    n_nonfinite = jnp.sum(mask & ~finite).astype(jnp.int32)
    mask = mask & finite
    # measurements relative to the first valid epoch keep the filter's numbers small
    ref = z[jnp.argmax(mask)]
    zc = jnp.where(mask[:, None], z - ref, 0.0)
    init = initial_values(t, zc, sigma, mask)
    model = cv_series_model(t, sigma, mask, q_scale * init.D_omega, center_offset=center_offset)
    res = kalman_filter(model, init.x0, init.P0, zc, mask=mask, save=("means", "covs", "pred_means", "pred_covs"))
    # both passes run (cheap at this size) so that ``smoother`` is an array leaf, not a recompilation
    means = jnp.where(smoother, rts_smoother(model, res, save=("means",)).means, res.means)
    # the position at the epoch is B_k X_k = xi + c (t - t_c) lambda (eq. (7))
    filt = jnp.einsum("tij,tj->ti", model.H, means) + ref
    ep = _to_reference(filt, transform, anomaly)
    raw = _to_reference(z, transform, anomaly)
    xyh, prec = _masked_mean_precision(ep, mask)
    raw_xyh, raw_prec = _masked_mean_precision(raw, mask)
    term = jnp.concatenate([xy_term, h_term[:, None]], axis=-1)
    term_mask = mask & jnp.all(jnp.isfinite(term), axis=-1)
    term_xyh, term_prec = _masked_mean_precision(jnp.where(term_mask[:, None], term, 0.0), term_mask)
    Hmean, _ = _masked_mean_precision(filt[:, 2:], mask)
    nan = jnp.full_like(ep, jnp.nan)
    return RtkResult(
        n=jnp.sum(mask),
        xyh=xyh,
        precision=prec,
        H=Hmean[0],
        raw_xyh=raw_xyh,
        raw_precision=raw_prec,
        formal_precision=jnp.sqrt(jnp.sum(jnp.where(mask[:, None], sigma**2, 0.0), axis=0)) / jnp.sum(mask),
        terminal_xyh=term_xyh,
        terminal_precision=term_prec,
        epochs=jnp.where(mask[:, None], ep, nan),
        raw_epochs=jnp.where(mask[:, None], raw, nan),
        gk=z,
        init=init._replace(x0=init.x0.at[:3].add(ref)),
        n_skipped=res.n_skipped,
        n_nonfinite=n_nonfinite,
        status=res.status,
    )


def _strong(tree):
    """Leaves as strongly typed arrays, so that Python scalars, weak-typed and NumPy inputs share
    one compilation of :func:`process_points`."""

    def conv(a):
        a = jnp.asarray(a)
        return jnp.array(a, dtype=a.dtype)  # an explicit dtype drops the weak type

    return jax.tree_util.tree_map(conv, tree)


def process_points(
    series: RtkSeries,
    *,
    lon0,
    transform: Similarity2D | None = None,
    anomaly: HeightAnomalyModel | None = None,
    ellipsoid: Ellipsoid = WGS84,
    smoother=False,
    center_offset=False,
    q_scale=1.0,
) -> RtkResult:
    """The S2 per-point pipeline for P points in one vmapped, jitted call (steps 1-4 of the module).

    Args:
      series: :class:`RtkSeries` with (P, T) leaves (pad with ``mask`` False).
      lon0: central meridian of the Gauss-Krüger projection, rad: scalar or (P,) per point (array leaf).
      transform: 4-parameter similarity WGS-84 GK -> reference frame (None: identity).
      anomaly: height-anomaly surface fitted in WGS-84 GK coordinates (None: zeta = 0, the result
        stays ellipsoidal).
      ellipsoid: ellipsoid of the measured (B, L, H); static.
      smoother: bool (array leaf, scalar or (P,)): False takes the forward filter of the paper, True
        the RTS pass after it (the post-processing optimum over the same model).
      center_offset: bool (array leaf, scalar or (P,)): use the literal S2 eq. (7) observation
        matrix (see :func:`cv_series_model`).
      q_scale: factor on the process noise D_Omega of eq. (17) (array leaf, scalar or (P,); 1 is
        the paper's value); a sweep over it shows how much the result depends on that choice.
    Returns:
      :class:`RtkResult` with a leading axis P (a point with fewer than 2 valid epochs has NaN
      precision; with none, NaN results).
    Raises:
      ValueError: leaves of inconsistent shapes (naming them).

    Notes:
      Internal precision. S2 evaluates the mean of the filtered epochs by eq. (19), the standard
      error sqrt(sum v^2 / (n (n - 1))) of the epochs' deviations v from their mean, and reports the
      filtered result "about 4x" more precise than the conventional one; the conventional formula
      (eq. (18)) is not legible in the source. Both candidates are returned: ``raw_precision``
      (eq. (19) on the unfiltered epochs) and ``formal_precision`` (the terminal's reported
      standard errors propagated to the mean as if independent). With S2's own initial values
      (D_Omega = 4 dt^-4 D_xi0, eq. (17)) the forward filter is far from a plain average (its
      steady gain is about 0.7), so the scatter-based factor stays near 1.1 (about 1.4 with the RTS
      pass) on the simulated survey; factors of 4 and more arise against ``formal_precision``
      when the reported sigmas are pessimistic: on the real static MatRTKLIB file, RTKLIB's sigmas
      propagated to a 2-minute mean are 6.2x (plane) and 5.6x (height) the eq. (19) precision of
      the filtered mean.
    """
    P, T = jnp.shape(series.t)
    lon0 = jnp.asarray(lon0, float)
    if lon0.shape not in ((), (P,)):
        raise ValueError(f"lon0 has shape {lon0.shape}; expected () or ({P},)")
    lon0 = jnp.broadcast_to(lon0, (P,))
    flags = [jnp.broadcast_to(jnp.asarray(f, bool), (P,)) for f in (smoother, center_offset)]
    q_scale = jnp.broadcast_to(jnp.asarray(q_scale, float), (P,))
    series, lon0, q_scale, transform, anomaly, flags = _strong((series, lon0, q_scale, transform, anomaly, flags))
    return _process_points(series, lon0, q_scale, transform, anomaly, *flags, ellipsoid=ellipsoid)


@partial(jax.jit, static_argnames=("ellipsoid",))
def _process_points(series, lon0, q_scale, transform, anomaly, smoother, center_offset, *, ellipsoid):
    P, T = jnp.shape(series.t)
    expect = dict(
        t=(P, T),
        lat=(P, T),
        lon=(P, T),
        H=(P, T),
        sigma=(P, T, 3),
        mask=(P, T),
        h_terminal=(P, T),
        xy_terminal=(P, T, 2),
    )
    bad = {k: jnp.shape(getattr(series, k)) for k, s in expect.items() if jnp.shape(getattr(series, k)) != s}
    if bad:
        raise ValueError(f"RtkSeries leaves have shapes {bad}; expected {expect}")

    def fn(*a):
        return _one_point(
            *a[:10], transform=transform, anomaly=anomaly, ellipsoid=ellipsoid, smoother=a[10], center_offset=a[11]
        )

    return jax.vmap(fn)(
        series.t,
        series.lat,
        series.lon,
        series.H,
        series.sigma,
        series.mask,
        series.h_terminal,
        series.xy_terminal,
        lon0,
        q_scale,
        smoother,
        center_offset,
    )


def pack_points(
    point, t, lat, lon, H, sigma, *, h_terminal=None, xy_terminal=None, mask=None, length: int | None = None
):
    """Group flat epoch arrays by point name (in order of appearance) into a padded :class:`RtkSeries`.

    Host side (numpy). A fixed ``length`` keeps one compiled pipeline for batches of different sizes.

    Args:
      point: (N,) names.  t: (N,) s.  lat, lon: (N,) rad.  H: (N,) m.  sigma: (N, 3) m.
      h_terminal: optional (N,) m.  xy_terminal: optional (N, 2) m.  mask: optional (N,) bool.
      length: padded length T (default: the largest epoch count).
    Returns:
      (names (P,), :class:`RtkSeries`).
    Raises:
      ValueError: inconsistent lengths, or a point with more epochs than ``length``.
    """
    point = np.asarray(point)
    N = len(point)
    arrs = dict(
        t=np.asarray(t, float),
        lat=np.asarray(lat, float),
        lon=np.asarray(lon, float),
        H=np.asarray(H, float),
        sigma=np.asarray(sigma, float),
    )
    arrs["h_terminal"] = np.full(N, np.nan) if h_terminal is None else np.asarray(h_terminal, float)
    arrs["xy_terminal"] = np.full((N, 2), np.nan) if xy_terminal is None else np.asarray(xy_terminal, float)
    arrs["mask"] = np.ones(N, bool) if mask is None else np.asarray(mask, bool)
    bad = {k: v.shape for k, v in arrs.items() if v.shape[:1] != (N,)}
    if bad or arrs["sigma"].shape != (N, 3) or arrs["xy_terminal"].shape != (N, 2):
        raise ValueError(
            f"pack_points: point has shape {point.shape}; other arrays "
            f"{ {k: v.shape for k, v in arrs.items()} } must have a leading {N} "
            "(sigma (N, 3), xy_terminal (N, 2))"
        )
    names, idx = [], {}
    for k, p in enumerate(point):
        if p not in idx:
            idx[p] = []
            names.append(p)
        idx[p].append(k)
    T = max(len(v) for v in idx.values()) if length is None else int(length)
    out = {}
    for key, a in arrs.items():
        fill = False if key == "mask" else 0.0
        b = np.full((len(names), T) + a.shape[1:], fill, dtype=a.dtype)
        for i, p in enumerate(names):
            rows = idx[p]
            if len(rows) > T:
                raise ValueError(f"pack_points: point {p!r} has {len(rows)} epochs, more than length={T}")
            b[i, : len(rows)] = a[rows]
            if key in ("t", "lat", "lon", "H") and len(rows) < T:
                b[i, len(rows) :] = a[rows[-1]]  # harmless finite padding
            if key in ("sigma",) and len(rows) < T:
                b[i, len(rows) :] = 1.0
        out[key] = b
    return np.array(names), RtkSeries(**out)


class LevellingComparison(NamedTuple):
    """Differences RTK height - levelled height over P points, in the form of S2 Table 3 (m).

    Attributes:
      diff: (P,) differences, m.  max_abs: largest |difference|.  mean: mean difference.
      std: standard deviation about the mean (n - 1).  rms: root mean square.
      thresholds: (K,) thresholds, m.  count_within: (K,) points with |difference| <= threshold.
      share_within: (K,) the same as a fraction.
    """

    diff: jax.Array
    max_abs: float
    mean: float
    std: float
    rms: float
    thresholds: jax.Array
    count_within: jax.Array
    share_within: jax.Array


def compare_levelling(h, h_level, thresholds=(0.007, 0.010, 0.015)) -> LevellingComparison:
    """Compare RTK normal heights with levelling in the form of S2 Table 3 (max, mean, std, shares).

    Args:
      h: (P,) RTK heights, m.  h_level: (P,) levelled heights, m (NaN entries are left out).
      thresholds: |difference| thresholds, m (S2: +-0.7, 1.0, 1.5 cm).
    Returns:
      :class:`LevellingComparison`.
    Raises:
      ValueError: shapes differ.
    """
    h, h_level = np.asarray(h, float), np.asarray(h_level, float)
    if h.shape != h_level.shape:
        raise ValueError(f"h has shape {h.shape} but h_level has shape {h_level.shape}")
    d = (h - h_level)[np.isfinite(h - h_level)]
    thr = np.asarray(thresholds, float)
    cnt = np.array([(np.abs(d) <= x + 1e-12).sum() for x in thr])
    return LevellingComparison(
        diff=h - h_level,
        max_abs=float(np.max(np.abs(d))),
        mean=float(np.mean(d)),
        std=float(np.std(d, ddof=1)) if d.size > 1 else float("nan"),
        rms=float(np.sqrt(np.mean(d**2))),
        thresholds=thr,
        count_within=cnt,
        share_within=cnt / max(d.size, 1),
    )


@partial(jax.jit, static_argnums=(3,))
def _gk_jit(lat, lon, lon0, ellipsoid):
    return gauss_kruger(lat, lon, lon0=lon0, ellipsoid=ellipsoid)


class ConnectionModels(NamedTuple):
    """Datum and height models of the connection survey (S2 step 3).

    Attributes:
      transform: :class:`jaxnav.geodesy.HelmertFit` of the 4-parameter similarity WGS-84 GK ->
        reference grid (None if the control points have no plane coordinates).
      anomaly: :class:`jaxnav.geodesy.HeightAnomalyModel` in WGS-84 GK coordinates (None if no
        control point has a normal height).
    """

    transform: HelmertFit | None
    anomaly: HeightAnomalyModel | None


def connection_models(
    lat, lon, H, xy, h, *, lon0, ellipsoid: Ellipsoid = WGS84, surface: str = "auto"
) -> ConnectionModels:
    """Estimate the connection survey's models from control points (S2 step 3).

    The control points' WGS-84 (B, L) are projected with the same Gauss-Krüger settings as the
    survey points; the 4-parameter similarity is fitted to their reference-grid (x, y) and the
    height-anomaly surface to zeta = H - h over their GK (x, y). Points with NaN x, y (or h)
    are left out of the respective fit.

    Args:
      lat, lon: (C,) rad.  H: (C,) ellipsoidal heights, m.  xy: (C, 2) reference grid, m (NaN allowed).
      h: (C,) normal heights, m (NaN allowed).  lon0: central meridian, rad.
      ellipsoid: of (B, L, H).  surface: ``"auto"``, ``"plane"`` or ``"quadratic"``.
    Returns:
      :class:`ConnectionModels`.
    Raises:
      ValueError: too few control points for the similarity (2) or the surface (3 or 6).
    """
    from jaxnav.geodesy import estimate_similarity2d, fit_height_anomaly

    lat, lon, H = np.asarray(lat, float), np.asarray(lon, float), np.asarray(H, float)
    xy, h = np.asarray(xy, float).reshape(-1, 2), np.asarray(h, float)
    gx, gy = (np.asarray(a) for a in _gk_jit(jnp.asarray(lat), jnp.asarray(lon), jnp.float64(lon0), ellipsoid))
    src = np.stack([gx, gy], -1)
    okp = np.all(np.isfinite(xy), axis=1)
    transform = None
    if okp.any():
        if okp.sum() < 2:
            raise ValueError(
                f"the plane similarity (4 parameters) needs at least 2 control points with x, y; got {int(okp.sum())}"
            )
        transform = estimate_similarity2d(src[okp], xy[okp])
    okh = np.isfinite(h)
    anomaly = None
    if okh.any():
        anomaly = fit_height_anomaly(gx[okh], gy[okh], H[okh] - h[okh], kind=surface)
    return ConnectionModels(transform=transform, anomaly=anomaly)


def series_from_simulation(sim) -> RtkSeries:
    """The :class:`RtkSeries` of a :class:`jaxnav.sim.RtkPointsSim` (what the terminal recorded)."""
    return RtkSeries(
        t=sim.t,
        lat=sim.lat,
        lon=sim.lon,
        H=sim.H,
        sigma=sim.sigma,
        mask=sim.mask,
        h_terminal=sim.h_terminal,
        xy_terminal=sim.xy_terminal,
    )


class MotionParams(NamedTuple):
    """Thresholds of the static/moving test of :func:`motion_segments` (host side; SI units).

    Attributes:
      v_max: an epoch is moving when the horizontal speed over the interval before or after it,
        |p_k - p_{k-1}| / (t_k - t_{k-1}), exceeds this, m/s (default 0.10: RTK-fixed noise at
        1-4 Hz stays below ~0.02 m/s, walking is ~1 m/s).
      window_s: length of the displacement test window, s (default 10).
      d_max: an epoch is moving when the horizontal displacement between the positions
        ``window_s``/2 before and after it exceeds this, m (default 0.10: catches creeping faster
        than ~1 cm/s that the speed test misses).
      max_gap_s: a gap between records longer than this ends a static segment (the antenna may
        have moved unseen), s (default 10).
      min_static_s: static runs shorter than this are not occupations and are excluded too, s
        (default 20).
    """

    v_max: float = 0.10
    window_s: float = 10.0
    d_max: float = 0.10
    max_gap_s: float = 10.0
    min_static_s: float = 20.0


class MotionSegments(NamedTuple):
    """Result of :func:`motion_segments` for N epochs.

    Attributes:
      segment: (N,) int static-segment number 0, 1, ... (-1 for excluded epochs).
      moving: (N,) bool, epochs that failed the speed or displacement test.
      short: (N,) bool, static epochs in runs shorter than ``min_static_s`` (excluded, not moving).
      speed: (N,) horizontal speed over the interval before each epoch, m/s (NaN for the first).
      n_segments: number of static segments.
    """

    segment: jax.Array
    moving: jax.Array
    short: jax.Array
    speed: jax.Array
    n_segments: int


def motion_segments(t, lat, lon, params: MotionParams = MotionParams()) -> MotionSegments:
    """Split a position series into static segments and moving epochs (host side, numpy).

    Horizontal positions relative to the first epoch on a sphere of radius 6 371 km (distances to
    < 0.5 %, enough for thresholds). An epoch is *moving* when (a) the speed over the interval
    before or after it exceeds ``v_max``, or (b) the positions ``window_s``/2 before and after it
    (nearest records) are more than ``d_max`` apart. The remaining epochs form static runs, cut at
    gaps longer than ``max_gap_s``; runs shorter than ``min_static_s`` are flagged ``short``.

    Args:
      t: (N,) increasing times, s.  lat, lon: (N,) rad.  params: :class:`MotionParams`.
    Returns:
      :class:`MotionSegments`.
    Raises:
      ValueError: arrays of different shapes or fewer than 1 epoch.
    """
    t, lat, lon = (np.asarray(a, float) for a in (t, lat, lon))
    if not (t.ndim == 1 and t.shape == lat.shape == lon.shape and t.size >= 1):
        raise ValueError(
            f"motion_segments: t, lat, lon must be (N,) arrays of one shape, N >= 1; got "
            f"{t.shape}, {lat.shape}, {lon.shape}"
        )
    R = 6.371e6
    e = (lon - lon[0]) * R * np.cos(lat[0])
    n = (lat - lat[0]) * R
    N = t.size
    dt = np.diff(t)
    step = np.hypot(np.diff(e), np.diff(n))
    speed = np.concatenate([[np.nan], step / np.where(dt > 0, dt, np.nan)])
    fast = speed > params.v_max
    moving = fast.copy()
    moving[:-1] |= fast[1:]
    lo = np.clip(np.searchsorted(t, t - params.window_s / 2.0), 0, N - 1)
    hi = np.clip(np.searchsorted(t, t + params.window_s / 2.0, side="right") - 1, 0, N - 1)
    moving |= np.hypot(e[hi] - e[lo], n[hi] - n[lo]) > params.d_max
    # static runs: consecutive static epochs without a long gap
    brk = np.concatenate([[True], moving[1:] | moving[:-1] | (dt > params.max_gap_s)])
    run = np.cumsum(brk) - 1
    segment = np.full(N, -1)
    short = np.zeros(N, bool)
    k = 0
    for r in np.unique(run[~moving]):
        idx = np.flatnonzero((run == r) & ~moving)
        if t[idx[-1]] - t[idx[0]] < params.min_static_s:
            short[idx] = True
        else:
            segment[idx] = k
            k += 1
    return MotionSegments(segment=segment, moving=moving, short=short, speed=speed, n_segments=k)


def windows_from_pos(
    sol,
    *,
    step: float = 2.0,
    window: int = 60,
    min_epochs: int = 30,
    fixed_only: bool = True,
    name: str | None = None,
    motion: MotionParams | None = MotionParams(),
):
    """Cut an RTKLIB solution into S2-style point occupations, static epochs only (host side).

    First the series is split by :func:`motion_segments` (skipped with ``motion=None``): moving
    epochs and too-short static runs are excluded and counted. Within each static segment the
    epochs are thinned to one every ``step`` seconds (S2 samples at 2 s; the grid is counted from
    the file's first epoch) and cut into consecutive windows of ``window`` epochs (60 epochs at
    2 s = the paper's 2 min); windows never span two segments, and windows with fewer than
    ``min_epochs`` epochs are dropped. Each window becomes one "point" named ``name#k``.
    Non-fixed epochs (Q != 1) are masked when ``fixed_only``.

    Args:
      sol: :class:`jaxnav.io.PosSolution`.
      step: thinning interval, s.  window: epochs per occupation.  min_epochs: shortest kept window.
      fixed_only: mask epochs that are not ambiguity-fixed.  name: point name stem (default: file stem).
      motion: :class:`MotionParams` of the static/moving test, or None to treat the whole file as static.
    Returns:
      dict of flat arrays ``point, t, lat, lon, H, sigma (north, east, up), mask, segment, grid``
      (``segment``: the static segment of the epoch, as ``name/s<k>``; ``grid``: the epoch's index
      on the ``step`` grid) for :func:`pack_points`, and the counts ``n_epochs`` (in the file),
      ``n_moving``, ``n_short_static`` (excluded) and ``n_segments``.
    Raises:
      ValueError: if no window has ``min_epochs`` epochs.
    """
    import pathlib

    stem = name or pathlib.Path(sol.path).stem
    t = np.asarray(sol.t)
    if motion is None:
        seg = MotionSegments(
            segment=np.zeros(len(t), int),
            moving=np.zeros(len(t), bool),
            short=np.zeros(len(t), bool),
            speed=np.full(len(t), np.nan),
            n_segments=1,
        )
    else:
        seg = motion_segments(t, sol.lat, sol.lon, motion)
    rel = t - t[0]
    grid = np.round(rel / step).astype(np.int64)
    keep = np.abs(rel / step - grid) < 1e-3
    sig = np.sqrt(np.stack([sol.cov_enu[:, 1, 1], sol.cov_enu[:, 0, 0], sol.cov_enu[:, 2, 2]], -1))
    out = {k: [] for k in ("point", "t", "lat", "lon", "H", "sigma", "mask", "segment", "grid")}
    k = 0
    for s in range(seg.n_segments):
        idx = np.flatnonzero(keep & (seg.segment == s))
        for start in range(0, len(idx), window):
            sel = idx[start : start + window]
            if len(sel) < min_epochs:
                continue
            k += 1
            out["point"] += [f"{stem}#{k}"] * len(sel)
            out["segment"] += [f"{stem}/s{s + 1}"] * len(sel)
            out["grid"].append(grid[sel])
            out["t"].append(t[sel])
            out["lat"].append(np.asarray(sol.lat)[sel])
            out["lon"].append(np.asarray(sol.lon)[sel])
            out["H"].append(np.asarray(sol.h)[sel])
            out["sigma"].append(sig[sel])
            out["mask"].append((np.asarray(sol.q)[sel] == 1) if fixed_only else np.ones(len(sel), bool))
    if not out["t"]:
        raise ValueError(
            f"{sol.path}: no window of {min_epochs} epochs at {step} s in a static segment (file has "
            f"{len(t)} epochs, {int(seg.moving.sum())} moving, {seg.n_segments} static segment(s))"
        )
    res = {k: (np.array(v) if k in ("point", "segment") else np.concatenate(v)) for k, v in out.items()}
    res.update(
        n_epochs=int(len(t)),
        n_moving=int(seg.moving.sum()),
        n_short_static=int(seg.short.sum()),
        n_segments=int(seg.n_segments),
    )
    return res


def sampling_grid(t, mask, names, point, grid) -> np.ndarray:
    """(P, T) sampling-grid index of each packed epoch (the ``grid`` of :func:`point_sigmas`).

    A point's epoch indices are those given per epoch (``.pos`` occupations cut from one static
    segment, :func:`windows_from_pos`), padded with the last; where they are -1 (an epoch log) they
    are round((t - t_0) / dt) with dt the median step of the point's valid epochs (1 s if none).

    Args:
      t: (P, T) packed epoch times, s.  mask: (P, T) bool valid epochs (:func:`pack_points`).
      names: (P,) point names in packed order.  point: (N,) point name of each input epoch.
      grid: (N,) int grid index of each input epoch, or -1 (to be derived).
    """
    t, mask, point, grid = np.asarray(t, float), np.asarray(mask, bool), np.asarray(point), np.asarray(grid)
    out = np.full(t.shape, -1, np.int64)
    for p, name in enumerate(names):
        g = grid[point == name]
        out[p, : len(g)] = g
        out[p, len(g) :] = g[-1] if len(g) else -1
        if out[p, 0] >= 0:
            continue
        tv = t[p][mask[p]]
        dt = float(np.median(np.diff(tv))) if tv.size > 1 else 1.0
        dt = dt if dt > 0 else 1.0
        out[p] = np.round((t[p] - (tv[0] if tv.size else t[p, 0])) / dt).astype(np.int64)
    return out


class PointSigmas(NamedTuple):
    """Precision of P point means under time-correlated epoch errors (:func:`point_sigmas`).

    Attributes:
      sigma: (P, 3) standard deviation of each point's mean (x north, y east, H), m, from the
        autocovariance of its static segment (``method``); NaN for a point with fewer than 2 valid
        epochs or a component without any scatter in its segment.
      sigma_naive: (P, 3) the same with the epochs taken as independent, s / sqrt(n), s the
        scatter of the point's own epochs (S2 eq. (19)), m.
      n_eff: (P, 3) effective number of independent epochs, gamma(0) / sigma^2.
      lag1: (P, 3) lag-1 autocorrelation (one grid step) of the segment.
      segment_epochs: (P,) valid epochs of the segment the autocovariance was estimated from.
      segment_points: (P,) points cut from that segment.
      method: name of the method (``sigma_method`` in the outputs).
    """

    sigma: jax.Array
    sigma_naive: jax.Array
    n_eff: jax.Array
    lag1: jax.Array
    segment_epochs: jax.Array
    segment_points: jax.Array
    method: str


@partial(jax.jit, static_argnames=("max_lag",))
def _segment_variances(series, have, idx, w, max_lag):
    """Autocovariances (3, max_lag + 1) of a segment's (N, 3) series and the variances (Pk, 3) of its points' means."""
    from jaxnav.survey._ar import autocovariance_masked, mean_variance_from_acov

    gam = jax.vmap(lambda x: autocovariance_masked(x, have, max_lag))(series.T)
    v = jax.vmap(lambda gm: jax.vmap(lambda k, wk: mean_variance_from_acov(gm, k, wk))(idx, w))(gam)
    return gam, v.T


#: name of the precision method of :func:`point_sigmas` (written as ``sigma_method``)
SIGMA_METHOD = "acf_ess_segment"


def point_sigmas(z, mask, grid, segment) -> PointSigmas:
    """Precision of each point's mean with time-correlated epochs (effective sample size).

    For each static segment (one antenna set-up: all points cut from it share its error process)
    the epochs of its points are laid on their common sampling grid, and per component the sample
    autocovariance gamma(k) of the segment is estimated (:func:`jaxnav.survey.autocovariance_masked`,
    mean of the segment removed). The variance of a point's plain mean over its n valid epochs at
    grid indices k_i is then (:func:`jaxnav.survey.mean_variance_from_acov`)

        sigma^2 = 1/n^2 sum_i sum_j gamma(|k_i - k_j|),

    floored at gamma(0)/n (never better than independent epochs). With n consecutive epochs this
    is gamma(0)/n [1 + 2 sum_k (1 - k/n) rho_k], the effective-sample-size correction. It describes
    the scatter of point means about the segment's long-run mean: error processes slower than the
    segment (and a point that is a segment of its own only sees correlation shorter than itself)
    are not in it, and neither are errors common to the whole session (base coordinates, datum).

    Args:
      z: (P, T, 3) epoch coordinates of the points (e.g. ``RtkResult.gk``), m.
      mask: (P, T) bool valid epochs.  grid: (P, T) int sampling-grid index of each epoch.
      segment: (P,) segment label of each point (points with equal labels share a segment).
    Returns:
      :class:`PointSigmas`.
    Raises:
      ValueError: inconsistent shapes.
    """
    z, mask, grid = np.asarray(z, float), np.asarray(mask, bool), np.asarray(grid, np.int64)
    segment = np.asarray(segment)
    P, T = mask.shape
    if z.shape != (P, T, 3) or grid.shape != (P, T) or segment.shape != (P,):
        raise ValueError(
            f"point_sigmas: z {z.shape}, mask {mask.shape}, grid {grid.shape}, segment "
            f"{segment.shape}; expected (P, T, 3), (P, T), (P, T), (P,)"
        )
    mask = mask & np.all(np.isfinite(z), axis=-1)
    sigma = np.full((P, 3), np.nan)
    naive = np.full((P, 3), np.nan)
    n_eff = np.full((P, 3), np.nan)
    lag1 = np.full((P, 3), np.nan)
    seg_n = np.zeros(P, int)
    seg_p = np.zeros(P, int)
    for lab in dict.fromkeys(segment.tolist()):
        pts = np.flatnonzero(segment == lab)
        valid = mask[pts]
        if not valid.any():
            continue
        g = grid[pts][valid]
        g0 = g.min()
        N = int(g.max() - g0 + 1)
        series = np.zeros((N, 3))
        have = np.zeros(N, bool)
        series[g - g0] = z[pts][valid]
        have[g - g0] = True
        spans = [int(np.ptp(grid[p][mask[p]])) if mask[p].any() else 0 for p in pts]
        # shapes bucketed (multiples of 32 / powers of 2) so that segments share compilations
        max_lag = int(-(-max(1, max(spans)) // 32) * 32)
        Npad = int(-(-max(N, max_lag + 1) // 128) * 128)
        Pk = len(pts)
        Ppad = 1 << (Pk - 1).bit_length()
        series_p = np.zeros((Npad, 3))
        series_p[:N] = series
        have_p = np.zeros(Npad, bool)
        have_p[:N] = have
        n = mask[pts].sum(1)  # (Pk,)
        w = np.zeros((Ppad, T))
        w[:Pk] = mask[pts] / np.maximum(n, 1)[:, None]
        idx = np.zeros((Ppad, T), np.int64)
        idx[:Pk] = grid[pts] - g0
        gam, v = (
            np.asarray(a)
            for a in _segment_variances(
                jnp.asarray(series_p), jnp.asarray(have_p), jnp.asarray(idx), jnp.asarray(w), max_lag
            )
        )
        v = v[:Pk]
        g0v = gam[:, 0][None, :]
        v = np.maximum(v, g0v / np.maximum(n, 1)[:, None])
        ok = (n > 1)[:, None] & (g0v > 0)
        sigma[pts] = np.where(ok, np.sqrt(np.where(ok, v, 1.0)), np.nan)
        n_eff[pts] = np.where(ok, g0v / np.where(ok, v, 1.0), np.nan)
        pos = gam[:, 0] > 0
        lag1[pts] = (
            np.where(pos, gam[:, 1] / np.where(pos, gam[:, 0], 1.0), np.nan) if gam.shape[1] > 1 else np.full(3, np.nan)
        )[None, :]
        seg_n[pts], seg_p[pts] = int(have.sum()), len(pts)
        for p, k in zip(pts, n):
            if k > 1:
                naive[p] = np.std(z[p][mask[p]], axis=0, ddof=1) / math.sqrt(k)
    return PointSigmas(
        sigma=sigma,
        sigma_naive=naive,
        n_eff=n_eff,
        lag1=lag1,
        segment_epochs=seg_n,
        segment_points=seg_p,
        method=SIGMA_METHOD,
    )


def central_meridians(series: RtkSeries, zone_width: int = 3) -> np.ndarray:
    """Central meridian of the Gauss-Krüger zone of each point's mean longitude.

    Args:
      series: :class:`RtkSeries` of P points (longitudes of the valid epochs averaged).
      zone_width: zone width, deg (3 or 6).
    Returns:
      (P,) central meridians, rad.
    """
    lon, mask = np.asarray(series.lon, float), np.asarray(series.mask, bool)
    lon_pt = np.array([np.nanmean(np.where(m, lo, np.nan)) for lo, m in zip(lon, mask)])
    return np.asarray(zone_central_meridian(jnp.asarray(lon_pt), zone_width)[0])


def unusable_epochs(mask, lat, lon, H, sigma) -> int:
    """Number of epochs the filter cannot use: masked, or with a non-finite position or standard error.

    Args:
      mask: (N,) bool valid epochs.  lat, lon: (N,) rad.  H: (N,) m.  sigma: (N, 3) m.
    """
    bad = ~np.asarray(mask, bool) | ~np.all(np.isfinite(np.asarray(sigma, float)), axis=1)
    for a in (lat, lon, H):
        bad = bad | ~np.isfinite(np.asarray(a, float))
    return int(np.sum(bad))


def _ratio(a: float, b: float) -> float:
    """a / b, NaN where b is 0 or either is not finite (identical epochs give a zero precision)."""
    return a / b if math.isfinite(a) and math.isfinite(b) and b != 0.0 else float("nan")


def connection_summary(con: ConnectionModels) -> dict:
    """The connection survey's fitted models (S2 step 3) as JSON-ready numbers in the units their keys name.

    Args:
      con: :class:`ConnectionModels` (:func:`connection_models`).
    Returns:
      dict with ``datum_transformation`` (4-parameter similarity: ``tx``, ``ty`` m, ``theta_arcsec``,
      ``m_ppm``, ``sigma0_mm``, ``residual_rms_mm`` (x, y), ``n_control``) where a transformation was
      fitted, and ``height_anomaly`` (``surface``, ``sigma0_mm``, ``n_control``, ``residuals_mm`` (C,))
      where a surface was fitted.
    """
    out = {}
    if con.transform is not None:
        tp = con.transform
        out["datum_transformation"] = dict(
            model="4-parameter plane similarity (x' = t + (1+m) R(theta) x)",
            tx=float(tp.params.t[0]),
            ty=float(tp.params.t[1]),
            theta_arcsec=float(tp.params.theta) / ARCSEC,
            m_ppm=float(tp.params.m) * 1e6,
            sigma0_mm=float(tp.sigma0) / MM,
            residual_rms_mm=[float(v) / MM for v in tp.rms],
            n_control=int(tp.residuals.shape[0]),
        )
    if con.anomaly is not None:
        an = con.anomaly
        out["height_anomaly"] = dict(
            surface=an.kind,
            sigma0_mm=float(an.sigma0) / MM,
            n_control=int(an.residuals.shape[0]),
            residuals_mm=[float(v) / MM for v in an.residuals],
        )
    return out


def precision_summary(res: RtkResult) -> dict:
    """Mean internal precision of the point means over P points (S2 eq. (19)), plane and height, mm.

    Args:
      res: :class:`RtkResult` (``precision``, ``raw_precision``, ``formal_precision``: (P, 3) m).
    Returns:
      {"filtered" | "conventional" | "formal": {"plane_mm", "height_mm"}} (NaN points left out;
      plane: sqrt(x^2 + y^2) per point) and ``factor_conventional_over_filtered``,
      ``factor_formal_over_filtered``: {"plane", "height"} ratios (NaN where the filtered one is 0).
    """
    out = {}
    for key, p in (("filtered", res.precision), ("conventional", res.raw_precision), ("formal", res.formal_precision)):
        p = np.asarray(p, float)
        out[key] = dict(
            plane_mm=float(np.nanmean(np.hypot(p[:, 0], p[:, 1]))) / MM, height_mm=float(np.nanmean(p[:, 2])) / MM
        )
    for key in ("conventional", "formal"):
        out[f"factor_{key}_over_filtered"] = dict(
            plane=_ratio(out[key]["plane_mm"], out["filtered"]["plane_mm"]),
            height=_ratio(out[key]["height_mm"], out["filtered"]["height_mm"]),
        )
    return out


def levelling_summary(res: RtkResult, h_level, thresholds=None) -> dict:
    """S2 Table 3 for each height path of the results: :func:`compare_levelling` in cm.

    Args:
      res: :class:`RtkResult` of P points; its filtered (``xyh``), terminal (``terminal_xyh``) and
        conventional (``raw_xyh``) heights are compared, m.
      h_level: (P,) levelled heights, m (NaN: not levelled).
      thresholds: |difference| thresholds, m (None: those of :func:`compare_levelling`, S2's 0.7, 1.0, 1.5 cm).
    Returns:
      {"filtered" | "conventional_terminal" | "conventional_H_anomaly": {``max_abs_cm``,
      ``mean_cm``, ``std_cm``, ``rms_cm``, ``thresholds_cm``, ``count_within``, ``share_within``}},
      only the paths with at least one point that has both heights.
    """
    h_level = np.asarray(h_level, float)
    out = {}
    for key, h in (
        ("filtered", res.xyh[:, 2]),
        ("conventional_terminal", res.terminal_xyh[:, 2]),
        ("conventional_H_anomaly", res.raw_xyh[:, 2]),
    ):
        h = np.asarray(h, float)
        if np.any(np.isfinite(h - h_level)):
            c = compare_levelling(h, h_level) if thresholds is None else compare_levelling(h, h_level, thresholds)
            out[key] = dict(
                max_abs_cm=c.max_abs / CM,
                mean_cm=c.mean / CM,
                std_cm=c.std / CM,
                rms_cm=c.rms / CM,
                thresholds_cm=[float(v) / CM for v in c.thresholds],
                count_within=[int(v) for v in c.count_within],
                share_within=[float(v) for v in c.share_within],
            )
    return out


def point_records(names, res: RtkResult, sigmas: PointSigmas, t, mask, segment) -> list[dict]:
    """One JSON-ready record per point: coordinates, precisions (m and mm as the keys name) and its epochs.

    Args:
      names: (P,) point names.  res: :class:`RtkResult`.  sigmas: :class:`PointSigmas` of the points.
      t: (P, T) epoch times, s.  mask: (P, T) bool valid epochs.  segment: (P,) static-segment label.
    Returns:
      list of P dicts: ``name``, ``n_epochs``, ``t_start``, ``t_end`` (first and last valid epoch, s;
      None without one), ``x_m``, ``y_m``, ``h_m``, ``sigma_{x,y,h}_m``, ``sigma_method``,
      ``sigma_naive_{x,y,h}_m``, ``n_eff`` and ``lag1_autocorrelation`` (x, y, h), ``segment``,
      ``segment_epochs``, ``segment_points``, ``precision_mm``, ``raw_precision_mm``,
      ``formal_precision_mm`` (x, y, h; S2 eq. (19)).
    """
    t, mask = np.asarray(t, float), np.asarray(mask, bool)
    ps = sigmas
    mm = lambda a: [float(v) / MM for v in a]
    out = []
    for i, n in enumerate(names):
        tv = t[i][mask[i]]
        out.append(
            dict(
                name=str(n),
                n_epochs=int(res.n[i]),
                t_start=float(tv[0]) if tv.size else None,
                t_end=float(tv[-1]) if tv.size else None,
                x_m=float(res.xyh[i, 0]),
                y_m=float(res.xyh[i, 1]),
                h_m=float(res.xyh[i, 2]),
                sigma_x_m=float(ps.sigma[i, 0]),
                sigma_y_m=float(ps.sigma[i, 1]),
                sigma_h_m=float(ps.sigma[i, 2]),
                sigma_method=ps.method,
                sigma_naive_x_m=float(ps.sigma_naive[i, 0]),
                sigma_naive_y_m=float(ps.sigma_naive[i, 1]),
                sigma_naive_h_m=float(ps.sigma_naive[i, 2]),
                n_eff=[float(v) for v in ps.n_eff[i]],
                lag1_autocorrelation=[float(v) for v in ps.lag1[i]],
                segment=str(segment[i]),
                segment_epochs=int(ps.segment_epochs[i]),
                segment_points=int(ps.segment_points[i]),
                precision_mm=mm(res.precision[i]),
                raw_precision_mm=mm(res.raw_precision[i]),
                formal_precision_mm=mm(res.formal_precision[i]),
            )
        )
    return out


def sigma_summary(sigmas: PointSigmas) -> dict:
    """RMS over points of the point-mean precisions with correlated and with independent epochs, mm.

    Args:
      sigmas: :class:`PointSigmas` of P points (points with a NaN in either left out).
    Returns:
      {"corrected": (3,) list or None, "naive": (3,) list or None, "components": ["x", "y", "h"]}.
    """
    s, sn = np.asarray(sigmas.sigma, float), np.asarray(sigmas.sigma_naive, float)
    ok = np.all(np.isfinite(s), axis=1) & np.all(np.isfinite(sn), axis=1)
    rms = lambda a: [float(v) / MM for v in np.sqrt(np.mean(a[ok] ** 2, axis=0))] if ok.any() else None
    return dict(corrected=rms(s), naive=rms(sn), components=["x", "y", "h"])
