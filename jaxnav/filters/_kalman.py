"""The Kalman filter driver: :func:`filter_step` scanned over a measurement series (S0 eqs. (4)-(17)).

``jax.vmap`` of :func:`kalman_filter` equals the loop of single runs, whatever the nesting of
``jit``, ``vmap`` and ``grad``; its ``vmap`` rule (:func:`._batch.vmap_filter_rule`) runs one
covariance recursion for a clean batch with shared model, P0, mask and a data-independent rule.
"""

from __future__ import annotations

import weakref
from functools import cache, partial
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from jaxnav.filters._model import LinearGaussian
from jaxnav.filters._step import ALL_OUTPUTS, KalmanResult, filter_step, prepare_inputs, scan_setup


def kalman_filter(
    model: LinearGaussian,
    x0,
    P0,
    zs,
    *,
    inflation=None,
    estimator=None,
    mask=None,
    save=ALL_OUTPUTS,
    unroll: int = 1,
    allow_float32: bool = False,
    check_finite: bool = True,
    joseph: bool = True,
) -> KalmanResult:
    """Run the Kalman filter family over a measurement series with ``lax.scan`` (S0 eqs. (4)-(17)).

    Convention: ``x0, P0`` are the estimate at k = 0 and every ``zs[t]`` is used after one
    prediction, so the first prediction has k = 1 (S_1 = 1). A masked or NaN epoch returns the
    prediction as its estimate.

    Batches: ``jax.vmap`` over any argument equals a loop of single runs. When the model, P0,
    mask and a data-independent rule are shared and ``zs`` is batched, a run-time check
    (``lax.cond``) picks: no unmasked NaN/inf in the whole batch -> one covariance recursion for
    all sequences (:func:`~jaxnav.filters.kalman_filter_batch`'s; saved covariances returned as
    B copies); else one filter per sequence (with masking on, each sequence's covariance depends
    on its own NaN/inf elements). Batches with a covariance per sequence (P0, mask, NaN/inf or
    model leaves per sequence) of the classic filter with a model of at most 8 states run
    batch-minor (:mod:`jaxnav.filters._minor`: the batch the minor axis of every array; the loop's
    results). Derivatives (``grad``, ``jvp``) are the plain filter's: exact, one per sequence
    under ``vmap``. With ``check_finite=False`` and shared inputs, ``vmap``
    shares the covariance recursion by itself. For batches with gaps common to all sequences,
    :func:`~jaxnav.filters.kalman_filter_batch` shares the recursion while masking NaN/inf.

    Args:
      model: :class:`LinearGaussian` with static or (T, ...) time-varying leaves.
      x0: (n,) initial mean.  P0: (n, n) initial covariance.
      zs: (T, m) measurements; NaN/inf elements are masked and counted.
      inflation: None (classic), ``constant(S)``, ``attenuated(b)``, ``fading(...)`` or any
        :class:`~jaxnav.filters.InflationRule`.
      estimator: None, ``variance_compensation(window)``, ``sage_husa(b)``, ``igg3()``, ... or any
        :class:`~jaxnav.filters.NoiseEstimator`.
      mask: optional (T,) or (T, m) bool, True where a measurement is used.
      save: tuple of per-epoch outputs to keep (subset of ``ALL_OUTPUTS``); static.
      unroll: ``lax.scan`` unroll factor; static.
      allow_float32: opt in to computing in float32; static. The classic filter and the
        data-independent rules (constant, attenuated) keep the variances to ~1e-6 relative at any
        horizon (200k epochs measured): their covariance recursion never sees the data. Data-dependent
        plug-ins (fading, Sage-Husa, variance compensation, IGG-III, Yang) compute lambda_k or the
        noise from float32 innovations, whose rounding grows with the size of z: the relative
        variance error is about 6e-7 |z|/sigma for fading and 7e-8 |z|/sigma for Sage-Husa, so
        keep z within ~100 sigma of the origin (local offsets) or use float64 (a 200k-epoch track
        drifting to 5 km put fading's variances 50 % off). A float32 run of such a plug-in with a
        measurement beyond that range sets FLOAT32_DATA_RANGE in ``status`` (an error flag).
      check_finite: static. True (default) masks NaN/inf measurement elements and counts them.
        False trusts the data: NaN/inf are still counted and raise the NONFINITE_UNMASKED error
        flag, but are not masked (they propagate into the estimate).
      joseph: static. True (default): Joseph-form covariance update, which keeps P positive
        semi-definite under rounding. False: the textbook P - K H P, about 40 % cheaper per epoch
        (what a covariance per sequence costs under ``vmap`` is mostly these products), for
        well-conditioned models in float64 (see :func:`~jaxnav.filters.update`).
    Returns:
      :class:`KalmanResult`.
    Raises:
      ValueError: at trace time, for inconsistent shapes (naming them), unknown output names, or
        a float32 computation without ``allow_float32``.
    """
    static = (tuple(save), unroll, allow_float32, check_finite, joseph)
    args = (model, x0, P0, zs, inflation, estimator, mask)
    out = _batch_aware(*static)(*args)
    _remember(out, FilterCall(args=args, static=static))
    return out


class FilterCall(NamedTuple):
    """How a :func:`kalman_filter` result was made: its arguments and static options (save, unroll,
    allow_float32, check_finite, joseph), for :func:`filter_call_of`."""

    args: Any
    static: Any


