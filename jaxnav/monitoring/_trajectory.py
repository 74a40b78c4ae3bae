"""Trajectory model of a daily station series with coloured noise, fitted by maximum likelihood.

Per component (east, north, up), on a daily grid with gaps (missing days are masked epochs):

  y(t) = a + b (t - t_ref) + sum_{h=1,2} [c_h cos(2 pi h t / yr) + s_h sin(2 pi h t / yr)]
         + sum_j o_j H(t - t_j) + w(t) + p(t) + q(t)

w white (sigma_w), p power-law noise of spectral index kappa (flicker, kappa = -1, by default;
Hector's GGM form with 1 - phi = 6.9e-6, approximated by a sum of first-order Gauss-Markov
processes, :mod:`jaxnav.monitoring._noise`), q a random walk starting at the first epoch. The
noise is a linear Gaussian state-space model, so the classic Kalman filter of
:mod:`jaxnav.filters` run over the data and over each column of the design matrix gives the
whitened (innovation / sqrt(innovation variance)) data y~ and design A~ (one covariance
recursion shared by all columns, ``vmap``). Generalised least squares on the whitened system
gives the trajectory parameters and their covariance (A~^T A~)^-1, and the log-likelihood
(Bos et al. 2013, J. Geod. 87, eqs. (4)-(8); Harville 1974 for the restricted form)

  ln L   = -1/2 [N ln 2 pi + sum ln S_t + |y~ - A~ beta|^2]         (ML, regression profiled out)
  ln L_R = ln L - 1/2 ln det(A~^T A~)                               (REML, Hector's default)

The noise parameters theta = (ln sigma_w, ln sigma_pl, ln sigma_rw[, kappa]) maximise ln L_R by
BFGS with the exact gradient (reverse mode through the filter scan) and an Armijo backtracking
step, projected on a box whose edges are reported; an estimate on an edge is flagged. Everything
is a pure function of arrays: ``jax.vmap`` fits many stations (or components) at once.
"""

from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxnav import filters as jf
from jaxnav.monitoring._noise import GGM_ONE_MINUS_PHI, gauss_markov_sum, gauss_markov_table
from jaxnav.units import DAY, YEAR

#: components of a station series, in the order of every (3,) array here
COMPONENTS = ("east", "north", "up")
#: names of the noise parameters (the order of ``NoiseFit.theta``)
NOISE_PARAMS = ("ln_sigma_white", "ln_sigma_powerlaw", "ln_sigma_random_walk", "kappa")
#: box of the noise parameters relative to the data scale s (robust std of the first residuals):
#: sigma_white in [1e-3, 10] s, sigma_powerlaw (per-day driving noise) in [1e-3, 10] s,
#: sigma_random_walk (per-day step) in [1e-5, 1] s; kappa in [-1.9, -0.1] when estimated
BOX_RELATIVE = ((1e-3, 10.0), (1e-3, 10.0), (1e-5, 1.0))
KAPPA_BOX = (-1.9, -0.1)
#: distance (in the parameter, ln units for the amplitudes) under which an estimate is "at a bound"
AT_BOUND_TOL = 0.05
UNROLL = 1
#: grid of d = -kappa/2 whose Gauss-Markov weights are interpolated when kappa is estimated
D_GRID = np.round(np.arange(0.05, 0.951, 0.05), 2)


class Design(NamedTuple):
    """Design matrix of the trajectory model on a daily grid.

    Attributes:
      A: (T, k) columns: offset, rate (years from t_ref), cos/sin annual, cos/sin semi-annual, further
        periods, steps, polynomial powers >= 2, post-seismic transients.
      names: (k,) column names ("offset", "rate", "annual_cos", "annual_sin", "semiannual_cos",
        "semiannual_sin", "step_0", ..., "poly_2", ..., "postseismic_0_log", ...).
      t_ref: reference epoch of the offset and rate, s since J2000 (mid-span).
      steps: (S,) step epochs, s since J2000.
    """

    A: jax.Array
    names: tuple
    t_ref: float
    steps: jax.Array


#: forms of a post-seismic transient (:func:`postseismic_column`)
POSTSEISMIC_FORMS = ("log", "exp")


