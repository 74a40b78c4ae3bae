"""Nonlinear filters (EKF, iterated EKF, UKF, CKF) and smoothers against filterpy, the linear filter,
a Gauss-Newton solve, finite differences and loops."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from filterpy.kalman import ExtendedKalmanFilter, MerweScaledSigmaPoints, UnscentedKalmanFilter
from scipy.optimize import least_squares

import jaxnav.filters as jf

jax.config.update("jax_enable_x64", True)

T, N, M = 500, 5, 2
STATION = np.array([-200.0, -300.0])
Q = np.diag([0.01, 0.01, 0.01, 1e-5, 1e-6])
R = np.diag([1.0, 1e-4])
X0 = np.array([0.0, 0.0, 5.0, 0.3, 0.01])
P0 = np.diag([10.0, 10.0, 1.0, 0.01, 1e-4])


def turn(x, t, dt=1.0):
    """Coordinated turn: (east, north, speed, heading, turn rate) -> next epoch."""
    px, py, v, th, om = x
    return jnp.array([px + v * jnp.cos(th) * dt, py + v * jnp.sin(th) * dt, v, th + om * dt, om])


def range_bearing(x, t, station=STATION):
    d = x[:2] - station
    return jnp.array([jnp.sqrt(d @ d), jnp.arctan2(d[1], d[0])])


def _simulate(seed=0):
    rng = np.random.default_rng(seed)
    f, h = jax.jit(turn), jax.jit(range_bearing)
    x, xs, zs = X0.copy(), [], []
    for t in range(T):
        x = np.asarray(f(x, t)) + rng.multivariate_normal(np.zeros(N), Q)
        xs.append(x)
        zs.append(np.asarray(h(x, t)) + rng.multivariate_normal(np.zeros(M), R))
    return np.array(xs), np.array(zs)


TRUTH, ZS = _simulate()
MODEL = jf.NonlinearGaussian(turn, range_bearing, Q, R)


def test_ekf_equals_filterpy_with_the_same_nonlinear_prediction():
    res = jf.extended_kalman_filter(MODEL, X0, P0, ZS)
    Fj, Hj, f, h = (jax.jit(g) for g in (jax.jacfwd(turn), jax.jacfwd(range_bearing), turn, range_bearing))
    ek = ExtendedKalmanFilter(N, M)
    ek.x, ek.P, ek.Q, ek.R = X0.copy(), P0.copy(), Q, R
    means, covs = [], []
    for t in range(T):
        F = np.asarray(Fj(ek.x, t))
        ek.x, ek.P = np.asarray(f(ek.x, t)), F @ ek.P @ F.T + Q
        ek.update(ZS[t], lambda x: np.asarray(Hj(x, t)), lambda x: np.asarray(h(x, t)))
        means.append(ek.x.copy())
        covs.append(ek.P.copy())
    means, covs = np.array(means), np.array(covs)
    np.testing.assert_allclose(res.means, means, rtol=0, atol=1e-9)
    np.testing.assert_allclose(res.covs, covs, rtol=0, atol=1e-9)
    assert int(res.status) == 0 and int(res.n_skipped) == 0
    # the extended RTS smoother against an independent loop of the textbook recursion
    sm = jf.extended_rts_smoother(MODEL, res)
    xs, Ps = means.copy(), covs.copy()
    for t in range(T - 2, -1, -1):
        F = np.asarray(Fj(means[t], t + 1))
        Pp = F @ covs[t] @ F.T + Q
        C = covs[t] @ F.T @ np.linalg.inv(Pp)
        xs[t] = means[t] + C @ (xs[t + 1] - np.asarray(f(means[t], t + 1)))
        Ps[t] = covs[t] + C @ (Ps[t + 1] - Pp) @ C.T
    np.testing.assert_allclose(sm.means, xs, rtol=0, atol=1e-8)
    np.testing.assert_allclose(sm.covs, Ps, rtol=0, atol=1e-9)
    # smoothing helps against the known truth
    err = lambda a: np.sqrt(np.mean((a[:, :2] - TRUTH[:, :2]) ** 2))
    assert err(sm.means) < 0.8 * err(res.means)


@pytest.mark.parametrize("alpha,tol", [(0.5, 1e-9), (1e-3, 1e-5)])
def test_ukf_and_smoother_equal_filterpy(alpha, tol):
    """alpha = 1e-3 puts weights of ~1e6 on the points: both sides round at ~1e-7 there."""
    f, h = jax.jit(turn), jax.jit(range_bearing)
    pts = MerweScaledSigmaPoints(N, alpha=alpha, beta=2.0, kappa=0.0)
    uk = UnscentedKalmanFilter(
        N, M, 1.0, hx=lambda x: np.asarray(h(x, 0)), fx=lambda x, dt: np.asarray(f(x, 0)), points=pts
    )
    uk.x, uk.P, uk.Q, uk.R = X0.copy(), P0.copy(), Q, R
    mu, cov = uk.batch_filter(ZS)[:2]
    xs, Ps, _ = uk.rts_smoother(mu, cov)
    res = jf.unscented_kalman_filter(MODEL, X0, P0, ZS, alpha=alpha)
    sm = jf.unscented_rts_smoother(MODEL, res, alpha=alpha)
    np.testing.assert_allclose(res.means, mu, rtol=0, atol=tol)
    np.testing.assert_allclose(res.covs, cov, rtol=0, atol=tol)
    np.testing.assert_allclose(sm.means, xs, rtol=0, atol=tol)
    np.testing.assert_allclose(sm.covs, Ps, rtol=0, atol=tol)
    assert int(res.status) == 0 and int(sm.status) == 0


def _linear_case(T_=200, seed=1):
    rng = np.random.default_rng(seed)
    dt = 0.5
    F = np.array([[1, dt, 0, 0], [0, 1, 0, 0], [0, 0, 1, dt], [0, 0, 0, 1.0]])
    H = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])
    Ql, Rl = 0.01 * np.eye(4), 0.5 * np.eye(2)
    zs = np.cumsum(rng.normal(size=(T_, 2)), axis=0)
    lin = jf.LinearGaussian(F=F, H=H, Q=Ql, R=Rl)
    model = jf.NonlinearGaussian(lambda x, t: jnp.asarray(F) @ x, lambda x, t: jnp.asarray(H) @ x, Ql, Rl)
    return lin, model, np.zeros(4), 4.0 * np.eye(4), zs


def test_linear_model_gives_the_kalman_filter_and_rts():
    lin, model, x0, P0l, zs = _linear_case(T)
    ref = jf.kalman_filter(lin, x0, P0l, zs)
    ref_s = jf.rts_smoother(lin, ref)
    runs = {
        "ekf": (jf.extended_kalman_filter(model, x0, P0l, zs), jf.extended_rts_smoother),
        "iekf": (jf.extended_kalman_filter(model, x0, P0l, zs, iterations=3), jf.extended_rts_smoother),
        "ukf": (
            jf.unscented_kalman_filter(model, x0, P0l, zs, alpha=1.0),
            lambda m, r: jf.unscented_rts_smoother(m, r, alpha=1.0),
        ),
        "ckf": (
            jf.cubature_kalman_filter(model, x0, P0l, zs),
            lambda m, r: jf.unscented_rts_smoother(m, r, alpha=1.0, beta=0.0),
        ),
    }
    for name, (res, smoother) in runs.items():
        for field in ("means", "covs", "pred_means", "pred_covs", "innovations", "nis", "logliks"):
            np.testing.assert_allclose(
                getattr(res, field),
                getattr(ref, field),
                rtol=0,
                atol=1e-12 * max(1.0, float(np.max(np.abs(getattr(ref, field))))),
                err_msg=f"{name} {field}",
            )
        sm = smoother(model, res)
        np.testing.assert_allclose(
            sm.means, ref_s.means, rtol=0, atol=1e-12 * np.max(np.abs(ref_s.means)), err_msg=name
        )
        np.testing.assert_allclose(sm.covs, ref_s.covs, rtol=0, atol=1e-12 * np.max(np.abs(ref_s.covs)), err_msg=name)


def test_iterated_ekf_is_gauss_newton_on_one_update():
    """One epoch with a poor prior: the IEKF converges to the MAP point of prior + measurement."""
    x_prev, P_prev = np.array([30.0, 10.0, 5.0, 0.3, 0.01]), np.diag([400.0, 400.0, 1.0, 0.01, 1e-4])
    z = np.asarray(range_bearing(np.array([10.0, 40.0, 0, 0, 0]), 0))[None]
    res = jf.extended_kalman_filter(MODEL, x_prev, P_prev, z, iterations=30)
    xp, Pp = np.asarray(res.pred_means[0]), np.asarray(res.pred_covs[0])
    Lp, Lr = np.linalg.cholesky(np.linalg.inv(Pp)), np.linalg.cholesky(np.linalg.inv(R))

    def resid(x):
        return np.concatenate([Lp.T @ (x - xp), Lr.T @ (z[0] - np.asarray(range_bearing(x, 0)))])

    # Gauss-Newton in information (normal-equation) form on the stacked whitened residuals
    Hj = jax.jit(jax.jacfwd(range_bearing))
    x = xp.copy()
    for _ in range(60):
        J = np.vstack([Lp.T, -Lr.T @ np.asarray(Hj(x, 0))])
        x = x - np.linalg.solve(J.T @ J, J.T @ resid(x))
    np.testing.assert_allclose(res.means[0], x, rtol=0, atol=1e-9)
    # the MAP point by an outside solver, to its own tolerance
    sol = least_squares(resid, xp, xtol=1e-15, ftol=1e-15, gtol=1e-15)
    np.testing.assert_allclose(res.means[0], sol.x, rtol=0, atol=1e-6)
    one = jf.extended_kalman_filter(MODEL, x_prev, P_prev, z)
    assert np.linalg.norm(one.means[0] - x) > 1e3 * np.linalg.norm(res.means[0] - x)
    # and a long run with iterations stays close to the EKF on this mildly nonlinear track
    long = jf.extended_kalman_filter(MODEL, X0, P0, ZS, iterations=2)
    assert int(long.status) == 0 and np.all(np.isfinite(long.means))


PLUGINS = {
    "constant": dict(inflation=jf.constant(1.05)),
    "attenuated": dict(inflation=jf.attenuated(0.97)),
    "fading": dict(inflation=jf.fading(window=10)),
    "switch": dict(inflation=jf.switch(1, [None, jf.fading(window=10)])),
    "variance_compensation": dict(estimator=jf.variance_compensation(30, horizon=2)),  # all of q observable
    "sage_husa": dict(estimator=jf.sage_husa(0.97)),
    "igg3": dict(estimator=jf.igg3()),
    "chain": dict(estimator=jf.chain(jf.sage_husa(0.97), jf.igg3())),
}


@pytest.mark.parametrize("name", sorted(PLUGINS))
def test_every_plugin_runs_on_ekf_and_ukf(name):
    """Each plug-in: on a linear model the EKF and UKF give kalman_filter's numbers with it; on the
    turning track both run (finite, or the divergence flagged as for the linear filter)."""
    kw = PLUGINS[name]
    lin, lmodel, x0, P0l, zs = _linear_case()
    ref = jf.kalman_filter(lin, x0, P0l, zs, **kw)
    ukf = lambda *a, **k: jf.unscented_kalman_filter(*a, alpha=1.0, **k)
    for run in (jf.extended_kalman_filter, ukf):
        res = run(lmodel, x0, P0l, zs, **kw)
        np.testing.assert_allclose(res.means, ref.means, rtol=0, atol=1e-9 * np.max(np.abs(ref.means)))
        np.testing.assert_allclose(res.factors, ref.factors, rtol=1e-9)
        assert int(res.status) == int(ref.status)
    for run in (jf.extended_kalman_filter, lambda *a, **k: jf.unscented_kalman_filter(*a, alpha=0.5, **k)):
        res = run(MODEL, X0, P0, ZS[:200], **kw)
        finite = np.all(np.isfinite(res.means)) and np.isfinite(float(res.loglik))
        assert finite or int(res.status) != 0, name


def test_robust_estimator_holds_against_gross_errors():
    zs = ZS[:200].copy()
    zs[50::20, 0] += 200.0  # 8 gross range errors (200 sigma)
    err = {}
    for name, kw in (("classic", {}), ("igg3", dict(estimator=jf.igg3()))):
        res = jf.extended_kalman_filter(MODEL, X0, P0, zs, **kw)
        err[name] = np.sqrt(np.mean((res.means[:, :2] - TRUTH[:200, :2]) ** 2))
    assert err["igg3"] < 0.5 * err["classic"], err


def test_nan_masked_and_counted():
    zs = ZS[:100].copy()
    zs[10, 0] = np.nan
    zs[20] = np.inf
    mask = np.isfinite(zs)
    for run in (jf.extended_kalman_filter, jf.unscented_kalman_filter, jf.cubature_kalman_filter):
        res = run(MODEL, X0, P0, zs)
        ref = run(MODEL, X0, P0, np.where(mask, zs, 0.0), mask=mask)
        assert int(res.n_nonfinite) == 3 and int(res.n_skipped) == 1
        assert int(res.status) & jf._step._status.NONFINITE_MEASUREMENT
        np.testing.assert_allclose(res.means, ref.means, rtol=0, atol=1e-12)
        assert int(res.valid[10]) == 1 and int(res.valid[20]) == 0


def test_vmap_over_sequences_equals_loop():
    B = 16
    zs = ZS[None, :150] + np.random.default_rng(3).normal(size=(B, 150, M)) * np.sqrt(np.diag(R))
    # alpha = 0.5: at 1e-3 the sigma-point moments amplify a last-bit difference between the batched
    # and the single program's fused kernels to ~1e-7 m (the conditioning the UKF docstring states)
    ukf = lambda *a, **k: jf.unscented_kalman_filter(*a, alpha=0.5, **k)
    for run in (jf.extended_kalman_filter, ukf):
        batched = jax.vmap(lambda z: run(MODEL, X0, P0, z, save=("means",)))(zs)
        for b in (0, 7, B - 1):
            one = run(MODEL, X0, P0, zs[b], save=("means",))
            np.testing.assert_allclose(batched.means[b], one.means, rtol=0, atol=1e-10)
            np.testing.assert_allclose(batched.loglik[b], one.loglik, rtol=1e-12)


def test_grad_of_loglik_wrt_closed_over_parameters_equals_finite_differences():
    zs = ZS[:100]

    def loglik(theta, run):
        sx, q = theta[0], theta[1]
        model = jf.NonlinearGaussian(turn, lambda x, t: range_bearing(x, t, jnp.stack([sx, STATION[1]])), Q * q, R)
        return run(model, X0, P0, zs, save=()).loglik

    theta = np.array([-195.0, 1.3])
    ukf = lambda *a, **k: jf.unscented_kalman_filter(*a, alpha=0.5, **k)  # alpha 0.5, not 1e-3: finite-difference noise
    for run in (jf.extended_kalman_filter, ukf):
        ll = jax.jit(lambda th: loglik(th, run))  # one compile for the differences
        g = np.asarray(jax.grad(ll)(theta))
        fd = []
        for i, step in enumerate((1e-3, 1e-5)):
            e = np.zeros(2)
            e[i] = step
            fd.append((ll(theta + e) - ll(theta - e)) / (2 * step))
        np.testing.assert_allclose(g, np.array(fd), rtol=1e-6)


def test_inputs_and_time_varying_noise():
    """f and h take the t-th slice of an ``inputs`` pytree; Q, R given per epoch equal the static ones."""
    zs = ZS[:60]
    dts = np.ones(60)
    model = jf.NonlinearGaussian(
        lambda x, u: turn(x, 0, u["dt"]),
        lambda x, u: range_bearing(x, 0),
        np.broadcast_to(Q, (60, N, N)),
        np.broadcast_to(R, (60, M, M)),
    )
    # two programs, equal up to rounding; the UKF's sigma-point moments at alpha = 1e-3 amplify rounding
    # (XLA's CPU emitters alone move its means by up to ~1e-7 m; the range noise is 1 m), the EKF's do not
    for run, smooth, atol in (
        (jf.extended_kalman_filter, jf.extended_rts_smoother, 1e-9),
        (jf.unscented_kalman_filter, jf.unscented_rts_smoother, 1e-6),
    ):
        res = run(model, X0, P0, zs, inputs={"dt": dts})
        ref = run(MODEL, X0, P0, zs)
        np.testing.assert_allclose(res.means, ref.means, rtol=0, atol=atol)
        np.testing.assert_allclose(
            smooth(model, res, inputs={"dt": dts}).means, smooth(MODEL, ref).means, rtol=0, atol=atol
        )


def test_shape_errors_name_the_shapes():
    with pytest.raises(ValueError, match=r"model.h\(x, t\) has shape \(3,\); expected \(2,\)"):
        bad = jf.NonlinearGaussian(turn, lambda x, t: x[:3], Q, R)
        jf.extended_kalman_filter(bad, X0, P0, ZS)
    with pytest.raises(ValueError, match=r"model.Q has shape \(4, 4\)"):
        jf.unscented_kalman_filter(jf.NonlinearGaussian(turn, range_bearing, np.eye(4), R), X0, P0, ZS)
    with pytest.raises(ValueError, match=r"P0 has shape \(4, 4\)"):
        jf.extended_kalman_filter(MODEL, X0, np.eye(4), ZS)
    with pytest.raises(ValueError, match="NonlinearGaussian"):
        jf.extended_kalman_filter(jf.LinearGaussian(F=np.eye(5), H=np.zeros((2, 5)), Q=Q, R=R), X0, P0, ZS)
