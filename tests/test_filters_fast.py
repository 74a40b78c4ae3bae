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


def test_trusted_batch_takes_the_blocks_only_when_finite(problem, always_block):
    """check_finite=False under vmap (covariances not saved): a batch with finite unmasked data runs the
    blocks (equal to the per-sequence filter); one unmasked NaN sends it to the per-sequence filter,
    which propagates and flags it in its own sequence only; a NaN under the user mask does not."""
    model, x0, P0, zs, mask = problem
    clean = jnp.where(jnp.isfinite(zs), zs, 0.0)
    batch = jnp.stack([clean, 0.5 * clean, clean + 1.0])
    save = ("means", "pred_means", "innovations", "nis", "logliks", "valid")  # no covariances: see below
    run = lambda z: jf.kalman_filter(model, x0, P0, z, mask=mask, check_finite=False, save=save)  # noqa: E731
    assert _shares(jax.vmap(run), batch)
    # saved covariances keep plain vmap, which returns one copy of them for the batch
    assert not _shares(jax.vmap(lambda z: jf.kalman_filter(model, x0, P0, z, mask=mask, check_finite=False)), batch)
    f = jax.jit(jax.vmap(run))
    for data in (batch, batch.at[2, 72, 0].set(jnp.nan)):  # epoch 72 is masked by the user
        got = f(data)
        for i in range(3):
            _assert_same(jax.tree_util.tree_map(lambda a: a[i], got), run(data[i]), rtol=1e-11, atol=1e-12)
        assert not np.any(np.asarray(got.status) & _status.NONFINITE_UNMASKED)
    with np.errstate(all="ignore"):
        dirty = batch.at[1, 30, 1].set(jnp.nan)
        got = f(dirty)
        ref = run(dirty[1])
    flags = [int(s) & (_status.NONFINITE_UNMASKED | _status.NONFINITE_STATE) for s in got.status]
    assert flags == [0, int(ref.status) & (_status.NONFINITE_UNMASKED | _status.NONFINITE_STATE), 0]
    assert flags[1] == _status.NONFINITE_UNMASKED | _status.NONFINITE_STATE
    assert [int(c) for c in got.n_nonfinite] == [0, 1, 0]
    np.testing.assert_array_equal(np.isfinite(np.asarray(got.means[1])), np.isfinite(np.asarray(ref.means)))
    assert np.all(np.isfinite(np.asarray(got.means[1, :30]))) and not np.any(np.isfinite(np.asarray(got.means[1, 30:])))
    _assert_same(jax.tree_util.tree_map(lambda a: a[0], got), run(dirty[0]), rtol=1e-11, atol=1e-12)


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


def _shares(fn, *args):
    """Whether the batch-level switch is in the program (its finiteness check is behind a barrier)."""
    return "optimization_barrier" in str(jax.make_jaxpr(fn)(*args))


