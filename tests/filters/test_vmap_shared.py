"""``jax.vmap`` of the filter, the smoother and the log-likelihood equals a loop of single runs.

Clean batches take the shared covariance recursion, a batch with one NaN the per-sequence
filters (the ``lax.cond`` of the vmap rules); both must give the loop's results, under every
nesting of ``jit``, ``vmap`` and ``grad``.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _trees import assert_tree_close, stack

import jaxnav
from jaxnav import filters as jf

jaxnav.enable_x64()

B, T = 3, 12
X0 = jnp.zeros(6)
P0 = jnp.diag(jnp.array([1.0] * 3 + [0.01] * 3))


def model(q=1e-4, sigma=0.05):
    return jf.constant_velocity(1.0, sigma=sigma, q=q)


@pytest.fixture(scope="module")
def data():
    rng = np.random.default_rng(5)
    v = 0.1 * rng.standard_normal((B, 1, 3))
    zs = np.cumsum(np.broadcast_to(v, (B, T, 3)), axis=1) + 0.05 * rng.standard_normal((B, T, 3))
    clean = jnp.asarray(zs)
    return {"clean": clean, "one NaN": clean.at[1, 4, 2].set(jnp.nan)}


@pytest.mark.parametrize("case", ["clean", "one NaN"])
def test_vmap_filter_and_smoother_equal_loop(data, case):
    zs = data[case]
    m = model()

    def filt(z):
        return jf.kalman_filter(m, X0, P0, z)

    def both(z):
        return jf.rts_smoother(m, filt(z))

    def all3(z):
        f = filt(z)
        return f, jf.rts_smoother(m, f), jf.log_likelihood(m, X0, P0, z)

    loop = stack([all3(z) for z in zs])
    loop_f = loop[0]
    assert_tree_close(jax.jit(jax.vmap(all3))(zs), loop)
    assert_tree_close(jax.vmap(jax.jit(filt))(zs), loop_f)
    if case == "clean":  # nested: vmap over two batch axes (2 x B), jit inside
        z2 = jnp.stack([zs, zs[::-1]])
        nested = jax.vmap(jax.vmap(jax.jit(both)))(z2)
        assert_tree_close(nested, stack([loop[1], stack([both(z) for z in zs[::-1]])]))
    assert int(jnp.sum(loop_f.n_nonfinite)) == (case == "one NaN")


def test_vmap_with_x0_batched_mask_and_saved_subset(data):
    zs = data["clean"]
    m = model()
    x0s = 0.01 * jnp.arange(B * 6, dtype=float).reshape(B, 6)
    mask = jnp.arange(T) % 4 != 1

    def filt(x0, z):
        return jf.kalman_filter(m, x0, P0, z, mask=mask, save=("means", "nis"), inflation=jf.constant(1.2))

    assert_tree_close(jax.jit(jax.vmap(filt))(x0s, zs), stack([filt(x, z) for x, z in zip(x0s, zs)]))
    # a NaN where the mask drops the epoch does not leave the shared path's results
    zm = zs.at[0, 1, 0].set(jnp.nan)
    assert_tree_close(jax.jit(jax.vmap(filt))(x0s, zm), stack([filt(x, z) for x, z in zip(x0s, zm)]))


def test_vmap_per_sequence_p0_and_data_dependent_rule(data):
    zs = data["clean"]
    m = model()
    P0s = P0 * (1.0 + jnp.arange(B))[:, None, None]
    f = lambda P, z: jf.kalman_filter(m, X0, P, z, save=("means", "covs"))
    assert_tree_close(jax.jit(jax.vmap(f))(P0s, zs), stack([f(P, z) for P, z in zip(P0s, zs)]))
    g = lambda z: jf.kalman_filter(m, X0, P0, z, save=("means",), inflation=jf.fading())
    assert_tree_close(jax.jit(jax.vmap(g))(zs), stack([g(z) for z in zs]))


@pytest.mark.parametrize("case", ["clean", "one NaN"])
def test_grad_under_vmap_equals_loop_of_grads(data, case):
    zs = data[case]

    def loss(theta, z):
        m = model(q=jnp.exp(theta[0]), sigma=jnp.exp(theta[1]))
        sm = jf.rts_smoother(m, jf.kalman_filter(m, X0, P0, z), save=("means",)).means
        return jf.kalman_filter(m, X0, P0, z, save=()).loglik + jnp.sum(sm[-1])

    theta = jnp.log(jnp.array([1e-4, 0.05]))
    want = jnp.stack([jax.grad(loss)(theta, z) for z in zs])
    got = jax.jit(jax.vmap(jax.grad(loss), in_axes=(None, 0)))(theta, zs)
    np.testing.assert_allclose(got, want, rtol=1e-10)
    # grad of a vmapped sum, and forward mode through vmap
    got = jax.jit(jax.grad(lambda th: jnp.sum(jax.vmap(lambda z: loss(th, z))(zs))))(theta)
    np.testing.assert_allclose(got, jnp.sum(want, axis=0), rtol=1e-10)
    got = jax.jit(jax.jacfwd(lambda th: jax.vmap(lambda z: loss(th, z))(zs)))(theta)
    np.testing.assert_allclose(got, want, rtol=1e-10)
    ll = lambda th, z: jf.log_likelihood(model(q=jnp.exp(th[0]), sigma=jnp.exp(th[1])), X0, P0, z)
    got = jax.jit(jax.vmap(jax.grad(ll), in_axes=(None, 0)))(theta, zs)
    np.testing.assert_allclose(got, jnp.stack([jax.grad(ll)(theta, z) for z in zs]), rtol=1e-10)


def test_unsaved_covariances_cost_no_batch_copies(data):
    """With covariances not saved, the compiled vmapped filter holds no (B, T, n, n) buffer."""
    zs = data["clean"]
    m = model()
    f = jax.jit(jax.vmap(lambda z: jf.kalman_filter(m, X0, P0, z, save=("means",))))
    text = f.lower(zs).compile().as_text()
    assert f"f64[{B},{T},6,6]" not in text
    g = jax.jit(jax.vmap(lambda z: jf.kalman_filter(m, X0, P0, z, save=("means", "covs"))))
    assert f"f64[{B},{T},6,6]" in g.lower(zs).compile().as_text()


@pytest.mark.parametrize("case", ["clean", "one NaN"])
def test_user_filter_and_smoother_composition(data, case):
    """``vmap(lambda z: rts_smoother(m, kalman_filter(m, x0, P0, z)).means)``: the loop's results, with
    inputs per sequence or shared, the smoother's own model or the filter's result changed in between."""
    zs = data[case]
    m = model()
    x0s = 0.01 * jnp.arange(B * 6, dtype=float).reshape(B, 6)
    mask = jnp.arange(T) % 5 != 2

    def both(x0, z):
        return jf.rts_smoother(m, jf.kalman_filter(m, x0, P0, z, mask=mask, inflation=jf.constant(1.1)))

    def other_f(z):  # the smoother's F is not the filter's: no redone filter
        return jf.rts_smoother(model(q=2e-4)._replace(F=2.0 * m.F), jf.kalman_filter(m, X0, P0, z))

    def changed(z):  # the filter's result changed before smoothing: the moments given are used
        f = jf.kalman_filter(m, X0, P0, z)
        return jf.rts_smoother(m, f._replace(means=f.means + 1.0))

    assert_tree_close(jax.jit(jax.vmap(both))(x0s, zs), stack([both(x, z) for x, z in zip(x0s, zs)]))
    means = jax.jit(jax.vmap(lambda z: both(X0, z).means))(zs)
    assert_tree_close(means, jnp.stack([both(X0, z).means for z in zs]))
    for fn in (other_f, changed):
        assert_tree_close(jax.jit(jax.vmap(fn))(zs), stack([fn(z) for z in zs]))


def test_user_composition_writes_no_batch_covariances(data):
    """Smoothed means only: neither the filter's nor the smoother's covariances are held B times."""
    zs = data["clean"]
    m = model()
    f = jax.jit(jax.vmap(lambda z: jf.rts_smoother(m, jf.kalman_filter(m, X0, P0, z)).means))
    text = f.lower(zs).compile().as_text()
    assert f"f64[{B},{T},6,6]" not in text
    np.testing.assert_allclose(
        f(zs), jnp.stack([jf.rts_smoother(m, jf.kalman_filter(m, X0, P0, z)).means for z in zs]), rtol=1e-12, atol=1e-12
    )
