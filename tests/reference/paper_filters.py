"""Plain-NumPy float64 reference loops of the S0 / S1 filters, written from the paper equations.

These are deliberately naive: one Python loop over the epochs, explicit matrix inverses, the
paper's covariance update P = (I - K H) P_pred (S0 eq. (9)) rather than the Joseph form, and
the innovation statistics kept as full m x m matrices. They share nothing with ``jaxnav`` and
serve as the oracle in ``tests/test_adaptive_reference.py``.

Conventions (``/work/shared/spec/SEEDS.md`` S0 eqs. (4)-(9)):

* ``x0, P0`` are the estimate at k = 0; measurement ``zs[t]`` is epoch k = t + 1 and is used
  after one prediction, so the first prediction has k = 1.
* Model leaves ``F, H, Q, R, G`` are static ((n, n), (m, n), (p, p), (m, m), (n, p)) or
  time-varying with a leading axis T; ``F[t]`` is the transition into epoch k = t + 1.
  The process noise is Gamma Q Gamma^T when ``G`` is given, else ``Q`` itself.
* A measurement row that is not all finite is skipped: the prediction is returned as the
  estimate (no update). Only whole rows may be missing in these references.

Every function returns a :class:`RefResult` with per-epoch arrays stacked over t.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "RefResult",
    "attenuated_factors",
    "attenuated_update_factors",
    "inflated_kf",
    "classic_kf",
    "constant_kf",
    "attenuated_kf",
    "fading_kf",
    "variance_compensation_kf",
    "sage_husa_kf",
]


# --------------------------------------------------------------------------------------------
# small helpers
# --------------------------------------------------------------------------------------------


@dataclass
class RefResult:
    """Per-epoch outputs of a reference loop (leading axis T)."""

    means: np.ndarray  # X_k
    covs: np.ndarray  # P_k
    pred_means: np.ndarray  # X_{k,k-1}
    pred_covs: np.ndarray  # P_{k,k-1}, after inflation / noise estimation
    innovations: np.ndarray  # v_k (zeros where skipped)
    innov_covs: np.ndarray  # H P_{k,k-1} H^T + R
    factors: np.ndarray  # inflation factor used in the prediction (1, S, S_k or lambda_k)
    nis: np.ndarray  # v^T S^{-1} v (0 where skipped)
    logliks: np.ndarray  # log N(v; 0, S) (0 where skipped)
    extra: dict = field(default_factory=dict)  # filter-specific outputs (q, Q, R, ...)


def _leaf(A, t, static_ndim):
    """The leaf at output index t (A[t] if A is time-varying)."""
    if A is None:
        return None
    A = np.asarray(A, dtype=np.float64)
    return A[t] if A.ndim == static_ndim + 1 else A


def _model_at(model, t):
    """(F, H, Q, R, G) at output index t; G may be None."""
    return (
        _leaf(model.F, t, 2),
        _leaf(model.H, t, 2),
        _leaf(model.Q, t, 2),
        _leaf(model.R, t, 2),
        _leaf(getattr(model, "G", None), t, 2),
    )


def _gamma_q_gamma(G, Q):
    """Gamma Q Gamma^T (S0 eq. (8)); Q itself when the model has no Gamma."""
    return Q if G is None else G @ Q @ G.T


def _observed(z):
    z = np.asarray(z, dtype=np.float64)
    fin = np.isfinite(z)
    if fin.any() and not fin.all():
        raise NotImplementedError("reference loops only skip whole measurement rows")
    return bool(fin.all())


def _update(x_pred, P_pred, z, H, R):
    """Measurement update in the paper's form (S0 eqs. (5), (7), (9); S1 eqs. (7)-(11)).

    v_k = Z_k - H X_{k,k-1}                          (S0 eq. (5), (17))
    K_k = P_{k,k-1} H^T (H P_{k,k-1} H^T + R)^{-1}  (S0 eq. (7))
    X_k = X_{k,k-1} + K_k v_k                        (S0 eq. (5))
    P_k = (I - K_k H) P_{k,k-1}                      (S0 eq. (9))
    """
    n = x_pred.shape[0]
    v = z - H @ x_pred
    S = H @ P_pred @ H.T + R
    K = P_pred @ H.T @ np.linalg.inv(S)
    x = x_pred + K @ v
    P = (np.eye(n) - K @ H) @ P_pred
    return x, P, v, S, K


class _Recorder:
    """Collects the per-epoch quantities and stacks them into a RefResult."""

    def __init__(self):
        self.rows = {
            k: []
            for k in (
                "means",
                "covs",
                "pred_means",
                "pred_covs",
                "innovations",
                "innov_covs",
                "factors",
                "nis",
                "logliks",
            )
        }
        self.extra = {}

    def add(self, x, P, x_pred, P_pred, v, S, factor, observed, **extra):
        if observed:
            nis = float(v @ np.linalg.inv(S) @ v)
            loglik = -0.5 * (nis + np.log(np.linalg.det(2.0 * np.pi * S)))
        else:
            nis = loglik = 0.0
        for name, val in (
            ("means", x),
            ("covs", P),
            ("pred_means", x_pred),
            ("pred_covs", P_pred),
            ("innovations", v),
            ("innov_covs", S),
            ("factors", factor),
            ("nis", nis),
            ("logliks", loglik),
        ):
            self.rows[name].append(np.array(val, dtype=np.float64))
        for name, val in extra.items():
            self.extra.setdefault(name, []).append(np.array(val))

    def result(self):
        return RefResult(
            **{k: np.stack(v) for k, v in self.rows.items()}, extra={k: np.stack(v) for k, v in self.extra.items()}
        )


def _step_update(x_pred, P_pred, z, H, R):
    """Update if Z_k is observed, else return the prediction as the estimate."""
    observed = _observed(z)
    if observed:
        x, P, v, S, _ = _update(x_pred, P_pred, np.asarray(z, np.float64), H, R)
    else:
        x, P, v, S = x_pred, P_pred, np.zeros(H.shape[0]), H @ P_pred @ H.T + R
    return x, P, v, S, observed


# --------------------------------------------------------------------------------------------
# classic, constant and attenuated-memory filters (S0 eqs. (4)-(12))
# --------------------------------------------------------------------------------------------


def attenuated_factors(b, T):
    """S_k = (1 - b^k) / (1 - b) for k = 1..T (S0 eq. (11)); S_1 = 1."""
    k = np.arange(1, T + 1, dtype=np.float64)
    return (1.0 - float(b) ** k) / (1.0 - float(b))


def inflated_kf(model, x0, P0, zs, factors) -> RefResult:
    """Kalman filter with a prescribed inflation sequence f_k of F P F^T.

    X_{k,k-1} = Phi X_{k-1}                                 (S0 eq. (4))
    P_{k,k-1} = Phi [f_k P_{k-1}] Phi^T + Gamma Q Gamma^T   (S0 eq. (8) f=1, (10) f=S, (12) f=S_k)
    then the update (S0 eqs. (5), (7), (9)).
    """
    zs = np.asarray(zs, dtype=np.float64)
    x, P = np.array(x0, np.float64), np.array(P0, np.float64)
    rec = _Recorder()
    for t in range(zs.shape[0]):
        F, H, Q, R, G = _model_at(model, t)
        f = float(factors[t])
        x_pred = F @ x  # (4)
        P_pred = F @ (f * P) @ F.T + _gamma_q_gamma(G, Q)  # (8) / (10) / (12)
        x, P, v, S, obs = _step_update(x_pred, P_pred, zs[t], H, R)  # (5), (7), (9)
        rec.add(x, P, x_pred, P_pred, v, S, f, obs)
    return rec.result()


def classic_kf(model, x0, P0, zs) -> RefResult:
    """The classic Kalman filter, S0 eqs. (4)-(9)."""
    return inflated_kf(model, x0, P0, zs, np.ones(np.shape(zs)[0]))


def constant_kf(model, x0, P0, zs, S) -> RefResult:
    """Constant inflation S, S0 eq. (10)."""
    return inflated_kf(model, x0, P0, zs, np.full(np.shape(zs)[0], float(S)))


def attenuated_update_factors(b, zs):
    """The attenuated-memory factor of each epoch when k counts filter updates (S0 eq. (11)).

    k advances only at an observed epoch (a measurement row that is all finite), which gets
    S_k = (1 - b^k) / (1 - b); an epoch without a measurement gets 1 and leaves k unchanged.
    """
    f, k = [], 0
    for z in np.asarray(zs, dtype=np.float64):
        if _observed(z):
            k += 1
            f.append((1.0 - float(b) ** k) / (1.0 - float(b)))
        else:
            f.append(1.0)
    return np.array(f)


def attenuated_kf(model, x0, P0, zs, b) -> RefResult:
    """Attenuated-memory filter, S0 eqs. (11)-(12): S_k counts filter updates (epochs with a
    measurement); the prediction into an epoch without one uses the factor 1 (classic, eq. (8))."""
    return inflated_kf(model, x0, P0, zs, attenuated_update_factors(b, zs))


# --------------------------------------------------------------------------------------------
# fading-memory filter (S0 eqs. (13)-(17))
# --------------------------------------------------------------------------------------------


def fading_kf(
    model, x0, P0, zs, *, window: int | None = None, rho=None, absolute=True, smooth=None, max_factor=None
) -> RefResult:
    """Fading-memory filter, S0 eqs. (13)-(17).

    lambda_k = max{1, |tr N_k / tr M_k|}                       (14)  (no |.| if absolute=False)
    N_k = P_vk - H Gamma Q Gamma^T H^T - R_k,  M_k = H Phi P_{k-1} Phi^T H^T   (15)
    P_vk: mean of v_i v_i^T over the last ``window`` observed epochs incl. k  (16), the 1/n of (14)
          or, with ``rho``, C_1 = v_1 v_1^T, C_k = (rho C_{k-1} + v_k v_k^T) / (1 + rho)
    v_k = Z_k - H X_{k,k-1}                                     (17)
    P_{k,k-1} = lambda_k Phi P_{k-1} Phi^T + Gamma Q Gamma^T    (13)

    Skipped epochs: lambda_k = 1 and the innovation statistics are left unchanged.
    ``smooth=tau`` replaces max(1, x) by 1 + tau * log(1 + exp((x - 1) / tau)).
    ``max_factor``: lambda_k = min(lambda_k, max_factor) (None: uncapped, eq. (14) as printed).
    """
    if window is not None and rho is not None:
        raise ValueError("window or rho, not both")
    n_win = 1 if window is None else int(window)
    zs = np.asarray(zs, dtype=np.float64)
    x, P = np.array(x0, np.float64), np.array(P0, np.float64)
    history = []  # v_i v_i^T of the observed epochs
    C = None  # recursive estimate of P_v
    rec = _Recorder()
    for t in range(zs.shape[0]):
        F, H, Q, R, G = _model_at(model, t)
        GQG = _gamma_q_gamma(G, Q)
        x_pred = F @ x  # (4)
        FPF = F @ P @ F.T
        lam = 1.0
        trN = trM = np.nan
        if _observed(zs[t]):
            v = zs[t] - H @ x_pred  # (17)
            vvT = np.outer(v, v)
            if rho is None:
                history.append(vvT)
                P_v = np.mean(history[-n_win:], axis=0)  # (16) with the 1/n of (14)
            else:
                C = vvT if C is None else (float(rho) * C + vvT) / (1.0 + float(rho))
                P_v = C
            N = P_v - H @ GQG @ H.T - R  # (15)
            M = H @ FPF @ H.T  # (15), P_{k-1} as meant
            trN, trM = np.trace(N), np.trace(M)
            ratio = trN / trM
            if absolute:
                ratio = abs(ratio)
            if smooth is None:
                lam = max(1.0, ratio)  # (14)
            else:
                tau = float(smooth)
                lam = 1.0 + tau * np.logaddexp(0.0, (ratio - 1.0) / tau)
            if max_factor is not None:
                lam = min(lam, float(max_factor))
        P_pred = lam * FPF + GQG  # (13)
        x, P, v, S, obs = _step_update(x_pred, P_pred, zs[t], H, R)
        rec.add(x, P, x_pred, P_pred, v, S, lam, obs, trN=trN, trM=trM)
    return rec.result()


# --------------------------------------------------------------------------------------------
# variance-compensation adaptive filter (S1 eqs. (7)-(19))
# --------------------------------------------------------------------------------------------


def _transition(Phis, k, j):
    """Phi_{k,j} = Phi_k Phi_{k-1} ... Phi_{j+1} (Phi_{k,k} = I); Phis[r] is the transition into r."""
    M = np.eye(Phis[k].shape[0])
    for r in range(j + 1, k + 1):
        M = Phis[r] @ M
    return M


def variance_compensation_kf(
    model, x0, P0, zs, *, window=30, horizon=1, floor=0.0, floor_rel=1e-2, ridge=0.0, min_epochs=None
) -> RefResult:
    """Variance-compensation adaptive filter, S1 eqs. (7)-(19).

    At epoch k, for every prediction step i = 1..horizon with k - i >= 0, the i-step predicted
    residual and its covariance are (S1 eqs. (12)-(16))
        V_{k,i} = L_k - B_k Phi_{k,k-i} X(k-i/k-i),   Phi_{k,j} = Phi_k Phi_{k-1} ... Phi_{j+1}
        D_vv    = B Phi_{k,k-i} D_X(k-i/k-i) Phi_{k,k-i}^T B^T
                  + sum_{r=k-i+1}^{k} B Phi_{k,r} Gamma_r D_Omega Gamma_r^T Phi_{k,r}^T B^T + D_Delta
    Its diagonal gives m equations in q = diag(D_Omega) (eqs. (17)-(18)):
        E_{k,i} = diag(V V^T) - diag(B Phi D_X Phi^T B^T + D_Delta) = A_{k,i} q + eta,
        A_{k,i} = sum_r (B Phi_{k,r} Gamma_r)^2 element-wise
    (Gamma_r: the noise input of the transition into epoch r). The equations of the last N
    observed epochs (the current one included) are stacked and solved
        q = (A^T A + ridge I)^{-1} A^T E                                            (S1 (19))
    then floored, q >= max(floor, floor_rel * diag(D_Omega_model)), and
        D_X(k/k-1) = Phi D_X(k-1/k-1) Phi^T + Gamma diag(q) Gamma^T                 (S1 (10))
    replaces the model D_Omega at the current epoch. Until ``min_epochs`` (default N) observed
    epochs are stored the model D_Omega is used. X(j/j), D_X(j/j) are this filter's own earlier
    estimates (at a skipped epoch, its prediction); horizon = 1 is the one-step innovation form.

    ``extra['q']`` (T, p): diag(D_Omega) used; ``extra['estimated']`` (T,) bool.
    """
    N, I = int(window), int(horizon)
    need = N if min_epochs is None else int(min_epochs)
    zs = np.asarray(zs, dtype=np.float64)
    x, P = np.array(x0, np.float64), np.array(P0, np.float64)
    posts = [(x, P)]  # posts[j] = (X(j/j), D_X(j/j)), j = 0, 1, ...
    Phis, Gammas = [None], [None]  # Phis[j], Gammas[j]: transition and noise input into epoch j
    eqs = []  # (E_k, A_k) stacked over i, one entry per observed epoch
    rec = _Recorder()
    for t in range(zs.shape[0]):
        k = t + 1
        F, H, Q, R, G = _model_at(model, t)
        if G is None:
            G = np.eye(F.shape[0])
        Phis.append(F)
        Gammas.append(G)

        x_pred = F @ x  # X(k/k-1) = Phi X(k-1/k-1)
        FPF = F @ P @ F.T
        if _observed(zs[t]):
            E_k, A_k = [], []
            for i in range(1, min(I, k) + 1):
                x_i, P_i = posts[k - i]
                Phi_ki = _transition(Phis, k, k - i)  # Phi_{k,k-i}
                V = zs[t] - H @ Phi_ki @ x_i  # (12)
                known = np.diag(H @ Phi_ki @ P_i @ Phi_ki.T @ H.T + R)  # (13)-(16) without D_Omega
                A = sum((H @ _transition(Phis, k, r) @ Gammas[r]) ** 2 for r in range(k - i + 1, k + 1))  # (18)
                E_k.append(V * V - known)  # (17)
                A_k.append(A)
            eqs.append((np.concatenate(E_k), np.concatenate(A_k, axis=0)))
        q = np.diag(Q).copy()
        estimated = False
        win = eqs[-N:]
        if len(win) >= need:
            E = np.concatenate([e for e, _ in win])
            A = np.concatenate([a for _, a in win], axis=0)
            p = A.shape[1]
            q = np.linalg.solve(A.T @ A + float(ridge) * np.eye(p), A.T @ E)  # (19)
            lower = np.maximum(np.broadcast_to(np.asarray(floor, np.float64), q.shape), float(floor_rel) * np.diag(Q))
            q = np.maximum(q, lower)  # negative components clipped to a positive floor
            estimated = True
        GQG = G @ np.diag(q) @ G.T if estimated else _gamma_q_gamma(G, Q)
        P_pred = FPF + GQG  # (10)
        x, P, v, S, obs = _step_update(x_pred, P_pred, zs[t], H, R)  # (7)-(11)
        posts.append((x, P))
        rec.add(x, P, x_pred, P_pred, v, S, 1.0, obs, q=q, estimated=estimated)
    return rec.result()


# --------------------------------------------------------------------------------------------
# Sage-Husa noise estimation (jaxnav's documented PSD-preserving form; not in S0/S1)
# --------------------------------------------------------------------------------------------


def sage_husa_kf(model, x0, P0, zs, *, b=0.95, estimate="R", eig_floor=0.0, r_min=1e-2, r_max=1e2) -> RefResult:
    """Sage-Husa adaptive filter as documented in ``jaxnav.filters.SageHusa``.

    Start: Qhat_0 = Gamma Q Gamma^T, Rhat_0 = R (the model's, used at the first epoch).
    After the c-th observed update, with d_c = (1 - b) / (1 - b^{c+1}):
        Rhat_c = (1 - d_c) Rhat_{c-1} + d_c (eps eps^T + H P_k H^T),   eps = Z_k - H X_k
        Qhat_c = (1 - d_c) Qhat_{c-1}
                 + d_c [K v v^T K^T + P_k - (P_{k,k-1} - Qhat_{c-1})]_+ (eigenvalues >= eig_floor)
    and the estimates are used in the next epoch's prediction / update. Then each variance of Rhat
    is bounded by the model's R_ii: if some Rhat_ii > r_max R_ii, Rhat restarts as the model's R;
    else a variance below r_min R_ii is raised to it by Rhat <- D Rhat D, D_ii = sqrt(r_min R_ii / Rhat_ii).

    ``extra['Q']`` (T, n, n) and ``extra['R']`` (T, m, m): the noise used at each epoch.
    """
    zs = np.asarray(zs, dtype=np.float64)
    x, P = np.array(x0, np.float64), np.array(P0, np.float64)
    Qhat = Rhat = None
    c = 0
    b = float(b)
    rec = _Recorder()
    for t in range(zs.shape[0]):
        F, H, Q, R, G = _model_at(model, t)
        if c == 0:  # no update yet: the model's noise
            Qhat = _gamma_q_gamma(G, Q) if "Q" in estimate else None
            Rhat = R if "R" in estimate else None
        Q_used = Qhat if "Q" in estimate else _gamma_q_gamma(G, Q)
        R_used = Rhat if "R" in estimate else R
        x_pred = F @ x  # (4)
        P_pred = F @ P @ F.T + Q_used  # (8)
        obs = _observed(zs[t])
        if obs:
            x, P, v, S, K = _update(x_pred, P_pred, zs[t], H, R_used)
            c += 1
            d = (1.0 - b) / (1.0 - b ** (c + 1))
            if "R" in estimate:
                eps = zs[t] - H @ x
                Rhat = (1.0 - d) * Rhat + d * (np.outer(eps, eps) + H @ P @ H.T)
                ratio = np.diag(Rhat) / np.diag(R)
                if np.any(ratio > r_max):
                    Rhat = np.array(R, np.float64)
                else:
                    D = np.diag(np.sqrt(np.maximum(ratio, r_min) / ratio))
                    Rhat = D @ Rhat @ D
            if "Q" in estimate:
                Kv = K @ v
                inc = np.outer(Kv, Kv) + P - (P_pred - Qhat)
                w, U = np.linalg.eigh(0.5 * (inc + inc.T))
                inc = U @ np.diag(np.maximum(w, float(eig_floor))) @ U.T
                Qhat = (1.0 - d) * Qhat + d * inc
        else:
            x, P, v, S = x_pred, P_pred, np.zeros(H.shape[0]), H @ P_pred @ H.T + R_used
        rec.add(x, P, x_pred, P_pred, v, S, 1.0, obs, Q=Q_used, R=R_used)
    return rec.result()
