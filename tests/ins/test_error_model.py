"""INS error model (S0 eqs. 18-19): F = Jacobian of the nonlinear navigation equations, discretisation.

The reference is the continuous nonlinear ENU navigation model written here from jaxnav's Earth
helpers; the error state is mapped to a perturbed (computed) state with the phi convention
C_bn_computed = exp(-[phi x]) C_bn_true, and F is compared with jax.jacfwd of the error dynamics.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.linalg import solve_discrete_lyapunov

from jaxnav import units
from jaxnav.ins import ImuNoise
from jaxnav.ins import error_model as em
from jaxnav.ins.attitude import euler_to_dcm, rv_to_dcm, skew
from jaxnav.ins.earth import earth_params, position_rate

TAU = jnp.array([300.0, 500.0, 1000.0])  # s, per-axis Markov correlation times


def qc18(arw, sigma, tau, vrw):
    """Qc of the 18-state model: gyro ARW, Markov drift sigma and tau, accelerometer VRW."""
    return em.ERROR_MODEL_18.Qc(ImuNoise(gyro_arw=arw, accel_vrw=vrw, gyro_bias_instability=sigma, gyro_bias_tau=tau))


def qc21(
    arw,
    vrw,
    *,
    gyro_bias_sigma=0.0,
    gyro_bias_tau=jnp.inf,
    accel_bias_sigma=0.0,
    accel_bias_tau=jnp.inf,
    gyro_bias_rw=0.0,
    accel_bias_rw=0.0,
    accel_scale_rw=0.0,
):
    """Qc of the 21-state model from datasheet values (SI)."""
    return em.ERROR_MODEL_21.Qc(
        ImuNoise(
            gyro_arw=arw,
            accel_vrw=vrw,
            gyro_bias_instability=gyro_bias_sigma,
            gyro_bias_tau=gyro_bias_tau,
            accel_bias_instability=accel_bias_sigma,
            accel_bias_tau=accel_bias_tau,
            gyro_bias_rw=gyro_bias_rw,
            accel_bias_rw=accel_bias_rw,
            accel_sf_rw=accel_scale_rw,
        )
    )


NAV_BLOCKS = {"phi": em.IDX18.phi, "dv": em.IDX18.dv, "dpos": em.IDX18.dpos}
ALL_BLOCKS = dict(NAV_BLOCKS, eps_b=em.IDX18.eps_b, eps_r=em.IDX18.eps_r, nabla=em.IDX18.nabla)


# ----------------------------------------------------------------------------- reference model
def _nav_dot(C, v, pos, w_ib, f_b, sign=1.0):
    """Continuous ENU navigation equations: C_dot, v_dot, pos_dot (sign = -1: reverse Earth rate)."""
    e = earth_params(pos, v, earth_rate_sign=sign)
    C_dot = C @ skew(w_ib) - skew(e.w_in_n) @ C
    v_dot = C @ f_b - jnp.cross(2.0 * e.w_ie_n + e.w_en_n, v) + e.g_n
    return C_dot, v_dot, position_rate(pos, v)


def _chart(Cc, C, vc, v, pc, p):
    """Error state of a computed state w.r.t. the true one: phi = -vee(asym(Cc C^T)), dv, dpos."""
    R = Cc @ C.T
    A = 0.5 * (R - R.T)  # = -[phi x] + O(|phi|^3)
    phi = -jnp.stack([A[2, 1], A[0, 2], A[1, 0]])
    return jnp.concatenate([phi, vc - v, pc - p])


def _error_dynamics(x, w, C, v, pos, w_ib, f_b, sign=1.0):
    """d/dt of the 9 navigation errors for the 18-state error x and noise w = [w_g, w_b, w_a]."""
    Cc = rv_to_dcm(-x[0:3]) @ C
    vc, pc = v + x[3:6], pos + x[6:9]
    w_c = w_ib + x[9:12] + x[12:15] + w[0:3]  # gyro reads true + eps_b + eps_r + w_g
    f_c = f_b + x[15:18] + w[6:9]  # accelerometer reads true + nabla + w_a
    Cc_dot, vc_dot, pc_dot = _nav_dot(Cc, vc, pc, w_c, f_c, sign)
    C_dot, v_dot, p_dot = _nav_dot(C, v, pos, w_ib, f_b, sign)
    return jax.jvp(_chart, (Cc, C, vc, v, pc, pos), (Cc_dot, C_dot, vc_dot, v_dot, pc_dot, p_dot))[1]


def _points():
    """Four nontrivial points; the first is S0's start (39 N, 108 E) moving at ~80 m/s.

    The last one uses the reversed Earth rate of backward navigation (earth_rate_sign = -1).
    """
    deg = units.DEG
    pos = jnp.array(
        [
            [39.0 * deg, 108.0 * deg, 205.8795],
            [-33.0 * deg, 151.0 * deg, 1200.0],
            [62.0 * deg, -20.0 * deg, 15.0],
            [5.0 * deg, 10.0 * deg, 3000.0],
        ]
    )
    v = jnp.array([[40.0, 69.3, 2.5], [-55.0, 20.0, -1.0], [10.0, -80.0, 0.5], [150.0, 30.0, 4.0]])
    att = jnp.array([[5.0, -3.0, -30.0], [-2.0, 8.0, 120.0], [1.0, 1.0, 45.0], [10.0, -15.0, -170.0]]) * deg
    C = euler_to_dcm(att)
    w_ib = jnp.array([[0.01, -0.02, 0.03], [-0.05, 0.01, 0.2], [0.0, 0.002, -0.01], [0.1, 0.1, -0.1]])
    f_b = jnp.array([[0.5, 1.2, 9.9], [-2.0, 0.3, 9.5], [0.1, -3.0, 10.4], [4.0, 2.0, 8.0]])
    return pos, v, C, w_ib, f_b


SIGNS = jnp.array([1.0, 1.0, 1.0, -1.0])


@pytest.fixture(scope="module")
def jac():
    """(analytic F, G, reference dx/dx, dx/dw) at each point, vmapped once."""
    pos, v, C, w_ib, f_b = _points()

    @jax.jit
    @jax.vmap
    def both(pos, v, C, w_ib, f_b, sign):
        x0, w0 = jnp.zeros(18), jnp.zeros(9)
        Jx = jax.jacfwd(_error_dynamics, argnums=0)(x0, w0, C, v, pos, w_ib, f_b, sign)
        Jw = jax.jacfwd(_error_dynamics, argnums=1)(x0, w0, C, v, pos, w_ib, f_b, sign)
        F = em.ERROR_MODEL_18.F(pos, v, C @ f_b, C, TAU, earth_rate_sign=sign)
        G = em.ERROR_MODEL_18.G(C)
        return F, G, Jx, Jw

    return jax.tree_util.tree_map(np.asarray, both(pos, v, C, w_ib, f_b, SIGNS))


def _block_errors(F, J):
    """{(row block, col block): |F - J|_F / |J|_F} (absolute |F| where J's block is zero)."""
    out = {}
    for rn, rs in NAV_BLOCKS.items():
        for cn, cs in ALL_BLOCKS.items():
            a, b = F[rs, cs], J[rs, cs]
            nb = np.linalg.norm(b)
            out[(rn, cn)] = np.linalg.norm(a - b) / nb if nb > 0 else np.linalg.norm(a)
    return out


# ----------------------------------------------------------------------------- 1. Jacobian
def test_F_equals_jacobian_of_nonlinear_navigation_blockwise(jac):
    F, _, Jx, _ = jac
    for k in range(F.shape[0]):
        errs = _block_errors(F[k, :9], Jx[k])
        worst = max(errs, key=errs.get)
        assert errs[worst] < 1e-6, (k, worst, errs[worst])
        # the blocks that physics makes nonzero are nonzero (the test is not vacuous)
        for blk in [
            ("phi", "phi"),
            ("phi", "dv"),
            ("phi", "dpos"),
            ("dv", "phi"),
            ("dv", "dv"),
            ("dv", "dpos"),
            ("dpos", "dv"),
            ("dpos", "dpos"),
            ("phi", "eps_b"),
            ("phi", "eps_r"),
            ("dv", "nabla"),
        ]:
            assert np.linalg.norm(Jx[k][NAV_BLOCKS[blk[0]], ALL_BLOCKS[blk[1]]]) > 0, blk


def test_F_equals_jacobian_elementwise(jac):
    """Stronger than the block test: every entry, incl. tiny ones (-2g/R, dR/dlat, w_ie terms)."""
    F, _, Jx, _ = jac
    for k in range(F.shape[0]):
        for rs in NAV_BLOCKS.values():
            for cs in ALL_BLOCKS.values():
                a, b = F[k, rs, cs], Jx[k, rs, cs]  # atol: rounding of the reference (~3e-13 |block|)
                np.testing.assert_allclose(a, b, rtol=1e-8, atol=1e-11 * np.linalg.norm(b) + 1e-30)
    # the small terms really are present: dg/dh ~ 2 g / R and the d(R_N)/dlat part of d(lon_dot)/dlat
    assert 2.5e-6 < F[0, 5, 8] < 3.5e-6


def test_G_equals_noise_jacobian(jac):
    _, G, _, Jw = jac
    np.testing.assert_allclose(G[:, :9], Jw, rtol=1e-12, atol=1e-20)


def test_sensor_and_markov_rows():
    pos, v, C, _, f_b = _points()
    F = em.ERROR_MODEL_18.F(pos[0], v[0], C[0] @ f_b[0], C[0], TAU)
    G = em.ERROR_MODEL_18.G(C[0])
    np.testing.assert_array_equal(F[9:12], 0.0)
    np.testing.assert_array_equal(F[15:18], 0.0)
    np.testing.assert_allclose(F[12:15], np.hstack([np.zeros((3, 12)), np.diag(-1.0 / TAU), np.zeros((3, 3))]))
    np.testing.assert_array_equal(G[9:12], 0.0)
    np.testing.assert_array_equal(G[15:18], 0.0)
    np.testing.assert_array_equal(G[12:15], np.hstack([np.zeros((3, 3)), np.eye(3), np.zeros((3, 3))]))


# ----------------------------------------------------------------------------- 2. discretisation
@pytest.fixture(scope="module")
def model():
    pos, v, C, _, f_b = _points()
    F = em.ERROR_MODEL_18.F(pos[0], v[0], C[0] @ f_b[0], C[0], TAU)
    G = em.ERROR_MODEL_18.G(C[0])
    Qc = qc18(0.01 * units.DEG_PER_SQRT_HOUR, 0.1 * units.DEG_PER_HOUR, TAU, jnp.array([1e-3, 2e-3, 3e-3]))
    return F, G, Qc


NOISY = np.r_[0:9, 12:15]  # states driven by noise (eps_b and nabla are random constants: Qd rows = 0)


def _scaled_err(A, B, Q):
    """max |A - B|_ij / sqrt(Q_ii Q_jj) over the noise-driven states: unit-independent error."""
    ix = np.ix_(NOISY, NOISY)
    d = np.sqrt(np.diag(np.asarray(Q)[ix]))
    return np.max(np.abs(np.asarray(A)[ix] - np.asarray(B)[ix]) / np.outer(d, d))


def test_van_loan_phi_and_qd_against_quadrature(model):
    F, G, Qc = model
    dt = 1.0
    Phi, Qd = jax.jit(em.discretize_van_loan)(F, G, Qc, dt)
    Phi_ref = jax.scipy.linalg.expm(F * dt)
    assert np.linalg.norm(Phi - Phi_ref) / np.linalg.norm(Phi_ref) < 1e-12
    # Simpson on 2001 nodes of expm(F s) G Qc G^T expm(F s)^T
    s = jnp.linspace(0.0, dt, 2001)
    Ps = jax.jit(jax.vmap(lambda t: jax.scipy.linalg.expm(F * t)))(s)
    GQG = G @ Qc @ G.T
    vals = np.asarray(jnp.einsum("kij,jl,kml->kim", Ps, GQG, Ps))
    wts = np.ones(s.size)
    wts[1:-1:2], wts[2:-1:2] = 4.0, 2.0
    Q_ref = np.tensordot(wts, vals, axes=1) * (dt / (s.size - 1)) / 3.0
    assert np.linalg.norm(Qd - Q_ref) / np.linalg.norm(Q_ref) < 1e-9
    assert _scaled_err(Qd, Q_ref, Q_ref) < 1e-9
    np.testing.assert_array_equal(Qd, Qd.T)
    np.testing.assert_array_equal(Qd[9:12], 0.0)
    np.testing.assert_array_equal(Qd[15:18], 0.0)
    Qn = np.asarray(Qd)[np.ix_(NOISY, NOISY)]
    d = 1.0 / np.sqrt(np.diag(Qn))
    assert np.linalg.eigvalsh(Qn * np.outer(d, d)).min() > -1e-12


@pytest.mark.parametrize("order", [1, 2, 3])
def test_series_converges_with_stated_order(model, order):
    F, G, Qc = model
    dts = [8.0, 4.0, 2.0]
    e_phi, e_q = [], []
    for dt in dts:
        Phi_x, Qd_x = em.discretize_van_loan(F, G, Qc, dt)
        Phi_s, Qd_s = em.discretize_series(F, G, Qc, dt, order=order)
        e_phi.append(np.linalg.norm(Phi_s - Phi_x))
        e_q.append(np.linalg.norm(Qd_s - Qd_x))  # absolute: Qd itself scales with dt (to dt^5 for dpos)
    rate_phi = np.log2(np.array(e_phi[:-1]) / np.array(e_phi[1:]))
    rate_q = np.log2(np.array(e_q[:-1]) / np.array(e_q[1:]))
    np.testing.assert_allclose(rate_phi, order + 1, atol=0.15)  # one-step Phi error O(dt^(order+1))
    np.testing.assert_allclose(rate_q, 3.0, atol=0.15)  # trapezoid: one-step Qd error O(dt^3)


def test_series_rejects_bad_order(model):
    F, G, Qc = model
    with pytest.raises(ValueError, match="order"):
        em.discretize_series(F, G, Qc, 1.0, order=0)


@pytest.mark.parametrize("dt", [0.01, 1.0, 2.0])
def test_taylor_equals_van_loan_to_rounding(model, dt):
    """Order 8 reproduces the exact discretisation at GPS-epoch intervals (the INS chain is nilpotent)."""
    F, G, Qc = model
    Phi_x, Qd_x = em.discretize_van_loan(F, G, Qc, dt)
    Phi_t, Qd_t, err = jax.jit(em.discretize_taylor)(F, G, Qc, dt)
    assert np.linalg.norm(Phi_t - Phi_x) / np.linalg.norm(Phi_x) < 1e-13
    assert _scaled_err(Qd_t, Qd_x, Qd_x) < 1e-11
    np.testing.assert_array_equal(Qd_t, Qd_t.T)
    assert float(err) < 1e-10


def test_taylor_error_estimate_tracks_the_truncation_error(model):
    """Few terms over a long interval: the reported last-term size bounds the Phi error and is large."""
    F, G, Qc = model
    Phi_x, _ = em.discretize_van_loan(F, G, Qc, 20.0)
    errs, ests = [], []
    for order in (2, 4, 6):
        Phi_t, _, est = em.discretize_taylor(F, G, Qc, 20.0, order=order)
        errs.append(float(jnp.max(jnp.abs(Phi_t - Phi_x)) / jnp.max(jnp.abs(Phi_x))))
        ests.append(float(est))
    assert errs[0] > errs[1] > errs[2] and ests[0] > ests[1] > ests[2]
    assert all(e <= 10 * t for e, t in zip(errs, ests)) and ests[0] > 1e-10
    with pytest.raises(ValueError, match="order"):
        em.discretize_taylor(F, G, Qc, 1.0, order=0)


# ----------------------------------------------------------------------------- 3. 15-state subset
def test_15_state_is_18_state_without_markov():
    pos, v, C, _, f_b = _points()
    keep = np.r_[0:12, 15:18]
    F18 = em.ERROR_MODEL_18.F(pos[1], v[1], C[1] @ f_b[1], C[1], TAU)
    F15 = em.ERROR_MODEL_15.F(pos[1], v[1], C[1] @ f_b[1], C[1], TAU)
    np.testing.assert_array_equal(F15, F18[np.ix_(keep, keep)])
    G18, G15 = em.ERROR_MODEL_18.G(C[1]), em.ERROR_MODEL_15.G(C[1])
    np.testing.assert_array_equal(G15, G18[np.ix_(keep, np.r_[0:3, 6:9])])
    Qc18 = qc18(1e-4, 2e-6, TAU, 3e-3)
    Qc15 = em.ERROR_MODEL_15.Qc(ImuNoise(gyro_arw=1e-4, accel_vrw=3e-3, gyro_bias_instability=2e-6, gyro_bias_tau=TAU))
    np.testing.assert_array_equal(Qc15, Qc18[np.ix_(np.r_[0:3, 6:9], np.r_[0:3, 6:9])])
    np.testing.assert_array_equal(Qc15, np.diag([1e-8] * 3 + [9e-6] * 3))
    assert em.STATE_NAMES15 == tuple(np.array(em.STATE_NAMES18)[keep])


def test_error_model_records():
    """ERROR_MODEL_15 (derived from the 18-state record) equals the 15-state model written out."""
    pos, v, C, _, f_b = _points()
    f_n = C[1] @ f_b[1]
    # S0 eq. 18 without eps_r: navigation block, phi_dot -= C_bn eps_b, dV_dot += C_bn nabla
    F = np.zeros((15, 15))
    F[:9, :9] = em.nav_error_F(pos[1], v[1], f_n, earth_rate_sign=-1.0)
    F[0:3, 9:12], F[3:6, 12:15] = -C[1], C[1]
    G = np.zeros((15, 6))
    G[0:3, 0:3], G[3:6, 3:6] = -C[1], C[1]
    m15, m18 = em.error_model_for(15), em.error_model_for(18)
    assert m15 is em.ERROR_MODEL_15 and m18 is em.ERROR_MODEL_18
    np.testing.assert_array_equal(m15.F(pos[1], v[1], f_n, C[1], TAU, earth_rate_sign=-1.0), F)
    np.testing.assert_array_equal(m15.G(C[1]), G)
    np.testing.assert_array_equal(
        m18.F(pos[1], v[1], f_n, C[1], TAU), em.ERROR_MODEL_18.F(pos[1], v[1], f_n, C[1], TAU)
    )
    assert (m15.n, m15.p, m18.n, m18.p) == (15, 6, 18, 9)
    assert m15.idx == em.IDX15 and m18.idx == em.IDX18 and m15.names == em.STATE_NAMES15
    noise = ImuNoise(gyro_arw=1e-4, accel_vrw=3e-3, gyro_bias_instability=2e-6, gyro_bias_tau=TAU)
    np.testing.assert_array_equal(m15.Qc(noise), m18.Qc(noise)[np.ix_(np.r_[0:3, 6:9], np.r_[0:3, 6:9])])
    # a record is a static argument of jit (hashed by identity)
    f = jax.jit(lambda m, c: m.G(c), static_argnums=0)
    np.testing.assert_array_equal(f(m15, C[1]), G)
    with pytest.raises(ValueError, match="n_states"):
        em.error_model_for(17)


# ----------------------------------------------------------------------------- 4. Markov block
def test_markov_decay_and_stationary_variance(model):
    F, G, _ = model
    sigma = jnp.array([1.0, 2.0, 3.0]) * units.DEG_PER_HOUR
    Qc = qc18(0.0, sigma, TAU, 0.0)
    dt, n = 1.0, 2000
    Phi, Qd = em.discretize_van_loan(F, G, Qc, dt)
    x0 = jnp.zeros(18).at[12:15].set(sigma)
    xn = jnp.linalg.matrix_power(Phi, n) @ x0
    np.testing.assert_allclose(xn[12:15], sigma * np.exp(-n * dt / TAU), rtol=1e-9)
    r = em.IDX18.eps_r
    P = solve_discrete_lyapunov(np.asarray(Phi[r, r]), np.asarray(Qd[r, r]))
    np.testing.assert_allclose(P, np.diag(sigma**2), rtol=1e-10, atol=1e-30)
    np.testing.assert_allclose(em.markov_psd(sigma, TAU) * TAU / 2.0, sigma**2, rtol=1e-15)


# ----------------------------------------------------------------------------- 5. transformations
def test_vmap_equals_loop_and_jit_equals_eager():
    pos, v, C, _, f_b = _points()
    f_n = jnp.einsum("kij,kj->ki", C, f_b)
    fn = jax.jit(jax.vmap(em.ERROR_MODEL_18.F, in_axes=(0, 0, 0, 0, None)))
    batched = fn(pos, v, f_n, C, TAU)
    looped = np.stack([em.ERROR_MODEL_18.F(pos[k], v[k], f_n[k], C[k], TAU) for k in range(4)])
    np.testing.assert_allclose(batched, looped, rtol=1e-14, atol=1e-30)
    F, G = looped[0], em.ERROR_MODEL_18.G(C[0])
    Qc = qc18(1e-4, 1e-6, TAU, 1e-3)
    for disc in (em.discretize_van_loan, em.discretize_series):
        eager = disc(F, G, Qc, 0.5)
        jitted = jax.jit(disc)(F, G, Qc, 0.5)
        np.testing.assert_allclose(jitted[0], eager[0], rtol=1e-13, atol=1e-30)
        np.testing.assert_allclose(jitted[1], eager[1], rtol=1e-12, atol=1e-30)


def test_grad_of_qd_wrt_noise_parameters(model):
    F, G, _ = model

    def loss(logs):
        Qc = qc18(jnp.exp(logs[0]), jnp.exp(logs[1]), TAU, jnp.exp(logs[2]))
        _, Qd = em.discretize_van_loan(F, G, Qc, 1.0)
        return jnp.log(Qd[0, 0]) + jnp.log(Qd[4, 4]) + jnp.log(Qd[13, 13])

    x = jnp.log(jnp.array([1e-4, 1e-6, 1e-3]))
    g = jax.grad(loss)(x)
    eps = 1e-5
    fd = np.array([(loss(x.at[i].add(eps)) - loss(x.at[i].add(-eps))) / (2 * eps) for i in range(3)])
    np.testing.assert_allclose(g, fd, rtol=1e-6)


def test_float32_position_raises():
    pos, v, C, _, f_b = _points()
    with pytest.raises(ValueError, match="enable_x64"):
        em.ERROR_MODEL_18.F(pos[0].astype(jnp.float32), v[0], f_b[0], C[0], TAU)


# ----------------------------------------------------------------------------- 6. 21-state model (issue 18)
TAU6 = jnp.array([3600.0, 2000.0, jnp.inf, 1000.0, jnp.inf, 500.0])  # s; inf: random-walk bias


def _error_dynamics21(x, w, C, v, pos, w_ib, f_b):
    """d/dt of the 9 navigation errors for the 21-state error x and noise w = [w_g, w_a, ...]:
    the corrected gyro reads w_ib + eps_b + diag(w_ib) s_g + w_g, the accelerometer f_b + nabla + diag(f_b) s_a + w_a."""
    Cc = rv_to_dcm(-x[0:3]) @ C
    vc, pc = v + x[3:6], pos + x[6:9]
    w_c = w_ib + x[9:12] + w_ib * x[15:18] + w[0:3]
    f_c = f_b + x[12:15] + f_b * x[18:21] + w[3:6]
    Cc_dot, vc_dot, pc_dot = _nav_dot(Cc, vc, pc, w_c, f_c)
    C_dot, v_dot, p_dot = _nav_dot(C, v, pos, w_ib, f_b)
    return jax.jvp(_chart, (Cc, C, vc, v, pc, pos), (Cc_dot, C_dot, vc_dot, v_dot, pc_dot, p_dot))[1]


def test_F21_and_G21_equal_jacobians_of_nonlinear_navigation_with_scale_factors():
    pos, v, C, w_ib, f_b = _points()

    @jax.jit
    @jax.vmap
    def both(pos, v, C, w_ib, f_b):
        x0, w0 = jnp.zeros(21), jnp.zeros(18)
        Jx = jax.jacfwd(_error_dynamics21, argnums=0)(x0, w0, C, v, pos, w_ib, f_b)
        Jw = jax.jacfwd(_error_dynamics21, argnums=1)(x0, w0, C, v, pos, w_ib, f_b)
        F = em.ERROR_MODEL_21.F(pos, v, C @ f_b, C, TAU6, Cw=C * w_ib[None, :], Cf=C * f_b[None, :])
        return F, em.ERROR_MODEL_21.G(C), Jx, Jw

    F, G, Jx, Jw = (np.asarray(a) for a in both(pos, v, C, w_ib, f_b))
    for k in range(F.shape[0]):
        for j in range(21):  # column by column: every error state's effect on the navigation errors
            np.testing.assert_allclose(F[k, :9, j], Jx[k, :, j], rtol=1e-8, atol=1e-11 * np.linalg.norm(Jx[k]) + 1e-30)
        np.testing.assert_allclose(G[k, :9], Jw[k], rtol=1e-12, atol=1e-20)
        # the scale-factor columns are nonzero where the motion excites them
        assert np.linalg.norm(Jx[k, 0:3, 15:18]) > 0 and np.linalg.norm(Jx[k, 3:6, 18:21]) > 0
    # sensor-error rows: Gauss-Markov biases (inf -> random walk, F = 0), constant scale factors
    np.testing.assert_allclose(np.diag(F[0, 9:15, 9:15]), -1.0 / np.asarray(TAU6))
    np.testing.assert_array_equal(F[0, 15:21], 0.0)
    np.testing.assert_array_equal(G[0, 9:21, 6:18], np.eye(12))
    assert em.error_model_for(21) is em.ERROR_MODEL_21 and em.ERROR_MODEL_21.tau_size == 6
    assert em.ERROR_MODEL_21.scale_factors and not em.ERROR_MODEL_15GM.scale_factors


def test_15gm_is_21_without_scale_factors():
    pos, v, C, w_ib, f_b = _points()
    F21 = em.ERROR_MODEL_21.F(pos[2], v[2], C[2] @ f_b[2], C[2], TAU6, Cw=C[2] * w_ib[2], Cf=C[2] * f_b[2])
    F15 = em.ERROR_MODEL_15GM.F(pos[2], v[2], C[2] @ f_b[2], C[2], TAU6)
    np.testing.assert_array_equal(F15, F21[:15, :15])
    np.testing.assert_array_equal(em.ERROR_MODEL_15GM.G(C[2]), em.ERROR_MODEL_21.G(C[2])[:15, :12])
    noise = ImuNoise(
        gyro_arw=1e-4,
        accel_vrw=1e-3,
        gyro_bias_instability=1e-5,
        gyro_bias_tau=3600.0,
        accel_bias_rw=1e-5,
        gyro_sf_rw=1e-7,
    )
    np.testing.assert_array_equal(em.ERROR_MODEL_15GM.Qc(noise), em.ERROR_MODEL_21.Qc(noise)[:12, :12])
    assert em.ERROR_MODEL_15GM.idx == em.IDX15
    np.testing.assert_array_equal(em.ERROR_MODEL_15GM.tau(noise), [3600.0] * 6)


def test_qc21_from_datasheet_values():
    """ARW, VRW, bias instability with its correlation time, bias random walk: q = 2 sigma^2 / tau + K^2."""
    arw, vrw = 0.1 * units.DEG_PER_SQRT_HOUR, 0.05  # rad/sqrt(s), m/s/sqrt(s)
    bi, tau = 5.0 * units.DEG_PER_HOUR, 1800.0
    rw = 1e-6  # rad/s/sqrt(s)
    Q = np.diag(
        np.asarray(
            qc21(
                arw,
                vrw,
                gyro_bias_sigma=bi,
                gyro_bias_tau=tau,
                gyro_bias_rw=rw,
                accel_bias_sigma=1e-3,
                accel_bias_tau=jnp.inf,
                accel_scale_rw=1e-7,
            )
        )
    )
    np.testing.assert_allclose(Q[0:3], arw**2)
    np.testing.assert_allclose(Q[3:6], vrw**2)
    np.testing.assert_allclose(Q[6:9], 2 * bi**2 / tau + rw**2)
    np.testing.assert_array_equal(Q[9:12], 0.0)  # tau = inf: the instability term is dropped (a random walk needs K)
    np.testing.assert_array_equal(Q[12:15], 0.0)
    np.testing.assert_allclose(Q[15:18], 1e-14)
    # stationary std of the Gauss-Markov bias in the discretised model equals the datasheet sigma
    pos, v, C, w_ib, f_b = _points()
    Qc = qc21(0.0, 0.0, gyro_bias_sigma=bi, gyro_bias_tau=tau)
    F = em.ERROR_MODEL_21.F(pos[0], v[0], C[0] @ f_b[0], C[0], jnp.full(6, tau))
    Phi, Qd = em.discretize_van_loan(F, em.ERROR_MODEL_21.G(C[0]), Qc, 1.0)
    r = em.IDX21.eps_b
    P = solve_discrete_lyapunov(np.asarray(Phi[r, r]), np.asarray(Qd[r, r]))
    np.testing.assert_allclose(np.diag(P), bi**2, rtol=1e-9)


def test_P0_helper_places_each_block():
    pos = jnp.array([0.7, 0.2, 100.0])
    P = np.asarray(
        em.ERROR_MODEL_21.P0(
            pos,
            att=1e-3,
            vel=0.1,
            pos_enu=[1.0, 2.0, 3.0],
            gyro_bias=1e-4,
            accel_bias=1e-2,
            gyro_scale=1e-3,
            accel_scale=2e-3,
        )
    )
    sd = np.sqrt(np.diag(P))
    np.testing.assert_allclose(sd[[0, 3, 8, 9, 12, 15, 18]], [1e-3, 0.1, 3.0, 1e-4, 1e-2, 1e-3, 2e-3])
    np.testing.assert_allclose(sd[7] * 6.39e6 * np.cos(0.7), 1.0, rtol=5e-3)  # lon from east metres
    assert (
        em.ERROR_MODEL_18.P0(pos, att=0, vel=0, pos_enu=0, gyro_bias=0, accel_bias=0, gyro_markov=1e-6)[13, 13] == 1e-12
    )


def test_F21_predicts_the_mechanization_error_growth():
    """Finite differences of the strapdown mechanization itself: integrate a constant-rate manoeuvre (turn,
    climb, acceleration) for 0.5 s with the true increments and with increments carrying scale-factor and bias
    errors, chart the difference as an error state and compare with Phi(T) x of the 21-state model (F at the
    interval's time averages, C diag(w) and C diag(f) averaged as in the filter)."""
    from jaxnav.ins import NavState, mechanize
    from jaxnav.ins.attitude import dcm_to_quat, quat_to_dcm

    deg = units.DEG
    pos0 = jnp.array([47.0 * deg, 8.0 * deg, 400.0])
    C0 = euler_to_dcm(jnp.array([2.0, -3.0, 40.0]) * deg)
    nav0 = NavState(q_bn=dcm_to_quat(C0), v_n=jnp.array([12.0, 15.0, 0.3]), pos=pos0)
    dt, K = 0.01, 50
    w = jnp.array([0.05, -0.03, 0.3])  # rad/s: a turn while pitching
    f = jnp.array([0.8, 2.0, 9.9])  # m/s^2
    dth, dv = jnp.tile(w * dt, (K, 1)), jnp.tile(f * dt, (K, 1))
    ref = mechanize(nav0, dth, dv, dt)
    x = (
        jnp.zeros(21)
        .at[9:12]
        .set(2e-5)
        .at[12:15]
        .set(jnp.array([3e-3, -2e-3, 1e-3]))
        .at[15:18]
        .set(jnp.array([2e-3, -3e-3, 5e-3]))
        .at[18:21]
        .set(jnp.array([-2e-3, 4e-3, 3e-3]))
    )
    # measured - applied = error: the computed increments carry bias and scale errors
    res = mechanize(nav0, dth * (1 + x[15:18]) + x[9:12] * dt, dv * (1 + x[18:21]) + x[12:15] * dt, dt)
    C = quat_to_dcm(ref.nav.q_bn)
    avg = lambda a: jnp.mean(a, axis=0)
    F = em.ERROR_MODEL_21.F(
        avg(ref.nav.pos),
        avg(ref.nav.v_n),
        avg(C @ f),
        avg(C),
        jnp.inf,
        Cw=avg(C * (w * 1.0)[None, None, :]),
        Cf=avg(C * f[None, None, :]),
    )
    Phi, _, _ = em.discretize_taylor(F, em.ERROR_MODEL_21.G(C0), jnp.zeros((18, 18)), K * dt)
    pred = (Phi @ x)[:9]
    last = lambda a: a[-1]
    got = _chart(
        quat_to_dcm(last(res.nav.q_bn)),
        last(C),
        last(res.nav.v_n),
        last(ref.nav.v_n),
        last(res.nav.pos),
        last(ref.nav.pos),
    )
    for sl in (slice(0, 3), slice(3, 6)):  # attitude and velocity errors (position is second order here)
        np.testing.assert_allclose(got[sl], pred[sl], rtol=2e-2, atol=2e-2 * float(jnp.max(jnp.abs(pred[sl]))))
    # without the scale-factor columns the prediction misses the dominant part of the error
    pred0 = (Phi @ x.at[15:21].set(0.0))[:6]
    assert float(jnp.max(jnp.abs(got[:3] - pred0[:3]))) > 10 * float(jnp.max(jnp.abs(got[:3] - pred[:3])))


def test_odometer_scale_state_appended_without_dynamics():
    """with_odometer_scale: one more state (a random constant) after the model's own, F and G padded with zeros,
    the noise inputs unchanged; applied twice it refuses."""
    from jaxnav import ins

    m = ins.ERROR_MODEL_21.with_odometer_scale()
    assert m.n == 22 and m.idx.s_odo == slice(21, 22) and m.p == ins.ERROR_MODEL_21.p and m.scale_factors
    pos, v, f = jnp.array([0.8, 0.2, 300.0]), jnp.array([5.0, 3.0, 0.1]), jnp.array([0.1, 0.2, 9.8])
    C, tau = jnp.eye(3), jnp.full(6, 300.0)
    Cw = jnp.diag(jnp.array([0.1, 0.2, 0.3]))
    F0 = ins.ERROR_MODEL_21.F(pos, v, f, C, tau, Cw=Cw, Cf=Cw)
    F1 = m.F(pos, v, f, C, tau, Cw=Cw, Cf=Cw)
    assert np.array_equal(F1[:21, :21], F0) and not np.any(F1[21]) and not np.any(F1[:, 21])
    G1 = m.G(C)
    assert np.array_equal(G1[:21], ins.ERROR_MODEL_21.G(C)) and not np.any(G1[21])
    P0 = m.P0(pos, att=0.01, vel=0.1, pos_enu=1.0, gyro_bias=1e-4, accel_bias=0.01, odo_scale=0.02)
    assert float(P0[21, 21]) == pytest.approx(4e-4)
    with pytest.raises(ValueError, match="already has"):
        m.with_odometer_scale()
