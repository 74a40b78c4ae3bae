"""vmap = loop, grad = finite differences, no retrace on new values; bad input; float32 opt-in."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxnav
from jaxnav import filters as jf
from jaxnav.sim import simulate_cv_scenario

T = 150


@pytest.fixture(scope="module")
def scen():
    sc = simulate_cv_scenario(jax.random.PRNGKey(3), T=T, sigma=0.003, accel_std=1e-4)
    model = jf.constant_velocity(1.0, sigma=0.003, accel_var=1e-8)
    x0 = jnp.concatenate([sc.zs[0], jnp.zeros(3)])
    P0 = jnp.diag(jnp.array([1e-4] * 3 + [1e-4] * 3))
    return model, x0, P0, sc


def _loss(model, x0, P0, sc):
    def loss(b):
        r = jf.kalman_filter(model, x0, P0, sc.zs, inflation=jf.attenuated(b), save=("means",))
        return jnp.sqrt(jnp.mean((r.means[:, :3] - sc.x_true[:, :3]) ** 2))

    return loss


def test_vmap_over_64_b_equals_loop(scen):
    model, x0, P0, sc = scen
    loss = _loss(model, x0, P0, sc)
    bs = jnp.linspace(0.0, 0.9, 64)
    batched = jax.jit(jax.vmap(loss))(bs)
    looped = np.array([float(loss(b)) for b in bs])
    np.testing.assert_allclose(batched, looped, rtol=1e-12, atol=0)
    assert np.ptp(looped) > 0  # b matters on this scenario


@pytest.mark.parametrize("b", [0.1, 0.254, 0.6])
def test_grad_b_matches_central_difference(scen, b):
    model, x0, P0, sc = scen
    loss = _loss(model, x0, P0, sc)
    g = float(jax.grad(loss)(b))
    h = 1e-5
    fd = (float(loss(b + h)) - float(loss(b - h))) / (2 * h)
    assert np.isfinite(g) and g != 0.0
    assert abs(g - fd) <= 1e-5 * abs(fd)


def test_grad_loglik_wrt_rho_and_smooth_fading_is_finite(scen):
    model, x0, P0, sc = scen

    def nll(rho, tau):
        r = jf.kalman_filter(model, x0, P0, sc.zs, inflation=jf.fading(rho=rho, smooth=tau), save=())
        return -r.loglik

    g = jax.grad(nll, argnums=(0, 1))(0.8, 0.05)
    assert all(np.isfinite(float(x)) for x in g)
    h = 1e-6
    fd = (float(nll(0.8 + h, 0.05)) - float(nll(0.8 - h, 0.05))) / (2 * h)
    assert abs(float(g[0]) - fd) <= 1e-4 * max(abs(fd), 1e-8)


def test_no_retrace_on_new_values(scen):
    model, x0, P0, sc = scen
    from jaxnav.filters._kalman import _kalman_filter  # the jitted driver behind kalman_filter

    f = jf.kalman_filter
    f(model, x0, P0, sc.zs, inflation=jf.attenuated(0.3))
    n = _kalman_filter._cache_size()
    f(model, x0 + 1.0, P0 * 2, sc.zs * 1.5, inflation=jf.attenuated(0.7))
    f(model._replace(R=model.R * 3), x0, P0, sc.zs, inflation=jf.attenuated(jnp.float64(0.1)))
    assert _kalman_filter._cache_size() == n


def test_jit_equals_eager(scen):
    model, x0, P0, sc = scen
    a = jf.kalman_filter(model, x0, P0, sc.zs, inflation=jf.fading(window=5))
    with jax.disable_jit():
        b = jf.kalman_filter(model, x0, P0, sc.zs[:12], inflation=jf.fading(window=5))
    np.testing.assert_allclose(a.means[:12], b.means, rtol=1e-12, atol=1e-15)


# ---------------------------------------------------------------- bad input


def test_wrong_shapes_raise_value_error_naming_shapes(scen):
    model, x0, P0, sc = scen
    with pytest.raises(ValueError, match=r"P0 has shape \(5, 5\)"):
        jf.kalman_filter(model, x0, jnp.eye(5), sc.zs)
    with pytest.raises(ValueError, match=r"model.H has shape \(2, 6\)"):
        jf.kalman_filter(model._replace(H=model.H[:2]), x0, P0, sc.zs)
    with pytest.raises(ValueError, match=r"model.F has shape \(7, 6, 6\)"):
        jf.kalman_filter(model._replace(F=jnp.broadcast_to(model.F, (7, 6, 6))), x0, P0, sc.zs)
    with pytest.raises(ValueError, match=r"zs has shape \(150,\)"):
        jf.kalman_filter(model, x0, P0, sc.zs[:, 0])
    with pytest.raises(ValueError, match=r"mask has shape \(3,\)"):
        jf.kalman_filter(model, x0, P0, sc.zs, mask=jnp.ones(3, bool))
    # also under vmap: the per-sequence shapes are named at trace time
    with pytest.raises(ValueError, match=r"P0 has shape"):
        jax.vmap(lambda z: jf.kalman_filter(model, x0, jnp.eye(4), z).means)(jnp.stack([sc.zs] * 2))


def test_nonfinite_rows_skip_update_and_are_counted(scen):
    model, x0, P0, sc = scen
    zs = np.array(sc.zs)
    zs[10] = np.nan
    zs[20, 1] = np.inf
    r = jf.kalman_filter(model, x0, P0, zs)
    assert int(r.n_nonfinite) == 4 and int(r.n_skipped) == 1
    assert np.all(np.isfinite(r.means)) and np.all(np.isfinite(r.covs))
    np.testing.assert_array_equal(r.means[10], r.pred_means[10])
    np.testing.assert_array_equal(r.covs[10], r.pred_covs[10])
    assert int(r.valid[10]) == 0 and int(r.valid[20]) == 2 and int(r.valid[0]) == 3
    assert int(r.status) & jaxnav._status.NONFINITE_MEASUREMENT
    jaxnav.raise_for_status(r.status)  # informational flag only
    # the same as an explicit mask for the fully bad row
    mask = np.ones(T, bool)
    mask[10] = False
    zs2 = np.array(sc.zs)
    zs2[20, 1] = np.nan
    r2 = jf.kalman_filter(model, x0, P0, zs2, mask=mask)
    np.testing.assert_allclose(r.means, r2.means, rtol=0, atol=0)
    # partial row: equals a filter that never sees component 1 at epoch 20
    ref = jf.kalman_filter(
        model,
        x0,
        P0,
        sc.zs[:21].at[10].set(0.0),
        mask=jnp.asarray(
            np.c_[np.ones((21, 3), bool)]
            & ~(np.arange(21)[:, None] == 10)
            & ~((np.arange(21)[:, None] == 20) & (np.arange(3)[None] == 1))
        ),
    )
    np.testing.assert_allclose(r.means[:21], ref.means, rtol=1e-13, atol=1e-15)


def test_validate_model_names_the_matrix(scen):
    model, x0, P0, sc = scen
    jf.validate_model(model, P0)
    bad = np.array(model.R)
    bad[0, 1] = 1e-3
    with pytest.raises(ValueError, match="R is not symmetric"):
        jf.validate_model(model._replace(R=bad), P0)
    with pytest.raises(ValueError, match="Q is indefinite"):
        jf.validate_model(model._replace(Q=-model.Q), P0)
    with pytest.raises(ValueError, match="P0 is indefinite"):
        jf.validate_model(model, P0 - 2e-4 * jnp.eye(6))
    with pytest.raises(ValueError, match=r"R\[3\] is not positive definite"):
        Rs = np.stack([np.array(model.R)] * 5)
        Rs[3] = 0.0
        jf.validate_model(model._replace(R=Rs))


def test_float32_needs_opt_in_and_is_stable(scen):
    model, x0, P0, sc = scen
    m32 = jf.LinearGaussian(*[None if a is None else jnp.asarray(a, jnp.float32) for a in model])
    x32, P32 = jnp.asarray(x0, jnp.float32), jnp.asarray(P0, jnp.float32)
    # work on local offsets (mm-level problem) as float32 paths must
    z32 = jnp.asarray(sc.zs - sc.zs[0], jnp.float32)
    with pytest.raises(ValueError, match="enable_x64"):
        jf.kalman_filter(m32, x32 - x32, P32, z32)
    r32 = jf.kalman_filter(
        m32, x32 - jnp.concatenate([sc.zs[0], jnp.zeros(3)]).astype(jnp.float32), P32, z32, allow_float32=True
    )
    r64 = jf.kalman_filter(model, x0 - jnp.concatenate([sc.zs[0], jnp.zeros(3)]), P0, sc.zs - sc.zs[0])
    assert r32.means.dtype == jnp.float32
    err = np.abs(np.asarray(r32.means, float) - np.asarray(r64.means))
    assert err.max() < 1e-6  # metres: far below the 3 mm noise
    var32 = np.asarray(jnp.diagonal(r32.covs, axis1=1, axis2=2), float)
    var64 = np.asarray(jnp.diagonal(r64.covs, axis1=1, axis2=2))
    assert np.max(np.abs(var32 / var64 - 1)) < 1e-4
    assert np.all(np.linalg.eigvalsh(np.asarray(r32.covs, float)) > 0)


def test_check_grads_loglik_wrt_b_noise_scale_x0(scen):
    """jax.test_util.check_grads (forward and reverse) through the filter, for every tunable kind."""
    from jax.test_util import check_grads

    model, x0, P0, sc = scen
    zs = sc.zs[:30]

    def nll(b, log_r, dx0):
        m = model._replace(R=model.R * jnp.exp(log_r))
        r = jf.kalman_filter(m, x0 + dx0, P0, zs, inflation=jf.attenuated(b), save=())
        return -r.loglik

    check_grads(nll, (0.3, 0.2, jnp.full(6, 1e-3)), order=1, modes=("fwd", "rev"), eps=1e-6, atol=1e-6, rtol=1e-5)


def test_check_finite_false_is_identical_on_clean_data_and_flags_nan(scen):
    model, x0, P0, sc = scen
    a = jf.kalman_filter(model, x0, P0, sc.zs)
    b = jf.kalman_filter(model, x0, P0, sc.zs, check_finite=False)
    np.testing.assert_array_equal(a.means, b.means)
    np.testing.assert_array_equal(a.covs, b.covs)
    assert float(a.loglik) == float(b.loglik) and int(b.status) == 0
    zs = np.array(sc.zs)
    zs[7, 0] = np.nan
    c = jf.kalman_filter(model, x0, P0, zs, check_finite=False)
    assert int(c.n_nonfinite) == 1
    assert int(c.status) & jaxnav._status.NONFINITE_UNMASKED
    with pytest.raises(jaxnav.StatusError, match="check_finite=False"):
        jaxnav.raise_for_status(c.status)


def test_smoother_output_selection(scen):
    model, x0, P0, sc = scen
    r = jf.kalman_filter(model, x0, P0, sc.zs, inflation=jf.fading(window=5))
    full = jf.rts_smoother(model, r)
    means_only = jf.rts_smoother(model, r, save=("means",))
    assert means_only.covs is None and means_only.gains is None
    np.testing.assert_array_equal(full.means, means_only.means)
    with pytest.raises(ValueError, match="unknown smoother outputs"):
        jf.rts_smoother(model, r, save=("nope",))
    with pytest.raises(ValueError, match="needs the filter output 'pred_covs'"):
        jf.rts_smoother(model, jf.kalman_filter(model, x0, P0, sc.zs, save=("means", "covs", "pred_means")))


def test_inflation_restricted_to_states(scen):
    """states=all equals the scalar rule; a subset scales that block by f, cross terms by sqrt(f)."""
    model, x0, P0, sc = scen
    full = jf.kalman_filter(model, x0, P0, sc.zs, inflation=jf.attenuated(0.4))
    all_states = jf.kalman_filter(model, x0, P0, sc.zs, inflation=jf.attenuated(0.4, states=range(6)))
    np.testing.assert_allclose(all_states.means, full.means, rtol=0, atol=1e-14)
    part = jf.kalman_filter(model, x0, P0, sc.zs, inflation=jf.attenuated(0.4, states=slice(0, 3)))
    k, S = 5, (1 - 0.4**6) / (1 - 0.4)  # output index 5 is epoch k = 6
    F, G, Q = (np.asarray(a) for a in (model.F, model.G, model.Q))
    FPF = F @ np.asarray(part.covs[k - 1]) @ F.T
    d = np.r_[[np.sqrt(S)] * 3, [1.0] * 3]
    np.testing.assert_allclose(part.pred_covs[k], d[:, None] * FPF * d[None, :] + G @ Q @ G.T, rtol=1e-12, atol=1e-20)
    np.testing.assert_allclose(part.factors[k], S, rtol=1e-14)
    r = jf.kalman_filter(model, x0, P0, sc.zs, inflation=jf.fading(window=5, states=(0, 1, 2)))
    assert np.all(np.isfinite(r.means)) and float(jnp.max(r.factors)) >= 1.0
    with pytest.raises(ValueError, match="states"):
        jf.fading(states=[])
