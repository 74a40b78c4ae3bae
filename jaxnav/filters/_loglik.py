"""Innovation log-likelihood of the classic Kalman filter with its exact gradient from one backward pass.

The derivative of log p(z_1..z_T) with respect to anything that enters the model at epoch t
only through the prior N(x_t; m_t|t-1, P_t|t-1) or the measurement density N(z_t; H_t x_t, R_t)
is the expectation of that density's own derivative under the *smoothing* distribution
N(x_t; m^s_t, P^s_t) (Fisher's identity applied one epoch at a time; Segal & Weinstein 1989).
In the backward (modified Bryson-Frazier) form of the smoother, m^s_t = m_t|t-1 + P_t|t-1 b_t
and P^s_t = P_t|t-1 - P_t|t-1 L_t P_t|t-1, and the derivatives read

  d/dm_t|t-1 = b_t,  d/dP_t|t-1 = (b_t b_t^T - L_t) / 2,
  d/dR_t = 1/2 R^-1 (e_t e_t^T + H P^s_t H^T) R^-1 - 1/2 R^-1,  d/dH_t = R^-1 (e_t m^s_t^T - H P^s_t),
  d/dz_t = -R^-1 e_t,  with e_t = z_t - H m^s_t,
  b_t = H^T S_t^-1 v_t + W_t b_t+1,  L_t = H^T S_t^-1 H + W_t L_t+1 W_t^T,  W_t = (I - K_t H)^T F_t+1^T

(v_t, S_t, K_t the filter's innovation, its covariance and gain). m_t|t-1 = F m_t-1 and
P_t|t-1 = F P_t-1 F^T + G Q G^T carry them to F, G, Q, x0 and P0. So one filter pass and one
backward pass give the value and the exact gradient, with no tape of the filter and no inverse
of a predicted covariance (singular ones, e.g. an exactly known x0, are fine). :func:`log_likelihood`
wraps that in a ``jax.custom_jvp``, so ``grad``, ``value_and_grad``, ``jvp`` (forward mode) and
``vmap`` all use it, through any parameterisation of the model.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from jaxnav._numerics import _loop_sum, cho_solve, cholesky, masked_measurement, mm
from jaxnav.filters import _kalman
from jaxnav.filters._kalman import kalman_filter
from jaxnav.filters._model import LinearGaussian
from jaxnav.filters._step import prepare_inputs

_FILTER_SAVE = ("means", "covs", "pred_means", "pred_covs")


def log_likelihood(model: LinearGaussian, x0, P0, zs, *, mask=None):
    """Innovation log-likelihood of the classic Kalman filter (S0 eqs. (4)-(9)), with exact derivatives.

    The value equals ``kalman_filter(model, x0, P0, zs, mask=mask).loglik`` (NaN/inf measurement
    elements masked). Derivatives (reverse or forward mode) come from one backward smoothing pass
    instead of differentiating through the filter (module docstring): exact to rounding, 2.1-2.3x
    the forward pass for one sequence where autodiff through the scan costs ~4x. Under ``vmap``
    it is memory-bound (each sequence writes and rereads its means): for a batch and a few
    parameters ``jaxnav.tune.value_and_grad(mode="forward")`` is faster (benchmarks/RESULTS.md).

    Args:
      model: :class:`~jaxnav.filters.LinearGaussian`, static or (T, ...) time-varying leaves.
      x0: (n,) initial mean.  P0: (n, n) initial covariance.
      zs: (T, m) measurements; NaN/inf elements are masked.
      mask: optional (T,) or (T, m) bool, True where a measurement is used.
    Returns:
      scalar log-likelihood (float64).
    Raises:
      ValueError: inconsistent shapes (named), as :func:`~jaxnav.filters.kalman_filter`.

    Only the classic filter: the prior-inflation rules and noise estimators change the filter
    away from the exact posterior, so their log-likelihood is differentiated through the filter
    (``kalman_filter(...).loglik``). The innovation covariances must be positive definite (the
    filter's status stays 0).
    """
    model, x0, P0, zs, mask, _, _, _, _ = prepare_inputs(model, x0, P0, zs, mask, (), False)
    return _loglik(model, x0, P0, zs, mask)


@jax.custom_jvp
def _loglik(model, x0, P0, zs, mask):
    return kalman_filter(model, x0, P0, zs, mask=mask, save=()).loglik


@_loglik.defjvp
def _loglik_jvp(primals, tangents):
    return loglik_jvp(primals, tangents[:4])


def loglik_jvp(primals, tangents):
    """(log-likelihood, its tangent) from the gradients of :func:`loglik_and_gradients` (module docstring).

    Args:
      primals: (model, x0, P0, zs, mask) as prepared by ``prepare_inputs``.
      tangents: (dmodel, dx0, dP0, dzs), shaped like the primals (symbolic zeros allowed).
    The gradients are a primal computation behind a ``vmap`` rule (one covariance recursion for a
    batch with a shared model, P0 and finite pattern); the tangent is linear in them, so reverse
    mode transposes only the final sum.
    """
    dmodel, dx0, dP0, dzs = tangents
    value, grads = _gradients(*primals)
    pairs = [(grads.x0, dx0), (grads.P0, dP0), (grads.zs, dzs)]
    pairs += [(g, t) for g, t in zip(grads.model, dmodel) if g is not None and t is not None]
    return value, sum(jnp.sum(g * jnp.asarray(t, g.dtype)) for g, t in pairs if not _is_zero(t))


def _is_zero(t):
    """A tangent that carries nothing (float0: the primal is an integer or bool array)."""
    return getattr(t, "dtype", None) == jax.dtypes.float0


_kalman.LOGLIK_JVP = loglik_jvp  # the classic filter's loglik tangent (see :func:`jaxnav.filters._kalman._batch_aware`)


@jax.custom_batching.custom_vmap
def _gradients(model, x0, P0, zs, mask):
    return loglik_and_gradients(model, x0, P0, zs, mask & jnp.isfinite(zs))


@_gradients.def_vmap
def _gradients_batched(axis_size, in_batched, model, x0, P0, zs, mask):
    """Under ``vmap``: when the model, P0 and mask are shared and every sequence has the same
    non-finite elements, the covariance-only terms (filter, smoother, their inverses) are computed
    once for the batch and only the means per sequence; else one full pass per sequence
    (``lax.cond`` picks, as :func:`jaxnav.filters.kalman_filter` does under ``vmap``)."""
    del axis_size
    axes = jax.tree_util.tree_map(lambda b: 0 if b else None, in_batched)
    per_sequence = jax.vmap(lambda m, x, P, z, k: loglik_and_gradients(m, x, P, z, k & jnp.isfinite(z)), in_axes=axes)
    shared = not any(jax.tree_util.tree_leaves([in_batched[i] for i in (0, 2, 4)]))
    if shared and in_batched[3]:
        fin = jnp.isfinite(jax.lax.optimization_barrier(zs))
        common = mask & fin[0]
        out = jax.lax.cond(
            jnp.all(fin == fin[0]),
            lambda: jax.vmap(loglik_and_gradients, in_axes=(None, axes[1], None, 0, None))(model, x0, P0, zs, common),
            lambda: per_sequence(model, x0, P0, zs, mask),
        )
    else:
        out = per_sequence(model, x0, P0, zs, mask)
    return out, jax.tree_util.tree_map(lambda _: True, out)


class LoglikGradients(NamedTuple):
    """d loglik / d input, shaped like the inputs (``model`` a :class:`LinearGaussian`)."""

    model: Any
    x0: Any
    P0: Any
    zs: Any


def loglik_and_gradients(model: LinearGaussian, x0, P0, zs, valid):
    """(log-likelihood, :class:`LoglikGradients`) from one filter and one backward pass (module docstring).

    Inputs as prepared by ``prepare_inputs``; ``valid`` (T, m) bool marks the measurement
    elements used, and must exclude the non-finite ones. Terms that depend on the covariances
    only are written apart from those with means, so that under ``vmap`` with a shared model and
    mask they are computed once.
    """
    T, m = zs.shape
    n = x0.shape[0]
    dtype = zs.dtype
    f = kalman_filter(model, x0, P0, zs, mask=valid, save=_FILTER_SAVE, check_finite=False)
    tv = {name: leaf is not None and leaf.ndim == 3 for name, leaf in zip(LinearGaussian._fields, model)}

    def fold(expr, *ops, leaf):
        """einsum over epochs t: kept for a time-varying leaf, summed for a static one."""
        lhs, out = expr.split("->")
        return jnp.einsum(f"{lhs}->{'t' if tv[leaf] else ''}{out}", *ops)

    def at(name):  # a model leaf with explicit epoch axis index letters: "t.." if time-varying
        return "t" if tv[name] else ""

    # Backward (modified Bryson-Frazier) recursion for b_t = d/dm_t|t-1 and Lambda_t, where
    # A_t = d/dP_t|t-1 = (b_t b_t^T - Lambda_t) / 2, m^s_t = m_t|t-1 + P_t|t-1 b_t and
    # P^s_t = P_t|t-1 - P_t|t-1 Lambda_t P_t|t-1 (the RTS moments): with W_t = (I - K_t H)^T F_t+1^T,
    # b_t = H^T S_t^-1 v_t + W_t b_t+1,  Lambda_t = H^T S_t^-1 H + W_t Lambda_t+1 W_t^T.
    # Only innovation covariances are inverted, so a singular P_t|t-1 (exactly known x0, a
    # rank-deficient G Q G^T) is fine.
    H, R = model.H, model.R
    Hm, Rm = masked_measurement(H, R, valid)
    vm = jnp.where(valid, zs - _loop_sum(Hm * f.pred_means[:, None, :], -1), 0.0)
    S = Hm @ f.pred_covs @ jnp.swapaxes(Hm, -1, -2) + Rm
    SiH = cho_solve(cholesky(S), Hm)  # S^-1 H (T, m, n), zero rows where invalid
    u = _loop_sum(SiH * vm[:, :, None], 1)  # H^T S^-1 v (T, n)
    K = f.pred_covs @ jnp.swapaxes(SiH, -1, -2)
    eye_n = jnp.eye(n, dtype=dtype)
    F = model.F
    F_next = (
        jnp.concatenate([F[1:], jnp.zeros((1, n, n), dtype)])
        if tv["F"]
        else jnp.concatenate([jnp.broadcast_to(F, (T - 1, n, n)), jnp.zeros((1, n, n), dtype)])
    )
    W = jnp.swapaxes(F_next @ (eye_n - K @ Hm), -1, -2)
    HtSiH = jnp.swapaxes(Hm, -1, -2) @ SiH

    def back(carry, inp):
        b_next, Lam_next = carry
        u_t, HSH_t, W_t = inp
        b_t = u_t + mm(W_t, b_next)
        Lam_t = HSH_t + mm(mm(W_t, Lam_next), W_t.T)
        return (b_t, Lam_t), (b_t, Lam_t)

    _, (b, Lam) = jax.lax.scan(back, (jnp.zeros(n, dtype), jnp.zeros((n, n), dtype)), (u, HtSiH, W), reverse=True)
    sm_means = f.pred_means + _loop_sum(f.pred_covs * b[:, None, :], -1)
    sm_covs = f.pred_covs - f.pred_covs @ Lam @ f.pred_covs
    A_cov = -0.5 * Lam  # A_t = A_cov + b b^T / 2
    m_prev = jnp.concatenate([x0[None], f.means[:-1]], axis=0)
    P_prev = jnp.concatenate([P0[None], f.covs[:-1]], axis=0)
    Fi = at("F")
    bF = jnp.einsum(f"tj,{Fi}jk->tk", b, F)
    bFP = _loop_sum(bF[:, :, None] * P_prev, 1)  # (b^T F P_t-1)_t
    gF = fold("ti,tj->ij", b, m_prev + bFP, leaf="F") + 2.0 * fold(f"tij,{Fi}jk,tkl->il", A_cov, F, P_prev, leaf="F")
    F0 = F[0] if tv["F"] else F
    gx0 = F0.T @ b[0]
    gP0 = F0.T @ (A_cov[0] + 0.5 * jnp.outer(b[0], b[0])) @ F0
    if model.G is None:
        gQ = (A_cov + 0.5 * b[:, :, None] * b[:, None, :]) if tv["Q"] else (jnp.sum(A_cov, axis=0) + 0.5 * b.T @ b)
        gG = None
    else:
        G, Q = model.G, model.Q
        Gi, Qi = at("G"), at("Q")
        bG = jnp.einsum(f"tj,{Gi}jk->tk", b, G)
        gQ = fold(f"{Gi}ji,tjk,{Gi}kl->il", G, A_cov, G, leaf="Q") + 0.5 * fold("ti,tl->il", bG, bG, leaf="Q")
        gG = 2.0 * fold(f"tij,{Gi}jk,{Qi}kl->il", A_cov, G, Q, leaf="G") + fold(
            "ti,tl->il", b, jnp.einsum(f"tk,{Qi}kl->tl", bG, Q), leaf="G"
        )

    # measurement sensitivities over the valid components (R^-1 of the valid block, zero elsewhere)
    both = valid[:, :, None] & valid[:, None, :]
    Ri = jnp.where(both, cho_solve(cholesky(Rm), jnp.broadcast_to(jnp.eye(m, dtype=dtype), (T, m, m))), 0.0)
    e = jnp.where(valid, zs - _loop_sum(Hm * sm_means[:, None, :], -1), 0.0)
    Rie = _loop_sum(Ri * e[:, None, :], -1)
    RiH = Ri @ Hm
    gR = 0.5 * (
        fold("ti,tj->ij", Rie, Rie, leaf="R")
        + fold("tij,tjk,tlk->il", RiH, sm_covs, RiH, leaf="R")
        - (Ri if tv["R"] else jnp.sum(Ri, axis=0))
    )
    gH = fold("ti,tj->ij", Rie, sm_means, leaf="H") - fold("tij,tjk->ik", RiH, sm_covs, leaf="H")
    gz = -Rie

    gmodel = LinearGaussian(F=gF, H=gH, Q=gQ, R=gR, G=gG)
    return f.loglik, LoglikGradients(model=gmodel, x0=gx0, P0=gP0, zs=gz)
