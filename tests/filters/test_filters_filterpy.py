"""Classic KF, constant-S inflation and RTS against filterpy (an outside reference) and a dense solve."""

import numpy as np
import pytest
from _models import random_stable_model, simulate
from filterpy.kalman import KalmanFilter

from jaxnav import filters as jf

SHAPES = [(2, 1), (4, 2), (6, 3), (9, 6), (5, 4)]
CASES = [(n, m, seed, tv) for (n, m) in SHAPES for seed in range(2) for tv in (False, True)]
T = 200


def _filterpy_run(F, H, Q, R, x0, P0, zs, alpha=1.0):
    n, m = x0.shape[0], zs.shape[1]
    kf = KalmanFilter(dim_x=n, dim_z=m)
    kf.x, kf.P = x0.copy(), P0.copy()
    kf.alpha = alpha
    tv = F.ndim == 3
    Fs = list(F) if tv else [F] * len(zs)
    Hs = list(H) if tv else [H] * len(zs)
    Qs = list(Q) if tv else [Q] * len(zs)
    Rs = list(R) if tv else [R] * len(zs)
    kf.F, kf.H, kf.Q, kf.R = Fs[0], Hs[0], Qs[0], Rs[0]
    means, covs, mp, Pp, ll = [], [], [], [], 0.0
    for t, z in enumerate(zs):
        kf.predict(F=Fs[t], Q=Qs[t])
        mp.append(kf.x.copy()), Pp.append(kf.P.copy())
        kf.update(z, R=Rs[t], H=Hs[t])
        means.append(kf.x.copy()), covs.append(kf.P.copy())
        ll += kf.log_likelihood
    means, covs = np.array(means), np.array(covs)
    xs_s, Ps_s, _, _ = kf.rts_smoother(means, covs, Fs=Fs, Qs=Qs)
    return dict(means=means, covs=covs, pred_means=np.array(mp), pred_covs=np.array(Pp), loglik=ll, sm=xs_s, sP=Ps_s)


@pytest.fixture(scope="module", params=CASES, ids=lambda c: f"n{c[0]}m{c[1]}s{c[2]}{'tv' if c[3] else ''}")
def case(request):
    n, m, seed, tv = request.param
    rng = np.random.default_rng(1000 + 17 * n + 5 * m + seed + 100 * tv)
    F, H, Q, R = random_stable_model(rng, n, m, T if tv else None)
    x0 = rng.normal(size=n)
    P0 = np.eye(n) * 2.0
    _, zs = simulate(rng, F, H, Q, R, x0, T)
    return dict(F=F, H=H, Q=Q, R=R, x0=x0, P0=P0, zs=zs)


def _rel(a, b):
    return np.max(np.abs(np.asarray(a) - b)) / max(1.0, np.max(np.abs(b)))


def test_kf_and_rts_equal_filterpy(case):
    c = case
    ref = _filterpy_run(c["F"], c["H"], c["Q"], c["R"], c["x0"], c["P0"], c["zs"])
    model = jf.LinearGaussian(c["F"], c["H"], c["Q"], c["R"])
    res = jf.kalman_filter(model, c["x0"], c["P0"], c["zs"])
    for name in ("means", "covs", "pred_means", "pred_covs"):
        assert _rel(getattr(res, name), ref[name]) < 1e-9, name
    assert abs(float(res.loglik) - ref["loglik"]) < 1e-9 * max(1.0, abs(ref["loglik"]))
    sm = jf.rts_smoother(model, res)
    assert _rel(sm.means, ref["sm"]) < 1e-9
    assert _rel(sm.covs, ref["sP"]) < 1e-9
    assert int(res.status) == 0 and int(sm.status) == 0


@pytest.mark.parametrize("alpha", [1.02, 1.2])
def test_constant_inflation_equals_filterpy_alpha(case, alpha):
    c = case
    ref = _filterpy_run(c["F"], c["H"], c["Q"], c["R"], c["x0"], c["P0"], c["zs"], alpha=alpha)
    model = jf.LinearGaussian(c["F"], c["H"], c["Q"], c["R"])
    res = jf.kalman_filter(model, c["x0"], c["P0"], c["zs"], inflation=jf.constant(alpha**2))
    assert _rel(res.means, ref["means"]) < 1e-9
    assert _rel(res.covs, ref["covs"]) < 1e-9
    np.testing.assert_allclose(res.factors, alpha**2, rtol=1e-15)


def _dense_posterior(F, H, Q, R, x0, P0, zs):
    """Joint Gaussian of X = [x_1..x_T] given x_0 ~ N(x0, P0), conditioned on all z (batch solution)."""
    T, m = zs.shape
    n = x0.shape[0]
    # x_t = Phi_t x_0 + sum_{s<=t} Phi_{t,s} w_s : build the linear map from [x_0, w_1..w_T]
    A = np.zeros((T * n, (T + 1) * n))
    Phi = np.eye(n)
    for t in range(T):
        Phi = F @ Phi
        A[t * n : (t + 1) * n, :n] = Phi
        Ps = np.eye(n)
        for s in range(t, -1, -1):
            A[t * n : (t + 1) * n, (s + 1) * n : (s + 2) * n] = Ps
            Ps = Ps @ F
    C0 = np.zeros(((T + 1) * n, (T + 1) * n))
    C0[:n, :n] = P0
    for s in range(T):
        C0[(s + 1) * n : (s + 2) * n, (s + 1) * n : (s + 2) * n] = Q
    mu = A[:, :n] @ x0
    Sig = A @ C0 @ A.T
    Hb = np.kron(np.eye(T), H)
    Rb = np.kron(np.eye(T), R)
    S = Hb @ Sig @ Hb.T + Rb
    K = np.linalg.solve(S, Hb @ Sig).T
    mean = mu + K @ (zs.ravel() - Hb @ mu)
    cov = Sig - K @ Hb @ Sig
    return mean.reshape(T, n), np.array([cov[t * n : (t + 1) * n, t * n : (t + 1) * n] for t in range(T)])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_rts_equals_dense_batch_solution(seed):
    rng = np.random.default_rng(seed)
    n, m, Tb = 4, 2, 30
    F, H, Q, R = random_stable_model(rng, n, m)
    x0, P0 = rng.normal(size=n), np.eye(n)
    _, zs = simulate(rng, F, H, Q, R, x0, Tb)
    model = jf.LinearGaussian(F, H, Q, R)
    sm = jf.rts_smoother(model, jf.kalman_filter(model, x0, P0, zs))
    mean, cov = _dense_posterior(F, H, Q, R, x0, P0, zs)
    np.testing.assert_allclose(sm.means, mean, atol=1e-8 * max(1, np.abs(mean).max()))
    np.testing.assert_allclose(sm.covs, cov, atol=1e-8 * max(1, np.abs(cov).max()))


def test_filter_with_G_equals_filter_with_GQG():
    rng = np.random.default_rng(5)
    model = jf.constant_velocity(2.0, sigma=0.01, accel_var=1e-4)
    dense = jf.LinearGaussian(model.F, model.H, model.G @ model.Q @ model.G.T, model.R)
    zs = np.cumsum(rng.normal(size=(50, 3)) * 0.01, axis=0)
    a = jf.kalman_filter(model, np.zeros(6), np.eye(6), zs)
    b = jf.kalman_filter(dense, np.zeros(6), np.eye(6), zs)
    np.testing.assert_allclose(a.means, b.means, rtol=0, atol=1e-13)
    np.testing.assert_allclose(a.covs, b.covs, rtol=0, atol=1e-13)
