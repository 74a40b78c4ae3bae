"""The classic Kalman filter for B sequences with a covariance each, laid out batch-minor.

Under ``jax.vmap`` the generic step (:func:`jaxnav.filters.filter_step`) works on (B, n, n) arrays:
every small product reduces over an axis that is not the minor one, and the minor axis holds only
n elements, so XLA:CPU's loops run at a fraction of vector speed. Here the batch is the minor axis
of every array: the covariances are (n, n, B), the means (n, B), and each small product is a sum
over k of (i, k, 1 or B) x (1, k, j, B) elementwise products, which XLA fuses into loops over
contiguous B-vectors (the layout simdkalman uses in NumPy). The Cholesky factorisation of S and
the triangular solves are unrolled over the m x m elements, each a B-vector operation.

The formulas, their order and the masking are those of :func:`~jaxnav.filters.filter_step` for
the classic filter (no inflation, no noise estimation; S0 eqs. (4)-(9), Joseph update by default):
the results equal ``jax.vmap(kalman_filter)`` to rounding (the sums run in another order). The
``vmap`` rule of :func:`~jaxnav.filters.kalman_filter` runs it for batches whose covariances differ
(P0, NaN/inf, a mask or model leaves per sequence) when the model is small (n <=
:data:`jaxnav._numerics.SMALL`); derivatives stay the generic filter's.
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp

from jaxnav import _status
from jaxnav._numerics import LOG_2PI, _loop_sum, cholesky_elements, solve_lower_rows, solve_upper_t_rows
from jaxnav.filters._smoother import SmootherResult
from jaxnav.filters._step import KalmanResult

# ---------------------------------------------------------------------------------------------
# algebra on batch-minor arrays: matrices (r, c, b), vectors (r, b); b is B or 1 (shared)


def _t(A):
    """Transpose of (r, c, b) matrices."""
    return jnp.swapaxes(A, 0, 1)


def _mv(A, x):
    """A x for (i, k, b) matrices and (k, b) vectors."""
    return _loop_sum(A * x[None], 1)


def _mm(A, C):
    """A C for (i, k, b) and (k, j, b) matrices."""
    return _loop_sum(A[:, :, None] * C[None], 1)


def _sym(P):
    """(P + P^T) / 2 of (r, r, b) matrices."""
    return 0.5 * (P + _t(P))


def _eye(n, dtype):
    """The (n, n, 1) identity, shared by the batch."""
    return jnp.eye(n, dtype=dtype)[:, :, None]


def _cholesky(S):
    """Lower Cholesky factors of (m, m, B) matrices, element by element (NaN where not positive definite)."""
    m = S.shape[0]
    L = cholesky_elements(lambda i, j: S[i, j], m, reciprocal=False)
    zero = jnp.zeros_like(S[0, 0])
    return jnp.stack([jnp.stack([L[i][j] if j <= i else zero for j in range(m)]) for i in range(m)])


def _solve_lower(L, Y):
    """L^-1 Y for (m, m, B) lower factors and (m, c, B) right-hand sides."""
    return jnp.stack(solve_lower_rows(lambda i, k: L[i, k][None], lambda i: Y[i], L.shape[0]))


def _solve_upper_t(L, Y):
    """L^-T Y for (m, m, B) lower factors and (m, c, B) right-hand sides."""
    return jnp.stack(solve_upper_t_rows(lambda i, k: L[i, k][None], lambda i: Y[i], L.shape[0]))


# ---------------------------------------------------------------------------------------------
# the step


def _step(carry, inp, *, Fs, Hs, GQGs, Rs, check_finite, joseph):
    """One epoch of the classic filter for the whole batch (the generic step's formulas, batch-minor)."""
    x, P, status, ll_sum, n_bad_sum, n_skip = carry
    z, mask, F, H, GQG, R = inp
    F = Fs if F is None else F
    H = Hs if H is None else H
    GQG = GQGs if GQG is None else GQG
    R = Rs if R is None else R
    n, m = x.shape[0], z.shape[0]
    dt = P.dtype

    finite = jnp.isfinite(z)
    valid = (mask & finite) if check_finite else jnp.broadcast_to(mask, z.shape)
    observed = jnp.any(valid, axis=0)
    if check_finite:
        z = jnp.where(valid, z, 0.0)

    x_pred = _mv(F, x)
    P_pred = _sym(_mm(_mm(F, P), _t(F)) + GQG)

    # masked measurement (jaxnav._numerics.masked_measurement) and the update (filters.update)
    Hm = jnp.where(valid[:, None], H, 0.0)
    both = valid[:, None] & valid[None, :]
    Rm = jnp.where(both, R, 0.0) + jnp.where(valid, 0.0, 1.0)[:, None] * _eye(m, dt)
    v = jnp.where(valid, z - _mv(Hm, x_pred), 0.0)
    PHt = _mm(P_pred, _t(Hm))
    S = _sym(_mm(Hm, PHt) + Rm)
    Lc = _cholesky(S)
    ok = jnp.all(jnp.isfinite(Lc), axis=(0, 1))
    Lc = jnp.where(ok, Lc, _eye(m, dt))
    K = _t(_solve_upper_t(Lc, _solve_lower(Lc, _t(PHt))))
    x_new = x_pred + _mv(K, v)
    if joseph:
        IKH = _eye(n, dt) - _mm(K, Hm)
        P_new = _sym(_mm(_mm(IKH, P_pred), _t(IKH)) + _mm(_mm(K, Rm), _t(K)))
    else:
        P_new = _sym(P_pred - _mm(K, _t(PHt)))
    w = _solve_lower(Lc, v[:, None])[:, 0]
    nis = jnp.sum(w * w, axis=0)
    n_valid = jnp.sum(valid, axis=0)
    logdet = 2.0 * jnp.sum(jnp.log(jnp.stack([Lc[i, i] for i in range(m)])), axis=0)
    loglik = -0.5 * (nis + logdet + n_valid * LOG_2PI)
    x_new = jnp.where(ok, x_new, x_pred)
    P_new = jnp.where(ok, P_new, P_pred)

    n_bad = jnp.sum(mask & ~finite, axis=0).astype(jnp.int32)
    bad_flag = _status.NONFINITE_MEASUREMENT if check_finite else _status.NONFINITE_UNMASKED
    flags = jnp.where(n_bad > 0, bad_flag, 0)
    flags = flags | jnp.where(observed & ~ok, _status.CHOLESKY_FAILED, 0)
    finite_state = jnp.all(jnp.isfinite(x_new), axis=0) & jnp.all(jnp.isfinite(P_new), axis=(0, 1))
    flags = flags | jnp.where(finite_state, 0, _status.NONFINITE_STATE)
    ll = jnp.where(observed & ok, loglik, 0.0)

    carry = (
        x_new,
        P_new,
        status | flags.astype(jnp.int32),
        ll_sum + ll,
        n_bad_sum + n_bad,
        n_skip + (~observed).astype(jnp.int32),
    )
    outs = dict(
        means=x_new,
        covs=P_new,
        pred_means=x_pred,
        pred_covs=P_pred,
        innovations=v,
        innov_covs=S,
        nis=jnp.where(observed, nis, 0.0),
        logliks=ll,
        factors=jnp.ones_like(ll),
        valid=n_valid.astype(jnp.int32),
    )
    return carry, outs


def _leaf_layout(a, batched):
    """A model leaf as (static (r, c, b), scan input (T, r, c, b)), the other None; b is B for a leaf
    given per sequence (leading axis B), else 1. Time-varying leaves (a T axis after any B) are scan
    inputs."""
    if a is None:
        return None, None
    a4 = jnp.asarray(a) if batched else jnp.asarray(a)[None]  # (b, [T,] r, c)
    x = jnp.moveaxis(a4, 0, -1)
    return (x, None) if a4.ndim == 3 else (None, x)


def _gqg(G, Q, gb, qb):
    """G Q G^T (or Q) with leading axes (b, t) of 1 or B and T, as (b, t, n, n)."""

    def lead(a, batched):
        a = a if batched else a[None]
        return a[:, None] if a.ndim == 3 else a

    Q4 = lead(jnp.asarray(Q), qb)
    if G is None:
        return Q4
    G4 = lead(jnp.asarray(G), gb)
    return G4 @ Q4 @ jnp.swapaxes(G4, -1, -2)


def _filter_scan(model, batched, x0s, P0s, zs, masks, save, check_finite, joseph, unroll):
    """The batch-minor scan: (final carry, per-epoch outputs ``save`` as (T, ..., B) arrays).

    ``batched`` (static): which leaves of ``model`` carry a leading batch axis B (given per sequence).
    """
    B = zs.shape[0]
    F, H, Q, R, G = model
    fb, hb, qb, rb, gb = batched
    Fs, Ft = _leaf_layout(F, fb)
    Hs, Ht = _leaf_layout(H, hb)
    Rs, Rt = _leaf_layout(R, rb)
    GQG = jnp.moveaxis(_gqg(G, Q, gb, qb), 0, -1)  # (t, n, n, b)
    GQGs, GQGt = (GQG[0], None) if GQG.shape[0] == 1 else (None, GQG)
    carry = (
        jnp.moveaxis(x0s, 0, -1),
        jnp.moveaxis(P0s, 0, -1),
        jnp.zeros((B,), jnp.int32),
        jnp.zeros((B,), zs.dtype),
        jnp.zeros((B,), jnp.int32),
        jnp.zeros((B,), jnp.int32),
    )
    inp = (jnp.moveaxis(zs, 0, -1), jnp.moveaxis(masks, 0, -1), Ft, Ht, GQGt, Rt)
    step = partial(_step, Fs=Fs, Hs=Hs, GQGs=GQGs, Rs=Rs, check_finite=check_finite, joseph=joseph)

    def body(c, i):
        c, outs = step(c, i)
        return c, {g: outs[g] for g in save if g in outs}

    return jax.lax.scan(body, carry, inp, unroll=unroll)


@partial(jax.jit, static_argnames=("save", "check_finite", "joseph", "unroll", "batched"))
def classic_filter_minor(model, x0s, P0s, zs, masks, *, save, check_finite, joseph, unroll=1, batched=(False,) * 5):
    """The classic filter (S0 eqs. (4)-(9)) for B sequences with a covariance each, batch-minor.

    Args:
      model: :class:`~jaxnav.filters.LinearGaussian` (static or (T, ...) leaves), cast; the leaves
        named in ``batched`` (static, five bools) with a leading batch axis B (per sequence).
      x0s: (B, n) initial means.  P0s: (B, n, n) initial covariances.
      zs: (B, T, m) measurements.  masks: (B, T, m) bool user masks.
      save, check_finite, joseph, unroll: as in :func:`~jaxnav.filters.kalman_filter` (static).
    Returns:
      :class:`~jaxnav.filters.KalmanResult` with a leading batch axis B on every field (``noise``
      is (): the classic filter estimates none).
    """
    (x, P, status, ll, n_bad, n_skip), outs = _filter_scan(
        model, batched, x0s, P0s, zs, masks, save, check_finite, joseph, unroll
    )
    per_epoch = {g: jnp.moveaxis(a, -1, 0) for g, a in outs.items()}  # (T, ..., B) -> (B, T, ...)
    return KalmanResult(
        **per_epoch,
        noise=() if "noise" in save else None,
        loglik=ll,
        n_nonfinite=n_bad,
        n_skipped=n_skip,
        status=status,
        x_final=jnp.moveaxis(x, -1, 0),
        P_final=jnp.moveaxis(P, -1, 0),
    )


@partial(jax.jit, static_argnames=("save", "check_finite", "joseph", "unroll", "batched"))
def classic_filter_rts_minor(model, x0s, P0s, zs, masks, *, save, check_finite, joseph, unroll=1, batched=(False,) * 5):
    """:func:`classic_filter_minor` then :func:`rts_minor` in one program: the filter's moments stay
    batch-minor between the two passes. Arguments as there; returns the smoother's result."""
    moments = ("means", "covs", "pred_means", "pred_covs")
    _, outs = _filter_scan(model, batched, x0s, P0s, zs, masks, moments, check_finite, joseph, unroll)
    Fs, Ft = _leaf_layout(model.F, batched[0])
    return rts_minor(Fs if Ft is None else Ft, *(outs[g] for g in moments), save=save)


def _cho_solve(L, Y):
    """(L L^T)^-1 Y for (m, m, B) lower factors and (m, c, B) right-hand sides, row by row with each
    row's sum over the rows before it as one reduction. XLA does not fuse a reduction into its
    consumers, so every row is computed once; written as a chain of subtractions (as in
    :func:`_solve_lower`), XLA fuses the rows of a 6 x 6 solve into the product that uses them and
    recomputes the chain for each element (the smoother's gains: 1.1 s more for B = 256, T = 3600)."""
    m = L.shape[0]
    y = []
    for i in range(m):
        s = Y[i] if i == 0 else Y[i] - _loop_sum(L[i, :i][:, None] * jnp.stack(y), 0)
        y.append(s / L[i, i][None])
    x = [None] * m
    for i in reversed(range(m)):
        s = y[i] if i == m - 1 else y[i] - _loop_sum(L[i + 1 :, i][:, None] * jnp.stack(x[i + 1 :]), 0)
        x[i] = s / L[i, i][None]
    return jnp.stack(x)


@partial(jax.jit, static_argnames=("save",))
def rts_minor(F, means, covs, pred_means, pred_covs, *, save):
    """RTS smoothing (S3 class 1) of B sequences with a covariance each, batch-minor.

    C_t = P_t F_t+1^T P_t+1|t^-1 (zero at the last epoch, and where P_t+1|t is not positive definite),
    x^s_t = x_t + C_t (x^s_t+1 - x_t+1|t), P^s_t = P_t + C_t (P^s_t+1 - P_t+1|t) C_t^T: the formulas of
    :func:`~jaxnav.filters.rts_smoother`, the gains formed inside the backward scan.

    Args:
      F: (n, n, b) or (T, n, n, b) transitions, b = B (per sequence) or 1 (shared).
      means, pred_means: (T, n, B).  covs, pred_covs: (T, n, n, B) the filter's moments, batch-minor.
      save: static subset of ("means", "covs", "gains").
    Returns:
      :class:`~jaxnav.filters.SmootherResult` with a leading batch axis B on every field.
    """
    T, n = means.shape[:2]
    tv = jnp.ndim(F) == 4
    Fs = None if tv else F

    def body(carry, inp):
        x_next, P_next, failed = carry
        x, P, xp, Pp, Ft = inp
        Fk = Fs if Ft is None else Ft
        Lc = _cholesky(Pp)
        ok = jnp.all(jnp.isfinite(Lc), axis=(0, 1))
        Lc = jnp.where(ok, Lc, _eye(n, Pp.dtype))
        # the means need only C_t d = P_t F^T (P_t+1|t^-1 d), one solve with a vector; the gains
        # themselves (six right-hand sides) only for the outputs that use them (dead code otherwise)
        u = _cho_solve(Lc, (x_next - xp)[:, None])[:, 0]
        x_s = x + jnp.where(ok, _mv(P, _mv(_t(Fk), u)), 0.0)
        out = {"means": x_s, "covs": P_next}
        if "covs" in save or "gains" in save:
            C = jnp.where(ok, _t(_cho_solve(Lc, _mm(Fk, P))), 0.0)
            out["gains"] = C
            if "covs" in save:
                out["covs"] = _sym(P + _mm(_mm(C, P_next - Pp), _t(C)))
        P_s = out["covs"]
        return (x_s, P_s, failed | ~ok), {g: out[g] for g in save}

    B = means.shape[-1]
    init = (means[-1], covs[-1], jnp.zeros((B,), bool))
    xs = (means[:-1], covs[:-1], pred_means[1:], pred_covs[1:], F[1:] if tv else None)
    (_, _, failed), outs = jax.lax.scan(body, init, xs, reverse=True)
    last = {"means": means[-1:], "covs": covs[-1:], "gains": jnp.zeros((1, n, n, B), covs.dtype)}
    res = {g: jnp.moveaxis(jnp.concatenate([outs[g], last[g]], axis=0), -1, 0) for g in save}
    status = jnp.where(failed, _status.SMOOTHER_FAILED, 0).astype(jnp.int32)
    return SmootherResult(means=res.get("means"), covs=res.get("covs"), gains=res.get("gains"), status=status)
