"""The shared predict/update and the Kalman filter driver (S0 eqs. (4)-(9), S1 eqs. (7)-(11)).

One predict step and one Joseph-form update serve every variant; prior-inflation rules
(:mod:`._rules`) and noise estimators (:mod:`._estimators`) plug into :func:`filter_step`.
"""

from __future__ import annotations

import contextlib
import math
from functools import partial
from typing import Any, NamedTuple, Optional

import jax
import jax.numpy as jnp

from jaxnav import _status
from jaxnav._numerics import cho_solve, cholesky, mm, symmetrize, whiten
from jaxnav.filters._estimators import NoEstimator, PostUpdate
from jaxnav.filters._model import LinearGaussian, check_shapes
from jaxnav.filters._rules import NoInflation, StepContext, inflation_scale

LOG_2PI = math.log(2.0 * math.pi)

#: trace-time choice of the small matrix products in predict/update/filter_step: False uses
#: ``@`` (XLA dots), True the fused multiply-sums of :func:`jaxnav._numerics.mm`. Set only by
#: :func:`kalman_filter` / :func:`rts_smoother` (``products=`` argument) while they trace.
_FUSED = [False]


def _mm(A, B):
    return mm(A, B) if _FUSED[0] else A @ B


@contextlib.contextmanager
def _fused_products(on: bool):
    old = _FUSED[0]
    _FUSED[0] = bool(on)
    try:
        yield
    finally:
        _FUSED[0] = old


def _under_vmap(*trees) -> bool:
    """Whether any argument is being batched by ``jax.vmap`` (a BatchTracer) at call time."""
    try:
        from jax._src.interpreters.batching import BatchTracer
    except Exception:  # pragma: no cover - private location changed: assume not batched
        return False
    def batched(x):
        for _ in range(32):  # look through autodiff tracers (grad inside vmap) to what they wrap
            if isinstance(x, BatchTracer):
                return True
            nxt = getattr(x, "primal", None)
            if nxt is None or nxt is x:
                return False
            x = nxt
        return False

    return any(batched(leaf) for leaf in jax.tree_util.tree_leaves(trees))


def _vmap_innermost() -> bool:
    """Whether the innermost transformation active at this call is ``vmap`` (not jvp/grad/jit).

    Then a ``custom_vmap`` rule runs right away in the batching trace, and any autodiff outside
    differentiates the ordinary operations the rule emits; under ``vmap(grad(f))`` it would not
    (``custom_vmap`` has no reverse mode), so that case keeps the plain filter.
    """
    try:
        from jax._src import core
        from jax._src.interpreters.batching import BatchTrace
        return isinstance(core.trace_ctx.trace, BatchTrace)
    except Exception:  # pragma: no cover - private location changed: keep the plain filter
        return False


def resolve_products(products: str, *trees) -> str:
    """Resolve ``products="auto"``: "dot" when called under ``vmap``, else "fused".

    Measured on the 6-state CV filter (benchmarks/bench_filters.py): for one sequence the
    fused elementwise products halve the run time (each tiny ``dot`` is a separate ~0.5 us
    kernel); under ``vmap`` with a covariance per sequence the batched dots are ~2x faster
    than the fused products, which become non-minor reductions over (B, n, n, n) arrays.
    The check sees ``vmap`` only when it is applied outside this call (``vmap(f)`` or
    ``jit(vmap(f))`` with ``f`` calling the filter); under ``vmap(jit(f))`` it sees one
    sequence and picks "fused" (correct, slower): pass ``products="dot"`` there.
    """
    if products == "auto":
        return "dot" if _under_vmap(*trees) else "fused"
    if products not in ("fused", "dot"):
        raise ValueError(f"products must be 'auto', 'fused' or 'dot', got {products!r}")
    return products

#: every per-epoch output :func:`kalman_filter` can save
ALL_OUTPUTS = (
    "means", "covs", "pred_means", "pred_covs", "innovations", "innov_covs",
    "nis", "logliks", "factors", "noise", "valid",
)