def test_vmap_shares_the_covariance_recursion_when_nothing_is_masked(problem):
    """Under vmap, clean data or gaps common to the batch run one covariance recursion, other NaN the masked one.

    All give exactly what the per-sequence filter gives, for every output, with the user mask,
    a time-varying model and the attenuated rule; NaN/inf are still counted and flagged.
    """
    model, x0, P0, zs, mask = problem
    clean = jnp.where(jnp.isfinite(zs), zs, 0.0)
    batch = jnp.stack([clean, 0.5 * clean, clean + 1.0])
    dirty = batch.at[1].set(zs)  # one sequence carries the NaN/inf of the fixture
    bad = ~jnp.isfinite(zs)
    common = jnp.where(bad[None], zs[None], batch)  # every sequence has the fixture's gaps
    run = lambda z: jf.kalman_filter(model, x0, P0, z, mask=mask, inflation=jf.attenuated(0.3))  # noqa: E731
    assert _shares(jax.vmap(run), batch)  # the batch-level switch is there
    for data in (batch, dirty, common):
        got = jax.jit(jax.vmap(run))(data)
        for i in range(3):
            _assert_same(jax.tree_util.tree_map(lambda a: a[i], got), run(data[i]), rtol=1e-12, atol=1e-12)
    got = jax.vmap(run)(dirty)
    assert [int(c) for c in got.n_nonfinite] == [0, 6, 0]
    assert [bool(int(s) & _status.NONFINITE_MEASUREMENT) for s in got.status] == [False, True, False]
    got = jax.vmap(run)(common)
    assert [int(c) for c in got.n_nonfinite] == [6, 6, 6] and [int(c) for c in got.n_skipped] == [6, 6, 6]
    assert all(int(s) & _status.NONFINITE_MEASUREMENT for s in got.status)
    assert not any(int(s) & _status.NONFINITE_UNMASKED for s in got.status)
    one_mask = lambda z: jf.kalman_filter(model, x0, P0, z, mask=mask[:, 0]).means  # noqa: E731  (T,) mask
    np.testing.assert_allclose(np.asarray(jax.vmap(one_mask)(common)[2]), np.asarray(one_mask(common[2])),
                               rtol=1e-12, atol=1e-12)


def test_vmap_dispatch_keeps_the_per_sequence_filter_where_it_must(problem):
    """Batched masks, data-dependent rules (fading) and vmap(grad) keep the plain per-sequence filter."""
    model, x0, P0, zs, mask = problem
    clean = jnp.where(jnp.isfinite(zs), zs, 0.0)
    batch = jnp.stack([clean, 0.5 * clean])
    masks = jnp.stack([mask, mask.at[10:20].set(False)])
    per_mask = jax.vmap(lambda z, mk: jf.kalman_filter(model, x0, P0, z, mask=mk).means)
    assert not _shares(per_mask, batch, masks)
    got = per_mask(batch, masks)
    for i in range(2):
        np.testing.assert_allclose(np.asarray(got[i]), np.asarray(jf.kalman_filter(model, x0, P0, batch[i],
                                                                                    mask=masks[i]).means),
                                   rtol=1e-12, atol=1e-12)
    fading = lambda z: jf.kalman_filter(model, x0, P0, z, inflation=jf.fading(10)).means  # noqa: E731
    assert not _shares(jax.vmap(fading), batch)
    np.testing.assert_allclose(np.asarray(jax.vmap(fading)(batch)[1]), np.asarray(fading(batch[1])),
                               rtol=1e-12, atol=1e-12)


@pytest.fixture
def always_block(monkeypatch):
    """Take the blocked batch path for any batch size (it starts at B T = 2**14 by default)."""
    from jaxnav.filters import _blocked
    monkeypatch.setattr(_blocked, "MIN_BATCH_EPOCHS", 0)


