"""Noise estimators that plug into the shared filter step: variance compensation, Sage-Husa.

An estimator is a :func:`~jaxnav.filters.pytree_dataclass` subclass of
:class:`jaxnav.filters.NoiseEstimator` (its constructor checks the arguments; the lower-case
functions are shorthands):

* ``init(n, m, p, dtype) -> state``
* ``noise(state, ctx) -> (GQG, R, state, (info, flags))``: the process noise G Q G^T (n, n) and
  the measurement noise R (m, m) to use at epoch k, given the innovation of that epoch;
* ``after(state, ctx, post) -> state``: learn from the update (post-fit quantities);
* ``screen(info, ctx) -> (m,) bool``: components later members of a chain must not learn from.
"""

from __future__ import annotations

from typing import ClassVar, NamedTuple

import jax
import jax.numpy as jnp

from jaxnav import _status
from jaxnav._numerics import cho_solve, cholesky, symmetrize
from jaxnav.filters._plugins import (
    NoiseEstimator,
    Range,
    check_ranges,
    leaf,
    pytree_dataclass,
    range_flags,
    static_field,
)


class VCState(NamedTuple):
    """Window of per-epoch equations E_j = A_j diag(D_Omega) + eta (S1 eqs. (12)-(18)).

    I = horizon (largest prediction step i), N = window epochs.

    Attributes:
      E: (N, I, m) diag(V V^T) - known part, per epoch and prediction step i.
      A: (N, I, m, p) sum_r (B Phi_{k,r} Gamma_r)^2 element-wise.
      W: (N, I, m) weights 1/0 of usable equations.
      pos: int32 ring position.  count: int32 epochs stored.
      x_lag: (I, n) Phi_{k,k-i} X(k-i/k-i), i = 1..I (propagated to the last epoch).
      P_lag: (I, n, n) Phi_{k,k-i} D_X(k-i/k-i) Phi_{k,k-i}^T.
      C_lag: (I, n, p) Phi_{k,r} Gamma_r for r = k, k-1, ..., k-I+1.
      n_lag: int32, lag slots holding an estimate.
    """

    E: jax.Array
    A: jax.Array
    W: jax.Array
    pos: jax.Array
    count: jax.Array
    x_lag: jax.Array
    P_lag: jax.Array
    C_lag: jax.Array
    n_lag: jax.Array


class VCInfo(NamedTuple):
    """Per-epoch output of :class:`VarianceCompensation`.

    Attributes:
      q: (p,) diag(D_Omega) used at the epoch.  estimated: scalar bool, q is not the model's prior.
    """

    q: jax.Array
    estimated: jax.Array