def postseismic_column(t, epoch, form: str, tau):
    """Unit-amplitude post-seismic transient after ``epoch`` (0 before it), (T,).

    Bevis & Brown (2014, J. Geod. 88, eqs. (11)-(12)), as in Hector's design options:

      log: log(1 + (t - t_eq) / tau)        exp: 1 - exp(-(t - t_eq) / tau)     for t >= t_eq

    Args:
      t: (T,) s since J2000.  epoch: t_eq, s since J2000.  form: "log" or "exp".  tau: time
        constant, s (> 0).
    Returns:
      (T,) dimensionless (its coefficient is the amplitude, m).
    """
    t = np.asarray(t, float)
    if form not in POSTSEISMIC_FORMS:
        raise ValueError(f"post-seismic form must be one of {POSTSEISMIC_FORMS}, got {form!r}")
    if not (np.isfinite(tau) and tau > 0):
        raise ValueError(f"post-seismic time constant must be > 0 s, got {tau}")
    dt = np.maximum(t - float(epoch), 0.0) / float(tau)
    return np.log1p(dt) if form == "log" else -np.expm1(-dt)


def design_matrix(
    t, *, steps=(), seasonal: bool = True, t_ref=None, periods_days=(), poly_degree: int = 1, postseismic=()
) -> Design:
    """Trajectory-model design matrix at epochs ``t`` (s since J2000).

    Columns in this order (Hector's design options): offset, rate, [annual, semi-annual], further
    periods, steps, then the powers 2 .. ``poly_degree`` of (t - t_ref) / yr ("poly_2", ...; the
    coefficient of power p is m/yr^p, so the acceleration is 2 x the "poly_2" coefficient), then
    the post-seismic transients ("postseismic_<j>_<form>", :func:`postseismic_column`). Since
    every added power vanishes with its slope at t_ref, the "rate" column's coefficient stays the
    velocity at t_ref whatever the degree.

    Args:
      t: (T,) s since J2000.
      steps: epochs of steps (Heaviside, 1 from the epoch on), s since J2000; steps outside the
        span (or with no epoch on one side) raise ValueError.
      seasonal: include the annual and semi-annual cos/sin terms (periods 365.25 and 182.625 days).
      t_ref: reference epoch of offset and rate (default mid-span), s.
      periods_days: further periodic terms (e.g. the GPS draconitic year 351.6 d): cos/sin columns
        "period_<P>d_cos", "period_<P>d_sin" of 2 pi t / P, t from J2000.
      poly_degree: degree of the polynomial in time (1: offset and rate).
      postseismic: sequence of (epoch s since J2000, form "log" | "exp", tau s).
    Returns:
      :class:`Design` (columns scaled to order one: rate in years, so its coefficient is m/yr).
    """
    t = np.asarray(t, float)
    t_ref = float(0.5 * (t[0] + t[-1])) if t_ref is None else float(t_ref)
    cols = [np.ones_like(t), (t - t_ref) / YEAR]
    names = ["offset", "rate"]
    if seasonal:
        ph = 2.0 * np.pi * t / YEAR
        cols += [np.cos(ph), np.sin(ph), np.cos(2 * ph), np.sin(2 * ph)]
        names += ["annual_cos", "annual_sin", "semiannual_cos", "semiannual_sin"]
    for p in np.atleast_1d(np.asarray(periods_days, float)):
        if not p > 0:
            raise ValueError(f"periods_days must be > 0, got {p}")
        ph = 2.0 * np.pi * t / (p * 86400.0)
        cols += [np.cos(ph), np.sin(ph)]
        names += [f"period_{p:g}d_cos", f"period_{p:g}d_sin"]
    steps = np.atleast_1d(np.asarray(steps, float))
    for j, ts in enumerate(steps):
        if not (t[0] < ts <= t[-1]):
            raise ValueError(
                f"step epoch {ts / YEAR + 2000.0:.4f} (decimal year) is outside the series "
                f"({t[0] / YEAR + 2000.0:.4f} .. {t[-1] / YEAR + 2000.0:.4f})"
            )
        cols.append((t >= ts).astype(float))
        names.append(f"step_{j}")
    if int(poly_degree) != poly_degree or poly_degree < 1:
        raise ValueError(f"poly_degree must be an integer >= 1, got {poly_degree}")
    for k in range(2, int(poly_degree) + 1):
        cols.append(((t - t_ref) / YEAR) ** k)
        names.append(f"poly_{k}")
    for j, (te, form, tau) in enumerate(postseismic):
        if not (t[0] < te < t[-1]):
            raise ValueError(
                f"post-seismic epoch {te / YEAR + 2000.0:.4f} (decimal year) is outside the series "
                f"({t[0] / YEAR + 2000.0:.4f} .. {t[-1] / YEAR + 2000.0:.4f})"
            )
        cols.append(postseismic_column(t, te, form, tau))
        names.append(f"postseismic_{j}_{form}")
    return Design(A=np.stack(cols, axis=1), names=tuple(names), t_ref=t_ref, steps=steps)