@pytest.mark.parametrize("T_", [13, 5])
def test_blocked_batch_filter_equals_per_sequence(problem, T_, always_block):
    """The shared-recursion batch runs its means in blocks of epochs (filters._blocked); every output equals
    the per-sequence filter: T not a multiple of the block (13) and shorter than one (5), x0 per
    sequence, a time-varying model with G, a user mask, a gap common to the batch, and one
    sequence starting from an infinite state (its own NONFINITE_STATE flag, the others clean)."""
    model, x0, P0, zs, mask = problem
    mod = jf.LinearGaussian(*[None if a is None else (a[:T_] if a.ndim == 3 else a) for a in model])
    clean = jnp.where(jnp.isfinite(zs[:T_]), zs[:T_], 0.0)
    batch = jnp.stack([clean, 0.5 * clean, clean + 1.0, clean - 2.0]).at[:, 2, 1].set(jnp.nan)
    x0s = jnp.stack([x0, x0 + 1.0, x0 - 0.5, x0.at[0].set(jnp.inf)])
    mk = mask[:T_].at[3, 0].set(False)
    run = lambda z, x: jf.kalman_filter(mod, x, P0, z, mask=mk, inflation=jf.attenuated(0.3))  # noqa: E731
    assert _shares(jax.vmap(run), batch, x0s)
    with np.errstate(all="ignore"):
        got = jax.jit(jax.vmap(run))(batch, x0s)
        for i in range(3):
            _assert_same(jax.tree_util.tree_map(lambda a: a[i], got), run(batch[i], x0s[i]), rtol=1e-11,
                         atol=1e-12)
        ref = run(batch[3], x0s[3])
    assert int(ref.status) & _status.NONFINITE_STATE
    assert [bool(int(s) & _status.NONFINITE_STATE) for s in got.status] == [False, False, False, True]
    assert int(got.status[3]) == int(ref.status) and int(got.n_nonfinite[0]) == 1
    np.testing.assert_array_equal(np.isfinite(np.asarray(got.means[3])), np.isfinite(np.asarray(ref.means)))
    if T_ == 13:  # grad(vmap) through the blocks equals the per-sequence gradients
        def nll(th, z):
            m = mod._replace(R=mod.R * jnp.exp(th))
            return -jf.kalman_filter(m, x0, P0, z, mask=mk, save=()).loglik

        g_ref = jax.vmap(jax.grad(nll), in_axes=(None, 0))(0.2, batch[:3]).sum()  # vmap(grad): per sequence
        g = jax.grad(lambda t: jax.vmap(lambda z: nll(t, z))(batch[:3]).sum())(0.2)
        np.testing.assert_allclose(float(g), float(g_ref), rtol=1e-9)


