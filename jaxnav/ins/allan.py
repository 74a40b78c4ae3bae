"""Overlapping Allan deviation in JAX (batched over leading axes, one jit compilation per data shape), and
the identification of IMU noise from it (white noise, bias instability, rate random walk).

For rate samples y_k (interval means over dt) the "phase" is x_0 = 0, x_k = dt sum_{i<k} y_i
(for IMU data: the running sum of increments). For an averaging time tau = m dt,

    AVAR(tau) = sum_{i=0}^{N-2m} (x_{i+2m} - 2 x_{i+m} + x_i)^2 / (2 tau^2 (N - 2m + 1)),

the fully overlapping estimator (IEEE Std 952 / allantools ``oadev`` with ``data_type="freq"``).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxnav import units
from jaxnav._numerics import check_float64


@jax.jit
def _oavar(x, dt, ms):
    """AVAR at each averaging factor of the int array ``ms`` (one compilation per shape of x and ms)."""
    n1 = x.shape[-1]
    i = jnp.arange(n1)

    def one(m):
        d = x[..., jnp.minimum(i + 2 * m, n1 - 1)] - 2.0 * x[..., jnp.minimum(i + m, n1 - 1)] + x
        valid = i + 2 * m <= n1 - 1
        tau = m * dt
        return jnp.sum(jnp.where(valid, d * d, 0.0), axis=-1) / (n1 - 2 * m) / (2.0 * tau * tau)

    return jnp.moveaxis(jax.lax.map(one, ms), 0, -1)


def octave_ms(n: int, max_fraction: float = 0.5):
    """Averaging factors 1, 2, 4, ... with 2m <= max_fraction * 2 * n (at least 2 clusters)."""
    ms, m = [], 1
    while 2 * m <= int(2 * max_fraction * n) and 2 * m <= n:
        ms.append(m)
        m *= 2
    return tuple(ms)


def allan_variance(y, dt, ms=None, *, kind: str = "rate"):
    """Overlapping Allan variance of a rate series.

    Args:
      y: (..., N) samples along the last axis: interval-mean rates (kind="rate") or increments
        (kind="increment", divided by dt first).
      dt: sample interval, s.
      ms: averaging factors (ints, tau = m dt); default octaves 1, 2, 4, ... up to N/2.
      kind: "rate" or "increment".
    Returns:
      (taus (k,) s as numpy, avar (..., k)) in the rate unit squared.
    """
    if kind not in ("rate", "increment"):
        raise ValueError(f"kind must be 'rate' or 'increment', got {kind!r}")
    y = jnp.asarray(y)
    n = y.shape[-1]
    ms = octave_ms(n) if ms is None else tuple(int(m) for m in ms)
    for m in ms:
        if m < 1 or 2 * m > n:
            raise ValueError(f"averaging factor m={m} needs 1 <= m <= N/2 = {n // 2}")
    inc = y if kind == "increment" else y * dt
    x = jnp.concatenate([jnp.zeros(y.shape[:-1] + (1,), y.dtype), jnp.cumsum(inc, axis=-1)], axis=-1)
    return np.asarray(ms, float) * float(dt), _oavar(x, dt, jnp.asarray(ms, dtype=int))


def allan_deviation(y, dt, ms=None, *, kind: str = "rate"):
    """Overlapping Allan deviation; see :func:`allan_variance` (returns (taus, adev))."""
    taus, av = allan_variance(y, dt, ms, kind=kind)
    return taus, jnp.sqrt(av)


# ----------------------------------------------------------------------------- noise identification
#
# The Allan variance of a sum of independent noises is the sum of theirs (IEEE Std 952-1997,
# Annex C; El-Sheimy, Hou, Niu, "Analysis and modeling of inertial sensors using Allan variance",
# IEEE Trans. Instrum. Meas. 57(1), 2008, Table I). For a rate (gyro rad/s, accelerometer m/s^2):
#
#     AVAR(tau) = N^2 / tau  +  (2 ln 2 / pi) B^2  +  K^2 tau / 3
#
# white noise N (angle / velocity random walk; slope -1/2 of the deviation, read at tau = 1 s),
# bias instability B (flicker, the flat floor 0.664 B) and rate random walk K (slope +1/2, read at
# tau = 3 s). The model is linear in (N^2, B^2, K^2): a weighted least squares over the taus.

#: Allan variance of flicker rate noise per B^2 (the deviation floor is sqrt of it = 0.664 B)
FLICKER_AVAR = 2.0 * math.log(2.0) / math.pi


def gauss_markov_avar(tau, sigma, T):
    """Allan variance of a first-order Gauss-Markov rate of steady sigma and correlation time T.

    AVAR(tau) = sigma^2 (T/tau)^2 (2 tau/T - 3 + 4 exp(-tau/T) - exp(-2 tau/T)) (the continuous-time
    limit of :func:`jaxnav.sim.allan_variance_theory`'s AR(1) term; a rate random walk 2 sigma^2 tau /
    (3 T) for tau << T, white noise 2 sigma^2 T / tau for tau >> T).

    Args:
      tau: averaging times, s (array).  sigma: rate unit.  T: s.
    Returns:
      AVAR, rate unit squared, shaped like ``tau``.
    """
    x = np.asarray(tau, float) / float(T)
    return float(sigma) ** 2 / x**2 * (2.0 * x - 3.0 + 4.0 * np.exp(-x) - np.exp(-2.0 * x))


def _gm_peak():
    x = np.exp(np.linspace(np.log(0.5), np.log(5.0), 20001))
    a = gauss_markov_avar(x, 1.0, 1.0)
    i = int(np.argmax(a))
    return float(x[i]), float(np.sqrt(a[i]))


#: a Gauss-Markov rate of sigma s and time T has its largest Allan deviation GM_PEAK_ADEV * s
#: (0.6174) at tau = GM_PEAK_TAU * T (1.893)
GM_PEAK_TAU, GM_PEAK_ADEV = _gm_peak()


def allan_model(taus, white=0.0, bias_instability=0.0, rate_rw=0.0):
    """The model sum N^2/tau + (2 ln 2/pi) B^2 + K^2 tau/3 (module section above).

    Args:
      taus: (k,) s.  white: N (rate unit * sqrt(s)).  bias_instability: B (rate unit).
      rate_rw: K (rate unit / sqrt(s)); each a scalar or (...,) batch.
    Returns:
      (..., k) Allan variance, rate unit squared.
    """
    t = np.asarray(taus, float)
    n, b, k = (np.asarray(v, float)[..., None] for v in (white, bias_instability, rate_rw))
    return n**2 / t + FLICKER_AVAR * b**2 + k**2 * t / 3.0


def allan_variance_sigma(avar, m, n):
    """Approximate 1-sigma of an Allan variance estimate from K = floor(n/m) clusters.

    The deviation's relative error is 1 / sqrt(2 (K - 1)) (IEEE Std 952-1997, Annex C.2; El-Sheimy
    et al. 2008, eq. 12), so the variance's is sqrt(2 / (K - 1)). For the overlapping estimator this
    is on the safe side (it has more degrees of freedom than K - 1).

    Args:
      avar: (..., k) Allan variance.  m: (k,) averaging factors.  n: samples.
    Returns:
      (..., k) standard deviations (same unit as ``avar``); inf where K < 2.
    """
    K = np.floor(n / np.asarray(m, float))
    with np.errstate(divide="ignore"):
        rel = np.where(K >= 2, np.sqrt(2.0 / np.maximum(K - 1.0, 1e-300)), np.inf)
    return np.asarray(avar, float) * rel


def _wls_one(taus, av, K):
    """Fit (N^2, B^2, K^2) >= 0 to one axis: weights from the model's own estimator variance (three
    reweighting passes), terms that come out negative dropped; returns (theta, cov, unconstrained
    theta and its sigma for dropped terms, chi2/dof)."""
    A = np.column_stack([1.0 / taus, np.full(taus.size, FLICKER_AVAR), taus / 3.0])
    rel2 = 2.0 / np.maximum(K - 1.0, 1.0)
    active = np.ones(3, bool)
    model = av.copy()
    theta = np.zeros(3)
    cov = np.zeros((3, 3))
    free_theta, free_sd = np.zeros(3), np.zeros(3)
    for _ in range(3):
        w = 1.0 / (rel2 * np.maximum(model, 1e-300) ** 2)
        active = np.ones(3, bool)
        while True:
            Aw = A[:, active] * np.sqrt(w)[:, None]
            M = Aw.T @ Aw
            Ci = np.linalg.pinv(M)
            th = Ci @ (Aw.T @ (av * np.sqrt(w)))
            if np.all(th >= 0) or active.sum() == 1:
                break
            # record the dropped term's unconstrained value and sigma (for an upper bound), then drop it
            j = np.flatnonzero(active)[int(np.argmin(th))]
            free_theta[j] = th[int(np.argmin(th))]
            free_sd[j] = math.sqrt(max(Ci[int(np.argmin(th)), int(np.argmin(th))], 0.0))
            active[j] = False
        theta = np.zeros(3)
        theta[active] = np.maximum(th, 0.0)
        cov = np.zeros((3, 3))
        cov[np.ix_(active, active)] = Ci
        model = np.maximum(A @ theta, 1e-300)
    r = (av - model) * np.sqrt(w)
    dof = max(taus.size - int(active.sum()), 1)
    chi2 = float(r @ r) / dof
    return theta, cov * max(1.0, chi2), active, free_theta, free_sd * math.sqrt(max(1.0, chi2)), chi2, r


class AllanFit(NamedTuple):
    """Allan deviation of one sensor's axes and the fitted noise terms (rate unit: rad/s or m/s^2).

    Attributes:
      taus: (k,) averaging times, s.  ms: (k,) averaging factors (tau = m dt).
      avar: (..., k) overlapping Allan variance.  avar_sigma: (..., k) its 1-sigma
        (:func:`allan_variance_sigma`).  fitted: (k,) bool, the taus used in the fit.
      white: (...) N, rate unit sqrt(s) (rad/sqrt(s) = angle random walk; m/s/sqrt(s) = velocity random walk).
      bias_instability: (...) B, rate unit (the flicker coefficient; deviation floor 0.664 B).
      rate_rw: (...) K, rate unit / sqrt(s) (rate random walk).
      white_sigma, bias_instability_sigma, rate_rw_sigma: (...) their approximate 1-sigma (for a term not resolved,
        i.e. fitted as zero, the sigma of the unconstrained fit).
      resolved: (..., 3) bool, whether N, B, K came out positive and above twice their sigma.
      upper: (..., 3) for each term its 2-sigma upper bound (value + 2 sigma).
      tau_floor: (...) s, the minimum of the fitted model (sqrt(3) N / K; the longest fitted tau if K
        is not resolved).
      chi2: (...) the fit's chi-square per degree of freedom (near 1 when the three terms explain
        the curve; much larger: other noise, e.g. quantization or an anti-alias filter at short tau).
      dt: sample interval, s.  n: samples.
    """

    taus: np.ndarray
    ms: np.ndarray
    avar: np.ndarray
    avar_sigma: np.ndarray
    fitted: np.ndarray
    white: np.ndarray
    bias_instability: np.ndarray
    rate_rw: np.ndarray
    white_sigma: np.ndarray
    bias_instability_sigma: np.ndarray
    rate_rw_sigma: np.ndarray
    resolved: np.ndarray
    upper: np.ndarray
    tau_floor: np.ndarray
    chi2: np.ndarray
    dt: float
    n: int


#: the largest chi-square per degree of freedom accepted before the shortest taus are dropped
CHI2_TRIM = 3.0


def _fit_axis(taus, av, K):
    """One axis: the WLS fit and what :class:`AllanFit` reports of it (values, sigmas, bounds, floor)."""
    th, cov, act, fth, fsd, chi2, _ = _wls_one(taus, av, K)
    p = np.sqrt(th)  # theta = (N^2, B^2, K^2): the design columns carry the model's constants
    sd_th = np.sqrt(np.maximum(np.diag(cov), 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        sd = np.where(act & (p > 0), sd_th / (2.0 * np.where(p > 0, p, 1.0)), np.sqrt(fsd))
    up = np.where(act & (p > 0), p + 2.0 * sd, np.sqrt(np.maximum(fth, 0.0) + 2.0 * fsd))
    res = act & (p > 2.0 * sd)  # resolved: positive and at least twice its sigma
    up = np.where(res, up, np.maximum(up, p + 2.0 * sd))
    floor = math.sqrt(3.0) * p[0] / p[2] if p[2] > 0 and p[0] > 0 else taus[-1] if p[2] <= 0 else taus[0]
    return {"theta": p, "sd": sd, "res": res, "up": up, "chi2": chi2, "floor": floor}


def _trim_short(taus, flat, K, fitted):
    """Drop the shortest tau while the three terms do not explain the curve there (on some axis the
    chi-square per degree of freedom exceeds :data:`CHI2_TRIM` and a normalised residual of the three
    shortest taus exceeds 3: an anti-alias filter, quantization or resampled time tags shape the short
    taus), keeping at least half of them and at least 6."""
    idx = np.flatnonzero(fitted)
    keep_min = max(6, (idx.size + 1) // 2)
    start = 0
    while idx.size - start > keep_min:
        fits = [_wls_one(taus[idx[start:]], a[idx[start:]], K[idx[start:]]) for a in flat]
        if not any(f[5] > CHI2_TRIM and np.max(np.abs(f[6][:3])) > 3.0 for f in fits):
            break
        start += 1
    out = np.zeros_like(fitted)
    out[idx[start:]] = True
    return out


def allan_ms(n: int, per_octave: int = 2, min_clusters: int = 3):
    """Averaging factors spaced ``per_octave`` to an octave from 1 up to n / min_clusters (distinct ints)."""
    top = n / float(min_clusters)
    if top < 1:
        raise ValueError(f"{n} samples are too few for an Allan variance (need >= {min_clusters})")
    k = int(math.floor(math.log2(top) * per_octave)) + 1
    ms = sorted({int(round(2.0 ** (i / per_octave))) for i in range(k)})
    return tuple(m for m in ms if 1 <= m <= top)


def allan_noise_fit(y, dt, *, tau_range=None, per_octave: int = 1, kind: str = "rate") -> AllanFit:
    """Identify white noise, bias instability and rate random walk of each axis from a static recording.

    The overlapping Allan variance (:func:`allan_variance`) at ``per_octave`` taus per octave (up to
    a third of the record, at least 3 clusters) is fitted with the model sum of the module section
    (:func:`allan_model`) by weighted least squares; the weights are the estimator's variance at the
    fitted model (:func:`allan_variance_sigma`, three reweighting passes), a term fitted negative is
    dropped, and the parameter covariance is scaled up by the chi-square per degree of freedom when
    that exceeds 1. Neighbouring taus share data and are treated as independent, so the sigmas are
    optimistic: on simulated white + flicker + rate random walk (2^19 samples, 20 seeds x 3 axes, one
    tau per octave) the errors of the fitted bias instability and rate random walk were 2.1 and 1.9
    times their stated sigmas (RMS; 2.9 and 2.6 with two taus per octave), those of the white noise
    about 1 % against a stated 0.1 %. Read them as a lower bound on the uncertainty.

    Args:
      y: (..., N) rate samples along the last axis (rad/s or m/s^2; a constant -- gravity, Earth
        rate, a bias -- does not matter), or increments with ``kind="increment"``.
      dt: sample interval, s (uniform; see :func:`uniform_rates` for uneven time tags).
      tau_range: (lo, hi) s, fit only these taus (e.g. to skip an anti-alias filter's short taus);
        None: all, except that the shortest are dropped while the model misses them (the fit's
        chi-square per degree of freedom above :data:`CHI2_TRIM` and a residual of the three shortest
        above 3 sigma; at most half of them; ``fitted`` says which were used).
      per_octave: taus per octave (1: octaves, whose estimates share less data).
    Returns:
      :class:`AllanFit`.
    Raises:
      ValueError: for too few samples, non-finite samples, or fewer than 3 taus in ``tau_range``.
    """
    y = np.asarray(y, float)
    if not np.all(np.isfinite(y)):
        raise ValueError("the samples contain non-finite values")
    check_float64(jnp.asarray(y), what="Allan variance input (a running sum over the whole record)")
    n = y.shape[-1]
    ms = allan_ms(n, per_octave)
    taus, av = allan_variance(y, dt, ms, kind=kind)
    av = np.asarray(av, float)
    m = np.asarray(ms, float)
    K = np.floor(n / m)
    fitted = np.ones(taus.size, bool)
    if tau_range is not None:
        lo, hi = (float(v) for v in tau_range)
        fitted = (taus >= lo * (1 - 1e-9)) & (taus <= hi * (1 + 1e-9))
    if fitted.sum() < 3:
        raise ValueError(
            f"only {int(fitted.sum())} averaging times to fit (taus {taus[0]:g}..{taus[-1]:g} s); "
            "need >= 3: a longer recording or a wider tau range"
        )
    batch = av.shape[:-1]
    flat = av.reshape(-1, taus.size)
    fitted = _trim_short(taus, flat, K, fitted) if tau_range is None else fitted
    out = {
        k: np.zeros((flat.shape[0],) + s)
        for k, s in (("theta", (3,)), ("sd", (3,)), ("res", (3,)), ("up", (3,)), ("chi2", ()), ("floor", ()))
    }
    for i, a in enumerate(flat):
        out_i = _fit_axis(taus[fitted], a[fitted], K[fitted])
        for k, v in out_i.items():
            out[k][i] = v
    r = lambda k: out[k].reshape(batch + out[k].shape[1:])
    th, sd = r("theta"), r("sd")
    return AllanFit(
        taus=taus,
        ms=m,
        avar=av,
        avar_sigma=allan_variance_sigma(av, m, n),
        fitted=fitted,
        white=th[..., 0],
        bias_instability=th[..., 1],
        rate_rw=th[..., 2],
        white_sigma=sd[..., 0],
        bias_instability_sigma=sd[..., 1],
        rate_rw_sigma=sd[..., 2],
        resolved=r("res").astype(bool),
        upper=r("up"),
        tau_floor=r("floor"),
        chi2=r("chi2"),
        dt=float(dt),
        n=int(n),
    )


def uniform_rates(t, rates, dt=None):
    """Rates on a uniform time grid from samples at uneven time tags, through their integral.

    The integral x(t_k) = sum_{i<=k} y_i (t_i - t_{i-1}) (each sample a mean over the interval that
    ends at its tag) is interpolated linearly at t_0 + j dt and differenced: exact for uniform tags,
    a mild low-pass (at tau ~ dt only) otherwise.

    Args:
      t: (N,) s, increasing.  rates: (N, c) rates (rad/s, m/s^2).  dt: the grid step, s (default:
        the median tag step).
    Returns:
      (dt, (c, M) rates on the grid) -- axes first, as :func:`allan_noise_fit` wants them.
    Raises:
      ValueError: for tags that do not increase.
    """
    t = np.asarray(t, float)
    y = np.asarray(rates, float).reshape(t.size, -1)
    steps = np.diff(t)
    if t.size < 2 or not np.all(steps > 0):
        raise ValueError("the time tags must increase")
    if dt is None:
        dt = float(np.median(steps))
    x = np.concatenate([np.zeros((1, y.shape[1])), np.cumsum(y[1:] * steps[:, None], axis=0)])
    grid = t[0] + dt * np.arange(int(math.floor((t[-1] - t[0]) / dt + 1e-9)) + 1)
    xg = np.stack([np.interp(grid, t, x[:, j]) for j in range(y.shape[1])])
    return float(dt), np.diff(xg, axis=1) / dt


def imu_noise_from_allan(gyro: AllanFit, accel: AllanFit, *, reduce=None):
    """The :class:`jaxnav.ins.ImuNoise` of fitted gyro and accelerometer Allan curves.

    White noise -> ``gyro_arw`` / ``accel_vrw``; rate random walk -> ``*_bias_rw``; bias instability
    -> a first-order Gauss-Markov bias whose Allan deviation peaks, at the fitted model's minimum
    tau_floor, at the flicker floor 0.664 B: sigma = 0.664 B / GM_PEAK_ADEV (= 1.075 B), correlation
    time tau_floor / GM_PEAK_TAU (Gauss-Markov constants of this module). A term not resolved is
    given its 2-sigma upper bound (the filter then allows for it rather than ignoring it).

    Args:
      gyro, accel: :class:`AllanFit` of (3,) axes (rad/s, m/s^2).
      reduce: None keeps (3,) per-axis values; a function such as ``np.max`` makes scalars.
    Returns:
      :class:`jaxnav.ins.ImuNoise` (SI); turn-on biases and scale factors 0 (a static recording
      cannot tell them).
    """
    from jaxnav.ins.noise import ImuNoise

    def pick(f: AllanFit, j):
        v = np.where(f.resolved[..., j], (f.white, f.bias_instability, f.rate_rw)[j], f.upper[..., j])
        return v if reduce is None else float(reduce(v))

    def gm(f: AllanFit):
        b = pick(f, 1)
        s = FLICKER_AVAR**0.5 * np.asarray(b) / GM_PEAK_ADEV
        T = np.asarray(f.tau_floor) / GM_PEAK_TAU
        return (s, T) if reduce is None else (float(s), float(reduce(T)))

    gs, gT = gm(gyro)
    as_, aT = gm(accel)
    return ImuNoise(
        gyro_arw=pick(gyro, 0),
        accel_vrw=pick(accel, 0),
        gyro_bias_instability=gs,
        gyro_bias_tau=gT,
        accel_bias_instability=as_,
        accel_bias_tau=aT,
        gyro_bias_rw=pick(gyro, 2),
        accel_bias_rw=pick(accel, 2),
    )


#: the largest deviation from standstill :func:`static_check` accepts: |mean specific force| within this of
#: g (m/s^2) and the rms of the gyro about its mean (rad/s) and of the accelerometers about theirs (m/s^2)
STATIC_LIMITS = {"gravity_m_s2": 1.0, "gyro_rms_rad_s": 0.05, "accel_rms_m_s2": 0.5}


def static_check(w_b, f_b, limits=STATIC_LIMITS) -> str | None:
    """None if an IMU recording looks static (:data:`STATIC_LIMITS`), else a sentence saying which test fails.

    Args:
      w_b: (N, 3) angular rates, rad/s.  f_b: (N, 3) specific forces, m/s^2.  limits: dict as :data:`STATIC_LIMITS`.
    """
    w_b, f_b = np.asarray(w_b, float), np.asarray(f_b, float)
    g = float(np.linalg.norm(np.mean(f_b, axis=0)))
    wr = float(np.sqrt(np.mean((w_b - w_b.mean(0)) ** 2)))
    ar = float(np.sqrt(np.mean((f_b - f_b.mean(0)) ** 2)))
    if abs(g - units.G0) > limits["gravity_m_s2"]:
        return f"the mean specific force is {g:.3f} m/s^2, not about g = 9.81 (wrong accelerometer unit?)"
    if wr > limits["gyro_rms_rad_s"]:
        return f"the angular rate varies by {units.rad_to_deg(wr):.3g} deg/s rms: the IMU moved"
    if ar > limits["accel_rms_m_s2"]:
        return f"the specific force varies by {ar:.3g} m/s^2 rms: the IMU moved"
    return None


def allan_fit_datasheet(fit: AllanFit, sensor: str) -> dict:
    """A fit's per-axis values in datasheet units, JSON-ready (lists; the unit in each key).

    Args:
      fit: :class:`AllanFit` of (3,) axes (rad/s or m/s^2).  sensor: ``"gyro"`` (deg/sqrt(h), deg/h,
        deg/h/sqrt(h)) or ``"accel"`` (m/s/sqrt(h), mg, mg/sqrt(h)).
    Returns:
      dict: per term (``arw`` / ``vrw``, ``bias_instability``, ``rate_rw``) the value, its sigma and
      its 2-sigma upper bound; ``resolved_white_bi_rrw``, ``tau_floor_s``, ``fit_chi2_per_dof``,
      ``tau_s``, the Allan deviation ``adev_*`` and its sigma per axis and tau, ``fitted``.
    """
    if sensor == "gyro":
        conv = (
            units.rad_per_sqrt_s_to_deg_per_sqrt_hour,
            units.rad_per_s_to_deg_per_hour,
            units.rad_per_s_per_sqrt_s_to_deg_per_hour_per_sqrt_hour,
        )
        heads = ("arw", "bias_instability", "rate_rw")
        tails = ("_deg_per_sqrt_h", "_deg_per_h", "_deg_per_h_per_sqrt_h")
        dev = ("adev", "_deg_per_h", units.rad_per_s_to_deg_per_hour)
    else:
        conv = (units.mps_per_sqrt_s_to_mps_per_sqrt_hour, units.mps2_to_mg, units.mps2_per_sqrt_s_to_mg_per_sqrt_hour)
        heads = ("vrw", "bias_instability", "rate_rw")
        tails = ("_m_per_s_per_sqrt_h", "_mg", "_mg_per_sqrt_h")
        dev = ("adev", "_mg", units.mps2_to_mg)
    lst = lambda a: [float(v) for v in np.asarray(a, float).reshape(-1)]
    out = {}
    for j, (c, h, t, v, s) in enumerate(
        zip(
            conv,
            heads,
            tails,
            (fit.white, fit.bias_instability, fit.rate_rw),
            (fit.white_sigma, fit.bias_instability_sigma, fit.rate_rw_sigma),
        )
    ):
        out[h + t] = lst(c(np.asarray(v)))
        out[h + "_sigma" + t] = lst(c(np.asarray(s)))
        out[h + "_upper_2sigma" + t] = lst(c(np.asarray(fit.upper)[..., j]))
    out["resolved_white_bi_rrw"] = [[bool(x) for x in r] for r in np.asarray(fit.resolved)]
    out["tau_floor_s"] = lst(fit.tau_floor)
    out["fit_chi2_per_dof"] = lst(fit.chi2)
    out["tau_s"] = lst(fit.taus)
    av = np.asarray(fit.avar)
    out[dev[0] + dev[1]] = [lst(dev[2](np.sqrt(a))) for a in av]
    out[dev[0] + "_sigma" + dev[1]] = [
        lst(dev[2](s / (2.0 * np.sqrt(np.maximum(a, 1e-300))))) for a, s in zip(av, np.asarray(fit.avar_sigma))
    ]
    out["fitted"] = [bool(x) for x in fit.fitted]
    return out