class NoiseFit(NamedTuple):
    """Maximum-likelihood fit of one component (leading batch axes under ``vmap``).

    Attributes:
      theta: (4,) ln sigma_white (m), ln sigma_powerlaw (per-day driving noise, m), ln
        sigma_random_walk (per-day step, m), kappa.
      lo, hi: (4,) the box of theta.  at_lower, at_upper: (4,) bool, estimate within
        :data:`AT_BOUND_TOL` of an edge (free parameters only).
      free: (4,) bool, the parameters estimated.
      theta_sigma: (4,) approximate standard deviations of theta from the BFGS inverse-Hessian
        approximation at the end (free, not at a bound; NaN else): a rough guide only.
      beta: (k,) trajectory parameters (offset m, rate m/yr, seasonal m, steps m).
      beta_cov: (k, k) their covariance (GLS with the fitted noise), m^2 and (m/yr)^2.
      loglik: ln L (ML), loglik_reml: ln L_R at the estimate.
      grad_norm: largest |d ln L_R / d theta| over the free parameters not at a bound.
      iterations: accepted BFGS steps.
      residuals: (T,) y - A beta (NaN where masked), m.
      hinv: (4, 4) the BFGS inverse-Hessian approximation of -ln L_R at the end (identity rows
        and columns for fixed parameters): with ``theta``, a warm start of a refit.
      gain_left: 0.5 g^T hinv g over the free parameters not at a bound: the rise of ln L_R that a
        further Newton step predicts (0 at a converged optimum; :data:`GAIN_LEFT_WARN`).
    """

    theta: jax.Array
    lo: jax.Array
    hi: jax.Array
    at_lower: jax.Array
    at_upper: jax.Array
    free: jax.Array
    theta_sigma: jax.Array
    beta: jax.Array
    beta_cov: jax.Array
    loglik: jax.Array
    loglik_reml: jax.Array
    grad_norm: jax.Array
    iterations: jax.Array
    residuals: jax.Array
    hinv: jax.Array
    gain_left: jax.Array


#: a fit whose ``gain_left`` exceeds this (ln L_R units) is reported as not converged: 0.01 is far
#: below any likelihood-ratio decision, yet a fit 0.02 short of its optimum was seen with a rate
#: sigma 5 % off
GAIN_LEFT_WARN = 0.01


def _noise_arrays(theta, r, W, d_grid, estimate_kappa: bool, random_walk: bool):
    """(f (n,), q (n,), p0 (n,), sigma_white) of white + Gauss-Markov sum (+ random walk) for theta.

    The state-space form: x_(t+1) = diag(f) x_t + n_t, n_t ~ N(0, diag(q)), y_t = 1^T x_t + white,
    x_0 ~ N(0, diag(p0)) (the Gauss-Markov processes start stationary, the random walk at zero).
    """
    sw, spl, srw = jnp.exp(theta[0]), jnp.exp(theta[1]), jnp.exp(theta[2])
    if estimate_kappa:
        w = jnp.stack([jnp.interp(-0.5 * theta[3], d_grid, W[:, j]) for j in range(W.shape[1])])
    else:
        w = W[0]
    var = spl**2 * w
    f, q, p0 = r, var * (1.0 - r**2), var
    if random_walk:
        f = jnp.concatenate([f, jnp.ones(1)])
        q = jnp.concatenate([q, srw[None] ** 2])
        p0 = jnp.concatenate([p0, jnp.zeros(1)])
    return f, q, p0, sw