class UpdateResult(NamedTuple):
    """Output of :func:`update`."""

    x: Any  # (n,) posterior mean
    P: Any  # (n, n) posterior covariance
    v: Any  # (m,) innovation (zero where invalid)
    S: Any  # (m, m) innovation covariance (identity rows/cols where invalid)
    K: Any  # (n, m) gain
    nis: Any  # scalar v^T S^{-1} v
    loglik: Any  # scalar log N(v; 0, S) over the valid components
    ok: Any  # bool, S was positive definite (else the prior is returned)


def predict(x, P, F, GQG, factor=1.0, FPF=None):
    """Prediction X_{k,k-1} = F X_{k-1}, P_{k,k-1} = f_k F P_{k-1} F^T + G Q G^T.

    S0 eqs. (4), (8); f_k = S (eq. (10)), S_k (eq. (12)) or lambda_k (eq. (13)).

    Args:
      x: (n,) estimate at k-1.  P: (n, n) its covariance.
      F: (n, n) transition.  GQG: (n, n) process noise.  factor: scalar inflation f_k.
      FPF: optional precomputed F P F^T (n, n).
    Returns:
      (x_pred (n,), P_pred (n, n)).
    """
    if FPF is None:
        FPF = _mm(_mm(F, P), F.T)
    return _mm(F, x), symmetrize(factor * FPF + GQG)


def update(x_pred, P_pred, z, H, R, valid=None):
    """Joseph-form measurement update with Cholesky solves (S0 eqs. (5), (7), (9)).

    K = P H^T (H P H^T + R)^{-1}; x = x_pred + K v; P = (I - K H) P (I - K H)^T + K R K^T,
    symmetrised. Invalid components (``valid`` False) are removed exactly: their H rows are
    zeroed and their rows/columns of S replaced by the identity, so K has zero columns for them.
    (Tried in issue 8 and not kept: expanding the Joseph product as W - K (H W),
    W = P - (P H^T) K^T, takes 3 n^2 m multiplications instead of 2 n^3 + n^2 m but rounds like
    P - K S K^T and loses the congruence that keeps P positive semi-definite; multiplying by the
    unmasked H and masking afterwards keeps H shared under a per-sequence vmap mask, but made
    the loosely coupled filter's single run 2x slower.)
    If S is not positive definite the prior is returned with ``ok = False``.

    Args:
      x_pred: (n,) prior mean.  P_pred: (n, n) prior covariance.
      z: (m,) measurement (any value where invalid).  H: (m, n).  R: (m, m).
      valid: optional (m,) bool.
    Returns:
      :class:`UpdateResult`.
    """
    m = z.shape[-1]
    dt = P_pred.dtype
    if valid is None:
        valid = jnp.ones((m,), bool)
    Hm = jnp.where(valid[:, None], H, 0.0)
    both = valid[:, None] & valid[None, :]
    Rm = jnp.where(both, R, 0.0)
    Rm = Rm + jnp.diag(jnp.where(valid, 0.0, 1.0).astype(dt))
    v = jnp.where(valid, z - _mm(Hm, x_pred), 0.0)
    PHt = _mm(P_pred, Hm.T)
    S = symmetrize(_mm(Hm, PHt) + Rm)
    L = cholesky(S)
    ok = jnp.all(jnp.isfinite(L))
    Lsafe = jnp.where(ok, L, jnp.eye(m, dtype=dt))
    K = cho_solve(Lsafe, PHt.T).T
    x = x_pred + _mm(K, v)
    IKH = jnp.eye(P_pred.shape[-1], dtype=dt) - _mm(K, Hm)
    P = symmetrize(_mm(_mm(IKH, P_pred), IKH.T) + _mm(_mm(K, Rm), K.T))
    w = whiten(Lsafe, v)
    nis = jnp.sum(w * w)
    mv = jnp.sum(valid)
    loglik = -0.5 * (nis + 2.0 * jnp.sum(jnp.log(jnp.diagonal(Lsafe))) + mv * LOG_2PI)
    x = jnp.where(ok, x, x_pred)
    P = jnp.where(ok, P, P_pred)
    return UpdateResult(x=x, P=P, v=v, S=S, K=jnp.where(ok, K, 0.0), nis=nis, loglik=loglik, ok=ok)