#: id of a filter result's ``covs`` -> (weak references to its four moments, the call)
_CALLS: dict = {}
_MOMENTS = ("means", "covs", "pred_means", "pred_covs")


def _remember(out, call):
    """Record ``call`` as the maker of ``out`` for as long as ``out.covs`` lives."""
    moments = tuple(getattr(out, name) for name in _MOMENTS)
    if any(a is None for a in moments):
        return
    try:
        refs = tuple(weakref.ref(a) for a in moments)
    except TypeError:  # values without weak references are not recorded
        return
    key = id(moments[1])
    _CALLS[key] = (refs, call)
    weakref.finalize(moments[1], _CALLS.pop, key, None)


def filter_call_of(means, covs, pred_means, pred_covs):
    """The :class:`FilterCall` whose result holds exactly these four moments (the same objects), else None.

    Lets :func:`~jaxnav.filters.rts_smoother` given a filter's result unchanged redo the filter
    behind its own ``vmap`` rule (:func:`jaxnav.filters.rts_smoother`).
    """
    entry = _CALLS.get(id(covs))
    if entry is None:
        return None
    refs, call = entry
    return call if all(r() is a for r, a in zip(refs, (means, covs, pred_means, pred_covs))) else None


#: (prepared primals, tangents) -> (loglik, its tangent) of the classic filter by one backward
#: smoothing pass; set by :mod:`jaxnav.filters._loglik` when the package is imported (it builds on
#: this module's filter, so this module cannot import it)
LOGLIK_JVP = None


@cache
def _batch_aware(save, unroll, allow_float32, check_finite, joseph):
    """:func:`_kalman_filter` for one static configuration, with a ``vmap`` rule and exact derivatives.

    Under ``vmap`` the rule (:func:`jaxnav.filters._batch.vmap_filter_rule`) shares one covariance
    recursion when the batch allows it and runs the plain per-sequence filters otherwise.
    ``custom_vmap`` has no reverse mode, so derivatives (``jvp``, ``grad``, any nesting with
    ``vmap``) are those of the plain filter: exact, per sequence under ``vmap``.
    """

    def plain(model, x0, P0, zs, inflation, estimator, mask):
        return _kalman_filter(
            model,
            x0,
            P0,
            zs,
            inflation=inflation,
            estimator=estimator,
            mask=mask,
            save=save,
            unroll=unroll,
            allow_float32=allow_float32,
            check_finite=check_finite,
            joseph=joseph,
        )

    @jax.custom_batching.custom_vmap
    def batched(*args):
        return plain(*args)

    @batched.def_vmap
    def rule(axis_size, in_batched, *args):
        from jaxnav.filters._batch import vmap_filter_rule

        return vmap_filter_rule(
            plain,
            in_batched,
            args,
            save=save,
            unroll=unroll,
            allow_float32=allow_float32,
            check_finite=check_finite,
            joseph=joseph,
        )

    @jax.custom_jvp
    def run(*args):
        return batched(*args)

    @run.defjvp
    def run_jvp(primals, tangents):
        out, t_out = jax.jvp(plain, primals, tangents)
        model, x0, P0, zs, inflation, estimator, mask = primals
        if inflation is None and estimator is None and check_finite and not allow_float32:
            # The classic filter's log-likelihood tangent from one filter and one backward pass
            # behind a vmap rule (:func:`jaxnav.filters._loglik.loglik_jvp`): under vmap(grad) a
            # clean batch keeps one covariance recursion, and the per-sequence tangents of the
            # other outputs are dropped by jit when only the log-likelihood is differentiated.
            prepared = prepare_inputs(model, x0, P0, zs, mask, (), allow_float32)[:5]
            # Its value (the same log-likelihood) replaces the filter's, so that when only the
            # log-likelihood is used the filter below is dead code and runs once, not twice.
            ll, t_ll = LOGLIK_JVP(prepared, tangents[:4])
            t_out = t_out._replace(loglik=jnp.asarray(t_ll, out.loglik.dtype))
            out = batched(*primals)._replace(loglik=jnp.asarray(ll, out.loglik.dtype))
        return out, t_out

    return run


@partial(jax.jit, static_argnames=("save", "unroll", "allow_float32", "check_finite", "joseph"))
def _kalman_filter(
    model, x0, P0, zs, *, inflation, estimator, mask, save, unroll, allow_float32, check_finite, joseph
) -> KalmanResult:
    params, init, xs, save, _, _, _ = scan_setup(model, x0, P0, zs, inflation, estimator, mask, save, allow_float32)

    def body(state, inp):
        return filter_step(state, inp, params, save, check_finite, joseph)

    # Under reverse-mode AD, recompute each step from its carry instead of storing every
    # intermediate (the fused small products would otherwise save broadcast operands per epoch):
    # the backward pass reads one state per epoch. No effect on forward runs or forward mode.
    final, info = jax.lax.scan(jax.checkpoint(body, prevent_cse=False), init, xs, unroll=unroll)
    return KalmanResult(
        **info._asdict(),
        loglik=final.loglik,
        n_nonfinite=final.n_nonfinite,
        n_skipped=final.n_skipped,
        status=final.status,
        x_final=final.x,
        P_final=final.P,
    )
