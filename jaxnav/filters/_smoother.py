"""Rauch-Tung-Striebel fixed-interval smoother over the saved filter moments (S3 class 1)."""

from __future__ import annotations

from functools import partial
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from jaxnav import _status
from jaxnav._numerics import cho_solve, cholesky, mm, symmetrize
from jaxnav.filters._kalman import resolve_products
from jaxnav.filters._model import LinearGaussian


class SmootherResult(NamedTuple):
    """RTS output, aligned with the filter's outputs.

    Attributes:
      means: (T, n) smoothed means.  covs: (T, n, n) smoothed covariances.
      gains: (T, n, n) smoother gains C_t (zero at the last epoch).
      status: int32 flags (SMOOTHER_FAILED if a predicted covariance was not PD).
    """

    means: Any
    covs: Any
    gains: Any
    status: Any


SMOOTHER_OUTPUTS = ("means", "covs", "gains")


def rts_smoother(model: LinearGaussian, filtered, *, unroll: int = 1, save=SMOOTHER_OUTPUTS,
                 products: str = "auto") -> SmootherResult:
    """RTS smoother: C_t = P_t F_{t+1}^T P_{t+1|t}^{-1}, x^s_t = x_t + C_t (x^s_{t+1} - x_{t+1|t}).

    P^s_t = P_t + C_t (P^s_{t+1} - P_{t+1|t}) C_t^T. It uses the filter's *saved* predicted
    moments, so for an inflated (attenuated or fading) filter it smooths with the inflated priors
    the filter actually used; for the classic filter it equals the textbook RTS.

    Args:
      model: the model given to the filter (only F is used; (n, n) or (T, n, n)).
      filtered: a :class:`KalmanResult` with ``means``, ``covs``, ``pred_means``, ``pred_covs``.
      unroll: ``lax.scan`` unroll factor.
      save: static subset of ("means", "covs", "gains") to return (others are None). The
        smoothed-covariance recursion is skipped when "covs" is not requested (the means need
        only the gains).
      products: static; "auto", "fused" or "dot" small-product kernels, as in
        :func:`~jaxnav.filters.kalman_filter` (see ``jaxnav.filters._kalman.resolve_products``).
    Returns:
      :class:`SmootherResult`.
    Raises:
      ValueError: if the needed outputs were not saved, or F has a wrong shape.
    """
    products = resolve_products(products, model, filtered)
    return _rts_smoother(model, filtered, unroll=unroll, save=tuple(save), products=products)


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


def _lower(model, filtered, *, unroll=1, save=SMOOTHER_OUTPUTS, products="auto"):
    products = resolve_products(products, model, filtered)
    return _rts_smoother.lower(model, filtered, unroll=unroll, save=tuple(save), products=products)


rts_smoother.lower = _lower  # ahead-of-time compilation, as on a jitted function


@partial(jax.jit, static_argnames=("unroll", "save", "products"))
def _rts_smoother(model, filtered, *, unroll, save, products) -> SmootherResult:
    prod = mm if products == "fused" else jnp.matmul
    save, Fn = smoother_inputs(model, filtered, save, "rts_smoother")
    xs, Ps, xp, Pp = filtered.means, filtered.covs, filtered.pred_means, filtered.pred_covs
    T, n = xs.shape
    if Fn.ndim == 2:
        Fn = jnp.broadcast_to(Fn, (T - 1, n, n))

    want_cov = "covs" in save

    # The gains depend on the filter's covariances only: one vectorised factorisation over all
    # epochs, so that the sequential scan is left with the two small products of each epoch
    # (filter + RTS means for T = 3600: 12.0 -> 8.0 ms, benchmarks/bench_filters.py case (b)).
    L = cholesky(Pp[1:])
    ok = jnp.all(jnp.isfinite(L), axis=(-2, -1))
    L = jnp.where(ok[:, None, None], L, jnp.eye(n, dtype=Ps.dtype))
    C = jnp.swapaxes(cho_solve(L, prod(Fn, Ps[:-1])), -1, -2)
    C = jnp.where(ok[:, None, None], C, 0.0)
    status = jnp.where(jnp.all(ok), 0, _status.SMOOTHER_FAILED).astype(jnp.int32)

    def body(carry, inp):
        xs_next, Ps_next = carry
        x, P, x_p, P_p, Ck = inp
        x_s = x + prod(Ck, xs_next - x_p)
        P_s = symmetrize(P + prod(prod(Ck, Ps_next - P_p), Ck.T)) if want_cov else Ps_next
        out = (x_s if "means" in save else None, P_s if "covs" in save else None)
        return (x_s, P_s), out

    init = (xs[-1], Ps[-1] if want_cov else jnp.zeros((), xs.dtype))
    inp = (xs[:-1], Ps[:-1] if want_cov else None, xp[1:], Pp[1:] if want_cov else None, C)
    _, (m_s, P_s) = jax.lax.scan(body, init, inp, reverse=True, unroll=unroll)
    C = C if "gains" in save else None
    means = None if m_s is None else jnp.concatenate([m_s, xs[-1:]], axis=0)
    covs = None if P_s is None else jnp.concatenate([P_s, Ps[-1:]], axis=0)
    gains = None if C is None else jnp.concatenate([C, jnp.zeros((1, n, n), xs.dtype)], axis=0)
    return SmootherResult(means=means, covs=covs, gains=gains, status=status)
