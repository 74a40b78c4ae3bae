"""The fused small-product step (jaxnav._numerics.mm) and the checkpointed scan, checked.

``kalman_filter`` forms its 6x6-sized products as fused elementwise multiply-sums and
rematerialises each scan step under reverse-mode AD (``jax.checkpoint``). These tests pin
what that must not change: the classic filter equals the identity inflation rule (S = 1,
the plug-in path) on every output with NaN/inf and user masks and a time-varying model with a
noise input matrix; status flags for unmasked NaN; vmap = loop; reverse-mode gradient =
finite differences = forward mode (used by ``jaxnav.tune``); ``mm`` = ``@``.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxnav import _status
from jaxnav import filters as jf
from jaxnav._numerics import mm

pytestmark = pytest.mark.timeout(120)

T = 120
FIELDS = ("means", "covs", "pred_means", "pred_covs", "innovations", "innov_covs", "nis", "logliks",
          "factors", "valid", "loglik", "n_nonfinite", "n_skipped", "status", "x_final", "P_final")


def _assert_same(a, b, rtol=1e-10, atol=1e-12):
    for name in FIELDS:
        np.testing.assert_allclose(np.asarray(getattr(a, name), float), np.asarray(getattr(b, name), float),
                                   rtol=rtol, atol=atol, err_msg=name)


@pytest.fixture(scope="module")
def problem():
    rng = np.random.default_rng(11)
    n, m, p = 4, 2, 2
    F = np.stack([np.eye(n) + 0.1 * rng.standard_normal((n, n)) for _ in range(T)])
    G = rng.standard_normal((T, n, p))
    H = rng.standard_normal((m, n))
    model = jf.LinearGaussian(F=jnp.asarray(F), H=jnp.asarray(H), Q=0.01 * jnp.eye(p),
                              R=jnp.asarray([[0.2, 0.05], [0.05, 0.1]]), G=jnp.asarray(G))
    x0 = jnp.asarray(rng.standard_normal(n))
    P0 = jnp.eye(n)
    zs = np.array(rng.standard_normal((T, m)))
    zs[5, 0] = np.nan
    zs[40] = np.inf
    zs[41:44, 1] = np.nan
    mask = np.ones((T, m), bool)
    mask[70:75] = False
    mask[90, 1] = False
    return model, x0, P0, jnp.asarray(zs), jnp.asarray(mask)


def test_classic_equals_identity_rule(problem):
    model, x0, P0, zs, mask = problem
    fast = jf.kalman_filter(model, x0, P0, zs, mask=mask)
    slow = jf.kalman_filter(model, x0, P0, zs, mask=mask, inflation=jf.constant(1.0))
    _assert_same(fast, slow)
    assert int(fast.n_nonfinite) == 1 + 2 + 3 and int(fast.n_skipped) == 1 + 5
    assert int(fast.status) & _status.NONFINITE_MEASUREMENT


def test_unmasked_nan_is_flagged(problem):
    model, x0, P0, zs, mask = problem
    fast = jf.kalman_filter(model, x0, P0, zs, mask=mask, check_finite=False, save=("means",))
    assert int(fast.status) & _status.NONFINITE_UNMASKED and int(fast.status) & _status.NONFINITE_STATE
    assert int(fast.n_nonfinite) == 1 + 2 + 3  # counted, though not masked


def test_vmap_grad_jvp(problem):
    model, x0, P0, zs, mask = problem
    zs = jnp.where(jnp.isfinite(zs), zs, 0.0)
    batch = jnp.stack([zs, zs * 0.5, zs + 1.0])

    def ll(scale, z, **kw):
        mod = model._replace(R=model.R * scale)
        return jf.kalman_filter(mod, x0, P0, z, mask=mask, save=(), **kw).loglik

    fast = jax.vmap(lambda z: ll(1.3, z))(batch)
    loop = np.array([float(ll(1.3, z)) for z in batch])
    np.testing.assert_allclose(np.asarray(fast), loop, rtol=1e-11)
    g = jax.grad(ll)(1.3, zs)
    h = 1e-5
    fd = (float(ll(1.3 + h, zs)) - float(ll(1.3 - h, zs))) / (2 * h)
    np.testing.assert_allclose(float(g), fd, rtol=1e-6)
    jv = jax.jvp(lambda s: ll(s, zs), (1.3,), (1.0,))[1]  # forward mode too (used by jaxnav.tune)
    np.testing.assert_allclose(float(jv), float(g), rtol=1e-9)


def test_mm_matches_matmul():
    rng = np.random.default_rng(0)
    A, B, v = rng.standard_normal((2, 4, 3)), rng.standard_normal((3, 5)), rng.standard_normal(3)
    np.testing.assert_allclose(np.asarray(mm(jnp.asarray(A), jnp.asarray(B))), A @ B, rtol=1e-14, atol=1e-14)
    np.testing.assert_allclose(np.asarray(mm(jnp.asarray(A[0]), jnp.asarray(v))), A[0] @ v, rtol=1e-14, atol=1e-14)
    big = rng.standard_normal((12, 12))
    np.testing.assert_allclose(np.asarray(mm(jnp.asarray(big), jnp.asarray(big))), big @ big, rtol=1e-12, atol=1e-12)


def test_products_auto_sees_vmap_through_grad():
    from jaxnav.filters._kalman import resolve_products

    seen = []

    def f(x):
        seen.append(resolve_products("auto", x))
        return jnp.sum(x * x)

    jax.vmap(f)(jnp.ones((2, 3)))
    jax.vmap(jax.grad(f))(jnp.ones((2, 3)))
    f(jnp.ones(3))
    assert seen == ["dot", "dot", "fused"]
    with pytest.raises(ValueError, match="products"):
        resolve_products("nope")
