"""Noise estimators that plug into the shared filter step: variance compensation, Sage-Husa.

An estimator is a frozen dataclass pytree with three methods:

* ``init(n, m, p, dtype) -> state``
* ``noise(state, ctx) -> (GQG, R, state, info)``: the process noise G Q G^T (n, n) and the
  measurement noise R (m, m) to use at epoch k, given the innovation of that epoch;
* ``after(state, ctx, post) -> state``: learn from the update (post-fit quantities).
"""

from __future__ import annotations

import dataclasses
from typing import Any, NamedTuple, Optional

import jax
import jax.numpy as jnp

from jaxnav import _status
from jaxnav._numerics import as_leaf, cho_solve, cholesky, symmetrize


class PostUpdate(NamedTuple):
    """What the update produced at epoch k (for estimators that learn after it)."""

    x: Any  # (n,) filtered mean
    P: Any  # (n, n) filtered covariance
    K: Any  # (n, m) gain (zero columns for invalid components)
    eps: Any  # (m,) post-fit residual Z - H x (zero where invalid)
    P_pred: Any  # (n, n) the prior covariance used


class NoEstimator:
    """Keep the model's Q and R (the default)."""

    def init(self, n, m, p, dtype):
        return ()

    def noise(self, state, ctx):
        return ctx.GQG, ctx.R, state, ((), jnp.zeros((), jnp.int32))

    def after(self, state, ctx, post):
        return state


jax.tree_util.register_pytree_node(NoEstimator, lambda s: ((), None), lambda a, c: NoEstimator())


class VCState(NamedTuple):
    """Window of per-epoch equations E_j = A_j diag(D_Omega) + eta (S1 eqs. (12)-(18))."""

    E: Any  # (N, m) diag(v v^T) - known part
    A: Any  # (N, m, p) (H G)^2 element-wise
    W: Any  # (N, m) weights 1/0 of valid components
    pos: Any  # int32 ring position
    count: Any  # int32 epochs stored


class VCInfo(NamedTuple):
    """Per-epoch output: q is diag(D_Omega) used at the epoch; estimated says it was not the prior."""

    q: Any  # (p,)
    estimated: Any  # bool


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class VarianceCompensation:
    """Variance-compensation adaptive filter: diag(D_Omega) by windowed least squares (S1 eqs. (12)-(19)).

    For every observed epoch j the one-step predicted residual v_j (S1 eq. (12) with i = 1)
    satisfies E[v_j v_j^T] = H F P_{j-1} F^T H^T + H G D_Omega G^T H^T + R_j. Its diagonal gives
    m linear equations in the p unknowns q = diag(D_Omega):
    E_j = diag(v_j v_j^T) - diag(H F P_{j-1} F^T H^T + R_j) = A_j q + eta_j, A_j = (H G)^{o2}.
    The last ``window`` observed epochs are stacked and solved by least squares,
    q = (A^T A + ridge I)^{-1} A^T E (eq. (19)), each component floored at
    ``max(floor, floor_rel * diag(Q_model))``, and G diag(q) G^T replaces G Q G^T at epoch k.

    Notes:
      The current epoch's innovation is part of the window (it does not depend on Q). Until
      ``min_epochs`` epochs are stored, or when the normal matrix is singular, the model's Q is
      used (a singular system also sets the ESTIMATOR_FALLBACK status flag). The i-step
      residuals of S1 for i > 1 add no unknowns and are not used. Default floor: 1e-4 of the
      model's diag(Q), so the estimate never collapses to zero (which would freeze the filter).

    Attributes:
      floor: scalar or (p,) absolute lower bound of q.
      floor_rel: scalar, lower bound relative to the model's diag(Q).
      ridge: scalar >= 0 added to the normal matrix (explicit jitter; default 0).
      window: static int N, epochs in the least-squares window.
      min_epochs: static int, epochs needed before estimating (default: window).
    """

    floor: Any = 0.0
    floor_rel: Any = 1e-4
    ridge: Any = 0.0
    window: int = dataclasses.field(default=30, metadata=dict(static=True))
    min_epochs: Optional[int] = dataclasses.field(default=None, metadata=dict(static=True))

    def init(self, n, m, p, dtype):
        N = int(self.window)
        return VCState(
            E=jnp.zeros((N, m), dtype),
            A=jnp.zeros((N, m, p), dtype),
            W=jnp.zeros((N, m), dtype),
            pos=jnp.zeros((), jnp.int32),
            count=jnp.zeros((), jnp.int32),
        )

    def noise(self, state, ctx):
        dt = ctx.FPF.dtype
        N = int(self.window)
        need = N if self.min_epochs is None else int(self.min_epochs)
        w = ctx.valid.astype(dt)
        HG = ctx.H @ ctx.G
        A_k = HG * HG
        known = jnp.diagonal(ctx.H @ ctx.FPF @ ctx.H.T) + jnp.diagonal(ctx.R_used)
        E_k = jnp.where(ctx.valid, ctx.v * ctx.v - known, 0.0)
        obs = ctx.observed
        st = VCState(
            E=jnp.where(obs, state.E.at[state.pos].set(E_k), state.E),
            A=jnp.where(obs, state.A.at[state.pos].set(A_k), state.A),
            W=jnp.where(obs, state.W.at[state.pos].set(w), state.W),
            pos=jnp.where(obs, (state.pos + 1) % N, state.pos),
            count=jnp.minimum(state.count + obs.astype(jnp.int32), N),
        )
        AW = st.A * st.W[:, :, None]
        p = A_k.shape[-1]
        Nmat = jnp.einsum("jip,jiq->pq", AW, st.A) + jnp.asarray(self.ridge, dt) * jnp.eye(p, dtype=dt)
        rhs = jnp.einsum("jip,ji->p", AW, st.E)
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
        return GQG, ctx.R_used, st, (VCInfo(q=q_used, estimated=ok), flag)

    def after(self, state, ctx, post):
        return state