def _near_psd(P, rel=1e-10):
    """Whether symmetric P has no eigenvalue below -rel * max(diag P): the Cholesky of the shifted P exists."""
    d = jnp.max(jnp.diagonal(P))
    shift = rel * jnp.abs(d) + jnp.finfo(P.dtype).tiny
    return jnp.all(jnp.isfinite(cholesky(P + shift * jnp.eye(P.shape[-1], dtype=P.dtype))))


class FilterState(NamedTuple):
    """Carry of the filter scan."""

    x: Any  # (n,) estimate at the last epoch
    P: Any  # (n, n)
    k: Any  # scalar float, epochs processed
    rule: Any  # inflation rule state
    est: Any  # estimator state
    status: Any  # int32 status flags (jaxnav._status)
    loglik: Any  # scalar accumulated log-likelihood
    n_nonfinite: Any  # int32, non-finite measurement elements masked
    n_skipped: Any  # int32, epochs with no valid component


class FilterParams(NamedTuple):
    """Static-in-time model parts plus the plug-ins (time-varying leaves come as inputs)."""

    model: LinearGaussian
    inflation: Any
    estimator: Any


class StepInput(NamedTuple):
    """Per-epoch inputs: the measurement, user mask, and any time-varying model leaves."""

    z: Any  # (m,)
    mask: Any  # (m,) bool
    F: Any = None
    H: Any = None
    Q: Any = None
    R: Any = None
    G: Any = None


class StepInfo(NamedTuple):
    """Per-epoch outputs (fields not requested are None)."""

    means: Any = None
    covs: Any = None
    pred_means: Any = None
    pred_covs: Any = None
    innovations: Any = None
    innov_covs: Any = None
    nis: Any = None
    logliks: Any = None
    factors: Any = None
    noise: Any = None
    valid: Any = None


def filter_step(state: FilterState, inp: StepInput, params: FilterParams, save=ALL_OUTPUTS,
                check_finite: bool = True):
    """One epoch of the Kalman filter family: predict, inflate, update (S0 eqs. (4)-(17)).

    Args:
      state: :class:`FilterState` at k-1.
      inp: :class:`StepInput` for epoch k (time-varying leaves given there, else in params).
      params: :class:`FilterParams`.
      save: names of the per-epoch outputs to return (see ``ALL_OUTPUTS``).
      check_finite: mask NaN/inf measurement elements (default); see :func:`kalman_filter`.
    Returns:
      (state at k, :class:`StepInfo`).
    """
    new, allv, _ = _filter_step(state, inp, params, check_finite)
    return new, StepInfo(**{name: allv[name] for name in save})


