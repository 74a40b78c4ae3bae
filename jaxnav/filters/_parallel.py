"""Parallel-in-time Kalman filter and RTS smoother by associative scans.

Särkkä and García-Fernández, "Temporal parallelization of Bayesian smoothers", IEEE TAC 66(1),
2021, Sec. IV (linear Gaussian case): every epoch becomes an element of an associative
operation, and ``jax.lax.associative_scan`` combines them in O(log T) depth. The results equal
the sequential :func:`~jaxnav.filters.kalman_filter` / :func:`~jaxnav.filters.rts_smoother`
(classic filter, no inflation rule or noise estimator) to rounding.

The combine steps use no LAPACK call: the only general solve, (I + C_i J_j)^{-1}, is the
unrolled Gauss-Jordan elimination :func:`jaxnav._numerics.solve_small`; innovation and
prediction covariances are factored by the unrolled Cholesky. (``jnp.linalg.solve`` inside an
associative scan hung intermittently on the development machine, see DESIGN.md.)
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp

from jaxnav import _status
from jaxnav._numerics import (
    cho_solve,
    gaussian_loglik,
    masked_measurement,
    mT,
    safe_cholesky,
    solve_small,
    symmetrize,
    whiten,
)
from jaxnav.filters._kalman import KalmanResult
from jaxnav.filters._model import LinearGaussian
from jaxnav.filters._smoother import SMOOTHER_OUTPUTS, SmootherResult, smoother_gains, smoother_inputs
from jaxnav.filters._step import ALL_OUTPUTS, prepare_inputs


def mm(A, B):
    """Batched matrix product over wide leading axes (XLA's batched dot).

    Unlike the fused multiply-sum of :func:`jaxnav._numerics.mm`, which wins for one small
    matrix per scan step, the elements here carry T or sqrt(T) matrices at once and the batched
    dot is ~4x faster (measured on the T = 3600 filter).
    """
    return jnp.matmul(A, B)


def _mv(A, x):
    """Matrix-vector product with leading batch axes on both: (..., r, c) x (..., c) -> (..., r)."""
    return jnp.sum(A * x[..., None, :], axis=-1)


def _filter_combine(ei, ej):
    """Combine filtering element i (earlier) with j (later) (Särkkä & García-Fernández, Lemma 8).

    Elements (A, b, C, eta, J) carry leading batch axes. With M = I + C_i J_j:
    A_ij = A_j M^{-1} A_i, b_ij = A_j M^{-1} (b_i + C_i eta_j) + b_j,
    C_ij = A_j M^{-1} C_i A_j^T + C_j, eta_ij = A_i^T M^{-T} (eta_j - J_j b_i) + eta_i,
    J_ij = A_i^T M^{-T} J_j A_i + J_i, using (I + J_j C_i)^{-1} = M^{-T} (C, J symmetric), so one
    solve with stacked right-hand sides serves all five.
    """
    Ai, bi, Ci, etai, Ji = ei
    Aj, bj, Cj, etaj, Jj = ej
    n = Ai.shape[-1]
    M = jnp.eye(n, dtype=Ai.dtype) + mm(Ci, Jj)
    rhs = jnp.concatenate([Ai, (bi + _mv(Ci, etaj))[..., None], Ci], axis=-1)
    W = solve_small(M, rhs)
    WA, Wb, WC = W[..., :n], W[..., n], W[..., n + 1 :]
    A = mm(Aj, WA)
    b = _mv(Aj, Wb) + bj
    C = symmetrize(mm(mm(Aj, WC), mT(Aj)) + Cj)
    eta = _mv(mT(WA), etaj - _mv(Jj, bi)) + etai
    J = symmetrize(mm(mm(mT(WA), Jj), Ai) + Ji)
    return A, b, C, eta, J


def _smoother_combine(later, earlier):
    """Combine smoothing elements (reverse scan): (E_i E_j, E_i g_j + g_i, E_i L_j E_i^T + L_i).

    i is the earlier epoch, j the later one (whose element already holds the smoothed moments
    from the end); Särkkä & García-Fernández, Lemma 10.
    """
    Ej, gj = later[0], later[1]
    Ei, gi = earlier[0], earlier[1]
    out = (mm(Ei, Ej), _mv(Ei, gj) + gi)
    if len(later) == 3:
        out = out + (symmetrize(mm(mm(Ei, later[2]), mT(Ei)) + earlier[2]),)
    return out


def _blocked_scan(fn, elems, identity, chunk):
    """Inclusive scan of an associative ``fn(acc, x)`` in two levels of sequential scans.

    The T elements are padded with ``identity`` to c chunks of ``chunk`` and laid out
    (chunk, c, ...). (1) One ``lax.scan`` of ``chunk`` steps scans all chunks at once, each
    step a combine over c elements in wide vector operations; (2) a ``lax.scan`` of c steps
    scans the chunk totals; (3) one combine over all elements adds each chunk's prefix. Depth
    chunk + c + 1 (smallest near chunk = sqrt(T)), work about 2T combines, and only three copies
    of ``fn`` in the compiled program, where ``lax.associative_scan`` inlines 2 log2(T) of them
    (a minute of XLA compile time for T = 3600 with the filter's combine on this machine).
    """
    leaves = jax.tree_util.tree_leaves(elems)
    T = leaves[0].shape[0]
    c = -(-T // chunk)
    pad = c * chunk - T

    def prep(x, e):
        if pad:
            x = jnp.concatenate([x, jnp.broadcast_to(e, (pad,) + e.shape)], axis=0)
        return jnp.swapaxes(x.reshape((c, chunk) + x.shape[1:]), 0, 1)  # (chunk, c, ...)

    xs = tuple(prep(x, e) for x, e in zip(elems, identity))
    first = tuple(x[0] for x in xs)

    def body(acc, x):
        new = fn(acc, x)
        return new, new

    _, loc = jax.lax.scan(body, first, tuple(x[1:] for x in xs))
    loc = tuple(jnp.concatenate([f[None], lo], axis=0) for f, lo in zip(first, loc))  # (chunk, c, ...)
    if c > 1:
        totals = tuple(lo[-1] for lo in loc)  # (c, ...)
        _, pref = jax.lax.scan(body, tuple(t[0] for t in totals), tuple(t[1:-1] for t in totals))
        pref = tuple(jnp.concatenate([t[:1], p], axis=0) for t, p in zip(totals, pref))  # (c-1, ...)
        fixed = fn(tuple(jnp.broadcast_to(p[None], (chunk,) + p.shape) for p in pref), tuple(lo[:, 1:] for lo in loc))
        loc = tuple(jnp.concatenate([lo[:, :1], f], axis=1) for lo, f in zip(loc, fixed))
    return tuple(jnp.swapaxes(lo, 0, 1).reshape((c * chunk,) + lo.shape[2:])[:T] for lo in loc)


def _scan(fn, elems, identity, method, chunk, reverse):
    """Inclusive associative scan by ``method`` ("blocked" or "tree"); ``fn(earlier_acc, x)``.

    With ``reverse`` the scan runs from the end and ``fn(later_acc, x)`` receives the
    accumulated later part first.
    """
    if method == "tree":
        return jax.lax.associative_scan(fn, elems, reverse=reverse)
    if method != "blocked":
        raise ValueError(f"method must be 'blocked' or 'tree', got {method!r}")
    T = elems[0].shape[0]
    if chunk is None:
        chunk = max(1, int(round(T**0.5)))
    if reverse:
        elems = tuple(jnp.flip(x, 0) for x in elems)
    out = _blocked_scan(fn, elems, identity, int(chunk))
    return tuple(jnp.flip(x, 0) for x in out) if reverse else out


def _tv(a, T, base_ndim):
    """Leaf with a leading T axis (static leaves are broadcast lazily by the products)."""
    return a if a.ndim == base_ndim + 1 else a[None]


@partial(jax.jit, static_argnames=("save", "allow_float32", "check_finite", "method", "chunk"))
def parallel_filter(
    model: LinearGaussian,
    x0,
    P0,
    zs,
    *,
    mask=None,
    save=ALL_OUTPUTS,
    allow_float32: bool = False,
    check_finite: bool = True,
    method: str = "blocked",
    chunk: int | None = None,
) -> KalmanResult:
    """Classic Kalman filter by a parallel associative scan (Särkkä & García-Fernández 2021, Sec. IV).

    Same model, convention and outputs as :func:`~jaxnav.filters.kalman_filter` without plug-ins
    (x0, P0 at k = 0; every zs[t] after one prediction; Joseph-form element covariances), and
    equal to it to rounding. Depth O(log T) instead of T: on a machine with many cores (or a
    GPU) it wins for long series; on few cores it does more total work (about 3x the
    arithmetic of the sequential step) but in wide vector operations, see
    ``benchmarks/bench_parallel.py`` for the crossover measured here.

    Masking as in the sequential filter: masked or NaN/inf components get zero H rows and unit
    noise, so they contribute nothing; an epoch with nothing valid is a pure prediction.

    Args:
      model: :class:`LinearGaussian`, static or (T, ...) time-varying leaves.
      x0: (n,) initial mean.  P0: (n, n) initial covariance.
      zs: (T, m) measurements (NaN/inf masked and counted when ``check_finite``).
      mask: optional (T,) or (T, m) bool, True where a measurement is used.
      save: static subset of ``ALL_OUTPUTS`` (``factors`` are ones, ``noise`` is ``()``).
      allow_float32: static; opt in to float32.
      check_finite: static; as in :func:`~jaxnav.filters.kalman_filter`.
      method: static. "blocked" (default): the associative operator applied in a two-level
        blocked scan (chunks scanned side by side, then the chunk totals), depth ~2 sqrt(T),
        compiles in seconds and suits CPUs with few cores. "tree": ``lax.associative_scan``,
        depth O(log T), for many-core devices; its compile time grows with log T.
      chunk: static chunk length of the blocked scan (default round(sqrt(T))).
    Returns:
      :class:`KalmanResult` with the same fields and flags as the sequential filter.
    Raises:
      ValueError: at trace time for inconsistent shapes, unknown outputs or float32 without
        ``allow_float32``.
    """
    model, x0, P0, zs, mask, save, (n, m, p, T), tv, dtype = prepare_inputs(
        model, x0, P0, zs, mask, save, allow_float32
    )
    F, H, Q, R, G = model
    # a model closed over by the caller's jit is constant: without the barrier XLA would
    # constant-fold the (T, n, n) element arrays built from it (minutes for T = 86 400)
    F, H, Q, R, G, x0, P0 = jax.lax.optimization_barrier((F, H, Q, R, G, x0, P0))
    F, H, R = _tv(F, T, 2), _tv(H, T, 2), _tv(R, T, 2)
    if G is None:
        GQG = _tv(Q, T, 2)
    else:
        Gt, Qt = _tv(G, T, 2), _tv(Q, T, 2)
        GQG = mm(mm(Gt, Qt), mT(Gt))
    GQG = jnp.broadcast_to(GQG, (T, n, n))
    eye_n = jnp.eye(n, dtype=dtype)

    finite = jnp.isfinite(zs)
    valid = mask & finite if check_finite else mask
    observed = jnp.any(valid, axis=-1)
    z = jnp.where(valid, zs, 0.0) if check_finite else zs
    Hm, Rm = masked_measurement(H, R, valid)  # (T, m, n), (T, m, m)

    # --- elements: epoch 1 from (x0, P0); later epochs from a zero-mean GQG prior ---
    F1 = F[0]
    Pk = GQG.at[0].set(symmetrize(mm(mm(F1, P0), F1.T) + GQG[0]))
    mk = jnp.zeros((T, n), dtype).at[0].set(mm(F1, x0))
    PHt = mm(Pk, mT(Hm))  # (T, n, m)
    S = symmetrize(mm(Hm, PHt) + Rm)
    Lsafe, ok = safe_cholesky(S)
    K = jnp.where(ok[:, None, None], mT(cho_solve(Lsafe, mT(PHt))), 0.0)  # (T, n, m)
    IKH = eye_n - mm(K, Hm)
    b = mk + _mv(K, z - _mv(Hm, mk))
    C = symmetrize(mm(mm(IKH, Pk), mT(IKH)) + mm(mm(K, Rm), mT(K)))
    A = mm(IKH, jnp.broadcast_to(F, (T, n, n))).at[0].set(0.0)
    HF = mm(Hm, F)  # (T, m, n)
    Wz = jnp.where(ok[:, None], cho_solve(Lsafe, z[..., None])[..., 0], 0.0)  # S^{-1} z
    eta = _mv(mT(HF), Wz).at[0].set(0.0)
    SiHF = jnp.where(ok[:, None, None], cho_solve(Lsafe, HF), 0.0)
    J = symmetrize(mm(mT(HF), SiHF)).at[0].set(0.0)

    zn, zv = jnp.zeros((n, n), dtype), jnp.zeros((n,), dtype)
    identity = (eye_n, zv, zn, zv, zn)
    _, means, covs, _, _ = _scan(_filter_combine, (A, b, C, eta, J), identity, method, chunk, False)

    # --- per-epoch outputs from the filtered moments, all epochs at once ---
    prev_m = jnp.concatenate([x0[None], means[:-1]], axis=0)
    prev_P = jnp.concatenate([P0[None], covs[:-1]], axis=0)
    pred_m = _mv(F, prev_m)
    pred_P = symmetrize(mm(mm(F, prev_P), mT(F)) + GQG)
    v = jnp.where(valid, z - _mv(Hm, pred_m), 0.0)
    Sp = symmetrize(mm(Hm, mm(pred_P, mT(Hm))) + Rm)
    Lp, okp = safe_cholesky(Sp)
    w = whiten(Lp, v[..., None])[..., 0]
    nis = jnp.sum(w * w, axis=-1)
    mv = jnp.sum(valid, axis=-1)
    ll = jnp.where(observed & okp, gaussian_loglik(w, Lp, mv), 0.0)

    n_bad = jnp.sum(mask & ~finite).astype(jnp.int32)
    bad_flag = _status.NONFINITE_MEASUREMENT if check_finite else _status.NONFINITE_UNMASKED
    status = jnp.where(n_bad > 0, bad_flag, 0)
    status = status | jnp.where(jnp.any(observed & ~ok), _status.CHOLESKY_FAILED, 0)
    status = status | jnp.where(jnp.all(jnp.isfinite(means)) & jnp.all(jnp.isfinite(covs)), 0, _status.NONFINITE_STATE)
    allv = dict(
        means=means,
        covs=covs,
        pred_means=pred_m,
        pred_covs=pred_P,
        innovations=v,
        innov_covs=Sp,
        nis=jnp.where(observed, nis, 0.0),
        logliks=ll,
        factors=jnp.ones((T,), dtype),
        noise=(),
        valid=mv.astype(jnp.int32),
    )
    out = {name: allv[name] for name in save}
    return KalmanResult(
        **out,
        loglik=jnp.sum(ll),
        n_nonfinite=n_bad,
        n_skipped=jnp.sum(~observed).astype(jnp.int32),
        status=status.astype(jnp.int32),
        x_final=means[-1],
        P_final=covs[-1],
    )


@partial(jax.jit, static_argnames=("save", "method", "chunk"))
def parallel_smoother(
    model: LinearGaussian, filtered, *, save=SMOOTHER_OUTPUTS, method: str = "blocked", chunk: int | None = None
) -> SmootherResult:
    """RTS smoother by a reverse associative scan (Särkkä & García-Fernández 2021, Sec. IV-B).

    Elements E_t = P_t F_{t+1}^T P_{t+1|t}^{-1}, g_t = x_t - E_t x_{t+1|t},
    L_t = P_t - E_t P_{t+1|t} E_t^T (and (0, x_T, P_T) at the end) combine into the smoothed
    moments; equal to :func:`~jaxnav.filters.rts_smoother` to rounding. Like it, it uses the
    filter's saved predicted moments.

    Args:
      model: the filter's model (only F is used; (n, n) or (T, n, n)).
      filtered: a :class:`KalmanResult` with ``means``, ``covs``, ``pred_means``, ``pred_covs``
        (from :func:`parallel_filter` or :func:`~jaxnav.filters.kalman_filter`).
      save: static subset of ("means", "covs", "gains"); without "covs" the covariance part of
        the scan is skipped.
      method, chunk: static; the scan schedule, as in :func:`parallel_filter`.
    Returns:
      :class:`SmootherResult`.
    Raises:
      ValueError: if the needed outputs were not saved, or F has a wrong shape.
    """
    save, _ = smoother_inputs(model, filtered, save, "parallel_smoother")
    xs, Ps, xp, Pp = filtered.means, filtered.covs, filtered.pred_means, filtered.pred_covs
    T, n = xs.shape
    E, status = smoother_gains(model, filtered, save, "parallel_smoother")  # (T, n, n), zero at the end
    g = jnp.concatenate([xs[:-1] - _mv(E[:-1], xp[1:]), xs[-1:]], axis=0)
    elems = (E, g)
    want_cov = "covs" in save
    if want_cov:
        Lc = symmetrize(Ps[:-1] - mm(mm(E[:-1], Pp[1:]), mT(E[:-1])))
        elems = elems + (jnp.concatenate([Lc, Ps[-1:]], axis=0),)
    identity = (jnp.eye(n, dtype=xs.dtype), jnp.zeros((n,), xs.dtype), jnp.zeros((n, n), xs.dtype))[: len(elems)]
    res = _scan(_smoother_combine, elems, identity, method, chunk, True)
    return SmootherResult(
        means=res[1] if "means" in save else None,
        covs=res[2] if want_cov else None,
        gains=E if "gains" in save else None,
        status=status,
    )
