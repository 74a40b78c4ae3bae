"""The public RTS smoother: routes a :func:`~jaxnav.filters.kalman_filter` result given unchanged to one
program with its filter (the batch filter and smoother on a clean batch under ``vmap``), anything else
to the smoother over the saved moments (:mod:`jaxnav.filters._smoother`)."""

from __future__ import annotations

from functools import cache

import jax
import jax.numpy as jnp

from jaxnav.filters._batch import (
    _broadcast_like,
    _kalman_filter_batch,
    _minor_applies,
    _rts_smoother_batch,
    per_sequence_minor,
)
from jaxnav.filters._kalman import _kalman_filter, filter_call_of
from jaxnav.filters._minor import classic_filter_rts_minor
from jaxnav.filters._model import LinearGaussian
from jaxnav.filters._plugins import data_independent
from jaxnav.filters._smoother import (
    SMOOTHER_OUTPUTS,
    SmootherResult,
    _batch_aware_rts,
    _Moments,
    _rts_rule,
    _rts_smoother,
    smoother_inputs,
)


def rts_smoother(model: LinearGaussian, filtered, *, unroll: int = 1, save=SMOOTHER_OUTPUTS) -> SmootherResult:
    """RTS smoother: C_t = P_t F_{t+1}^T P_{t+1|t}^{-1}, x^s_t = x_t + C_t (x^s_{t+1} - x_{t+1|t}).

    P^s_t = P_t + C_t (P^s_{t+1} - P_{t+1|t}) C_t^T. It uses the filter's *saved* predicted
    moments, so for an inflated (attenuated or fading) filter it smooths with the inflated priors
    the filter actually used; for the classic filter it equals the textbook RTS.

    The gains depend only on the filter's covariances: under ``jax.vmap`` with a shared model they
    are computed once for the batch when the covariances are not batched, or when every
    sequence's equal the first's (checked at run time), else per sequence. Given the result of
    :func:`~jaxnav.filters.kalman_filter` unchanged (the same arrays), the smoother redoes that
    filter behind one run-time choice under ``vmap`` (:func:`_batch_aware_filter_rts`): a clean
    batch runs :func:`~jaxnav.filters.kalman_filter_batch` and
    :func:`~jaxnav.filters.rts_smoother_batch`, so the filter's covariances are never written B
    times; a batch with unmasked NaN/inf runs the filter and smoother of every sequence (if the
    filter's own outputs are used too, its per-sequence filter then runs twice). Derivatives are
    the plain smoother's.
    :func:`~jaxnav.filters.rts_smoother_batch` smooths a :func:`~jaxnav.filters.kalman_filter_batch` result.

    Args:
      model: the model given to the filter (only F is used; (n, n) or (T, n, n)).
      filtered: a :class:`KalmanResult` with ``means``, ``covs``, ``pred_means``, ``pred_covs``.
      unroll: ``lax.scan`` unroll factor.
      save: static subset of ("means", "covs", "gains") to return (others are None). The
        smoothed-covariance recursion is skipped when "covs" is not requested (the means need
        only the gains).
    Returns:
      :class:`SmootherResult`.
    Raises:
      ValueError: if the needed outputs were not saved, or F has a wrong shape.
    """
    save = tuple(save)
    moments = tuple(getattr(filtered, name, None) for name in ("means", "covs", "pred_means", "pred_covs"))
    if any(a is None for a in moments):
        smoother_inputs(model, filtered, save, "rts_smoother")  # raises, naming the missing output
    call = filter_call_of(*moments)
    if call is not None and _same_array(getattr(model, "F", None), call.args[0].F):
        return _batch_aware_filter_rts(unroll, save, call.static)(model, call.args, *moments)
    return _batch_aware_rts(unroll, save)(model, *moments)


def _same_array(a, b):
    """Whether a and b are one array: the same object, or equal concrete values (trace time)."""
    if a is b:
        return True
    if a is None or b is None or isinstance(a, jax.core.Tracer) or isinstance(b, jax.core.Tracer):
        return False
    return jnp.shape(a) == jnp.shape(b) and bool(jnp.all(jnp.asarray(a) == jnp.asarray(b)))