def _filter_step(state: FilterState, inp: StepInput, params: FilterParams, check_finite: bool):
    """:func:`filter_step` returning (state, every output by name, the gain K (n, m) applied)."""
    model, rule, est = params
    F = model.F if inp.F is None else inp.F
    H = model.H if inp.H is None else inp.H
    Q = model.Q if inp.Q is None else inp.Q
    R = model.R if inp.R is None else inp.R
    G = model.G if inp.G is None else inp.G
    dt = state.P.dtype
    n = state.x.shape[0]

    finite = jnp.isfinite(inp.z)
    valid = inp.mask & finite if check_finite else inp.mask
    observed = jnp.any(valid)
    z = jnp.where(valid, inp.z, 0.0) if check_finite else inp.z
    Hm = jnp.where(valid[:, None], H, 0.0)
    Gm = jnp.eye(n, dtype=dt) if G is None else G
    GQG = Q if G is None else _mm(_mm(G, Q), G.T)

    k = state.k + 1.0
    x_pred = _mm(F, state.x)
    FPF = _mm(_mm(F, state.P), F.T)
    v = jnp.where(valid, z - _mm(Hm, x_pred), 0.0)
    ctx = StepContext(k=k, v=v, z=z, x_pred=x_pred, valid=valid, observed=observed, F=F, H=Hm, G=Gm, Q=Q, R=R,
                      FPF=FPF, GQG=GQG, R_used=R)
    GQG, R_used, est_state, (noise_info, est_flag) = est.noise(state.est, ctx)
    ctx = ctx._replace(GQG=GQG, R_used=R_used)
    factor, rule_state = rule.factor(state.rule, ctx)
    states = getattr(rule, "states", None)
    if states is None:
        x_pred, P_pred = predict(state.x, state.P, F, GQG, factor, FPF=FPF)
    else:
        d = inflation_scale(factor, n, states)
        x_pred, P_pred = predict(state.x, state.P, F, GQG, 1.0, FPF=d[:, None] * FPF * d[None, :])
    up = update(x_pred, P_pred, z, H, R_used, valid)
    post = PostUpdate(x=up.x, P=up.P, K=up.K, eps=jnp.where(valid, z - _mm(Hm, up.x), 0.0), P_pred=P_pred)
    est_state = est.after(est_state, ctx, post)

    n_bad = jnp.sum(inp.mask & ~finite).astype(jnp.int32)
    bad_flag = _status.NONFINITE_MEASUREMENT if check_finite else _status.NONFINITE_UNMASKED
    flags = est_flag | jnp.where(n_bad > 0, bad_flag, 0)
    flags = flags | jnp.where(observed & ~up.ok, _status.CHOLESKY_FAILED, 0)
    finite = jnp.all(jnp.isfinite(up.x)) & jnp.all(jnp.isfinite(up.P))
    flags = flags | jnp.where(finite, 0, _status.NONFINITE_STATE)
    if not (_data_independent(rule) and _data_independent(est)):
        # adaptive inflation or noise estimates can diverge (S0 eq. (14) with variance compensation
        # drives lambda_k and Q to 1e7-1e12), and the Joseph form then loses PSD to rounding
        # without S failing: say so (only here: the fixed rules keep P bounded)
        psd = _near_psd(up.P) & _near_psd(P_pred)
        flags = flags | jnp.where(finite & ~psd, _status.COVARIANCE_INDEFINITE, 0)
    ll = jnp.where(observed & up.ok, up.loglik, 0.0)
    new = FilterState(
        x=up.x, P=up.P, k=k, rule=rule_state, est=est_state,
        status=state.status | flags.astype(jnp.int32), loglik=state.loglik + ll,
        n_nonfinite=state.n_nonfinite + n_bad,
        n_skipped=state.n_skipped + (~observed).astype(jnp.int32),
    )
    allv = dict(means=up.x, covs=up.P, pred_means=x_pred, pred_covs=P_pred, innovations=up.v,
                innov_covs=up.S, nis=jnp.where(observed, up.nis, 0.0), logliks=ll,
                factors=factor, noise=noise_info, valid=jnp.sum(valid).astype(jnp.int32))
    return new, allv, up.K