def noise_state_space(theta, r, W, d_grid, *, estimate_kappa: bool = False, random_walk: bool = True):
    """The noise model as a :class:`jaxnav.filters.LinearGaussian` and its P0 (for checks and smoothing).

    Returns:
      (model, P0): F = diag(f), H = 1^T, Q = diag(q), R = sigma_white^2; x0 = 0.
    """
    f, q, p0, sw = _noise_arrays(theta, r, W, d_grid, estimate_kappa, random_walk)
    n = f.shape[0]
    return jf.LinearGaussian(F=jnp.diag(f), H=jnp.ones((1, n)), Q=jnp.diag(q), R=sw[None, None] ** 2), jnp.diag(p0)


def _whitening_step(f, q, sw):
    """One epoch of the whitening filter (:func:`_whitened`): ((X, P), (z, ok)) -> ((X, P), (w, ln S)).

    X (n, c) holds the filtered states of c columns (data or design) that share the covariance P
    (n, n); z (c,) their values at the epoch, ok whether the epoch is valid; w (c,) the whitened
    values (0 where not valid).
    """
    Qd = jnp.diag(q)
    ff = f[:, None] * f[None, :]

    def step(carry, inp):
        X, P = carry
        z, ok = inp
        Xp = f[:, None] * X
        Pp = ff * P + Qd
        hp = jnp.sum(Pp, axis=1)
        S = jnp.sum(hp) + sw**2
        v = z - jnp.sum(Xp, axis=0)
        K = hp / S
        Pn = Pp - jnp.outer(K, hp)
        Xn = jnp.where(ok, Xp + K[:, None] * v[None, :], Xp)
        Pn = jnp.where(ok, 0.5 * (Pn + Pn.T), Pp)
        return (Xn, Pn), (jnp.where(ok, v / jnp.sqrt(S), 0.0), jnp.where(ok, jnp.log(S), 0.0))

    return step


def step_scan_sums(theta, valid, cand, e, Q, r, W, d_grid, estimate_kappa, random_walk):
    """Sums over epochs of the whitened step columns, for the step statistic of :func:`jaxnav.monitoring.detect_steps`.

    The step column of candidate j (1 from epoch cand_j on) is whitened on the fly, epoch by epoch,
    with the same filter as :func:`_whitened` (one covariance recursion for all M columns), and only
    its products with the whitened residual e~ and the orthonormal basis Q of the whitened design
    are kept: memory O(M k) instead of the (T, M) whitened columns.

    Args:
      theta: (4,) noise parameters.  valid: (T,) bool.  cand: (M,) int epoch indices.
      e: (T,) whitened residual (orthogonal to Q).  Q: (T, k) orthonormal basis of the whitened design.
    Returns:
      (s~^T e~ (M,), |s~|^2 (M,), Q^T s~ (k, M)).
    """
    f, q, p0, sw = _noise_arrays(theta, r, W, d_grid, estimate_kappa, random_walk)
    step = _whitening_step(f, q, sw)
    M, k = cand.shape[0], Q.shape[1]

    def body(carry, inp):
        state, num, full, QtS = carry
        t, ok, et, Qt = inp
        z = jnp.where(ok, (t >= cand).astype(e.dtype), 0.0)
        state, (w, _) = step(state, (z, ok))
        return (state, num + w * et, full + w * w, QtS + Qt[:, None] * w[None, :]), None

    T = valid.shape[0]
    zero = jnp.zeros(M, e.dtype)
    init = ((jnp.zeros((f.shape[0], M), e.dtype), jnp.diag(p0)), zero, zero, jnp.zeros((k, M), e.dtype))
    (_, num, full, QtS), _ = jax.lax.scan(body, init, (jnp.arange(T), valid, e, Q), unroll=UNROLL)
    return num, full, QtS


