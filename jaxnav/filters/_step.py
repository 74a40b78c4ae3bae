"""One epoch of the Kalman filter family: the records, predict, update and the plug-in step
(S0 eqs. (4)-(17), S1 eqs. (7)-(11)).

One prediction and one Joseph-form update serve every variant; prior-inflation rules and noise
estimators (:mod:`._plugins`) plug into :func:`filter_step`. The drivers
(:func:`jaxnav.filters.kalman_filter`, the batch entry points, the INS/GNSS filter) scan it.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from jaxnav import _status
from jaxnav._numerics import (
    check_float64,
    cho_solve,
    cholesky,
    gaussian_loglik,
    masked_measurement,
    mm,
    safe_cholesky,
    symmetrize,
    whiten,
)
from jaxnav.filters._model import LinearGaussian, check_shapes
from jaxnav.filters._plugins import (
    InflationRule,
    NoEstimator,
    NoInflation,
    NoiseEstimator,
    PostUpdate,
    StepContext,
    data_independent,
)
from jaxnav.filters._rules import inflation_scale

#: every per-epoch output a filter run can save
ALL_OUTPUTS = (
    "means",
    "covs",
    "pred_means",
    "pred_covs",
    "innovations",
    "innov_covs",
    "nis",
    "logliks",
    "factors",
    "noise",
    "valid",
)


class FilterState(NamedTuple):
    """Carry of the filter scan.

    Attributes:
      x: (n,) estimate at the last epoch.  P: (n, n) its covariance.
      k: scalar float, epochs processed.  rule, est: the plug-ins' states.
      status: int32 status flags (:mod:`jaxnav._status`).  loglik: scalar accumulated log-likelihood.
      n_nonfinite: int32, non-finite measurement elements seen.  n_skipped: int32, epochs with no valid component.
    """

    x: jax.Array
    P: jax.Array
    k: jax.Array
    rule: Any
    est: Any
    status: jax.Array
    loglik: jax.Array
    n_nonfinite: jax.Array
    n_skipped: jax.Array


class FilterParams(NamedTuple):
    """Static-in-time model parts plus the plug-ins (time-varying leaves come as inputs).

    Attributes:
      model: :class:`~jaxnav.filters.LinearGaussian` with None for the leaves given per epoch.
      inflation: the :class:`~jaxnav.filters.InflationRule`.
      estimator: the :class:`~jaxnav.filters.NoiseEstimator`.
    """

    model: LinearGaussian
    inflation: InflationRule
    estimator: NoiseEstimator


class StepInput(NamedTuple):
    """Per-epoch inputs: the measurement, user mask, and any time-varying model leaves.

    Attributes:
      z: (m,) measurement.  mask: (m,) bool, components to use.
      F: (n, n), H: (m, n), Q: (p, p), R: (m, m), G: (n, p) this epoch's model leaves, or None
        for the static ones in :class:`FilterParams`.
    """

    z: jax.Array
    mask: jax.Array
    F: jax.Array | None = None
    H: jax.Array | None = None
    Q: jax.Array | None = None
    R: jax.Array | None = None
    G: jax.Array | None = None


class StepInfo(NamedTuple):
    """Per-epoch outputs of :func:`filter_step`; fields not requested in ``save`` are None.

    The fields are ``ALL_OUTPUTS``, one epoch of :class:`KalmanResult` (same meaning, no
    leading axis T).
    """

    means: jax.Array | None = None
    covs: jax.Array | None = None
    pred_means: jax.Array | None = None
    pred_covs: jax.Array | None = None
    innovations: jax.Array | None = None
    innov_covs: jax.Array | None = None
    nis: jax.Array | None = None
    logliks: jax.Array | None = None
    factors: jax.Array | None = None
    noise: Any = None
    valid: jax.Array | None = None


class UpdateResult(NamedTuple):
    """Output of :func:`update`.

    Attributes:
      x: (n,) posterior mean.  P: (n, n) posterior covariance.
      v: (m,) innovation (zero where invalid).
      S: (m, m) innovation covariance (identity rows/cols where invalid).
      K: (n, m) gain.  nis: scalar v^T S^{-1} v.
      loglik: scalar log N(v; 0, S) over the valid components.
      ok: scalar bool, S was positive definite (else the prior is returned).
    """

    x: jax.Array
    P: jax.Array
    v: jax.Array
    S: jax.Array
    K: jax.Array
    nis: jax.Array
    loglik: jax.Array
    ok: jax.Array


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
        FPF = mm(mm(F, P), F.T)
    return mm(F, x), symmetrize(factor * FPF + GQG)


def update(x_pred, P_pred, z, H, R, valid=None, joseph: bool = True):
    """Measurement update with Cholesky solves (S0 eqs. (5), (7), (9)), Joseph form by default.

    K = P H^T (H P H^T + R)^{-1}; x = x_pred + K v; P = (I - K H) P (I - K H)^T + K R K^T,
    symmetrised. Invalid components (``valid`` False) are removed exactly
    (:func:`jaxnav._numerics.masked_measurement`), so K has zero columns for them.
    If S is not positive definite the prior is returned with ``ok = False``.

    ``joseph=False`` (static) uses the textbook form P = P_pred - K H P_pred, symmetrised: equal
    for the optimal gain, about 40 % less work per epoch on the 6-state model (the Joseph
    products are most of what a filter with a covariance per sequence costs under ``vmap``,
    benchmarks/bench_filters.py case (d)), but it can lose positive semi-definiteness to rounding
    when R is small next to H P H^T; the Joseph form is a congruence plus a PSD term and keeps it.

    Notes:
      Not used: expanding the Joseph product as W - K (H W),
      W = P - (P H^T) K^T, takes 3 n^2 m multiplications instead of 2 n^3 + n^2 m but rounds
      like P - K S K^T and loses the congruence that keeps P positive semi-definite.

    Args:
      x_pred: (n,) prior mean.  P_pred: (n, n) prior covariance.
      z: (m,) measurement (any value where invalid).  H: (m, n).  R: (m, m).
      valid: optional (m,) bool.  joseph: static, the covariance form (above).
    Returns:
      :class:`UpdateResult`.
    """
    m = z.shape[-1]
    dt = P_pred.dtype
    if valid is None:
        valid = jnp.ones((m,), bool)
    Hm, Rm = masked_measurement(H, R, valid)
    v = jnp.where(valid, z - mm(Hm, x_pred), 0.0)
    PHt = mm(P_pred, Hm.T)
    S = symmetrize(mm(Hm, PHt) + Rm)
    L, ok = safe_cholesky(S)
    K = cho_solve(L, PHt.T).T
    x = x_pred + mm(K, v)
    if joseph:
        IKH = jnp.eye(P_pred.shape[-1], dtype=dt) - mm(K, Hm)
        P = symmetrize(mm(mm(IKH, P_pred), IKH.T) + mm(mm(K, Rm), K.T))
    else:
        P = symmetrize(P_pred - mm(K, PHt.T))
    return update_result(x_pred, P_pred, x, P, v, S, K, L, valid, ok)


def update_result(x_pred, P_pred, x, P, v, S, K, L, valid, ok) -> UpdateResult:
    """:class:`UpdateResult` of an update: the posterior (x, P) where the Cholesky factor L of S succeeded
    (``ok``), else the prior with a zero gain; NIS and Gaussian log-likelihood of the innovation v (m,)
    whitened by L over the ``valid`` components."""
    w = whiten(L, v)
    return UpdateResult(
        x=jnp.where(ok, x, x_pred),
        P=jnp.where(ok, P, P_pred),
        v=v,
        S=S,
        K=jnp.where(ok, K, 0.0),
        nis=jnp.sum(w * w),
        loglik=gaussian_loglik(w, L, jnp.sum(valid)),
        ok=ok,
    )


def _near_psd(P, rel=1e-10):
    """Whether symmetric P has no eigenvalue below -rel * max(diag P): the Cholesky of the shifted P exists."""
    d = jnp.max(jnp.diagonal(P))
    shift = rel * jnp.abs(d) + jnp.finfo(P.dtype).tiny
    return jnp.all(jnp.isfinite(cholesky(P + shift * jnp.eye(P.shape[-1], dtype=P.dtype))))


def filter_step(
    state: FilterState,
    inp: StepInput,
    params: FilterParams,
    save=ALL_OUTPUTS,
    check_finite: bool = True,
    joseph: bool = True,
):
    """One epoch of the Kalman filter family: noise, inflation, predict, update (S0 eqs. (4)-(17)).

    Args:
      state: :class:`FilterState` at k-1.
      inp: :class:`StepInput` for epoch k (time-varying leaves given there, else in params).
      params: :class:`FilterParams`.
      save: names of the per-epoch outputs to return (see ``ALL_OUTPUTS``).
      check_finite: mask NaN/inf measurement elements (default); see :func:`~jaxnav.filters.kalman_filter`.
      joseph: static, the covariance update form (:func:`update`).
    Returns:
      (state at k, :class:`StepInfo`).
    """
    new, allv, _ = step_with_gain(state, inp, params, check_finite, joseph)
    return new, StepInfo(**{name: allv[name] for name in save})


def step_with_gain(
    state: FilterState, inp: StepInput, params: FilterParams, check_finite: bool, joseph: bool = True, lin=None
):
    """:func:`filter_step` returning (state, every output by name, the gain K (n, m) applied).

    The batch entry points run it once on zero data for the batch's shared covariances and gains.
    ``lin`` (static): None for the linear model, else a linearisation of a nonlinear model at this
    epoch (:mod:`._nonlinear`) giving the prediction f(x), F P F^T and the affine measurement
    z ~ H x + b; everything else (plug-ins, masking, Joseph update, flags) is this step's.
    """
    model, rule, est = params
    F, H, Q, R, G = (getattr(model, f) if getattr(inp, f) is None else getattr(inp, f) for f in LinearGaussian._fields)
    dt = state.P.dtype
    n = state.x.shape[0]

    # the measurement: NaN/inf elements are masked (or, trusted, let through and flagged)
    finite = jnp.isfinite(inp.z)
    valid = inp.mask & finite if check_finite else inp.mask
    observed = jnp.any(valid)
    z = jnp.where(valid, inp.z, 0.0) if check_finite else inp.z

    # the plug-ins choose the noise, then the inflation factor, from the prior and the innovation
    k = state.k + 1.0
    Gm = jnp.eye(n, dtype=dt) if G is None else G
    GQG = Q if G is None else mm(mm(G, Q), G.T)
    if lin is None:
        x_pred = mm(F, state.x)
        FPF = mm(mm(F, state.P), F.T)
        Hm = jnp.where(valid[:, None], H, 0.0)
        v = jnp.where(valid, z - mm(Hm, x_pred), 0.0)
    else:
        F, x_pred, FPF = lin.predict(state.x, state.P)
        first = lin.measure(x_pred, symmetrize(FPF + GQG))
        H, z_hat = first[0], first[1]
        Hm = jnp.where(valid[:, None], H, 0.0)
        v = jnp.where(valid, z - z_hat, 0.0)
        z_obs = z
        z = jnp.where(valid, z - z_hat + mm(H, x_pred), 0.0)  # the affine model's z - b
    ctx = StepContext(
        k=k,
        v=v,
        z=z,
        x_pred=x_pred,
        valid=valid,
        observed=observed,
        F=F,
        H=Hm,
        G=Gm,
        Q=Q,
        R=R,
        FPF=FPF,
        GQG=GQG,
        R_used=R,
    )
    GQG, R_used, est_state, (noise_info, est_flag) = est.noise(state.est, ctx)
    ctx = ctx._replace(GQG=GQG, R_used=R_used)
    factor, rule_state, rule_flag = rule.factor(state.rule, ctx)
    if rule.states is not None:  # partial inflation: scale the block of the inflated states
        d = inflation_scale(factor, n, rule.states)
        FPF = d[:, None] * FPF * d[None, :]
        factor_used = 1.0
    else:
        factor_used = factor

    x_lin, P_pred = predict(state.x, state.P, F, GQG, factor_used, FPF=FPF)
    if lin is None:
        x_pred = x_lin
        up = update(x_pred, P_pred, z, H, R_used, valid, joseph)
    else:
        redo = not (isinstance(rule, NoInflation) and isinstance(est, NoEstimator))
        up, Hm, z = lin.update(x_pred, P_pred, z_obs, R_used, valid, joseph, first, redo)
    post = PostUpdate(x=up.x, P=up.P, K=up.K, eps=jnp.where(valid, z - mm(Hm, up.x), 0.0), P_pred=P_pred)
    est_state = est.after(est_state, ctx, post)

    # status flags and counts
    n_bad = jnp.sum(inp.mask & ~finite).astype(jnp.int32)
    bad_flag = _status.NONFINITE_MEASUREMENT if check_finite else _status.NONFINITE_UNMASKED
    flags = est_flag | rule_flag | jnp.where(n_bad > 0, bad_flag, 0)
    flags = flags | jnp.where(observed & ~up.ok, _status.CHOLESKY_FAILED, 0)
    finite_state = jnp.all(jnp.isfinite(up.x)) & jnp.all(jnp.isfinite(up.P))
    flags = flags | jnp.where(finite_state, 0, _status.NONFINITE_STATE)
    if not data_independent(rule, est):
        # adaptive inflation or noise estimates can diverge (S0 eq. (14) with variance compensation
        # drives lambda_k and Q to 1e7-1e12), and the Joseph form then loses PSD to rounding
        # without S failing: say so (only here: the fixed rules keep P bounded)
        psd = _near_psd(up.P) & _near_psd(P_pred)
        flags = flags | jnp.where(finite_state & ~psd, _status.COVARIANCE_INDEFINITE, 0)
        if dt == jnp.float32:  # the documented float32 range of these plug-ins: |z| within ~100 sigma
            sigma = jnp.sqrt(jnp.abs(jnp.diagonal(R)))
            far = jnp.any(valid & (jnp.abs(jnp.where(valid, inp.z, 0.0)) > _status.FLOAT32_Z_RANGE * sigma))
            flags = flags | jnp.where(far, _status.FLOAT32_DATA_RANGE, 0)
    ll = jnp.where(observed & up.ok, up.loglik, 0.0)

    new = FilterState(
        x=up.x,
        P=up.P,
        k=k,
        rule=rule_state,
        est=est_state,
        status=state.status | flags.astype(jnp.int32),
        loglik=state.loglik + ll,
        n_nonfinite=state.n_nonfinite + n_bad,
        n_skipped=state.n_skipped + (~observed).astype(jnp.int32),
    )
    allv = dict(
        means=up.x,
        covs=up.P,
        pred_means=x_pred,
        pred_covs=P_pred,
        innovations=up.v,
        innov_covs=up.S,
        nis=jnp.where(observed, up.nis, 0.0),
        logliks=ll,
        factors=factor,
        noise=noise_info,
        valid=jnp.sum(valid).astype(jnp.int32),
    )
    return new, allv, up.K


def init_state(x0, P0, m: int, *, p=None, inflation=None, estimator=None) -> FilterState:
    """The filter's carry at k = 0: estimate (x0, P0), the plug-ins' initial states, zero counts.

    Args:
      x0: (n,) initial mean.  P0: (n, n) its covariance.
      m: static measurement size.  p: static process-noise size (default n).
      inflation, estimator: the plug-ins (None: classic filter, model noise).
    Returns:
      :class:`FilterState`.
    """
    x0 = jnp.asarray(x0)
    dtype = jnp.result_type(x0, P0, float)
    n = x0.shape[-1]
    p = n if p is None else p
    rule = NoInflation() if inflation is None else inflation
    est = NoEstimator() if estimator is None else estimator
    return FilterState(
        x=jnp.asarray(x0, dtype),
        P=jnp.asarray(P0, dtype),
        k=jnp.zeros((), dtype),
        rule=rule.init(n, m, p, dtype),
        est=est.init(n, m, p, dtype),
        status=jnp.zeros((), jnp.int32),
        loglik=jnp.zeros((), dtype),
        n_nonfinite=jnp.zeros((), jnp.int32),
        n_skipped=jnp.zeros((), jnp.int32),
    )


def prepare_inputs(model, x0, P0, zs, mask, save, allow_float32):
    """Validate and cast a filter call's inputs (trace time), shared by every filter driver.

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
    check_float64(dtype, what="the Kalman filter's arrays", allow_float32=allow_float32)
    cast = lambda a: None if a is None else jnp.asarray(a, dtype)
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
    """Validated inputs of a filter scan: (params, initial state, scan inputs, save, sizes, tv, dtype).

    Sizes are (n, m, p, T); ``tv`` says which model leaves are time-varying (they become scan
    inputs, the static ones stay in ``params.model``).
    """
    model, x0, P0, zs, mask, save, (n, m, p, T), tv, dtype = prepare_inputs(
        model, x0, P0, zs, mask, save, allow_float32
    )
    static = LinearGaussian(*[None if tv[name] else getattr(model, name) for name in LinearGaussian._fields])
    xs = StepInput(z=zs, mask=mask, **{name: getattr(model, name) for name in tv if tv[name]})
    params = FilterParams(
        model=static,
        inflation=NoInflation() if inflation is None else inflation,
        estimator=NoEstimator() if estimator is None else estimator,
    )
    init = init_state(x0, P0, m, p=p, inflation=params.inflation, estimator=params.estimator)
    return params, init, xs, save, (n, m, p, T), tv, dtype


class KalmanResult(NamedTuple):
    """Result of :func:`~jaxnav.filters.kalman_filter`; per-epoch arrays have a leading axis T (None if not saved).

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
      x_final, P_final: (n,), (n, n) the last estimate (always returned).

    The batch entry points (:func:`~jaxnav.filters.kalman_filter_batch`) return the same record
    with a leading batch axis B on the per-sequence fields and none on the shared ones.
    """

    means: jax.Array | None = None
    covs: jax.Array | None = None
    pred_means: jax.Array | None = None
    pred_covs: jax.Array | None = None
    innovations: jax.Array | None = None
    innov_covs: jax.Array | None = None
    nis: jax.Array | None = None
    logliks: jax.Array | None = None
    factors: jax.Array | None = None
    noise: Any = None
    valid: jax.Array | None = None
    loglik: jax.Array | None = None
    n_nonfinite: jax.Array | None = None
    n_skipped: jax.Array | None = None
    status: jax.Array | None = None
    x_final: jax.Array | None = None
    P_final: jax.Array | None = None