class KalmanResult(NamedTuple):
    """Result of :func:`kalman_filter`; per-epoch arrays have a leading axis T (None if not saved).

    Attributes:
      means: (T, n) filtered means X_k.  covs: (T, n, n) P_k.
      pred_means: (T, n) X_{k,k-1}.  pred_covs: (T, n, n) P_{k,k-1} (after inflation).
      innovations: (T, m) v_k (0 where invalid).  innov_covs: (T, m, m) H P_{k,k-1} H^T + R.
      nis: (T,) v^T S^{-1} v.  logliks: (T,) per-epoch log-likelihood.
      factors: (T,) inflation factor (1, S, S_k or lambda_k).
      noise: per-epoch estimator output (e.g. VCInfo, SageHusaInfo) or ().
      valid: (T,) number of valid measurement components.
      loglik: scalar total innovation log-likelihood.
      n_nonfinite: int, NaN/inf measurement elements masked.  n_skipped: int, epochs without update.
      status: int32 flags (see :func:`jaxnav.raise_for_status`).
      x_final, P_final: the last estimate (always returned).
    """

    means: Any = None
    covs: Any = None
    pred_means: Any = None
    pred_covs: Any = None
    innovations: Any = None
    innov_covs: Any = None
    nis: Any = None
    logliks: Any = None
    factors: Any = None
    noise: Any = None
    valid: Any = None
    loglik: Any = None
    n_nonfinite: Any = None
    n_skipped: Any = None
    status: Any = None
    x_final: Any = None
    P_final: Any = None


def _check_dtype(dtype, allow_float32):
    if dtype != jnp.float64 and not allow_float32:
        raise ValueError(
            f"kalman_filter computes in {jnp.dtype(dtype).name}; navigation and geodetic filtering "
            "needs float64: call jaxnav.enable_x64() before creating arrays, or pass "
            "allow_float32=True to opt in to the float32 path"
        )


def kalman_filter(model: LinearGaussian, x0, P0, zs, *, inflation=None, estimator=None, mask=None,
                  save=ALL_OUTPUTS, unroll: int = 1, allow_float32: bool = False,
                  check_finite: bool = True, products: str = "auto") -> KalmanResult:
    """Run the Kalman filter family over a measurement series with ``lax.scan`` (S0 eqs. (4)-(17)).

    Convention: ``x0, P0`` are the estimate at k = 0 and every ``zs[t]`` is used after one
    prediction, so the first prediction has k = 1 (S_1 = 1). A masked or NaN epoch returns the
    prediction as its estimate.

    Args:
      model: :class:`LinearGaussian` with static or (T, ...) time-varying leaves.
      x0: (n,) initial mean.  P0: (n, n) initial covariance.
      zs: (T, m) measurements; NaN/inf elements are masked and counted.
      inflation: None (classic), ``constant(S)``, ``attenuated(b)`` or ``fading(...)``.
      estimator: None, ``variance_compensation(window)`` or ``sage_husa(b)``.
      mask: optional (T,) or (T, m) bool, True where a measurement is used.
      save: tuple of per-epoch outputs to keep (subset of ``ALL_OUTPUTS``); static.
      unroll: ``lax.scan`` unroll factor; static.
      allow_float32: opt in to computing in float32; static.
      products: static kernel choice for the small matrix products: "auto" (default) picks
        "fused" elementwise products for a single sequence and "dot" (batched XLA dots) when
        called under ``vmap``; see :func:`resolve_products`. Results agree to rounding.
      check_finite: static. True (default) masks NaN/inf measurement elements and counts them.
        False trusts the data: NaN/inf are still counted and raise the NONFINITE_UNMASKED error
        flag, but are not masked. Under ``vmap`` the default needs no such choice for speed:
        when the model, P0, mask and rule (classic, constant, attenuated) are shared by the
        batch, the batch is checked once and, if every sequence has the same non-finite
        elements (none, or common gaps), one covariance recursion serves every sequence
        (~10-20x faster than one per sequence; see :func:`_batched_filter`), and from
        B T = 2^14 sequence-epochs the means of the whole batch run in blocks of epochs as dense
        products (``filters._blocked``; equal to rounding; 40.9 vs 68.8 ms for stepping every
        sequence at B = 256, T = 3600 in benchmarks/bench_filters.py). NaN patterns that differ between
        sequences, or a data-dependent rule or estimator, run one masked recursion per sequence.
        With ``check_finite=False`` and no covariances saved, a shared batch takes the same blocks
        when all its unmasked measurements are finite, else steps every sequence (propagating the
        NaN/inf).
    Returns:
      :class:`KalmanResult`.
    Raises:
      ValueError: at trace time, for inconsistent shapes (naming them), unknown output names, or
        a float32 computation without ``allow_float32``.
    """
    trees = (model, x0, P0, zs, mask, inflation, estimator)
    batched = _under_vmap(*trees)
    products = resolve_products(products, *trees)
    static = dict(save=tuple(save), unroll=unroll, allow_float32=allow_float32, products=products)
    # check_finite=False only without saved covariances: plain vmap keeps those unbatched (one
    # copy for the batch), where the batch rule would return B copies (log_likelihood saves them)
    if (batched and _vmap_innermost() and _data_independent(inflation) and _data_independent(estimator)
            and (check_finite or not set(static["save"]) & {"covs", "pred_covs", "innov_covs"})):
        return _batched_filter(*trees, check_finite=check_finite, **static)
    return _kalman_filter(model, x0, P0, zs, inflation=inflation, estimator=estimator, mask=mask,
                          check_finite=check_finite, **static)