@pytree_dataclass
class VarianceCompensation(NoiseEstimator):
    """Variance-compensation adaptive filter: diag(D_Omega) by windowed least squares (S1 eqs. (12)-(19)).

    At epoch k the i-step predicted residuals V_{k,i} = L_k - B Phi_{k,k-i} X(k-i/k-i),
    i = 1..I (S1 eq. (12)), have covariance
    B Phi D_X(k-i/k-i) Phi^T B^T + sum_{r=k-i+1}^{k} B Phi_{k,r} Gamma D_Omega Gamma^T Phi_{k,r}^T B^T + D_Delta
    (eqs. (13)-(16)). Their diagonals give m equations each in the p unknowns q = diag(D_Omega):
    E_{k,i} = diag(V V^T) - diag(known part) = A_{k,i} q + eta, A_{k,i} = sum_r (B Phi_{k,r} Gamma_r)^{o2}
    (eqs. (17)-(18)). The equations of the last ``window`` observed epochs are stacked and solved
    by least squares, q = (A^T A + ridge I)^{-1} A^T E (eq. (19)), each component floored at
    ``max(floor, floor_rel * diag(Q_model))``, and G diag(q) G^T replaces G Q G^T at epoch k.

    Notes:
      The current epoch's residuals are part of the window (they do not depend on the Q of
      epoch k). Longer horizons I make D_Omega far better determined when the process noise is
      small against the measurement noise (its weight grows like i^3 for constant velocity);
      ``horizon=1`` is the plain one-step innovation form. The least squares ignore the
      correlation between overlapping residuals, as eq. (19) does. Until ``min_epochs`` epochs
      are stored, or when the normal matrix is singular, the model's Q is used (a singular system
      also sets the ESTIMATOR_FALLBACK status flag). The per-epoch equations are very noisy when
      D_Omega is small against D_Delta, so the raw least-squares estimate is often negative; the
      floor max(floor, floor_rel * diag(Q_model)) keeps it positive. Default floor_rel = 1e-2
      (never below 1 % of the prior, so the filter never freezes); floor_rel = 1 makes the
      filter only *compensate* missing variance, never remove modelled variance.

    Attributes:
      floor: scalar or (p,) absolute lower bound of q.
      floor_rel: scalar, lower bound relative to the model's diag(Q).
      ridge: scalar >= 0 added to the normal matrix (explicit jitter; default 0).
      window: static int N, epochs in the least-squares window.
      horizon: static int I >= 1, largest prediction step i of the residuals.
      min_epochs: static int, epochs needed before estimating (default: window).

    Raises:
      ValueError: window, horizon or min_epochs not a positive integer (min_epochs <= window);
        concrete floor, floor_rel or ridge negative.
    """

    ranges: ClassVar[dict] = {"floor": Range(0.0), "floor_rel": Range(0.0), "ridge": Range(0.0)}

    floor: jax.Array = 0.0
    floor_rel: jax.Array = 1e-2
    ridge: jax.Array = 0.0
    window: int = static_field(30)
    horizon: int = static_field(1)
    min_epochs: int | None = static_field(None)

    def __post_init__(self):
        window, horizon, min_epochs = self.window, self.horizon, self.min_epochs
        if int(window) != window or window < 1:
            raise ValueError(f"VarianceCompensation: window must be a positive integer, got {window!r}")
        if int(horizon) != horizon or horizon < 1:
            raise ValueError(f"VarianceCompensation: horizon must be a positive integer, got {horizon!r}")
        if min_epochs is not None and (int(min_epochs) != min_epochs or not 1 <= min_epochs <= window):
            raise ValueError(f"VarianceCompensation: min_epochs must be in 1..window, got {min_epochs!r}")
        check_ranges("VarianceCompensation", self.ranges, floor=self.floor, floor_rel=self.floor_rel, ridge=self.ridge)
        for name in ("floor", "floor_rel", "ridge"):
            object.__setattr__(self, name, leaf(getattr(self, name)))
        object.__setattr__(self, "window", int(window))
        object.__setattr__(self, "horizon", int(horizon))
        object.__setattr__(self, "min_epochs", None if min_epochs is None else int(min_epochs))

    def init(self, n, m, p, dtype):
        N, I = int(self.window), int(self.horizon)
        return VCState(
            E=jnp.zeros((N, I, m), dtype),
            A=jnp.zeros((N, I, m, p), dtype),
            W=jnp.zeros((N, I, m), dtype),
            pos=jnp.zeros((), jnp.int32),
            count=jnp.zeros((), jnp.int32),
            x_lag=jnp.zeros((I, n), dtype),
            P_lag=jnp.zeros((I, n, n), dtype),
            C_lag=jnp.zeros((I, n, p), dtype),
            n_lag=jnp.zeros((), jnp.int32),
        )

    def noise(self, state, ctx):
        dt = ctx.FPF.dtype
        N, I = int(self.window), int(self.horizon)
        need = N if self.min_epochs is None else int(self.min_epochs)
        F, H = ctx.F, ctx.H
        # propagate the lagged estimates to epoch k and shift in the one-step prediction
        x_lag = jnp.concatenate([ctx.x_pred[None], (state.x_lag[:-1] @ F.T)], axis=0)
        P_lag = jnp.concatenate([ctx.FPF[None], F @ state.P_lag[:-1] @ F.T], axis=0)
        C_lag = jnp.concatenate([ctx.G[None], F @ state.C_lag[:-1]], axis=0)
        n_lag = jnp.minimum(state.n_lag + 1, I)
        HC = jnp.einsum("mn,inp->imp", H, C_lag)
        A_k = jnp.cumsum(HC * HC, axis=0)  # (I, m, p): sum over r of the first i terms
        V = ctx.z[None, :] - x_lag @ H.T  # (I, m)
        known = jnp.diagonal(H @ P_lag @ H.T, axis1=-2, axis2=-1) + jnp.diagonal(ctx.R_used)[None]
        use = ctx.valid[None, :] & (jnp.arange(I) < n_lag)[:, None]
        E_k = jnp.where(use, V * V - known, 0.0)
        w = use.astype(dt)
        obs = ctx.observed
        st = VCState(
            E=jnp.where(obs, state.E.at[state.pos].set(E_k), state.E),
            A=jnp.where(obs, state.A.at[state.pos].set(A_k), state.A),
            W=jnp.where(obs, state.W.at[state.pos].set(w), state.W),
            pos=jnp.where(obs, (state.pos + 1) % N, state.pos),
            count=jnp.minimum(state.count + obs.astype(jnp.int32), N),
            x_lag=x_lag,
            P_lag=P_lag,
            C_lag=C_lag,
            n_lag=n_lag,
        )
        AW = st.A * st.W[..., None]
        p = A_k.shape[-1]
        Nmat = jnp.einsum("jimp,jimq->pq", AW, st.A) + jnp.asarray(self.ridge, dt) * jnp.eye(p, dtype=dt)
        rhs = jnp.einsum("jimp,jim->p", AW, st.E)
        enough = st.count >= need
        # double-where: factor an identity when not enough data so gradients stay finite
        Nsafe = jnp.where(enough, Nmat, jnp.eye(p, dtype=dt))
        L = cholesky(Nsafe)
        q = cho_solve(L, jnp.where(enough, rhs, 0.0))
        solved = jnp.all(jnp.isfinite(q))
        ok = enough & solved
        qprior = jnp.diagonal(ctx.Q)
        floor = jnp.maximum(jnp.asarray(self.floor, dt), jnp.asarray(self.floor_rel, dt) * qprior)
        q = jnp.maximum(jnp.where(ok, q, qprior), floor)
        GQG_est = (ctx.G * q) @ ctx.G.T
        GQG = jnp.where(ok, GQG_est, ctx.GQG)
        q_used = jnp.where(ok, q, qprior)
        flag = jnp.where(enough & ~solved, _status.ESTIMATOR_FALLBACK, 0).astype(jnp.int32)
        flag = flag | range_flags(self, self.ranges)
        return GQG, ctx.R_used, st, (VCInfo(q=q_used, estimated=ok), flag)


