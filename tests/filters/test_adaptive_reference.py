"""jaxnav's filter family against independent NumPy loops written from the paper equations.

The oracle is ``tests/reference/paper_filters.py`` (S0 eqs. (4)-(17), S1 eqs. (7)-(19)): plain
float64 loops with explicit inverses and the paper's P = (I - K H) P_pred update, while jaxnav
uses Cholesky solves and the Joseph form. Agreement is required to 1e-10 relative to
max(1, max |reference|) of each compared array (positions reach a few hundred metres in the
scenarios; the observed differences are ~1e-13 relative, see ``_agree``).
"""

import numpy as np
import pytest
from reference import paper_filters as ref

from jaxnav import filters as jf

TOL = 1e-10
T_RANDOM = 200
T_CV = 200  # both constant-velocity scenarios share T, so they share compiled filters
FLOOR_REL = 1e-4  # variance compensation: always passed explicitly (independent of the default)


def _agree(got, want, name="", tol=TOL):
    """max |got - want| <= tol * max(1, max |want|); prints the difference (pytest -s)."""
    got = np.asarray(got, dtype=np.float64)
    want = np.asarray(want, dtype=np.float64)
    assert got.shape == want.shape, f"{name}: shape {got.shape} != {want.shape}"
    scale = max(1.0, float(np.max(np.abs(want)))) if want.size else 1.0
    err = float(np.max(np.abs(got - want))) if want.size else 0.0
    print(f"  {name:<40s} max|diff| = {err:.3e}  (scale {scale:.3g})")
    assert err <= tol * scale, f"{name}: max |jaxnav - reference| = {err:.3e} > {tol:g} * {scale:.3g}"
    return err


def _agree_filter(
    res,
    rr,
    tag,
    fields=("means", "covs", "pred_means", "pred_covs", "innovations", "innov_covs", "factors", "nis", "logliks"),
):
    for f in fields:
        _agree(getattr(res, f), getattr(rr, f), f"{tag} {f}")


def _np_model(model):
    return jf.LinearGaussian(*[None if a is None else np.asarray(a, np.float64) for a in model])


# ------------------------------------------------------------------------------------------
# scenarios (module-scoped)
# ------------------------------------------------------------------------------------------


def _random_model(rng, n, m, p):
    """A random stable model: spectral radius of F 0.95, SPD Q (p x p or n x n) and R."""
    A = rng.standard_normal((n, n))
    F = 0.95 * A / np.max(np.abs(np.linalg.eigvals(A)))
    H = rng.standard_normal((m, n))
    B = rng.standard_normal((m, m))
    R = 0.1 * (B @ B.T + np.eye(m))
    k = n if p is None else p
    C = rng.standard_normal((k, k))
    Q = 0.05 * (C @ C.T + 0.2 * np.eye(k))
    G = None if p is None else rng.standard_normal((n, p))
    return jf.LinearGaussian(F=F, H=H, Q=Q, R=R, G=G)


def _simulate(rng, model, T):
    n, m = model.F.shape[0], model.H.shape[0]
    GQG = model.Q if model.G is None else model.G @ model.Q @ model.G.T
    w, U = np.linalg.eigh(GQG)
    Lq = U * np.sqrt(np.maximum(w, 0.0))
    Lr = np.linalg.cholesky(model.R)
    x = rng.standard_normal(n)
    zs = np.empty((T, m))
    for t in range(T):
        x = model.F @ x + Lq @ rng.standard_normal(n)
        zs[t] = model.H @ x + Lr @ rng.standard_normal(m)
    return zs


RANDOM_SHAPES = [(2, 1, None), (4, 2, 2), (6, 3, 3), (6, 3, None)]  # (n, m, p); p None: no Gamma


@pytest.fixture(scope="module")
def random_cases():
    rng = np.random.default_rng(20190933)
    cases = {}
    for n, m, p in RANDOM_SHAPES:
        model = _random_model(rng, n, m, p)
        zs = _simulate(rng, model, T_RANDOM)
        cases[(n, m, p)] = (model, np.zeros(n), np.eye(n), zs)
    return cases