def _data_independent(plugin) -> bool:
    """Whether a rule/estimator leaves the covariance recursion independent of the measurements."""
    return plugin is None or bool(getattr(plugin, "data_independent", False))


def _batched_filter(model, x0, P0, zs, mask, inflation, estimator, *, check_finite=True, **static):
    """:func:`kalman_filter` under ``vmap``: one covariance recursion when all sequences have the same gaps.

    With ``check_finite=True`` the NaN masks make every sequence's covariance recursion its own,
    so ``vmap`` runs B of them. When the model, P0, the user mask and the plug-ins are shared and
    data-independent, the recursion differs between sequences only if some measurement is
    NaN/inf. This batching rule (``jax.custom_batching.custom_vmap``) looks at the whole batch
    once: if every sequence has the same non-finite elements (none at all, or common gaps such as
    the outages of a Monte Carlo study), it masks those for all and runs
    :func:`._blocked.blocked_batch_filter`: one covariance recursion, and the batch's means in
    blocks of epochs as dense products (equal to the per-sequence filter to rounding; counts and
    flags identical); else the per-sequence masked filter. Both are compiled; ``lax.cond`` runs
    one. With ``check_finite=False`` the shared recursion never depends on the data; the blocks
    are taken when every unmasked measurement of the batch is finite (then both filters agree to
    rounding), else the per-sequence filter, which propagates and flags the NaN/inf.
    Taken only when ``vmap`` is the innermost transformation (see :func:`_vmap_innermost`):
    ``grad(vmap(f))`` gets it, ``vmap(grad(f))`` and ``vmap(jit(f))`` keep the per-sequence filter.
    """
    def call(check_finite, *a):
        m, x, P, z, mk, inf, est = a
        return _kalman_filter(m, x, P, z, inflation=inf, estimator=est, mask=mk, check_finite=check_finite,
                              **static)

    @jax.custom_batching.custom_vmap
    def f(*a):
        return call(check_finite, *a)

    @f.def_vmap
    def rule(axis_size, in_batched, *a):
        axes = tuple(jax.tree_util.tree_map(lambda b: 0 if b else None, in_batched))

        def run(check_finite, *b):
            return jax.vmap(partial(call, check_finite), in_axes=axes)(*b)

        def worth(x, z):
            from jaxnav.filters._blocked import worth_blocking

            zshape = jnp.shape(z)[1:] if axes[3] == 0 else jnp.shape(z)
            return len(zshape) == 2 and worth_blocking(axis_size, zshape[0], jnp.shape(x)[-1], zshape[1],
                                                       static["save"], jnp.dtype(jnp.result_type(z)).itemsize)

        def blocked(m, x, P, z, mk, inf, est):
            # the shared recursion with the means of the whole batch in blocks of epochs as
            # dense products (._blocked); equal to run(False, ...) to rounding
            from jaxnav.filters._blocked import blocked_batch_filter

            if not worth(x, z):
                return run(False, m, x, P, z, mk, inf, est)
            batch = lambda v, ax: jnp.broadcast_to(v, (axis_size,) + jnp.shape(v)) if ax is None else v  # noqa: E731
            return blocked_batch_filter(m, batch(jnp.asarray(x), axes[1]), P, batch(jnp.asarray(z), axes[3]), mk,
                                        inf, est, save=static["save"], unroll=static["unroll"],
                                        allow_float32=static["allow_float32"])

        shared = not any(jax.tree_util.tree_leaves([in_batched[i] for i in (0, 2, 4, 5, 6)]))
        if not check_finite:
            if shared and worth(a[1], a[3]):
                # data trusted: the blocks when every unmasked measurement is finite; else the
                # per-sequence filter, which lets the NaN/inf through and flags them
                z, mk = jnp.asarray(a[3]), a[4]
                fin = jnp.isfinite(jax.lax.optimization_barrier(z))
                if mk is not None:
                    fin = fin | ~jnp.broadcast_to(jnp.asarray(mk, bool).reshape(fin.shape[-2:-1] + (-1,)),
                                                  fin.shape[-2:])
                trusted = jax.checkpoint(partial(run, False))
                out = jax.lax.cond(jnp.all(fin), lambda: blocked(*a), lambda: trusted(*a))
            else:
                out = run(False, *a)
        elif shared:
            z, mk = jnp.asarray(a[3]), a[4]
            # the barrier keeps XLA from constant-folding this reduction when the data is a
            # jit constant (seconds of compile time for a 256 x 3600 batch)
            fin = jnp.isfinite(jax.lax.optimization_barrier(z))
            fin0 = fin[0] if axes[3] == 0 else fin
            user = jnp.ones(fin0.shape, bool) if mk is None else jnp.broadcast_to(
                jnp.asarray(mk, bool).reshape(fin0.shape[:1] + (-1,)), fin0.shape)
            same = jnp.all(fin == fin0) if axes[3] == 0 else jnp.asarray(True)

            def common_gaps():
                # every sequence has the same non-finite elements (none, or e.g. the outages of a
                # Monte Carlo study): mask them for all, share the recursion, count them as the
                # masked filter does
                b = list(a)
                b[4] = user & fin0
                res = blocked(*b)
                n = jnp.sum(user & ~fin0).astype(jnp.int32)
                return res._replace(n_nonfinite=res.n_nonfinite + n,
                                    status=res.status | jnp.where(n > 0, _status.NONFINITE_MEASUREMENT, 0))

            # the masked branch is rematerialised: under reverse-mode AD lax.cond keeps every
            # branch's residuals, and this one's are B covariance sequences (zeros when not taken)
            masked = jax.checkpoint(partial(run, True))
            out = jax.lax.cond(same, common_gaps, lambda: masked(*a))
        else:
            out = run(True, *a)
        return out, jax.tree_util.tree_map(lambda _: True, out)

    return f(model, x0, P0, zs, mask, inflation, estimator)