@cache
def _batch_aware_filter_rts(unroll, save, fstatic):
    """:func:`_rts_smoother` of a :func:`~jaxnav.filters.kalman_filter` result given with that filter's arguments.

    Without ``vmap`` it is the plain smoother of the four moments (the filter's arguments are
    unused). Under ``vmap``, when the filter's rule could share one covariance recursion (model,
    P0, mask and a data-independent rule shared, NaN masking on), the filter is redone here behind
    one run-time choice: a batch with no unmasked NaN/inf runs
    :func:`~jaxnav.filters.kalman_filter_batch` and :func:`~jaxnav.filters.rts_smoother_batch`
    (covariances and gains once, the means in blocks), any other batch the plain filter and
    smoother of every sequence. The moments given are then unused, so the filter's own run is
    dead code under ``jit`` when only the smoother's outputs are used, and its covariances are
    never written B times. Either branch equals a loop. Derivatives are the plain smoother's.
    """
    fsave, funroll, allow_float32, check_finite, joseph = fstatic

    def plain(model, fargs, means, covs, pred_means, pred_covs):
        return _rts_smoother(model, _Moments(means, covs, pred_means, pred_covs), unroll=unroll, save=save)

    @jax.custom_batching.custom_vmap
    def batched(*args):
        return plain(*args)

    @batched.def_vmap
    def rule(axis_size, in_batched, model, fargs, *moments):

        fmodel, x0, P0, zs, inflation, estimator, mask = fargs
        fb = in_batched[1]
        shareable = (
            check_finite
            and fb[3]
            and all(in_batched[2:])
            and data_independent(inflation, estimator)
            and not any(jax.tree_util.tree_leaves([in_batched[0]] + [fb[i] for i in (0, 2, 4, 5, 6)]))
            and jnp.ndim(zs) == 3
        )
        minor = _minor_applies(fb, fargs, check_finite)
        if not (shareable or minor):
            return _rts_rule(model, moments, (in_batched[0],) + tuple(in_batched[2:]), unroll, save)
        faxes = jax.tree_util.tree_map(lambda b: 0 if b else None, fb)

        def filt(*a):
            return _kalman_filter(
                *a[:4],
                inflation=a[4],
                estimator=a[5],
                mask=a[6],
                save=fsave,
                unroll=funroll,
                allow_float32=allow_float32,
                check_finite=check_finite,
                joseph=joseph,
            )

        def smooth(md, f):
            return _rts_smoother(md, _Moments(f.means, f.covs, f.pred_means, f.pred_covs), unroll=unroll, save=save)

        def per_sequence():
            maxes = jax.tree_util.tree_map(lambda b: 0 if b else None, in_batched[0])
            return jax.vmap(lambda md, *a: smooth(md, filt(*a)), in_axes=(maxes, *faxes))(model, *fargs)

        like = jax.eval_shape(per_sequence)

        def minor_branch():  # filter and smoother of every sequence, batch-minor, in one program
            like_f = jax.eval_shape(lambda: jax.vmap(filt, in_axes=faxes)(*fargs))
            return per_sequence_minor(
                classic_filter_rts_minor,
                fargs,
                fb,
                like_f,
                like,
                save=save,
                unroll=funroll,
                check_finite=check_finite,
                joseph=joseph,
            )

        if not shareable:
            out = minor_branch()
            return out, jax.tree_util.tree_map(lambda _: True, out)

        def shared():
            res = _kalman_filter_batch(
                fmodel,
                x0,
                P0,
                zs,
                inflation=inflation,
                estimator=estimator,
                mask=mask,
                save=("means", "covs", "pred_covs"),
                unroll=funroll,
                allow_float32=allow_float32,
                block="auto",
                joseph=joseph,
            )
            return _broadcast_like(_rts_smoother_batch(model, res, save=save, unroll=unroll), like)

        used = True if mask is None else jnp.asarray(mask, bool)
        if jnp.ndim(used) == 1:
            used = used[:, None]
        clean = jnp.all(jnp.isfinite(zs) | ~jnp.asarray(used, bool))
        out = jax.lax.cond(clean, shared, minor_branch if minor else per_sequence)
        return out, jax.tree_util.tree_map(lambda _: True, out)

    @jax.custom_jvp
    def run(*args):
        return batched(*args)

    run.defjvp(lambda primals, tangents: jax.jvp(plain, primals, tangents))
    return run