def _whitened(theta, y, valid, A, r, W, d_grid, estimate_kappa, random_walk):
    """Kalman-filter whitening of [y, A] by the noise model: (y~ (T,), A~ (T, k), sum ln S).

    The classic Kalman filter (S0 eqs. (4)-(9)) written for this model: a scalar measurement
    with H = 1^T and a diagonal transition, so that the gain is K = P_pred 1 / S and one
    covariance recursion serves the data and every design column (their means are the columns of
    an (n, 1 + k) matrix). Equal to :func:`jaxnav.filters.kalman_filter` on
    :func:`noise_state_space` (tests/monitoring/test_trajectory.py) at about 1/20 of its cost.
    """
    f, q, p0, sw = _noise_arrays(theta, r, W, d_grid, estimate_kappa, random_walk)
    Z = jnp.concatenate([jnp.where(valid, y, 0.0)[:, None], jnp.where(valid[:, None], A, 0.0)], axis=1)
    step = _whitening_step(f, q, sw)
    X0 = jnp.zeros((f.shape[0], Z.shape[1]), Z.dtype)
    _, (V, lS) = jax.lax.scan(step, (X0, jnp.diag(p0)), (Z, valid), unroll=UNROLL)
    return V[:, 0], V[:, 1:], jnp.sum(lS)


def _gls(yt, At, logdetS, n_valid):
    N = At.T @ At
    L = jnp.linalg.cholesky(N)
    beta = jax.scipy.linalg.cho_solve((L, True), At.T @ yt)
    e = yt - At @ beta
    ll = -0.5 * (n_valid * jnp.log(2.0 * jnp.pi) + logdetS + e @ e)
    logdetN = 2.0 * jnp.sum(jnp.log(jnp.diagonal(L)))
    return beta, L, ll, ll - 0.5 * logdetN


def component_loglik(theta, y, valid, A, r, W, d_grid, *, estimate_kappa=False, random_walk=True, reml=True):
    """ln L_R (or ln L) of one component for noise parameters ``theta`` (differentiable).

    Args:
      theta: (4,) as :attr:`NoiseFit.theta`.  y: (T,) m (masked where ``valid`` is False).
      valid: (T,) bool.  A: (T, k) design.  r: (K,) AR(1) coefficients.  W: (G, K) weights per d of
        ``d_grid`` (G = 1 and d_grid unused when kappa is fixed).
    Returns:
      scalar log-likelihood.
    """
    yt, At, lds = _whitened(theta, y, valid, A, r, W, d_grid, estimate_kappa, random_walk)
    _, _, ll, llr = _gls(yt, At, lds, jnp.sum(valid))
    return llr if reml else ll


