"""``jax.vmap`` of the classic filter with a covariance per sequence runs batch-minor and equals a loop.

P0 per sequence, a mask per sequence or NaN/inf per sequence give every sequence its own covariance;
the vmap rules of :func:`~jaxnav.filters.kalman_filter` and :func:`~jaxnav.filters.rts_smoother`
then run :mod:`jaxnav.filters._minor` (arrays (n, n, B)). Every output must be the loop's, for static
and time-varying models, with G, both covariance forms, trusted data, skipped epochs and a failed
factorisation; derivatives stay the plain filter's.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _trees import assert_tree_close, stack

import jaxnav
from jaxnav import _status
from jaxnav import filters as jf

jaxnav.enable_x64()

B, T = 4, 15
X0 = jnp.zeros(6)
P0 = jnp.diag(jnp.array([1.0] * 3 + [0.01] * 3))
P0S = P0 * (1.0 + 0.5 * jnp.arange(B))[:, None, None]


@pytest.fixture(scope="module")
def zs():
    rng = np.random.default_rng(11)
    v = 0.1 * rng.standard_normal((B, 1, 3))
    z = np.cumsum(np.broadcast_to(v, (B, T, 3)), axis=1) + 0.05 * rng.standard_normal((B, T, 3))
    return jnp.asarray(z)


def time_varying(m):
    k = 1.0 + 0.1 * jnp.arange(T)[:, None, None]
    return m._replace(F=jnp.broadcast_to(m.F, (T, 6, 6)) * jnp.where(jnp.eye(6, dtype=bool), 1.0, k), R=m.R * k[:, :1])


def with_g(m):
    G = jnp.vstack([0.5 * jnp.eye(3), jnp.eye(3)])
    return m._replace(Q=1e-3 * jnp.eye(3), G=G)


MODELS = {
    "static": lambda: jf.constant_velocity(1.0, sigma=0.05, q=1e-4),
    "time-varying": lambda: time_varying(jf.constant_velocity(1.0, sigma=0.05, q=1e-4)),
    "G": lambda: with_g(jf.constant_velocity(1.0, sigma=0.05, q=1e-4)),
}


@pytest.mark.parametrize("name,joseph", [("static", True), ("static", False), ("time-varying", True), ("G", True)])
def test_p0_per_sequence_equals_loop(zs, name, joseph):
    m = MODELS[name]()
    z = zs.at[2, 5, 1].set(jnp.nan).at[3, 7].set(jnp.nan)  # one element, and a whole epoch skipped

    def f(P, zz):
        return jf.kalman_filter(m, X0, P, zz, joseph=joseph)

    got = jax.jit(jax.vmap(f))(P0S, z)
    want = stack([f(P, zz) for P, zz in zip(P0S, z)])
    assert_tree_close(got, want)
    assert int(got.n_skipped[3]) == 1 and int(got.n_nonfinite[2]) == 1
    sm = lambda P, zz: jf.rts_smoother(m, f(P, zz))
    assert_tree_close(jax.jit(jax.vmap(sm))(P0S, z), stack([sm(P, zz) for P, zz in zip(P0S, z)]))


def test_runs_batch_minor(zs):
    """The compiled vmapped filter holds the covariances as (n, n, B) (the batch the minor axis)."""
    m = MODELS["static"]()
    f = jax.jit(jax.vmap(lambda P, z: jf.kalman_filter(m, X0, P, z, save=("means",)).means))
    assert f"f64[6,6,{B}]" in f.lower(P0S, zs).compile().as_text()


def test_masks_nan_and_shared_data_equal_loop(zs):
    m = MODELS["static"]()
    masks = jnp.stack([jnp.arange(T) % (b + 2) != 1 for b in range(B)])
    f = lambda mk, zz: jf.kalman_filter(m, X0, P0, zz, mask=mk, save=("means", "covs", "nis", "valid"))
    assert_tree_close(jax.jit(jax.vmap(f))(masks, zs), stack([f(mk, zz) for mk, zz in zip(masks, zs)]))
    # one NaN per sequence, shared P0: the per-sequence branch of the run-time choice
    zn = zs.at[jnp.arange(B), jnp.arange(B) + 2, jnp.arange(B) % 3].set(jnp.nan)
    g = lambda zz: jf.rts_smoother(m, jf.kalman_filter(m, X0, P0, zz))
    assert_tree_close(jax.jit(jax.vmap(g))(zn), stack([g(zz) for zz in zn]))
    # shared data, P0 and x0 per sequence
    x0s = 0.1 * jnp.arange(B * 6, dtype=float).reshape(B, 6)
    h = lambda x0, P: jf.kalman_filter(m, x0, P, zs[0])
    assert_tree_close(jax.jit(jax.vmap(h))(x0s, P0S), stack([h(x, P) for x, P in zip(x0s, P0S)]))


def test_trusted_data_and_failed_factorisation_flags(zs):
    m = MODELS["static"]()
    zi = zs.at[1, 3, 0].set(jnp.inf)
    f = lambda P, zz: jf.kalman_filter(m, X0, P, zz, check_finite=False)
    got = jax.jit(jax.vmap(f))(P0S, zi)
    assert_tree_close(got, stack([f(P, zz) for P, zz in zip(P0S, zi)]))
    assert got.status[1] & _status.NONFINITE_UNMASKED and not got.status[0] & _status.NONFINITE_UNMASKED
    # an indefinite prior in one sequence: S fails there only, the update is skipped and flagged
    bad = P0S.at[2].set(-P0)
    g = lambda P, zz: jf.kalman_filter(m, X0, P, zz)
    got = jax.jit(jax.vmap(g))(bad, zs)
    assert_tree_close(got, stack([g(P, zz) for P, zz in zip(bad, zs)]))
    assert got.status[2] & _status.CHOLESKY_FAILED and not got.status[0] & _status.CHOLESKY_FAILED


def test_grad_with_p0_per_sequence_equals_loop(zs):
    def loss(theta, P, zz):
        m = jf.constant_velocity(1.0, sigma=jnp.exp(theta[1]), q=jnp.exp(theta[0]))
        return jf.kalman_filter(m, X0, P, zz, save=()).loglik + jnp.sum(
            jf.rts_smoother(m, jf.kalman_filter(m, X0, P, zz)).means[0]
        )

    theta = jnp.log(jnp.array([1e-4, 0.05]))
    got = jax.jit(jax.vmap(jax.grad(loss), in_axes=(None, 0, 0)))(theta, P0S, zs)
    want = jnp.stack([jax.grad(loss)(theta, P, zz) for P, zz in zip(P0S, zs)])
    np.testing.assert_allclose(got, want, rtol=1e-10)


def test_nested_vmap_and_float32(zs):
    """vmap over two axes (an outer vmap of the batch-minor rule) and the opt-in float32 path."""
    m = MODELS["static"]()
    f = lambda P, zz: jf.kalman_filter(m, X0, P, zz, save=("means", "covs"))
    P2, z2 = jnp.stack([P0S, P0S[::-1]]), jnp.stack([zs, zs[::-1]])
    got = jax.jit(jax.vmap(jax.vmap(f)))(P2, z2)
    assert_tree_close(got, stack([stack([f(P, zz) for P, zz in zip(Pb, zb)]) for Pb, zb in zip(P2, z2)]))
    m32 = jax.tree_util.tree_map(lambda a: jnp.asarray(a, jnp.float32), m)
    g = lambda P, zz: jf.kalman_filter(m32, X0.astype(jnp.float32), P, zz, allow_float32=True)
    P32, z32 = P0S.astype(jnp.float32), zs.astype(jnp.float32)
    got = jax.jit(jax.vmap(g))(P32, z32)
    want = stack([g(P, zz) for P, zz in zip(P32, z32)])
    assert got.means.dtype == jnp.float32
    assert_tree_close(got, want, rtol=1e-5, atol=1e-5)


def test_model_per_sequence_equals_loop(zs):
    """A parameter swept per sequence (the noise scales) batches the model: batch-minor too."""
    scales = 0.5 + 0.5 * jnp.arange(B)

    def model(k):
        return jf.constant_velocity(1.0, sigma=0.05 * k, q=1e-4 / k)

    def both(k, zz):
        m = model(k)
        f = jf.kalman_filter(m, X0, P0, zz)
        return f, jf.rts_smoother(m, f)

    got = jax.jit(jax.vmap(both))(scales, zs)
    assert_tree_close(got, stack([both(k, zz) for k, zz in zip(scales, zs)]))
    f = jax.jit(jax.vmap(lambda k, zz: jf.kalman_filter(model(k), X0, P0, zz, save=("means",)).means))
    assert f"f64[6,6,{B}]" in f.lower(scales, zs).compile().as_text()