@partial(jax.jit, static_argnames=("save", "unroll", "allow_float32", "check_finite", "products"))
def _kalman_filter(model, x0, P0, zs, *, inflation, estimator, mask, save, unroll, allow_float32, check_finite,
                   products):
    with _fused_products(products == "fused"):
        return _kalman_filter_traced(model, x0, P0, zs, inflation, estimator, mask, save, unroll, allow_float32,
                                     check_finite)


def _lower(model, x0, P0, zs, *, products="auto", save=ALL_OUTPUTS, inflation=None, estimator=None, mask=None, **kw):
    products = resolve_products(products, model, x0, P0, zs, mask, inflation, estimator)
    return _kalman_filter.lower(model, x0, P0, zs, products=products, save=tuple(save), inflation=inflation,
                                estimator=estimator, mask=mask, **{"unroll": 1, "allow_float32": False,
                                                                   "check_finite": True, **kw})


kalman_filter.lower = _lower  # ahead-of-time compilation, as on a jitted function
kalman_filter._cache_size = lambda: _kalman_filter._cache_size()


def prepare_inputs(model, x0, P0, zs, mask, save, allow_float32):
    """Validate and cast a filter call's inputs (trace time), shared by the sequential and parallel filters.

    Returns:
      (model, x0, P0, zs, mask (T, m) bool, save tuple, (n, m, p, T), tv dict, dtype), the arrays
      cast to the common floating dtype.
    Raises:
      ValueError: unknown outputs, inconsistent shapes (named), float32 without ``allow_float32``.
    """
    save = tuple(save)
    unknown = [s for s in save if s not in ALL_OUTPUTS]
    if unknown:
        raise ValueError(f"unknown outputs {unknown}; choose from {ALL_OUTPUTS}")
    n, m, p, T, tv = check_shapes(model, x0, P0, zs, mask)
    leaves = [x0, P0, zs] + [a for a in model if a is not None]
    dtype = jnp.result_type(*leaves)
    if not jnp.issubdtype(dtype, jnp.floating):
        dtype = jnp.result_type(float)
    _check_dtype(dtype, allow_float32)
    cast = lambda a: None if a is None else jnp.asarray(a, dtype)  # noqa: E731
    model = LinearGaussian(*[cast(a) for a in model])
    x0, P0, zs = cast(x0), cast(P0), cast(zs)
    if mask is None:
        mask = jnp.ones((T, m), bool)
    else:
        mask = jnp.asarray(mask, bool)
        if mask.ndim == 1:
            mask = jnp.broadcast_to(mask[:, None], (T, m))
    return model, x0, P0, zs, mask, save, (n, m, p, T), tv, dtype