class SageHusaState(NamedTuple):
    """Current noise estimates, the number of updates that formed them, and whether R hit a bound.

    Attributes:
      Q: (n, n) estimated G Q G^T.  R: (m, m) estimated R.
      count: scalar float, updates so far.
      bounded: scalar bool, the last update of R was clipped to [r_min, r_max] x the model's variances.
    """

    Q: jax.Array
    R: jax.Array
    count: jax.Array
    bounded: jax.Array


class SageHusaInfo(NamedTuple):
    """Per-epoch output of :class:`SageHusa`: the noise used at the epoch.

    Attributes:
      Q: (n, n) G Q G^T.  R: (m, m).
    """

    Q: jax.Array
    R: jax.Array


def _psd_clip(A, floor):
    w, V = jnp.linalg.eigh(symmetrize(A))
    return symmetrize((V * jnp.maximum(w, floor)) @ V.T)


def _bound_variances(A, ref, lo, hi):
    """Scale A congruently, D A D, so that each variance A_ii lies in [lo ref_ii, hi ref_ii].

    D = diag(sqrt(clip(A_ii) / A_ii)) keeps the correlations and positive semi-definiteness.
    Returns (the bounded matrix, bool: some variance was below lo by more than rounding, bool: some
    was above hi or not finite).
    Components with ref_ii <= 0 are left alone.
    """
    a, r = jnp.diagonal(A), jnp.diagonal(ref)
    use = r > 0
    target = jnp.clip(a, lo * r, hi * r)
    ok = use & (a > 0)
    d = jnp.where(ok, jnp.sqrt(jnp.where(ok, target, 1.0) / jnp.where(ok, a, 1.0)), 1.0)
    # a zero (or negative) variance cannot be scaled up: put the lower bound on the diagonal
    A = d[:, None] * A * d[None, :]
    A = A + jnp.diag(jnp.where(use & ~(a > 0), target - a, 0.0))
    low = use & (a < lo * r * (1.0 - 1e-9))
    high = use & ((a > hi * r * (1.0 + 1e-9)) | ~jnp.isfinite(a))
    return symmetrize(A), jnp.any(low), jnp.any(high)


