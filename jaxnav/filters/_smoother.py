"""Rauch-Tung-Striebel fixed-interval smoother over the saved filter moments (S3 class 1)."""

from __future__ import annotations

from functools import cache, partial
from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxnav import _status
from jaxnav._numerics import cho_solve, mm, safe_cholesky, symmetrize


class SmootherResult(NamedTuple):
    """RTS output, aligned with the filter's outputs; a field left out of ``save`` is None.

    Attributes:
      means: (T, n) smoothed means.  covs: (T, n, n) smoothed covariances.
      gains: (T, n, n) smoother gains C_t (zero at the last epoch).
      status: int32 flags (SMOOTHER_FAILED if a predicted covariance was not PD).
    """

    means: jax.Array | None
    covs: jax.Array | None
    gains: jax.Array | None
    status: jax.Array


SMOOTHER_OUTPUTS = ("means", "covs", "gains")


@cache
def _batch_aware_rts(unroll, save):
    """:func:`_rts_smoother` on the four saved moments, with a ``vmap`` rule and exact derivatives.

    Under ``vmap`` with a shared model and batched covariances, ``lax.cond`` checks whether every
    sequence's covariances equal the first's (what :func:`~jaxnav.filters.kalman_filter` returns
    under ``vmap`` for a clean batch with a shared model): then the gains and smoothed covariances
    are computed once and only the means per sequence; else the plain per-sequence smoothers.
    Derivatives are those of the plain smoother (``custom_vmap`` has no reverse mode).
    """

    def plain(model, means, covs, pred_means, pred_covs):
        filtered = _Moments(means=means, covs=covs, pred_means=pred_means, pred_covs=pred_covs)
        return _rts_smoother(model, filtered, unroll=unroll, save=save)

    @jax.custom_batching.custom_vmap
    def batched(*args):
        return plain(*args)

    @batched.def_vmap
    def rule(axis_size, in_batched, model, *moments):
        return _rts_rule(model, moments, in_batched, unroll, save)

    @jax.custom_jvp
    def run(*args):
        return batched(*args)

    run.defjvp(lambda primals, tangents: jax.jvp(plain, primals, tangents))
    return run


def _rts_rule(model, moments, in_batched, unroll, save):
    """The ``vmap`` rule of the smoother on its four moments (:func:`_batch_aware_rts`).

    Args:
      model: the smoother's model.  moments: (means, covs, pred_means, pred_covs), batch axis first where batched.
      in_batched: bools for (model, *moments).  unroll, save: the smoother's static options.
    Returns:
      (SmootherResult, its pytree of bools: which leaves have the leading batch axis).
    """
    means, covs, pred_means, pred_covs = moments
    args = (model, means, covs, pred_means, pred_covs)
    axes = jax.tree_util.tree_map(lambda b: 0 if b else None, tuple(in_batched))

    def plain(model, means, covs, pred_means, pred_covs):
        return _rts_smoother(model, _Moments(means, covs, pred_means, pred_covs), unroll=unroll, save=save)

    def per_sequence():
        return jax.vmap(plain, in_axes=axes)(*args)

    like = jax.eval_shape(per_sequence)
    if any(jax.tree_util.tree_leaves(in_batched[0])) or not (in_batched[2] and in_batched[4]):
        # F per sequence, or covariances not batched: what plain vmap shares stays shared
        return vmap_sharing(plain, axes, args, ("covs", "gains", "status"))

    def shared():
        one = _Moments(means=means[0], covs=covs[0], pred_means=pred_means[0], pred_covs=pred_covs[0])
        C, status = smoother_gains(model, one, save)
        sm = (
            jax.vmap(lambda x, xp: smoothed_means(C, x, xp, unroll), in_axes=(axes[1], axes[3]))(means, pred_means)
            if "means" in save
            else None
        )
        P_s = smoothed_covs(C, covs[0], pred_covs[0], unroll) if "covs" in save else None
        out = SmootherResult(means=sm, covs=P_s, gains=C if "gains" in save else None, status=status)
        return jax.tree_util.tree_map(lambda a, s: jnp.broadcast_to(a, s.shape), out, like)

    same = jnp.all(covs == covs[:1]) & jnp.all(pred_covs == pred_covs[:1])
    out = jax.lax.cond(same, shared, per_sequence)
    return out, jax.tree_util.tree_map(lambda _: True, out)


def vmap_sharing(fn, in_axes, args, fields):
    """``jax.vmap(fn)`` in a ``custom_vmap`` rule: (outputs, out_batched), ``fields`` unbatched where vmap allows.

    ``fn`` returns a NamedTuple. The named fields are first asked for with ``out_axes=None``
    (what plain ``vmap`` does for values that do not depend on the batched inputs); if any of
    them depends on the batch (``vmap`` refuses at trace time), every field is batched.
    """
    out_type = jax.eval_shape(lambda: jax.vmap(fn, in_axes=in_axes)(*args))
    names = type(out_type)._fields
    axes = type(out_type)(*[None if name in fields else 0 for name in names])
    try:
        out = jax.vmap(fn, in_axes=in_axes, out_axes=axes)(*args)
    except ValueError:
        axes = type(out_type)(*[0] * len(names))
        out = jax.vmap(fn, in_axes=in_axes, out_axes=axes)(*args)
    batched = type(out_type)(
        *[jax.tree_util.tree_map(lambda _, a=a: a == 0, getattr(out, name)) for name, a in zip(names, axes)]
    )
    return out, batched