@partial(jax.jit, static_argnames=("estimate_kappa", "random_walk", "reml", "iterations"))
def fit_component(
    y,
    valid,
    A,
    r,
    W,
    d_grid,
    theta0,
    lo,
    hi,
    *,
    estimate_kappa=False,
    random_walk=True,
    reml=True,
    iterations: int = 40,
    hinv0=None,
) -> NoiseFit:
    """Maximum-likelihood noise parameters and GLS trajectory of one component (vmappable).

    BFGS on -ln L_R with the exact gradient (through the Kalman-filter whitening), a fixed number
    of ``lax.scan`` steps (so ``vmap`` batches need no while loop): each step tries the
    (projected) quasi-Newton direction, at most 2 in ln sigma, with a step length doubled after an
    accepted (Armijo) step and quartered after a rejected one; parameters at an edge of the box
    [lo, hi] whose gradient points out of it are held there.

    Args:
      y: (T,) m.  valid: (T,) bool.  A: (T, k).  r, W, d_grid: the Gauss-Markov sum (see
        :func:`component_loglik`).  theta0, lo, hi: (4,) start and box (a parameter with lo == hi
        is fixed).
      estimate_kappa, random_walk, reml: static model choices.  iterations: BFGS steps (static).
      hinv0: None, or (4, 4) the starting inverse Hessian (a previous fit's ``hinv``, with
        ``theta0`` its ``theta``: a warm start); ignored where not finite or not positive definite.
    Returns:
      :class:`NoiseFit`.
    """
    idx = np.array([0, 1] + ([2] if random_walk else []) + ([3] if estimate_kappa else []))
    p = idx.shape[0]
    free = jnp.zeros(4, bool).at[idx].set(True) & (hi > lo)
    theta0 = jnp.clip(theta0, lo, hi)
    lo_p, hi_p, free_p = lo[idx], hi[idx], free[idx]

    def negll(u, base):
        th = base.at[idx].set(u)
        return -component_loglik(
            th, y, valid, A, r, W, d_grid, estimate_kappa=estimate_kappa, random_walk=random_walk, reml=reml
        )

    vg = jax.value_and_grad(negll)

    def step(carry, _):
        u, f, g, Hinv, alpha, n_acc = carry
        held = ((u <= lo_p + 1e-9) & (g > 0)) | ((u >= hi_p - 1e-9) & (g < 0))
        act = free_p & ~held
        both = act[:, None] & act[None, :]
        d = -jnp.where(both, Hinv, 0.0) @ jnp.where(act, g, 0.0)
        d = jnp.where(jnp.sum(d * g) < 0, d, -jnp.where(act, g, 0.0))  # keep a descent direction
        d = d * jnp.minimum(1.0, 2.0 / jnp.maximum(jnp.max(jnp.abs(d)), 1e-30))  # at most 2 in ln sigma
        u_new = jnp.where(act, jnp.clip(u + alpha * d, lo_p, hi_p), u)
        f_new, g_new = vg(u_new, theta0)
        ok = jnp.isfinite(f_new) & (f_new <= f + 1e-4 * jnp.sum(g * (u_new - u)))  # Armijo
        s_, y_ = u_new - u, g_new - g
        sy = jnp.sum(s_ * y_)
        rho = jnp.where(sy > 1e-12, 1.0 / sy, 0.0)
        V = jnp.eye(p) - rho * jnp.outer(s_, y_)
        H_upd = jnp.where(sy > 1e-12, V @ Hinv @ V.T + rho * jnp.outer(s_, s_), Hinv)
        carry = (
            jnp.where(ok, u_new, u),
            jnp.where(ok, f_new, f),
            jnp.where(ok, g_new, g),
            jnp.where(ok, H_upd, Hinv),
            jnp.where(ok, jnp.minimum(1.0, alpha * 2.0), alpha * 0.25),
            n_acc + ok.astype(jnp.int32),
        )
        return carry, None

    u0 = theta0[idx]
    f0, g0 = vg(u0, theta0)
    H0 = jnp.eye(p) / jnp.maximum(jnp.max(jnp.abs(g0)), 1.0)  # first step at most 1 in ln sigma
    if hinv0 is not None:
        Hw = jnp.asarray(hinv0)[idx[:, None], idx[None, :]]
        Hw = 0.5 * (Hw + Hw.T)
        pd = jnp.all(jnp.isfinite(Hw)) & jnp.all(jnp.linalg.eigvalsh(jnp.where(jnp.isfinite(Hw), Hw, 0.0)) > 0)
        H0 = jnp.where(pd, Hw, H0)
    (u, f, g, Hinv, _, n_acc), _ = jax.lax.scan(
        step, (u0, f0, g0, H0, jnp.asarray(1.0), jnp.zeros((), jnp.int32)), None, length=iterations
    )
    th = theta0.at[idx].set(u)
    gfull = jnp.zeros(4).at[idx].set(g)
    Hfull = jnp.eye(4).at[idx[:, None], idx[None, :]].set(Hinv)
    at_lower = free & (th <= lo + AT_BOUND_TOL)
    at_upper = free & (th >= hi - AT_BOUND_TOL)
    inner = free & ~at_lower & ~at_upper
    cov = jnp.where(inner[:, None] & inner[None, :], Hfull, 0.0)  # the BFGS inverse-Hessian approximation
    theta_sigma = jnp.where(inner, jnp.sqrt(jnp.abs(jnp.diagonal(cov))), jnp.nan)
    gi = jnp.where(inner, gfull, 0.0)
    yt, At, lds = _whitened(th, y, valid, A, r, W, d_grid, estimate_kappa, random_walk)
    beta, L, ll, llr = _gls(yt, At, lds, jnp.sum(valid))
    Linv = jax.scipy.linalg.solve_triangular(L, jnp.eye(L.shape[0]), lower=True)
    beta_cov = Linv.T @ Linv
    res = jnp.where(valid, y - A @ beta, jnp.nan)
    return NoiseFit(
        theta=th,
        lo=lo,
        hi=hi,
        at_lower=at_lower,
        at_upper=at_upper,
        free=free,
        theta_sigma=theta_sigma,
        beta=beta,
        beta_cov=beta_cov,
        loglik=ll,
        loglik_reml=llr,
        grad_norm=jnp.max(jnp.where(inner, jnp.abs(gfull), 0.0)),
        iterations=n_acc,
        residuals=res,
        hinv=Hfull,
        gain_left=0.5 * gi @ Hfull @ gi,
    )