class SageHusaState(NamedTuple):
    """Current noise estimates and the number of updates that formed them."""

    Q: Any  # (n, n) estimated G Q G^T
    R: Any  # (m, m) estimated R
    count: Any  # float, updates so far


class SageHusaInfo(NamedTuple):
    """Per-epoch output: the noise used at the epoch."""

    Q: Any  # (n, n)
    R: Any  # (m, m)


def _psd_clip(A, floor):
    w, V = jnp.linalg.eigh(symmetrize(A))
    return symmetrize((V * jnp.maximum(w, floor)) @ V.T)


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class SageHusa:
    """Sage-Husa noise estimation with fading weights d_k = (1 - b) / (1 - b^{k+1}), kept PSD.

    With the model's Q, R as the estimate before the first update (k = 0), after the k-th
    observed update:

    * R_k = (1 - d_k) R_{k-1} + d_k (eps eps^T + H P_k H^T), eps = Z_k - H x_k the post-fit
      residual. Both terms are PSD, so R stays PSD; the term is unbiased for an optimal filter.
    * Q_k = (1 - d_k) Q_{k-1} + d_k [K v v^T K^T + P_k - (P_{k,k-1} - Q_{k-1})]_+, the classic
      unbiased increment projected onto the PSD cone (eigenvalues clipped at ``eig_floor``).

    The estimates formed after epoch k are used at epoch k + 1. Q is the effective process noise
    G Q G^T (n, n).

    Attributes:
      b: scalar array in (0, 1), forgetting factor (larger = longer memory).
      eig_floor: scalar >= 0, eigenvalue floor of the Q increment.
      estimate: static, "R", "Q" or "QR".
    """

    b: Any = 0.95
    eig_floor: Any = 0.0
    estimate: str = dataclasses.field(default="R", metadata=dict(static=True))

    def init(self, n, m, p, dtype):
        return SageHusaState(Q=jnp.zeros((n, n), dtype), R=jnp.zeros((m, m), dtype), count=jnp.zeros((), dtype))

    def noise(self, state, ctx):
        first = state.count == 0
        Q = jnp.where(first, symmetrize(ctx.GQG), state.Q) if "Q" in self.estimate else ctx.GQG
        R = jnp.where(first, symmetrize(ctx.R), state.R) if "R" in self.estimate else ctx.R
        st = state._replace(Q=Q, R=R)
        return Q, R, st, (SageHusaInfo(Q=Q, R=R), jnp.zeros((), jnp.int32))

    def after(self, state, ctx, post):
        dt = post.P.dtype
        b = jnp.asarray(self.b, dt)
        obs = ctx.observed
        c = state.count + 1.0
        d = (1.0 - b) / (1.0 - b ** (c + 1.0))
        Q, R = state.Q, state.R
        if "R" in self.estimate:
            Rinc = jnp.outer(post.eps, post.eps) + ctx.H @ post.P @ ctx.H.T
            both = ctx.valid[:, None] & ctx.valid[None, :]
            R = jnp.where(both & obs, symmetrize((1.0 - d) * R + d * Rinc), R)
        if "Q" in self.estimate:
            Kv = post.K @ ctx.v
            Qinc = jnp.outer(Kv, Kv) + post.P - (post.P_pred - state.Q)
            Qnew = (1.0 - d) * Q + d * _psd_clip(Qinc, jnp.asarray(self.eig_floor, dt))
            Q = jnp.where(obs, symmetrize(Qnew), Q)
        return SageHusaState(Q=Q, R=R, count=jnp.where(obs, c, state.count))


def variance_compensation(window: int = 30, *, floor=0.0, floor_rel=1e-4, ridge=0.0,
                          min_epochs: Optional[int] = None) -> VarianceCompensation:
    """Variance-compensation estimator of diag(D_Omega) (S1 eqs. (12)-(19)); see the class.

    Args:
      window: static int N >= 1, epochs in the least-squares window.
      floor: absolute lower bound of each estimated variance (units of Q).
      floor_rel: lower bound relative to the model's diag(Q) (default 1e-4).
      ridge: explicit ridge added to A^T A (default 0).
      min_epochs: epochs required before the estimate replaces the model Q (default N).

    Raises:
      ValueError: window or min_epochs not a positive integer.
    """
    if int(window) != window or window < 1:
        raise ValueError(f"variance_compensation(): window must be a positive integer, got {window!r}")
    if min_epochs is not None and (int(min_epochs) != min_epochs or not 1 <= min_epochs <= window):
        raise ValueError(f"variance_compensation(): min_epochs must be in 1..window, got {min_epochs!r}")
    return VarianceCompensation(
        floor=as_leaf(floor), floor_rel=as_leaf(floor_rel), ridge=as_leaf(ridge),
        window=int(window), min_epochs=None if min_epochs is None else int(min_epochs),
    )


def sage_husa(b=0.95, *, estimate: str = "R", eig_floor=0.0) -> SageHusa:
    """Sage-Husa adaptive noise estimation in a PSD-preserving form; see :class:`SageHusa`.

    Args:
      b: forgetting factor in (0, 1).
      estimate: "R" (measurement noise), "Q" (process noise) or "QR".
      eig_floor: eigenvalue floor of the Q increment.

    Raises:
      ValueError: unknown ``estimate``.
    """
    if estimate not in ("R", "Q", "QR"):
        raise ValueError(f"sage_husa(): estimate must be 'R', 'Q' or 'QR', got {estimate!r}")
    return SageHusa(b=as_leaf(b), eig_floor=as_leaf(eig_floor), estimate=estimate)