class _Moments(NamedTuple):
    """The four filter outputs the smoother reads."""

    means: jax.Array
    covs: jax.Array
    pred_means: jax.Array
    pred_covs: jax.Array


@partial(jax.jit, static_argnames=("unroll", "save"))
def _rts_smoother(model, filtered, *, unroll, save) -> SmootherResult:
    C, status = smoother_gains(model, filtered, save)
    means = smoothed_means(C, filtered.means, filtered.pred_means, unroll) if "means" in save else None
    covs = smoothed_covs(C, filtered.covs, filtered.pred_covs, unroll) if "covs" in save else None
    return SmootherResult(means=means, covs=covs, gains=C if "gains" in save else None, status=status)


def smoother_inputs(model, filtered, save, who):
    """Check a smoother call (trace time): the outputs asked for, the filter outputs it needs, F's shape.

    Returns:
      (save tuple, F for steps 1..T-1: (n, n) if time-invariant, else (T-1, n, n)).
    Raises:
      ValueError: naming the missing filter output or F's shape against the expected ones.
    """
    save = tuple(save)
    unknown = [s for s in save if s not in SMOOTHER_OUTPUTS]
    if unknown:
        raise ValueError(f"unknown smoother outputs {unknown}; choose from {SMOOTHER_OUTPUTS}")
    for name in ("means", "covs", "pred_means", "pred_covs"):
        if getattr(filtered, name, None) is None:
            raise ValueError(f"{who} needs the filter output '{name}': run the filter with it in save=")
    T, n = filtered.means.shape
    F = jnp.asarray(model.F, filtered.means.dtype)
    if F.shape == (n, n):
        return save, F
    if F.shape == (T, n, n):
        return save, F[1:]
    raise ValueError(f"model.F has shape {F.shape}; expected {(n, n)} or {(T, n, n)}")


def smoother_gains(model, filtered, save=SMOOTHER_OUTPUTS, who="rts_smoother"):
    """The RTS gains C_t = P_t F_{t+1}^T P_{t+1|t}^{-1} of all epochs at once (zero at the last).

    Vectorised over the epochs, outside any scan, so that the recursions are left with the small
    products of each epoch (filter + RTS means for T = 3600: 12.0 -> 8.0 ms,
    benchmarks/bench_filters.py case (b)).

    Returns:
      (C (T, n, n), int32 status: SMOOTHER_FAILED if a predicted covariance was not positive definite).
    """
    _, Fn = smoother_inputs(model, filtered, save, who)
    Ps, Pp = filtered.covs, filtered.pred_covs
    T, n = filtered.means.shape
    Fn = jnp.broadcast_to(Fn, (T - 1, n, n))
    L, ok = safe_cholesky(Pp[1:])
    C = jnp.where(ok[:, None, None], jnp.swapaxes(cho_solve(L, mm(Fn, Ps[:-1])), -1, -2), 0.0)
    status = jnp.where(jnp.all(ok), 0, _status.SMOOTHER_FAILED).astype(jnp.int32)
    return jnp.concatenate([C, jnp.zeros((1, n, n), C.dtype)], axis=0), status


def smoothed_means(C, xs, xp, unroll=1):
    """x^s_t = x_t + C_t (x^s_{t+1} - x_{t+1|t}), x^s_T = x_T, by a reverse scan.

    Args:
      C: (T, n, n) gains.  xs: (T, n) filtered means.  xp: (T, n) predicted means.
    Returns:
      (T, n) smoothed means.
    """

    def body(x_next, inp):
        x, x_p, Ck = inp
        x_s = x + mm(Ck, x_next - x_p)
        return x_s, x_s

    _, m_s = jax.lax.scan(body, xs[-1], (xs[:-1], xp[1:], C[:-1]), reverse=True, unroll=unroll)
    return jnp.concatenate([m_s, xs[-1:]], axis=0)


def smoothed_covs(C, Ps, Pp, unroll=1):
    """P^s_t = P_t + C_t (P^s_{t+1} - P_{t+1|t}) C_t^T, P^s_T = P_T, by a reverse scan.

    Args:
      C: (T, n, n) gains.  Ps: (T, n, n) filtered covariances.  Pp: (T, n, n) predicted ones.
    Returns:
      (T, n, n) smoothed covariances.
    """

    def body(P_next, inp):
        P, P_p, Ck = inp
        P_s = symmetrize(P + mm(mm(Ck, P_next - P_p), Ck.T))
        return P_s, P_s

    _, P_s = jax.lax.scan(body, Ps[-1], (Ps[:-1], Pp[1:], C[:-1]), reverse=True, unroll=unroll)
    return jnp.concatenate([P_s, Ps[-1:]], axis=0)