@pytree_dataclass
class SageHusa(NoiseEstimator):
    """Sage-Husa noise estimation with fading weights d_k = (1 - b) / (1 - b^{k+1}), kept PSD.

    With the model's Q, R as the estimate before the first update (k = 0), after the k-th
    observed update:

    * R_k = (1 - d_k) R_{k-1} + d_k (eps eps^T + H P_k H^T), eps = Z_k - H x_k the post-fit
      residual. Both terms are PSD, so R stays PSD; the term is unbiased for an optimal filter.
      An epoch with only some components valid updates their block only and then projects R
      onto the PSD cone (the old cross terms could otherwise make it indefinite).
    * Q_k = (1 - d_k) Q_{k-1} + d_k [K v v^T K^T + P_k - (P_{k,k-1} - Q_{k-1})]_+, the classic
      unbiased increment projected onto the PSD cone (eigenvalues clipped at ``eig_floor``).

    The estimates formed after epoch k are used at epoch k + 1. Q is the effective process noise
    G Q G^T (n, n).

    Notes:
      Each variance of the estimated R is kept within [r_min, r_max] times the model's R_ii, and
      an epoch where a bound acts sets NOISE_ESTIMATE_BOUNDED in ``status``. Below r_min the
      estimate is scaled up to the bound (the congruence D R D, D diagonal, keeps the
      correlations and PSD). Above r_max the estimate restarts from the model's R: the
      residuals are then not measurement noise. Without the bound the estimate has a runaway
      mode: an unmodelled change of dynamics (an acceleration burst the model's Q does not
      allow) shows as large residuals, they are read as measurement noise, the larger R makes
      the filter follow the change even less, and the residuals grow further. On the 3 mm
      constant-velocity scenario of :func:`jaxnav.sim.simulate_cv_scenario` (seed 0, model
      acceleration variance 1e-10 m^2/s^4) the unbounded R reached (7.2 m)^2 and the position
      RMS 2.3 m against 2.2 cm for the classic filter; merely clipping R at 100 R_model still
      gave 1.3-4 m (the filter never caught up), restarting gives 3.0 cm. The default range
      [0.01, 100] lets the estimated standard deviations move by a factor 10 either way from
      the model's; widen it when the model's R is only a rough guess. The bound acts after an
      update and its flag is raised with the next epoch's noise (not after the last epoch).

    Attributes:
      b: scalar array in (0, 1), forgetting factor (larger = longer memory).
      eig_floor: scalar >= 0, eigenvalue floor of the Q increment.
      r_min: scalar array in (0, 1], lower bound of R_ii / R_model_ii.
      r_max: scalar array in [1, inf), upper bound of R_ii / R_model_ii.
      estimate: static, "R", "Q" or "QR".

    Raises:
      ValueError: unknown ``estimate``; concrete b, eig_floor, r_min or r_max out of range (traced
        values are flagged in ``status`` instead).
    """

    ranges: ClassVar[dict] = {
        "b": Range(0.0, 1.0, lo_open=True),
        "eig_floor": Range(0.0),
        "r_min": Range(0.0, 1.0, lo_open=True, hi_open=False),
        "r_max": Range(1.0),
    }

    b: jax.Array = 0.95
    eig_floor: jax.Array = 0.0
    r_min: jax.Array = 1e-2
    r_max: jax.Array = 1e2
    estimate: str = static_field("R")

    def __post_init__(self):
        if self.estimate not in ("R", "Q", "QR"):
            raise ValueError(f"SageHusa: estimate must be 'R', 'Q' or 'QR', got {self.estimate!r}")
        check_ranges("SageHusa", self.ranges, b=self.b, eig_floor=self.eig_floor, r_min=self.r_min, r_max=self.r_max)
        for name in ("b", "eig_floor", "r_min", "r_max"):
            object.__setattr__(self, name, leaf(getattr(self, name)))

    def init(self, n, m, p, dtype):
        return SageHusaState(
            Q=jnp.zeros((n, n), dtype),
            R=jnp.zeros((m, m), dtype),
            count=jnp.zeros((), dtype),
            bounded=jnp.zeros((), bool),
        )

    def noise(self, state, ctx):
        first = state.count == 0
        Q = jnp.where(first, symmetrize(ctx.GQG), state.Q) if "Q" in self.estimate else ctx.GQG
        R = jnp.where(first, symmetrize(ctx.R), state.R) if "R" in self.estimate else ctx.R
        st = state._replace(Q=Q, R=R)
        flags = range_flags(self, self.ranges) | jnp.where(state.bounded, _status.NOISE_ESTIMATE_BOUNDED, 0)
        return Q, R, st, (SageHusaInfo(Q=Q, R=R), flags.astype(jnp.int32))

    def after(self, state, ctx, post):
        dt = post.P.dtype
        b = jnp.asarray(self.b, dt)
        obs = ctx.observed
        c = state.count + 1.0
        d = (1.0 - b) / (1.0 - b ** (c + 1.0))
        Q, R = state.Q, state.R
        bounded = jnp.zeros((), bool)
        if "R" in self.estimate:
            Rinc = jnp.outer(post.eps, post.eps) + ctx.H @ post.P @ ctx.H.T
            both = ctx.valid[:, None] & ctx.valid[None, :]
            R = jnp.where(both & obs, symmetrize((1.0 - d) * R + d * Rinc), R)
            # a partially observed epoch updates only the valid block; with the old cross terms
            # the whole R can turn indefinite, so project it back onto the PSD cone then
            partial = obs & ~jnp.all(ctx.valid)
            R = jnp.where(partial, _psd_clip(R, jnp.zeros((), dt)), R)
            R, low, high = _bound_variances(R, ctx.R, jnp.asarray(self.r_min, dt), jnp.asarray(self.r_max, dt))
            # above r_max the residuals are not measurement noise (an unmodelled change of dynamics):
            # restart from the model's R, which lets the filter follow the change as the classic one does
            R = jnp.where(high & obs, symmetrize(ctx.R), R)
            bounded = (low | high) & obs
        if "Q" in self.estimate:
            Kv = post.K @ ctx.v
            Qinc = jnp.outer(Kv, Kv) + post.P - (post.P_pred - state.Q)
            Qnew = (1.0 - d) * Q + d * _psd_clip(Qinc, jnp.asarray(self.eig_floor, dt))
            Q = jnp.where(obs, symmetrize(Qnew), Q)
        return SageHusaState(Q=Q, R=R, count=jnp.where(obs, c, state.count), bounded=bounded)