class NoiseSpec(NamedTuple):
    """Arrays of the noise model shared by the components of a fit (host side).

    Attributes:
      r: (K,) AR(1) coefficients.  W: (G, K) weights (G = 1: fixed kappa).  d_grid: (G,) d values.
      kappa: the fixed spectral index (None when estimated).  max_rel_error: of the approximation.
    """

    r: jax.Array
    W: jax.Array
    d_grid: jax.Array
    kappa: float | None
    max_rel_error: float


def noise_spec(
    n_days: int, *, kappa=-1.0, per_decade: float = 1.5, one_minus_phi: float = GGM_ONE_MINUS_PHI
) -> NoiseSpec:
    """The Gauss-Markov sum of the power-law noise for a series of ``n_days`` days.

    Args:
      n_days: daily grid length.
      kappa: fixed spectral index in (-2, 0) (-1 flicker), or None to estimate it in
        :data:`KAPPA_BOX` (weights tabulated on :data:`D_GRID` and interpolated linearly).
    """
    if kappa is None:
        r, W, err = gauss_markov_table(D_GRID, n_days, per_decade=per_decade, one_minus_phi=one_minus_phi)
        return NoiseSpec(r=r, W=W, d_grid=D_GRID.astype(float), kappa=None, max_rel_error=err)
    if not -2.0 < float(kappa) < 0.0:
        raise ValueError(f"spectral index kappa = {kappa!r} must lie in (-2, 0) (random walk is its own term)")
    gm = gauss_markov_sum(-0.5 * float(kappa), n_days, per_decade=per_decade, one_minus_phi=one_minus_phi)
    return NoiseSpec(
        r=gm.r, W=gm.w[None], d_grid=np.array([-0.5 * float(kappa)]), kappa=float(kappa), max_rel_error=gm.max_rel_error
    )


def start_and_box(scale, *, kappa=-1.0, random_walk=True):
    """(theta0, lo, hi) (..., 4) for data scales ``scale`` (m; robust std of first residuals)."""
    ls = np.log(np.asarray(scale, float))[..., None]
    lo = ls + np.log([BOX_RELATIVE[0][0], BOX_RELATIVE[1][0], BOX_RELATIVE[2][0]])
    hi = ls + np.log([BOX_RELATIVE[0][1], BOX_RELATIVE[1][1], BOX_RELATIVE[2][1]])
    th0 = ls + np.log([0.7, 0.3, 3e-3])
    k = -1.0 if kappa is None else float(kappa)
    kb = KAPPA_BOX if kappa is None else (k, k)
    shape = ls.shape[:-1]
    lo = np.concatenate([lo, np.full(shape + (1,), kb[0])], axis=-1)
    hi = np.concatenate([hi, np.full(shape + (1,), kb[1])], axis=-1)
    th0 = np.concatenate([th0, np.full(shape + (1,), k)], axis=-1)
    if not random_walk:
        lo[..., 2] = hi[..., 2] = th0[..., 2] = lo[..., 2]
    return th0, lo, hi


def robust_scale(res, axis=0):
    """1.4826 x median absolute deviation from the median (NaN ignored)."""
    med = np.nanmedian(res, axis=axis, keepdims=True)
    return 1.4826 * np.nanmedian(np.abs(res - med), axis=axis)


def powerlaw_amplitude(theta, dt=DAY):
    """Power-law amplitude in SI, m s^(kappa/4) = m / s^(-kappa/4): sigma_pl / dt^(-kappa/4).

    Hector's amplitude (mm/yr^(-kappa/4)) is this x YEAR^(-kappa/4) / MM
    (:func:`jaxnav.units.powerlaw_amplitude_to_mm_yr`)."""
    theta = np.asarray(theta)
    return np.exp(theta[..., 1]) / dt ** (-theta[..., 3] / 4.0)


def random_walk_amplitude(theta, dt=DAY):
    """Random-walk amplitude, m/sqrt(s): sigma_rw / sqrt(dt) (0 when the model has none)."""
    return np.exp(np.asarray(theta)[..., 2]) / np.sqrt(dt)