def scan_setup(model, x0, P0, zs, inflation, estimator, mask, save, allow_float32):
    """Validated inputs of the filter scan: (model, params, initial state, scan inputs, save, sizes, tv, dtype).

    Shared by :func:`kalman_filter` and the blocked batch filter (:mod:`._blocked`); sizes is
    (n, m, p, T) and ``tv`` says which model leaves are time-varying.
    """
    model, x0, P0, zs, mask, save, (n, m, p, T), tv, dtype = prepare_inputs(model, x0, P0, zs, mask, save,
                                                                             allow_float32)
    rule = NoInflation() if inflation is None else inflation
    est = NoEstimator() if estimator is None else estimator
    static = LinearGaussian(*[None if tv[name] else getattr(model, name) for name in LinearGaussian._fields])
    xs = StepInput(z=zs, mask=mask, **{name: getattr(model, name) for name in tv if tv[name]})
    params = FilterParams(model=static, inflation=rule, estimator=est)
    init = FilterState(
        x=x0, P=P0, k=jnp.zeros((), dtype), rule=rule.init(m, dtype), est=est.init(n, m, p, dtype),
        status=jnp.zeros((), jnp.int32), loglik=jnp.zeros((), dtype),
        n_nonfinite=jnp.zeros((), jnp.int32), n_skipped=jnp.zeros((), jnp.int32),
    )
    return model, params, init, xs, save, (n, m, p, T), tv, dtype


def _kalman_filter_traced(model, x0, P0, zs, inflation, estimator, mask, save, unroll, allow_float32,
                          check_finite) -> KalmanResult:
    _, params, init, xs, save, _, _, _ = scan_setup(model, x0, P0, zs, inflation, estimator, mask, save,
                                                    allow_float32)

    def body(state, inp):
        return filter_step(state, inp, params, save, check_finite)

    # Under reverse-mode AD, recompute each step from its carry instead of storing every
    # intermediate (the fused small products would otherwise save broadcast operands per epoch):
    # the backward pass reads one state per epoch. No effect on forward runs or forward mode.
    final, info = jax.lax.scan(jax.checkpoint(body, prevent_cse=False), init, xs, unroll=unroll)
    return KalmanResult(
        **info._asdict(), loglik=final.loglik, n_nonfinite=final.n_nonfinite,
        n_skipped=final.n_skipped, status=final.status, x_final=final.x, P_final=final.P,
    )