def variance_compensation(
    window: int = 30, *, horizon: int = 1, floor=0.0, floor_rel=1e-2, ridge=0.0, min_epochs: int | None = None
) -> VarianceCompensation:
    """Variance-compensation estimator of diag(D_Omega) (S1 eqs. (12)-(19)); see the class.

    Args:
      window: static int N >= 1, epochs in the least-squares window.
      horizon: static int I >= 1, residuals of 1..I-step predictions per epoch (S1 eq. (12)).
      floor: absolute lower bound of each estimated variance (units of Q).
      floor_rel: lower bound relative to the model's diag(Q) (default 1e-2).
      ridge: explicit ridge added to A^T A (default 0).
      min_epochs: epochs required before the estimate replaces the model Q (default N).

    Raises:
      ValueError: window, horizon or min_epochs not a positive integer; negative floor, floor_rel, ridge.
    """
    return VarianceCompensation(
        floor=floor, floor_rel=floor_rel, ridge=ridge, window=window, horizon=horizon, min_epochs=min_epochs
    )


def sage_husa(b=0.95, *, estimate: str = "R", eig_floor=0.0, r_min=1e-2, r_max=1e2) -> SageHusa:
    """Sage-Husa adaptive noise estimation in a PSD-preserving form, R bounded; see :class:`SageHusa`.

    Args:
      b: forgetting factor in (0, 1).
      estimate: "R" (measurement noise), "Q" (process noise) or "QR".
      eig_floor: eigenvalue floor of the Q increment (>= 0).
      r_min, r_max: range of each estimated variance R_ii relative to the model's, 0 < r_min <= 1
        <= r_max (default 0.01, 100: standard deviations within a factor 10 of the model's).

    Raises:
      ValueError: unknown ``estimate``; concrete b, eig_floor, r_min or r_max out of range (traced
        values are flagged in ``status`` instead).
    """
    return SageHusa(b=b, eig_floor=eig_floor, r_min=r_min, r_max=r_max, estimate=estimate)
