"""The fused small-product step (jaxnav._numerics.mm), the checkpointed scan and the batch entry points.

``kalman_filter`` forms its 6x6-sized products elementwise and rematerialises each scan step
under reverse-mode AD (``jax.checkpoint``). These tests pin what that must not change: the
classic filter equals the identity inflation rule (S = 1, the plug-in path) on every output
with NaN/inf and user masks and a time-varying model with a noise input matrix; status flags
for unmasked NaN; vmap = loop whatever the nesting with grad; reverse-mode gradient = finite
differences = forward mode (used by ``jaxnav.tune``); ``mm`` = ``@``; and
``kalman_filter_batch`` / ``rts_smoother_batch`` = the per-sequence filter and smoother.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxnav
from jaxnav import _status
from jaxnav import filters as jf
from jaxnav._numerics import mm

pytestmark = pytest.mark.timeout(120)

T = 120
FIELDS = (
    "means",
    "covs",
    "pred_means",
    "pred_covs",
    "innovations",
    "innov_covs",
    "nis",
    "logliks",
    "factors",
    "valid",
    "loglik",
    "n_nonfinite",
    "n_skipped",
    "status",
    "x_final",
    "P_final",
)


def _assert_same(a, b, rtol=1e-10, atol=1e-12):
    for name in FIELDS:
        np.testing.assert_allclose(
            np.asarray(getattr(a, name), float), np.asarray(getattr(b, name), float), rtol=rtol, atol=atol, err_msg=name
        )


@pytest.fixture(scope="module")
def problem():
    rng = np.random.default_rng(11)
    n, m, p = 4, 2, 2
    F = np.stack([np.eye(n) + 0.1 * rng.standard_normal((n, n)) for _ in range(T)])
    G = rng.standard_normal((T, n, p))
    H = rng.standard_normal((m, n))
    model = jf.LinearGaussian(
        F=jnp.asarray(F),
        H=jnp.asarray(H),
        Q=0.01 * jnp.eye(p),
        R=jnp.asarray([[0.2, 0.05], [0.05, 0.1]]),
        G=jnp.asarray(G),
    )
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


def test_textbook_covariance_update_equals_joseph(problem):
    """joseph=False (P - K H P) equals the Joseph form for the optimal gain, in the filter, its vmap with a
    covariance per sequence, and the batch entry point; PSD is kept on this well-conditioned model."""
    model, x0, P0, zs, mask = problem
    _assert_same(
        jf.kalman_filter(model, x0, P0, zs, mask=mask, joseph=False),
        jf.kalman_filter(model, x0, P0, zs, mask=mask),
        rtol=1e-9,
        atol=1e-11,
    )
    P0s = jnp.stack([P0, 2.0 * P0])
    run = lambda P, j: jf.kalman_filter(model, x0, P, zs, mask=mask, joseph=j)
    got = jax.jit(jax.vmap(lambda P: run(P, False)))(P0s)
    for i in range(2):
        _assert_same(jax.tree_util.tree_map(lambda a: a[i], got), run(P0s[i], True), rtol=1e-9, atol=1e-11)
        assert np.all(np.linalg.eigvalsh(np.asarray(got.covs[i])) > 0)
    clean = jnp.where(jnp.isfinite(zs), zs, 0.0)
    b = jf.kalman_filter_batch(model, x0, P0, jnp.stack([clean, -clean]), mask=mask, joseph=False)
    np.testing.assert_allclose(
        np.asarray(b.covs), np.asarray(jf.kalman_filter(model, x0, P0, clean, mask=mask).covs), rtol=1e-9, atol=1e-11
    )


def test_unmasked_nan_is_flagged(problem):
    model, x0, P0, zs, mask = problem
    fast = jf.kalman_filter(model, x0, P0, zs, mask=mask, check_finite=False, save=("means",))
    assert int(fast.status) & _status.NONFINITE_UNMASKED and int(fast.status) & _status.NONFINITE_STATE
    assert int(fast.n_nonfinite) == 1 + 2 + 3  # counted, though not masked


def test_trusted_data_under_vmap_share_one_covariance_recursion(problem):
    """check_finite=False with a shared model, P0 and mask: nothing in the covariance recursion depends on the
    batched data, so plain vmap leaves the covariances unbatched (vmap accepts out_axes=None for them, which it
    refuses for batched values); the results equal the per-sequence runs and an unmasked NaN is propagated and
    flagged in its own sequence only."""
    model, x0, P0, zs, mask = problem
    clean = jnp.where(jnp.isfinite(zs), zs, 0.0)
    batch = jnp.stack([clean, 0.5 * clean, clean + 1.0])
    run = lambda z: jf.kalman_filter(model, x0, P0, z, mask=mask, check_finite=False)
    axes = jf.KalmanResult(*[0] * len(jf.KalmanResult._fields))._replace(
        covs=None, pred_covs=None, innov_covs=None, P_final=None
    )
    got = jax.jit(jax.vmap(run, out_axes=axes))(batch)
    for i in range(3):
        ref = run(batch[i])
        for name in ("means", "pred_means", "innovations", "nis", "logliks", "loglik", "x_final"):
            np.testing.assert_allclose(
                np.asarray(getattr(got, name)[i]), np.asarray(getattr(ref, name)), rtol=1e-11, atol=1e-12, err_msg=name
            )
        np.testing.assert_allclose(np.asarray(got.covs), np.asarray(ref.covs), rtol=1e-11, atol=1e-12)
    with pytest.raises(ValueError):  # with NaN masking (the default) each sequence has its own covariances
        jax.vmap(lambda z: jf.kalman_filter(model, x0, P0, z, mask=mask), out_axes=axes)(batch)
    with np.errstate(all="ignore"):
        dirty = batch.at[1, 30, 1].set(jnp.nan)
        got = jax.vmap(run)(dirty)
    flags = [int(s) & (_status.NONFINITE_UNMASKED | _status.NONFINITE_STATE) for s in got.status]
    assert flags == [0, _status.NONFINITE_UNMASKED | _status.NONFINITE_STATE, 0]
    assert [int(c) for c in got.n_nonfinite] == [0, 1, 0]
    assert np.all(np.isfinite(np.asarray(got.means[1, :30]))) and not np.any(np.isfinite(np.asarray(got.means[1, 30:])))


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


def test_plain_vmap_equals_the_loop(problem):
    """vmap over data, per-sequence masks and data-dependent rules is the per-sequence computation."""
    model, x0, P0, zs, mask = problem
    clean = jnp.where(jnp.isfinite(zs), zs, 0.0)
    batch = jnp.stack([clean, 0.5 * clean]).at[1].set(zs)
    masks = jnp.stack([mask, mask.at[10:20].set(False)])
    per_mask = jax.jit(
        jax.vmap(lambda z, mk: jf.kalman_filter(model, x0, P0, z, mask=mk, inflation=jf.attenuated(0.3)))
    )
    got = per_mask(batch, masks)
    for i in range(2):
        _assert_same(
            jax.tree_util.tree_map(lambda a: a[i], got),
            jf.kalman_filter(model, x0, P0, batch[i], mask=masks[i], inflation=jf.attenuated(0.3)),
            rtol=1e-9,
            atol=1e-10,
        )  # rounding: XLA fuses the batched products differently
    fading = lambda z: jf.kalman_filter(model, x0, P0, z, inflation=jf.fading(10)).means
    np.testing.assert_allclose(
        np.asarray(jax.vmap(fading)(batch)[1]), np.asarray(fading(batch[1])), rtol=1e-9, atol=1e-10
    )


def _batch_problem(problem, T_):
    model, x0, P0, zs, mask = problem
    mod = jf.LinearGaussian(*[None if a is None else (a[:T_] if a.ndim == 3 else a) for a in model])
    clean = jnp.where(jnp.isfinite(zs[:T_]), zs[:T_], 0.0)
    batch = jnp.stack([clean, 0.5 * clean, clean + 1.0, clean - 2.0])
    return mod, x0, P0, batch, mask[:T_].at[3, 0].set(False)


@pytest.mark.parametrize("block", [4, 8, None])
@pytest.mark.parametrize("T_", [13, 5])
def test_kalman_filter_batch_equals_per_sequence(problem, T_, block):
    """kalman_filter_batch (one covariance recursion; the means in blocks of 8 epochs or by a scan) equals the
    per-sequence filter on every output: T not a multiple of the block (13) and shorter than one (5), x0 per
    sequence, a time-varying model with G, a user mask, a gap common to the batch (counted per sequence), and one
    sequence starting from an infinite state (its own NONFINITE_STATE flag, the others clean)."""
    mod, x0, P0, batch, mk = _batch_problem(problem, T_)
    batch = batch.at[:, 2, 1].set(jnp.nan)
    x0s = jnp.stack([x0, x0 + 1.0, x0 - 0.5, x0.at[0].set(jnp.inf)])
    rule = jf.attenuated(0.3)
    run = lambda z, x: jf.kalman_filter(mod, x, P0, z, mask=mk, inflation=rule)
    with np.errstate(all="ignore"):
        got = jf.kalman_filter_batch(mod, x0s, P0, batch, mask=mk, inflation=rule, block=block)
        refs = [run(batch[i], x0s[i]) for i in range(4)]
    shared = ("covs", "pred_covs", "innov_covs", "factors", "valid", "n_skipped", "P_final")
    for i in range(3):
        for name in FIELDS:
            a = getattr(got, name) if name in shared else getattr(got, name)[i]
            np.testing.assert_allclose(
                np.asarray(a, float), np.asarray(getattr(refs[i], name), float), rtol=1e-11, atol=1e-12, err_msg=name
            )
    assert int(refs[3].status) & _status.NONFINITE_STATE
    assert [bool(int(s) & _status.NONFINITE_STATE) for s in got.status] == [False, False, False, True]
    assert int(got.status[3]) == int(refs[3].status) and [int(c) for c in got.n_nonfinite] == [1, 1, 1, 1]
    np.testing.assert_array_equal(np.isfinite(np.asarray(got.means[3])), np.isfinite(np.asarray(refs[3].means)))
    # with only the means saved the blocks write nothing else; the log-likelihood (from the blocks'
    # whitened innovations, time-varying F here) still equals the per-sequence value
    lean = jf.kalman_filter_batch(mod, x0s[:3], P0, batch[:3], mask=mk, inflation=rule, block=block, save=("means",))
    np.testing.assert_allclose(np.asarray(lean.loglik), [float(r.loglik) for r in refs[:3]], rtol=1e-11)
    np.testing.assert_allclose(np.asarray(lean.means), np.asarray(got.means[:3]), rtol=1e-12, atol=1e-12)
    sm = jf.rts_smoother_batch(mod, got)
    for i in range(3):
        ref = jf.rts_smoother(mod, refs[i])
        np.testing.assert_allclose(np.asarray(sm.means[i]), np.asarray(ref.means), rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(np.asarray(sm.covs), np.asarray(ref.covs), rtol=1e-10, atol=1e-12)
    # in one jit returning both, the smoother (which overwrites the filtered means where it may)
    # leaves the filtered means intact
    both = jax.jit(
        lambda z: (lambda r: (r.means, jf.rts_smoother_batch(mod, r).means))(
            jf.kalman_filter_batch(mod, x0s[:3], P0, z, mask=mk, inflation=rule, block=block)
        )
    )(batch[:3])
    np.testing.assert_allclose(np.asarray(both[0]), np.asarray(got.means[:3]), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(np.asarray(both[1]), np.asarray(sm.means[:3]), rtol=1e-12, atol=1e-12)
    if T_ == 13 and block == 8:  # gradients through the blocks equal the per-sequence gradients

        def nll(th, z):
            m = mod._replace(R=mod.R * jnp.exp(th))
            return -jf.kalman_filter(m, x0, P0, z, mask=mk, save=()).loglik

        g_ref = jax.vmap(jax.grad(nll), in_axes=(None, 0))(0.2, batch[:3]).sum()
        g = jax.grad(
            lambda t: (
                -jf.kalman_filter_batch(
                    mod._replace(R=mod.R * jnp.exp(t)), x0, P0, batch[:3], mask=mk, save=(), block=8
                ).loglik.sum()
            )
        )(0.2)
        np.testing.assert_allclose(float(g), float(g_ref), rtol=1e-9)


def test_kalman_filter_batch_widens_the_mask_for_nan_of_one_sequence(problem):
    """A NaN of one sequence masks that element in all: counted in its own sequence, the others flagged
    BATCH_MASK_WIDENED, and the results are those of the per-sequence filter with that element masked."""
    mod, x0, P0, batch, mk = _batch_problem(problem, 40)
    batch = batch.at[1, 7, 0].set(jnp.nan)
    got = jf.kalman_filter_batch(mod, x0, P0, batch, mask=mk)
    assert [int(c) for c in got.n_nonfinite] == [0, 1, 0, 0]
    assert [bool(int(s) & _status.BATCH_MASK_WIDENED) for s in got.status] == [True, False, True, True]
    with pytest.raises(jaxnav.StatusError, match="another sequence"):
        jaxnav.raise_for_status(got.status)
    ref = jf.kalman_filter(mod, x0, P0, batch[0], mask=mk.at[7, 0].set(False))
    np.testing.assert_allclose(np.asarray(got.means[0]), np.asarray(ref.means), rtol=1e-11, atol=1e-12)
    with pytest.raises(ValueError, match="data-independent"):
        jf.kalman_filter_batch(mod, x0, P0, batch, inflation=jf.fading(5))
    with pytest.raises(ValueError, match=r"zs has shape \(40, 2\)"):
        jf.kalman_filter_batch(mod, x0, P0, batch[0])
    with pytest.raises(ValueError, match="rts_smoother_batch needs a kalman_filter_batch result"):
        jf.rts_smoother_batch(mod, jf.kalman_filter(mod, x0, P0, batch[0]))


def test_blocking_is_kept_for_batches_whose_maps_stay_small():
    """The block maps grow with T, not B: a long series with few sequences keeps the per-sequence recursion."""
    from jaxnav.filters._batch import worth_blocking

    assert worth_blocking(256, 3600, 6, 3, ("means",)) and worth_blocking(8, 3600, 6, 3, ())
    assert worth_blocking(256, 86_400, 6, 3, ("means",))  # maps ~0.6 GB < the 1.4 GB of outputs
    assert not worth_blocking(2, 86_400, 6, 3, ("means",))  # ~0.6 GB of maps for 11 MB of means
    assert not worth_blocking(4, 120, 6, 3, ("means",))  # too small to pay for the extra compile


@pytest.mark.parametrize("nan", ["none", "one sequence"])
def test_gradients_whatever_the_nesting(problem, nan):
    """grad(vmap), vmap(grad), jvp(vmap) and vmap(vmap) all equal the per-sequence results."""
    model, x0, P0, zs, mask = problem
    clean = jnp.where(jnp.isfinite(zs), zs, 0.0)
    batch = jnp.stack([clean, 0.5 * clean, clean + 1.0, clean - 1.0])
    if nan == "one sequence":
        batch = batch.at[2, 7, 0].set(jnp.nan)

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
        _assert_same(
            jf.kalman_filter(model, x0, P0, zs, mask=mask, inflation=jf.switch(i, parts)),
            alone[i],
            rtol=1e-13,
            atol=1e-13,
        )
    run = lambda i: jf.kalman_filter(model, x0, P0, zs, mask=mask, inflation=jf.switch(i, parts), save=("means",))
    batched = jax.jit(jax.vmap(run))(jnp.arange(3.0))
    for i in range(3):
        np.testing.assert_allclose(np.asarray(batched.means[i]), np.asarray(alone[i].means), rtol=1e-9, atol=1e-9)

    def ll(b, rule):
        r = jf.switch(rule, [jf.attenuated(b), jf.fading(window=5)])
        return jf.kalman_filter(model, x0, P0, zs, mask=mask, inflation=r, save=()).loglik

    g = jax.grad(ll)(0.3, 0)
    g_alone = jax.grad(
        lambda b: jf.kalman_filter(model, x0, P0, zs, mask=mask, inflation=jf.attenuated(b), save=()).loglik
    )(0.3)
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
