"""log_likelihood: value and gradients from the RTS smoother against a closed form, central
differences and reverse-mode autodiff through the filter; masks, NaN, time-varying leaves, G,
vmap (shared and per-sequence paths), forward mode, bad shapes."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxnav.filters as jf

T = 150


def _sym(a):
    return 0.5 * (a + jnp.swapaxes(a, -1, -2))


def _cv(theta):
    return jf.constant_velocity(1.0, sigma=jnp.exp(theta[1]), q=jnp.exp(theta[0]))


@pytest.fixture(scope="module")
def data():
    rng = np.random.default_rng(7)
    m0 = _cv(jnp.log(jnp.array([0.05, 2.0])))
    Qf = np.asarray(m0.Q if m0.G is None else m0.G @ m0.Q @ m0.G.T)
    x, zs = np.zeros(6), []
    for _ in range(T):
        x = np.asarray(m0.F) @ x + rng.multivariate_normal(np.zeros(6), Qf)
        zs.append(np.asarray(m0.H) @ x + 2.0 * rng.standard_normal(3))
    zs = np.array(zs)
    zs[40:52] = np.nan  # an outage
    zs[90, 1] = np.inf  # one bad element
    return jnp.asarray(zs), jnp.zeros(6), 25.0 * jnp.eye(6)


def _ref(theta, zs, x0, P0, mask=None):
    """Autodiff through the filter: ``kalman_filter``'s own loglik tangent comes from the backward
    pass too (with ``check_finite=True``), so the reference masks explicitly and trusts the data."""
    fin = jnp.isfinite(zs)
    keep = fin if mask is None else fin & (mask if mask.ndim == 2 else mask[:, None])
    z = jnp.where(fin, zs, 0.0)
    return jf.kalman_filter(_cv(theta), x0, P0, z, mask=keep, save=(), check_finite=False).loglik


def _new(theta, zs, x0, P0, mask=None):
    return jf.log_likelihood(_cv(theta), x0, P0, zs, mask=mask)


def test_closed_form_one_epoch():
    """x0 ~ N(0, p0), x1 = x0 + w (q), z = x1 + v (r): loglik = log N(z; 0, s), s = p0 + q + r,
    d/dq = d/dr = d/dp0 = (z^2 / s - 1) / (2 s), d/dz = -z / s."""
    p0, q, r, z = 2.0, 0.5, 0.3, 1.7
    s = p0 + q + r

    def f(q, r, p0, z):
        model = jf.LinearGaussian(F=jnp.eye(1), H=jnp.eye(1), Q=q * jnp.eye(1), R=r * jnp.eye(1))
        return jf.log_likelihood(model, jnp.zeros(1), p0 * jnp.eye(1), jnp.full((1, 1), z))

    val, grads = jax.value_and_grad(f, argnums=(0, 1, 2, 3))(q, r, p0, z)
    assert float(val) == pytest.approx(-0.5 * (np.log(2 * np.pi * s) + z * z / s), rel=1e-14)
    dq = (z * z / s - 1.0) / (2.0 * s)
    np.testing.assert_allclose(np.array(grads, float), [dq, dq, dq, -z / s], rtol=1e-12)


def test_value_and_gradient_match_autodiff_and_central_differences(data):
    """Against reverse mode through kalman_filter (agreement observed ~1e-14 relative) and
    central differences (h = 1e-5 in log q, log sigma: ~1e-9 relative), with no mask, whole
    epochs masked and single elements masked (one compiled program: the masks are arrays)."""
    zs, x0, P0 = data
    masks = {
        "none": jnp.ones((T, 3), bool),
        "epochs": jnp.broadcast_to((jnp.arange(T) % 7 != 3)[:, None], (T, 3)),
        "elements": jnp.asarray(np.random.default_rng(3).random((T, 3)) > 0.2),
    }
    th = jnp.log(jnp.array([0.03, 1.6]))
    vg_ref, vg_new, ref = jax.jit(jax.value_and_grad(_ref)), jax.jit(jax.value_and_grad(_new)), jax.jit(_ref)
    h = 1e-5
    for name, mask in masks.items():
        v_ref, g_ref = vg_ref(th, zs, x0, P0, mask)
        v_new, g_new = vg_new(th, zs, x0, P0, mask)
        assert float(v_new) == pytest.approx(float(v_ref), rel=1e-14), name
        np.testing.assert_allclose(np.asarray(g_new), np.asarray(g_ref), rtol=1e-10, err_msg=name)
        fd = [(ref(th + h * e, zs, x0, P0, mask) - ref(th - h * e, zs, x0, P0, mask)) / (2 * h) for e in jnp.eye(2)]
        np.testing.assert_allclose(np.asarray(g_new), np.array(fd, float), rtol=1e-7, err_msg=name)
    # mask=None is the all-True mask
    assert float(_new(th, zs, x0, P0)) == float(vg_new(th, zs, x0, P0, masks["none"])[0])


def test_gradients_of_every_input_match_autodiff(data):
    """d/dF, dH, dQ, dR, dG, dx0, dP0, dzs against autodiff through the filter, with a noise input
    matrix G (p = 3 < n = 6), static H, Q, G (gradients summed over epochs) and per-epoch F, R
    (per-epoch gradients), with P0 given and P0 = 0. Covariance gradients are compared as
    symmetric parts (the directions a symmetric matrix can move in)."""
    zs, x0, P0 = data
    m0 = _cv(jnp.log(jnp.array([0.03, 1.6])))
    s = 1.0 + 0.2 * jnp.sin(jnp.arange(T) / 9.0)
    Ft = m0.F[None] * (1.0 + 0.01 * s[:, None, None])
    Rt = m0.R[None] * s[::-1, None, None]
    G = jnp.kron(jnp.eye(3), jnp.array([[0.5], [1.0]]))  # (6, 3)
    args = (Ft, m0.H, 0.04 * jnp.eye(3), Rt, G, x0 + 0.3, P0, jnp.where(jnp.isfinite(zs), zs, 0.0))

    def ref(F, H, Q, R, G, x0, P0, z):
        return jf.kalman_filter(jf.LinearGaussian(F, H, Q, R, G), x0, P0, z, save=(), check_finite=False).loglik

    def new(F, H, Q, R, G, x0, P0, z):
        return jf.log_likelihood(jf.LinearGaussian(F, H, Q, R, G), x0, P0, z)

    grad_ref = jax.jit(jax.grad(ref, argnums=tuple(range(8))))
    grad_new = jax.jit(jax.grad(new, argnums=tuple(range(8))))
    # P0 = 0 (an exactly known start) makes the first predicted covariance G Q G^T singular
    # (rank 3 of 6): the gradient needs no inverse of it
    for P0_case in (P0, jnp.zeros_like(P0)):
        args = args[:6] + (P0_case,) + args[7:]
        ga, gb = grad_ref(*args), grad_new(*args)
        for name, a, b, sym in zip("F H Q R G x0 P0 z".split(), ga, gb, (0, 0, 1, 1, 0, 0, 1, 0)):
            assert b.shape == a.shape, name
            a, b = (_sym(a), _sym(b)) if sym else (a, b)
            assert float(jnp.max(jnp.abs(a - b))) < 1e-10 * float(jnp.max(jnp.abs(a))), name


def test_vmap_forward_mode_and_per_sequence(data):
    """grad(vmap) on a clean batch, one NaN in one sequence and a gap common to all (the
    shared-covariance path when the NaN patterns agree, per-sequence otherwise: ``lax.cond``
    picks at run time, so one program serves all three) and jvp (forward mode, as
    ``jaxnav.tune.value_and_grad(mode="forward")`` uses), against autodiff through the filter."""
    zs, x0, P0 = data
    rng = np.random.default_rng(11)
    clean = jnp.where(jnp.isfinite(zs), zs, 0.0)[None] + jnp.asarray(rng.standard_normal((4, T, 3)))
    batches = {
        "clean": clean,
        "one NaN": clean.at[2, 17, 0].set(jnp.nan),
        "common gap": clean.at[:, 60:70, :].set(jnp.nan),
    }
    th = jnp.log(jnp.array([0.03, 1.6]))
    x0B = x0 + jnp.arange(4.0)[:, None] * 0.1

    def total(fn):
        return lambda t, zB: jnp.sum(jax.vmap(lambda z, x: fn(t, z, x, P0))(zB, x0B))

    vg_ref = jax.jit(jax.value_and_grad(total(_ref)))
    vg_new = jax.jit(jax.value_and_grad(total(_new)))
    jvp = jax.jit(lambda t, zB: jax.jvp(lambda u: total(_new)(u, zB), (t,), (jnp.array([0.0, 1.0]),))[1])
    for name, zB in batches.items():
        v_ref, g_ref = vg_ref(th, zB)
        v_new, g_new = vg_new(th, zB)
        assert float(v_new) == pytest.approx(float(v_ref), rel=1e-13), name
        np.testing.assert_allclose(np.asarray(g_new), np.asarray(g_ref), rtol=1e-10, err_msg=name)
        assert float(jvp(th, zB)) == pytest.approx(float(g_ref[1]), rel=1e-10), name


def test_bad_shapes_name_them(data):
    zs, x0, P0 = data
    with pytest.raises(ValueError, match=r"P0 has shape \(5, 5\)"):
        jf.log_likelihood(_cv(jnp.zeros(2)), x0, jnp.eye(5), zs)
    with pytest.raises(ValueError, match=r"model.R has shape"):
        jf.log_likelihood(_cv(jnp.zeros(2))._replace(R=jnp.eye(2)), x0, P0, zs)


def test_kalman_filter_loglik_gradient_matches_autodiff(data):
    """The classic ``kalman_filter``'s loglik is differentiated by the backward pass (one covariance
    recursion under vmap): its gradient, single and vmapped (per sequence, one NaN in one sequence),
    equals autodiff through the filter; the tangents of the means stay the filter's own."""
    zs, x0, P0 = data

    def default(theta, z):
        return jf.kalman_filter(_cv(theta), x0, P0, z, save=()).loglik

    th = jnp.log(jnp.array([0.03, 1.6]))
    g = jax.jit(jax.grad(default))(th, zs)
    np.testing.assert_allclose(np.asarray(g), np.asarray(jax.grad(_ref)(th, zs, x0, P0)), rtol=1e-10)
    clean = jnp.where(jnp.isfinite(zs), zs, 0.0)
    zB = jnp.stack([clean, clean + 0.5, clean.at[5, 1].set(jnp.nan)])
    got = jax.jit(jax.vmap(jax.grad(default), in_axes=(None, 0)))(th, zB)
    want = jnp.stack([jax.grad(_ref)(th, z, x0, P0) for z in zB])
    np.testing.assert_allclose(np.asarray(got), np.asarray(want), rtol=1e-10)

    def means(theta, z, **kw):
        return jnp.sum(jf.kalman_filter(_cv(theta), x0, P0, z, save=("means",), **kw).means)

    np.testing.assert_allclose(
        np.asarray(jax.grad(means)(th, clean)), np.asarray(jax.grad(means)(th, clean, check_finite=False)), rtol=1e-12
    )