@pytest.fixture(scope="module")
def jump_case():
    """S1 constant-velocity model (3-D, dt = 1 s) on a track whose velocity jumps mid-series.

    The jump of (3, -2, 1.5) m/s at t = T/2 and a random-walk velocity drift far above the
    model's acceleration variance make lambda_k > 1 at many epochs.
    """
    rng = np.random.default_rng(17)
    T = T_CV
    model = _np_model(jf.constant_velocity(1.0, sigma=0.5, accel_var=1e-3))
    vel = np.tile([2.0, -1.0, 0.5], (T, 1))
    vel[T // 2 :] += [3.0, -2.0, 1.5]
    vel = vel + np.cumsum(0.03 * rng.standard_normal((T, 3)), axis=0)
    pos = np.cumsum(vel, axis=0)
    zs = pos + 0.5 * rng.standard_normal((T, 3))
    x0 = np.concatenate([zs[0], [2.0, -1.0, 0.5]])
    P0 = np.diag([1.0] * 3 + [0.1] * 3)
    return model, x0, P0, zs


@pytest.fixture(scope="module")
def vc_case():
    """S1 constant-velocity model whose D_Omega (1e-3) understates the truth (0.04, 0.02, 0.01)."""
    rng = np.random.default_rng(2)
    T = T_CV
    model = _np_model(jf.constant_velocity(1.0, sigma=0.1, accel_var=1e-3))
    acc = np.sqrt([0.04, 0.02, 0.01]) * rng.standard_normal((T, 3))
    X = np.zeros(6)
    zs = np.empty((T, 3))
    for t in range(T):
        X = model.F @ X + model.G @ acc[t]
        zs[t] = X[:3] + 0.1 * rng.standard_normal(3)
    return model, np.zeros(6), 0.01 * np.eye(6), zs


@pytest.fixture(scope="module")
def tv_case():
    """A time-varying model: every leaf (T, ...) including Gamma."""
    rng = np.random.default_rng(5)
    T, n, m, p = 150, 4, 2, 2
    base = _random_model(rng, n, m, p)
    th = 0.05 * np.arange(T)
    rot = np.zeros((T, n, n))
    rot[:, 0, 0] = rot[:, 1, 1] = np.cos(th)
    rot[:, 0, 1], rot[:, 1, 0] = -np.sin(th), np.sin(th)
    rot[:, 2, 2] = rot[:, 3, 3] = 1.0
    F = np.einsum("tij,jk->tik", rot, base.F)  # still spectral radius 0.95 (orthogonal x F)
    H = base.H[None] * (1.0 + 0.3 * np.sin(th))[:, None, None]
    Q = base.Q[None] * (1.0 + 0.5 * np.cos(th))[:, None, None]
    R = base.R[None] * (1.0 + 0.5 * (np.arange(T) % 7) / 7.0)[:, None, None]
    G = base.G[None] + 0.1 * rng.standard_normal((T, n, p))
    model = jf.LinearGaussian(F=F, H=H, Q=Q, R=R, G=G)
    x = rng.standard_normal(n)
    zs = np.empty((T, m))
    for t in range(T):
        x = F[t] @ x + G[t] @ np.linalg.cholesky(Q[t]) @ rng.standard_normal(p)
        zs[t] = H[t] @ x + np.linalg.cholesky(R[t]) @ rng.standard_normal(m)
    return model, np.zeros(n), np.eye(n), zs


# ------------------------------------------------------------------------------------------
# 1. attenuated memory (S0 eqs. (11)-(12)) and constant inflation (eq. (10))
# ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("b", [0.1, 0.254, 0.5, 0.9])
def test_attenuated_factor_sequence(random_cases, b):
    model, x0, P0, zs = random_cases[(2, 1, None)]
    res = jf.kalman_filter(model, x0, P0, zs, inflation=jf.attenuated(b))
    S = np.asarray(res.factors)
    k = np.arange(1, T_RANDOM + 1)
    closed = (1.0 - b**k) / (1.0 - b)  # eq. (11)
    _agree(S, closed, f"S_k closed form b={b}", tol=1e-14)
    _agree(S, ref.attenuated_factors(b, T_RANDOM), f"S_k reference b={b}", tol=1e-14)
    assert S[0] == 1.0  # S_1 = 1: the first prediction has k = 1
    assert np.all(np.diff(S) >= 0.0) and S[-1] <= 1.0 / (1.0 - b) + 1e-12


@pytest.mark.parametrize("shape", RANDOM_SHAPES, ids=lambda s: f"n{s[0]}m{s[1]}p{s[2]}")
def test_attenuated_matches_reference(random_cases, shape):
    model, x0, P0, zs = random_cases[shape]
    for b in (0.1, 0.254, 0.5, 0.9):
        res = jf.kalman_filter(model, x0, P0, zs, inflation=jf.attenuated(b))
        rr = ref.attenuated_kf(model, x0, P0, zs, b)
        _agree_filter(res, rr, f"attenuated {shape} b={b}")


def test_constant_matches_reference(random_cases):
    model, x0, P0, zs = random_cases[(4, 2, 2)]
    for S in (1.0, 1.05, 1.3):
        res = jf.kalman_filter(model, x0, P0, zs, inflation=jf.constant(S))
        _agree_filter(res, ref.constant_kf(model, x0, P0, zs, S), f"constant S={S}")


def test_time_varying_model_matches_reference(tv_case):
    """Time-varying F, H, Q, R, Gamma: F[t] is the transition into output index t."""
    model, x0, P0, zs = tv_case
    res = jf.kalman_filter(model, x0, P0, zs, inflation=jf.attenuated(0.254))
    _agree_filter(res, ref.attenuated_kf(model, x0, P0, zs, 0.254), "time-varying attenuated")
    cfg = dict(window=10, horizon=3, min_epochs=4, floor_rel=FLOOR_REL)  # i-step Phi_{k,r} Gamma_r
    res = jf.kalman_filter(model, x0, P0, zs, estimator=jf.variance_compensation(**cfg))
    rr = ref.variance_compensation_kf(model, x0, P0, zs, **cfg)
    _agree_filter(res, rr, "time-varying VC N=10 I=3")
    _agree(res.noise.q, rr.extra["q"], "time-varying VC q")


# ------------------------------------------------------------------------------------------
# 2. fading memory (S0 eqs. (13)-(17))
# ------------------------------------------------------------------------------------------

FADING_CONFIGS = [
    dict(),  # single epoch
    dict(window=1),
    dict(window=5),
    dict(window=10),
    dict(rho=0.5),
    dict(rho=0.9),
]


@pytest.mark.parametrize("absolute", [True, False], ids=["abs", "noabs"])
@pytest.mark.parametrize("cfg", FADING_CONFIGS, ids=lambda c: "-".join(f"{k}{v}" for k, v in c.items()) or "single")
def test_fading_matches_reference(jump_case, cfg, absolute):
    model, x0, P0, zs = jump_case
    T = zs.shape[0]
    res = jf.kalman_filter(model, x0, P0, zs, inflation=jf.fading(**cfg, absolute=absolute))
    rr = ref.fading_kf(model, x0, P0, zs, **cfg, absolute=absolute)
    _agree_filter(res, rr, f"fading {cfg} abs={absolute}")
    lam = np.asarray(res.factors)
    # the scenario exercises the rule: lambda_k > 1 often, and right after the jump
    assert np.mean(lam > 1.0) > 0.3, np.mean(lam > 1.0)
    assert np.sum(lam[T // 2 : T // 2 + 10] > 1.0) >= 5
    assert lam.max() > 4.0


def test_fading_smooth_matches_reference(jump_case):
    model, x0, P0, zs = jump_case
    res = jf.kalman_filter(model, x0, P0, zs, inflation=jf.fading(window=5, smooth=0.1))
    rr = ref.fading_kf(model, x0, P0, zs, window=5, smooth=0.1)
    _agree_filter(res, rr, "fading smooth tau=0.1")
    assert np.all(np.asarray(res.factors) > 1.0)  # the surrogate is strictly above max(1, x)


# ------------------------------------------------------------------------------------------
# 3. variance compensation (S1 eqs. (12)-(19))
# ------------------------------------------------------------------------------------------

VC_CONFIGS = [  # few static variants (window, horizon, min_epochs): each one is an XLA compilation
    dict(window=10, floor_rel=FLOOR_REL),
    dict(window=30, floor_rel=FLOOR_REL),
    dict(window=10, floor_rel=FLOOR_REL, floor=0.02, ridge=1e-3),  # shares the first compilation
    dict(window=10, floor_rel=0.5, horizon=3, min_epochs=4),  # S1's i-step residuals, i = 1..3
]


@pytest.mark.parametrize("cfg", VC_CONFIGS, ids=lambda c: "-".join(f"{k}{v}" for k, v in c.items()))
def test_variance_compensation_matches_reference(vc_case, cfg):
    model, x0, P0, zs = vc_case
    T = zs.shape[0]
    res = jf.kalman_filter(model, x0, P0, zs, estimator=jf.variance_compensation(**cfg))
    rr = ref.variance_compensation_kf(model, x0, P0, zs, **cfg)
    _agree_filter(res, rr, f"VC {cfg}")
    q, est = np.asarray(res.noise.q), np.asarray(res.noise.estimated)
    _agree(q, rr.extra["q"], f"VC {cfg} q")
    np.testing.assert_array_equal(est, rr.extra["estimated"])
    need = cfg.get("min_epochs", cfg["window"])
    assert est.sum() == T - need + 1 and not est[: need - 1].any()
    prior = np.diag(model.Q)
    floor = np.maximum(cfg.get("floor", 0.0), cfg["floor_rel"] * prior)
    np.testing.assert_array_equal(q[~est], np.broadcast_to(prior, q[~est].shape))
    assert np.all(q[est] >= floor)
    free = (q[est] > floor * (1 + 1e-12)) & (np.abs(q[est] - prior) > 1e-12)
    if "floor" in cfg:  # the absolute floor (above the third true variance 0.01) is active
        assert np.any(q[est] == floor) and free.mean() > 0.3, free.mean()
    else:  # q is really estimated: most estimated components are neither the prior nor the floor
        assert free.mean() > 0.5, free.mean()


# ------------------------------------------------------------------------------------------
# 4. Sage-Husa (jaxnav's documented form)
# ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("estimate", ["R", "QR"])
def test_sage_husa_matches_reference(vc_case, estimate):
    model, x0, P0, zs = vc_case
    for b in (0.9, 0.99):
        res = jf.kalman_filter(model, x0, P0, zs, estimator=jf.sage_husa(b, estimate=estimate))
        rr = ref.sage_husa_kf(model, x0, P0, zs, b=b, estimate=estimate)
        _agree_filter(res, rr, f"sage-husa {estimate} b={b}")
        _agree(res.noise.R, rr.extra["R"], f"sage-husa {estimate} b={b} R")
        _agree(res.noise.Q, rr.extra["Q"], f"sage-husa {estimate} b={b} Q")
    if "R" in estimate:  # the estimate moved away from the model R
        assert np.max(np.abs(rr.extra["R"][-1] - model.R)) > 1e-3


# ------------------------------------------------------------------------------------------
# 5. reductions to the classic filter
# ------------------------------------------------------------------------------------------


def test_classic_matches_reference(random_cases):
    for shape, (model, x0, P0, zs) in random_cases.items():
        res = jf.kalman_filter(model, x0, P0, zs)
        _agree_filter(res, ref.classic_kf(model, x0, P0, zs), f"classic {shape}")


@pytest.mark.parametrize("shape", RANDOM_SHAPES, ids=lambda s: f"n{s[0]}m{s[1]}p{s[2]}")
def test_reductions_to_classic(random_cases, shape):
    """b -> 0 (b = 0 exactly and b = 1e-12) and S = 1 are the classic filter."""
    model, x0, P0, zs = random_cases[shape]
    classic = jf.kalman_filter(model, x0, P0, zs)
    cases = [("attenuated b=0", jf.attenuated(0.0)), ("attenuated b=1e-12", jf.attenuated(1e-12))]
    if shape == (4, 2, 2):  # constant() is compiled for this shape only (test_constant_...)
        cases.append(("constant 1", jf.constant(1.0)))
    for name, infl in cases:
        res = jf.kalman_filter(model, x0, P0, zs, inflation=infl)
        _agree_filter(res, classic, f"{name} vs classic {shape}")
    res = jf.kalman_filter(model, x0, P0, zs, inflation=jf.attenuated(0.0))
    assert np.all(np.asarray(res.factors) == 1.0)


def test_fading_without_inflation_is_classic(vc_case):
    """Innovations smaller than predicted (R overstated 100x): tr N_k < 0, so without the
    absolute value of eq. (14) lambda_k == 1 at every epoch and the filter is the classic one."""
    model, x0, P0, zs = vc_case
    big_R = model._replace(R=100.0 * model.R, Q=np.diag([0.04, 0.02, 0.01]))
    classic = jf.kalman_filter(big_R, x0, P0, zs)
    for cfg in (dict(), dict(window=10), dict(rho=0.9)):
        res = jf.kalman_filter(big_R, x0, P0, zs, inflation=jf.fading(**cfg, absolute=False))
        assert np.all(np.asarray(res.factors) == 1.0), cfg
        _agree_filter(res, classic, f"fading {cfg} lambda==1 vs classic")
        _agree_filter(res, ref.fading_kf(big_R, x0, P0, zs, **cfg, absolute=False), f"fading {cfg} ref")


def test_variance_compensation_long_window_is_classic(vc_case):
    model, x0, P0, zs = vc_case
    T = zs.shape[0]
    res = jf.kalman_filter(model, x0, P0, zs, estimator=jf.variance_compensation(window=T + 1, floor_rel=FLOOR_REL))
    assert not np.asarray(res.noise.estimated).any()
    _agree_filter(res, jf.kalman_filter(model, x0, P0, zs), "VC N>T vs classic")
    _agree_filter(res, ref.classic_kf(model, x0, P0, zs), "VC N>T vs reference classic")


@pytest.mark.parametrize("cfg", [VC_CONFIGS[0], VC_CONFIGS[3]], ids=lambda c: "-".join(f"{k}{v}" for k, v in c.items()))
def test_variance_compensation_is_classic_with_its_q(vc_case, cfg):
    """Feeding the estimated D_Omega back as a time-varying Q reproduces the adaptive filter
    (the "true D_Omega reproduces the classic filter" identity)."""
    model, x0, P0, zs = vc_case
    window = cfg["window"]
    res = jf.kalman_filter(model, x0, P0, zs, estimator=jf.variance_compensation(**cfg))
    q = np.asarray(res.noise.q)
    Qk = np.einsum("ti,ij->tij", q, np.eye(q.shape[1]))
    tv = model._replace(Q=Qk)
    _agree_filter(res, jf.kalman_filter(tv, x0, P0, zs), f"VC N={window} vs classic Q_k")
    _agree_filter(res, ref.classic_kf(tv, x0, P0, zs), f"VC N={window} vs reference classic Q_k")


# ------------------------------------------------------------------------------------------
# 6. missing measurements
# ------------------------------------------------------------------------------------------


def _with_gaps(zs, rows):
    z = np.array(zs, dtype=np.float64)
    z[list(rows)] = np.nan
    return z


GAP_ROWS = (60, 61, 100, 150)


@pytest.mark.parametrize("kind", ["classic", "attenuated", "fading", "vc", "sage_husa"])
def test_nan_rows_skip_update(jump_case, kind):
    model, x0, P0, zs = jump_case
    z = _with_gaps(zs, GAP_ROWS)
    T, m = zs.shape
    runs = {
        "classic": (dict(), lambda: ref.classic_kf(model, x0, P0, z)),
        "attenuated": (dict(inflation=jf.attenuated(0.254)), lambda: ref.attenuated_kf(model, x0, P0, z, 0.254)),
        "fading": (dict(inflation=jf.fading(window=5)), lambda: ref.fading_kf(model, x0, P0, z, window=5)),
        "vc": (
            dict(estimator=jf.variance_compensation(**VC_CONFIGS[3])),
            lambda: ref.variance_compensation_kf(model, x0, P0, z, **VC_CONFIGS[3]),
        ),
        "sage_husa": (dict(estimator=jf.sage_husa(0.95)), lambda: ref.sage_husa_kf(model, x0, P0, z, b=0.95)),
    }
    kw, reference = runs[kind]
    res = jf.kalman_filter(model, x0, P0, z, **kw)
    rr = reference()
    rows = list(GAP_ROWS)
    _agree_filter(
        res,
        rr,
        f"NaN rows {kind}",
        fields=("means", "covs", "pred_means", "pred_covs", "innovations", "factors", "nis", "logliks"),
    )
    seen = np.setdiff1d(np.arange(T), rows)  # jaxnav documents S = I at a skipped epoch
    _agree(np.asarray(res.innov_covs)[seen], rr.innov_covs[seen], f"NaN rows {kind} innov_covs")
    np.testing.assert_array_equal(np.asarray(res.innovations)[rows], 0.0)
    np.testing.assert_array_equal(np.asarray(res.means)[rows], np.asarray(res.pred_means)[rows])
    np.testing.assert_array_equal(np.asarray(res.covs)[rows], np.asarray(res.pred_covs)[rows])
    assert int(res.n_skipped) == len(rows) and int(res.n_nonfinite) == len(rows) * m
    if kind == "attenuated":  # S_k counts updates: 1 at the skipped epochs, the sequence continues after them
        f = np.asarray(res.factors)
        np.testing.assert_array_equal(f[rows], 1.0)
        _agree(f[seen], ref.attenuated_factors(0.254, len(seen)), "S_k with gaps", tol=1e-14)
    if kind == "fading":
        assert np.all(np.asarray(res.factors)[rows] == 1.0)
    if kind == "classic":  # an explicit mask gives the same result as NaN rows
        mask = np.ones(T, bool)
        mask[rows] = False
        res_m = jf.kalman_filter(model, x0, P0, zs, mask=mask, **kw)
        _agree_filter(res_m, res, f"mask vs NaN {kind}", fields=("means", "covs", "factors"))