def test_blocking_is_kept_for_batches_whose_maps_stay_small():
    """The block maps grow with T, not B: a long series with few sequences keeps the per-sequence scan."""
    from jaxnav.filters._blocked import worth_blocking
    assert worth_blocking(256, 3600, 6, 3, ("means",)) and worth_blocking(8, 3600, 6, 3, ())
    assert worth_blocking(256, 86_400, 6, 3, ("means",))  # maps ~0.6 GB < the 1.4 GB of outputs
    assert not worth_blocking(2, 86_400, 6, 3, ("means",))  # ~0.6 GB of maps for 11 MB of means
    assert not worth_blocking(4, 120, 6, 3, ("means",))  # too small to pay for the extra compile
    model = jf.constant_velocity(1.0, sigma=0.1, q=0.01)
    zs = jnp.asarray(np.random.default_rng(3).standard_normal((2, 40, 3)))
    run = lambda z: jf.kalman_filter(model, jnp.zeros(6), jnp.eye(6), z, save=("means",)).means  # noqa: E731
    np.testing.assert_allclose(np.asarray(jax.vmap(run)(zs)[1]), np.asarray(run(zs[1])), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("nan", ["none", "one sequence", "common"])
def test_batched_dispatch_under_autodiff(problem, nan):
    """grad(vmap), vmap(grad), jvp(vmap) and vmap(vmap) all equal the per-sequence results."""
    model, x0, P0, zs, mask = problem
    clean = jnp.where(jnp.isfinite(zs), zs, 0.0)
    batch = jnp.stack([clean, 0.5 * clean, clean + 1.0, clean - 1.0])
    if nan == "one sequence":
        batch = batch.at[2, 7, 0].set(jnp.nan)
    elif nan == "common":
        batch = batch.at[:, 7, 0].set(jnp.nan).at[:, 30].set(jnp.inf)

    def nll(th, z):
        mod = model._replace(Q=model.Q * jnp.exp(th[0]), R=model.R * jnp.exp(th[1]))
        return -jf.kalman_filter(mod, x0, P0, z, mask=mask, save=()).loglik

    th = jnp.array([0.2, -0.1])
    v_ref = sum(float(nll(th, z)) for z in batch)
    g_ref = sum(np.asarray(jax.grad(nll)(th, z)) for z in batch)
    v, g = jax.value_and_grad(lambda t: jax.vmap(lambda z: nll(t, z))(batch).sum())(th)
    np.testing.assert_allclose(float(v), v_ref, rtol=1e-12)
    np.testing.assert_allclose(np.asarray(g), g_ref, rtol=1e-9, atol=1e-9)
    g2 = jax.vmap(jax.grad(nll), in_axes=(None, 0))(th, batch).sum(0)
    np.testing.assert_allclose(np.asarray(g2), g_ref, rtol=1e-9, atol=1e-9)
    d = jnp.array([1.0, 0.5])
    jv = jax.jvp(lambda t: jax.vmap(lambda z: nll(t, z))(batch).sum(), (th,), (d,))[1]
    np.testing.assert_allclose(float(jv), float(g_ref @ np.asarray(d)), rtol=1e-9)
    nested = jax.vmap(jax.vmap(lambda z: nll(th, z)))(batch.reshape((2, 2) + batch.shape[1:]))
    np.testing.assert_allclose(float(nested.sum()), v_ref, rtol=1e-12)


def test_switch_equals_each_rule_in_one_program(problem):
    """switch(i, [classic, attenuated, fading]) gives each rule's filter exactly, also vmapped over i."""
    model, x0, P0, zs, mask = problem
    parts = [None, jf.attenuated(0.3), jf.fading(window=5)]
    alone = [jf.kalman_filter(model, x0, P0, zs, mask=mask, inflation=r) for r in parts]
    for i in range(3):
        _assert_same(jf.kalman_filter(model, x0, P0, zs, mask=mask, inflation=jf.switch(i, parts)), alone[i],
                     rtol=1e-13, atol=1e-13)
    run = lambda i: jf.kalman_filter(model, x0, P0, zs, mask=mask, inflation=jf.switch(i, parts), save=("means",))  # noqa: E731
    batched = jax.jit(jax.vmap(run))(jnp.arange(3.0))  # vmapped: "dot" products, rounding-level differences
    for i in range(3):
        np.testing.assert_allclose(np.asarray(batched.means[i]), np.asarray(alone[i].means), rtol=1e-9, atol=1e-9)

    def ll(b, rule):
        r = jf.switch(rule, [jf.attenuated(b), jf.fading(window=5)])
        return jf.kalman_filter(model, x0, P0, zs, mask=mask, inflation=r, save=()).loglik

    g = jax.grad(ll)(0.3, 0)
    g_alone = jax.grad(lambda b: jf.kalman_filter(model, x0, P0, zs, mask=mask, inflation=jf.attenuated(b),
                                                  save=()).loglik)(0.3)
    np.testing.assert_allclose(float(g), float(g_alone), rtol=1e-12)
    assert float(jax.grad(ll)(0.3, 1)) == 0.0  # the fading filter does not depend on b
    with pytest.raises(ValueError, match="different states"):
        jf.switch(0, [jf.attenuated(0.3, states=range(2)), jf.fading(window=5)])


def test_rts_smoother_flags_a_non_pd_prediction(problem):
    """The vectorised gains: a non-PD predicted covariance sets SMOOTHER_FAILED and zeroes that gain only."""
    model, x0, P0, zs, mask = problem
    res = jf.kalman_filter(model, x0, P0, zs, mask=mask)
    good = jf.rts_smoother(model, res)
    assert int(good.status) == 0
    bad_pp = res.pred_covs.at[50].set(-jnp.eye(4))
    bad = jf.rts_smoother(model, res._replace(pred_covs=bad_pp))
    assert int(bad.status) & _status.SMOOTHER_FAILED
    np.testing.assert_array_equal(np.asarray(bad.gains[49]), 0.0)
    np.testing.assert_allclose(np.asarray(bad.gains[:49]), np.asarray(good.gains[:49]), rtol=0, atol=0)
