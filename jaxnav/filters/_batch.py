"""Batches that share one covariance recursion: :func:`kalman_filter_batch`, :func:`rts_smoother_batch`.

In a Monte Carlo study every sequence has the same model, P0 and mask, and a classic, constant
or attenuated filter has the same covariances and gains K_t for all of them (S0 eqs. (4)-(9):
nothing in P_k depends on the measurements). Only the means differ, and they follow a linear
recursion with the shared gains,

    x_t|t-1 = F_t x_t-1,   v_t = z_t - H_t x_t|t-1,   x_t = x_t|t-1 + K_t v_t,   w_t = L_t^-1 v_t,

with S_t = L_t L_t^T (w_t gives the NIS |w_t|^2 and the log-likelihood). So the batch runs the
covariance recursion once (:func:`jaxnav.filters.filter_step` on zero data) and then the means
of all B sequences. Over a block of L epochs every output is a fixed linear map of the state
before the block and the block's measurements, so for the whole batch one dense product

    Y = s M_s + z_block M_z,     (B, n) x (n, R)  +  (B, L m) x (L m, R),

gives every requested output of the L epochs, written once, in place, in the (B, T, ...) result.
Results equal ``jax.vmap(kalman_filter)`` to rounding (products of up to L transitions are
formed once per block).

The shared covariance outputs (``covs``, ``pred_covs``, ``innov_covs``, ``factors``, ``valid``,
``n_skipped``, ``P_final``, ``noise``) are returned once, without a batch axis; the per-sequence
ones (``means``, ``pred_means``, ``innovations``, ``nis``, ``logliks``, ``loglik``,
``n_nonfinite``, ``status``, ``x_final``) with a leading axis B.

``jax.vmap(kalman_filter)`` uses this recursion too (:func:`vmap_filter_rule`), but only when
the whole batch is free of unmasked NaN/inf, since a loop's covariances then agree; it returns
saved covariances as B copies. Here the batch is explicit and so is the policy: a NaN/inf
element of one sequence masks that element in every sequence (exact for clean batches and gaps
common to all sequences, the Monte Carlo case); sequences that lose finite data that way are
flagged (``BATCH_MASK_WIDENED``). Batches with their own gaps per sequence (real stations) keep
``jax.vmap(kalman_filter)``, which then runs one filter per sequence.
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp

from jaxnav import _status
from jaxnav._numerics import SMALL, safe_cholesky, whiten
from jaxnav.filters._minor import classic_filter_minor
from jaxnav.filters._model import LinearGaussian
from jaxnav.filters._plugins import NoEstimator, NoInflation, data_independent
from jaxnav.filters._smoother import SMOOTHER_OUTPUTS, SmootherResult, smoothed_covs, smoother_gains, vmap_sharing
from jaxnav.filters._step import ALL_OUTPUTS, KalmanResult, scan_setup, step_with_gain

#: per-epoch outputs that differ between the sequences of a shared-recursion batch
PER_SEQUENCE = ("means", "pred_means", "innovations", "nis", "logliks")

#: epochs per block: the products' width grows with L and their count falls with it. For the
#: 6-state model at B = 256, T = 3600 (benchmarks/bench_filters.py case (c), every output) L = 3
#: and 4 ran 36 ms, 5 45 ms, 8 52 ms (interleaved, best of 10; the floor of reading the data and
#: writing the means 15-17 ms)
BLOCK = 4

#: smallest batch size x epochs for which the blocks are used by default. Below it the plain
#: per-sequence mean recursion costs a few ms at most, and the blocks' extra program (maps, block
#: loop, and their derivatives) would double the compile time (measured 2.0 -> 5.2 s for grad at
#: B = 4, T = 120). At B = 8, T = 3600 (28 800) the blocks already run 12.3 vs 15.8 ms.
MIN_BATCH_EPOCHS = 2**14

#: epochs per block of the batch smoother's means: 4 was the fastest of 2, 3, 4, 6 and 8 at B = 256,
#: T = 3600 (64 vs 71-78 ms on the loaded 2-core machine; its product is wider than the filter's)
RTS_BLOCK = 4


def worth_blocking(B, T, n, m, save, itemsize=8, block=BLOCK, floor_bytes=256 * 2**20) -> bool:
    """Whether the means of a shared-recursion batch run in blocks (``block="auto"``).

    True when the batch is large enough (B T >= :data:`MIN_BATCH_EPOCHS`) and the block maps
    (T / L blocks of (n + L m) x R, a few copies while built) stay small next to what the batch
    writes anyway: below ``floor_bytes`` or below the batch's per-epoch outputs. A long series
    with few sequences (e.g. B = 2, T = 86 400: ~0.5 GB of maps for 11 MB of means) keeps the
    recursion per sequence.
    """
    if B * T < MIN_BATCH_EPOCHS:
        return False
    L = max(1, min(block, T))
    _, width, R = _groups(save, n, m, L)
    maps = 3 * -(-T // L) * (n + L * m) * R * itemsize
    out = B * T * (2 + sum(width[g] for g in ("means", "pred_means", "innovations") if g in save)) * itemsize
    return maps <= max(floor_bytes, out)


def kalman_filter_batch(
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
    block="auto",
    joseph: bool = True,
) -> KalmanResult:
    """The Kalman filter for B sequences that share one covariance recursion (S0 eqs. (4)-(12)).

    Equal to ``jax.vmap(kalman_filter)`` for batches whose non-finite elements are common to all
    sequences (none, or shared outages), at a fraction of its cost: one covariance recursion and
    the means in blocks of epochs (module docstring).

    Args:
      model: shared :class:`LinearGaussian` (static or (T, ...) leaves).
      x0: (n,) shared or (B, n) per-sequence initial means.  P0: (n, n) shared initial covariance.
      zs: (B, T, m) measurements. A NaN/inf element of any sequence masks that element in every
        sequence: counted in ``n_nonfinite`` of the sequences that have it (flag
        NONFINITE_MEASUREMENT); sequences that lose a finite element that way get the error flag
        BATCH_MASK_WIDENED.
      inflation, estimator: shared data-independent plug-ins (classic, :func:`constant`,
        :func:`attenuated`, or any with ``data_independent = True``).
      mask: None, (T,) or (T, m) shared bool mask.
      save, unroll, allow_float32, joseph: as in :func:`~jaxnav.filters.kalman_filter` (static).
      block: static; "auto" (blocks of :data:`BLOCK` epochs where :func:`worth_blocking` says so,
        else the per-sequence mean recursion with the shared gains), an int L >= 1, or None
        (never blocks).
    Returns:
      :class:`KalmanResult`: per-sequence fields with a leading axis B, shared ones without.
    Raises:
      ValueError: shapes (named), a data-dependent plug-in, a bad ``block``.
    """
    if not data_independent(inflation, estimator):
        raise ValueError(
            "kalman_filter_batch shares one covariance recursion, which needs a data-independent "
            "inflation rule and noise estimator (classic, constant, attenuated); for fading, "
            "variance compensation, Sage-Husa or robust filters use jax.vmap(kalman_filter)"
        )
    if not (block == "auto" or block is None or (isinstance(block, int) and block >= 1)):
        raise ValueError(f"block must be 'auto', None or an integer >= 1, got {block!r}")
    zshape = jnp.shape(zs)
    if len(zshape) != 3:
        raise ValueError(f"zs has shape {zshape}; expected (B, T, m)")
    if jnp.ndim(x0) not in (1, 2) or (jnp.ndim(x0) == 2 and jnp.shape(x0)[0] != zshape[0]):
        raise ValueError(f"x0 has shape {jnp.shape(x0)}; expected (n,) or ({zshape[0]}, n) to match zs {zshape}")
    return _kalman_filter_batch(
        model,
        x0,
        P0,
        zs,
        inflation=inflation,
        estimator=estimator,
        mask=mask,
        save=tuple(save),
        unroll=unroll,
        allow_float32=allow_float32,
        block=block,
        joseph=joseph,
    )


@partial(jax.jit, static_argnames=("save", "unroll", "allow_float32", "block", "joseph"))
def _kalman_filter_batch(model, x0, P0, zs, *, inflation, estimator, mask, save, unroll, allow_float32, block, joseph):
    B, T, m = zs.shape
    x0s = jnp.broadcast_to(x0, (B, jnp.shape(x0)[-1]))
    params, init, xs, save, (n, _, _, _), tv, dtype = scan_setup(
        model, x0s[0], P0, zs[0], inflation, estimator, mask, save, allow_float32
    )
    zs = jnp.asarray(zs, dtype)
    # the batch's common mask: an element non-finite in any sequence is masked in all
    user = xs.mask
    fin = jnp.isfinite(zs)
    common = user & jnp.all(fin, axis=0)

    def per_sequence_counts():
        n_bad = jnp.sum(user & ~fin, axis=(1, 2), dtype=jnp.int32)
        return n_bad, jnp.any(user & fin & ~common, axis=(1, 2))

    # the per-sequence counts read the whole batch again; a clean batch (the usual case) skips them
    n_bad, widened = jax.lax.cond(
        jnp.all(common == user),
        lambda: (jnp.zeros((B,), jnp.int32), jnp.zeros((B,), bool)),
        per_sequence_counts,
    )
    xs = xs._replace(mask=common)
    seq_flags = (
        jnp.where(n_bad > 0, _status.NONFINITE_MEASUREMENT, 0) | jnp.where(widened, _status.BATCH_MASK_WIDENED, 0)
    ).astype(jnp.int32)

    final, (allv, K) = _covariance_pass(params, init, xs, unroll, joseph)
    L = (
        block
        if isinstance(block, int)
        else (BLOCK if block == "auto" and worth_blocking(B, T, n, m, save, jnp.dtype(dtype).itemsize) else None)
    )
    if L is None:
        out, ll, x_final, fin_state = _means_recursion(model, tv, allv, K, xs, x0s, zs, save)
    else:
        out, ll, x_final, fin_state = _means_blocks(model, tv, allv, K, xs, x0s, zs, save, min(L, T))
    shared = {g: allv[g] for g in save if g not in PER_SEQUENCE}
    status = final.status | seq_flags | jnp.where(fin_state, 0, _status.NONFINITE_STATE).astype(jnp.int32)
    return KalmanResult(
        **out,
        **shared,
        loglik=ll,
        n_nonfinite=n_bad,
        n_skipped=final.n_skipped,
        status=status,
        x_final=x_final,
        P_final=final.P,
    )


def _covariance_pass(params, init, xs, unroll, joseph):
    """The covariance recursion once, on zero data with the shared mask: every shared output and the gains."""
    zero = init._replace(x=jnp.zeros_like(init.x))

    def body(state, inp):
        new, allv, K = step_with_gain(state, inp._replace(z=jnp.zeros_like(inp.z)), params, False, joseph)
        return new, (allv, K)

    return jax.lax.scan(body, zero, xs, unroll=unroll)


def _shared_terms(model, tv, allv, K, xs):
    """Per-epoch shared matrices of the mean recursion: F, masked H, K, L^-1, valid (0/1), log-lik constant."""
    valid = xs.mask
    T, m = valid.shape
    n = K.shape[1]
    dtype = K.dtype
    Lc, ok = safe_cholesky(allv["innov_covs"])
    Linv = whiten(Lc, jnp.broadcast_to(jnp.eye(m, dtype=dtype), (T, m, m)))
    F = model.F if tv["F"] else jnp.broadcast_to(jnp.asarray(model.F, dtype), (T, n, n))
    H = model.H if tv["H"] else jnp.broadcast_to(jnp.asarray(model.H, dtype), (T, m, n))
    Hm = jnp.where(valid[:, :, None], jnp.asarray(H, dtype), 0.0)
    observed = jnp.any(valid, axis=-1)
    # allv["logliks"] is -(log det S + m log 2 pi) / 2 where observed and S factored (zero data)
    return dict(
        F=F,
        Hm=Hm,
        K=K,
        Linv=Linv,
        valid=valid.astype(dtype),
        c_ll=allv["logliks"],
        okf=(observed & ok).astype(dtype),
        obsf=observed.astype(dtype),
    )


def _means_recursion(model, tv, allv, K, xs, x0s, zs, save):
    """The means of every sequence by its own scan with the shared gains (small batches)."""
    sh = _shared_terms(model, tv, allv, K, xs)

    def one(x0, z):
        def step(x, inp):
            F, Hm, Kt, Linv, vf, c, okf, obsf, zt = inp
            xp = F @ x
            v = vf * jnp.nan_to_num(zt - Hm @ xp, nan=0.0, posinf=0.0, neginf=0.0)
            x = xp + Kt @ v
            w = Linv @ v
            nis = jnp.sum(w * w)
            outs = dict(means=x, pred_means=xp, innovations=v, nis=obsf * nis, logliks=okf * (c - 0.5 * nis))
            return x, {g: outs[g] for g in PER_SEQUENCE if g in save or g == "logliks"}

        inp = (sh["F"], sh["Hm"], sh["K"], sh["Linv"], sh["valid"], sh["c_ll"], sh["okf"], sh["obsf"], z)
        x_final, outs = jax.lax.scan(step, x0, inp)
        return x_final, outs

    x_final, outs = jax.vmap(one)(x0s, zs)
    ll = jnp.sum(outs["logliks"], axis=1)
    out = {g: outs[g] for g in PER_SEQUENCE if g in save}
    fin = jnp.all(jnp.isfinite(x_final), axis=-1) & jnp.all(jnp.isfinite(outs["logliks"]), axis=-1)
    return out, ll, x_final, fin


def _groups(save, n, m, block):
    """The column groups of the block maps for ``save`` and their total width R (static)."""
    want = tuple(g for g in ("means", "pred_means", "innovations") if g in save)
    groups = want + ("w",) + (() if "means" in save else ("end",))
    width = dict(means=n, pred_means=n, innovations=m, w=m, end=n)
    return groups, width, sum(width[g] * (1 if g == "end" else block) for g in groups)


def _block_maps(F, Hm, K, Linv, valid, groups):
    """The linear maps from (state before the block, block measurements) to each output group.

    Args (leading axes (nb, L): nb blocks of L epochs):
      F: (nb, L, n, n) transitions.  Hm: (nb, L, m, n) measurement matrices with masked rows zeroed.
      K: (nb, L, n, m) gains (zero columns where masked, zero where S failed).
      Linv: (nb, L, m, m) inverse Cholesky factors of S.  valid: (nb, L, m) 0/1 float.
      groups: static names in column order, from "means", "pred_means", "innovations", "w", "end".
    Returns:
      (M (nb, n + L m, R)): rows for the state, then the block's measurements; group g of epoch j
      occupies r_g columns at the group's offset + j r_g ("end", the state after the block: n).
    """
    nb, L, n, _ = F.shape
    m = Hm.shape[2]
    sel = jnp.eye(L * m, dtype=F.dtype).reshape(L, m, L * m)  # picks z_j out of the block

    def step(carry, inp):
        Phi, Psi = carry  # x_{j-1} = Phi s + Psi z_block
        Fj, Hj, Kj, Lj, vj, Sj = inp
        pPhi, pPsi = Fj @ Phi, Fj @ Psi
        vPhi, vPsi = -(Hj @ pPhi), vj[..., None] * Sj - Hj @ pPsi
        xPhi, xPsi = pPhi + Kj @ vPhi, pPsi + Kj @ vPsi
        maps = dict(means=(xPhi, xPsi), pred_means=(pPhi, pPsi), innovations=(vPhi, vPsi), w=(Lj @ vPhi, Lj @ vPsi))
        return (xPhi, xPsi), tuple(maps[g] for g in groups if g != "end")

    lead = lambda a: jnp.swapaxes(a, 0, 1)  # (L, nb, ...) for the scan
    init = (jnp.broadcast_to(jnp.eye(n, dtype=F.dtype), (nb, n, n)), jnp.zeros((nb, n, L * m), F.dtype))
    (Phi, Psi), outs = jax.lax.scan(step, init, (lead(F), lead(Hm), lead(K), lead(Linv), lead(valid), sel))
    Ms, Mz = [], []
    for aPhi, aPsi in outs:  # (L, nb, r, n), (L, nb, r, L m)
        r = aPhi.shape[2]
        Ms.append(jnp.transpose(aPhi, (1, 3, 0, 2)).reshape(nb, n, L * r))
        Mz.append(jnp.transpose(aPsi, (1, 3, 0, 2)).reshape(nb, L * m, L * r))
    if "end" in groups:
        Ms.append(jnp.swapaxes(Phi, 1, 2))
        Mz.append(jnp.swapaxes(Psi, 1, 2))
    return jnp.concatenate([jnp.concatenate(Ms, axis=-1), jnp.concatenate(Mz, axis=-1)], axis=1)


def _means_blocks(model, tv, allv, K, xs, x0s, zs, save, Lb):
    """The means of the whole batch in blocks of ``Lb`` epochs, one dense product per block."""
    sh = _shared_terms(model, tv, allv, K, xs)
    B, T, m = zs.shape
    n = K.shape[1]
    dtype = zs.dtype
    groups, width, _ = _groups(save, n, m, Lb)
    want = [g for g in groups if g in save]
    nb, tail = divmod(T, Lb)
    Z = zs.reshape(B, T * m)
    vflat = sh["valid"].reshape(T * m)
    bufs0 = {g: jnp.zeros((B, T * width[g]), dtype) for g in want}
    for g in ("nis", "logliks"):
        if g in save:
            bufs0[g] = jnp.zeros((B, T), dtype)

    def apply(carry, t0, Lk, M):
        s, bufs, ll = carry
        # masked elements may hold NaN/inf: zero them (multiply-then-clean is a plain vector
        # operation here; a select on the mask costs ~10 us per block, measured)
        zb = jax.lax.dynamic_slice_in_dim(Z, t0 * m, Lk * m, axis=1)
        zb = jnp.nan_to_num(zb * jax.lax.dynamic_slice_in_dim(vflat, t0 * m, Lk * m), nan=0.0, posinf=0.0, neginf=0.0)
        Y = jnp.concatenate([s, zb], axis=1) @ M
        cols, off = {}, 0
        for g in groups:
            w = width[g] * (1 if g == "end" else Lk)
            cols[g] = Y[:, off : off + w]
            off += w
        wv = cols["w"].reshape(B, Lk, m)
        nis = jnp.sum(wv * wv, axis=-1)
        sl = lambda a: jax.lax.dynamic_slice_in_dim(a, t0, Lk)
        lls = sl(sh["okf"]) * (sl(sh["c_ll"]) - 0.5 * nis)
        vals = dict(cols, nis=sl(sh["obsf"]) * nis, logliks=lls)
        bufs = {
            g: jax.lax.dynamic_update_slice_in_dim(b, vals[g], t0 * (b.shape[1] // T), axis=1) for g, b in bufs.items()
        }
        state = cols["means"] if "means" in cols else cols["end"]
        return state[:, -n:], bufs, ll + jnp.sum(lls, axis=1)

    carry = (jnp.asarray(x0s, dtype), bufs0, jnp.zeros((B,), dtype))
    per_epoch = (sh["F"], sh["Hm"], sh["K"], sh["Linv"], sh["valid"])
    if nb:
        blk = [a[: nb * Lb].reshape((nb, Lb) + a.shape[1:]) for a in per_epoch]
        maps = _block_maps(*blk, groups)
        carry, _ = jax.lax.scan(lambda c, k: (apply(c, k * Lb, Lb, maps[k]), None), carry, jnp.arange(nb))
    if tail:
        blk = [a[nb * Lb :][None] for a in per_epoch]
        carry = apply(carry, nb * Lb, tail, _block_maps(*blk, groups)[0])
    x_final, bufs, ll = carry
    # a non-finite state stays non-finite through the blocks' products (NaN x 0 is NaN), so the
    # final state tells whether any state of the run was non-finite
    fin = jnp.all(jnp.isfinite(x_final), axis=-1)
    shape = {g: (B, T, width[g]) for g in ("means", "pred_means", "innovations")}
    out = {g: bufs[g].reshape(shape.get(g, (B, T))) for g in PER_SEQUENCE if g in save}
    return out, ll, x_final, fin


def rts_smoother_batch(
    model: LinearGaussian, filtered: KalmanResult, *, save=SMOOTHER_OUTPUTS, unroll: int = 1
) -> SmootherResult:
    """RTS smoothing of a :func:`kalman_filter_batch` result: shared gains, per-sequence means.

    The gains C_t = P_t F_{t+1}^T P_{t+1|t}^{-1} and the smoothed covariances depend only on
    the shared covariances, so they are computed once; the smoothed means of all sequences
    follow x^s_t = x_t + C_t (x^s_{t+1} - x_{t+1|t}) (see :func:`~jaxnav.filters.rts_smoother`).

    Args:
      model: the filter's model (only F is used).
      filtered: a batch result saved with means (B, T, n) and covs and pred_covs (T, n, n)
        (``save=("means", "covs", "pred_covs")`` is all it needs).
      save: static subset of ("means", "covs", "gains").  unroll: ``lax.scan`` unroll factor.
    Returns:
      :class:`SmootherResult` with means (B, T, n), covs and gains (T, n, n) shared, status scalar.
    Raises:
      ValueError: missing filter outputs or shapes that are not a batch result's.
    """
    for name in ("means", "covs", "pred_covs"):  # the predicted means are F x: not needed
        if getattr(filtered, name) is None:
            raise ValueError(f"rts_smoother_batch needs the filter output '{name}': run the filter with it in save=")
    if jnp.ndim(filtered.means) != 3 or jnp.ndim(filtered.covs) != 3:
        raise ValueError(
            f"rts_smoother_batch needs a kalman_filter_batch result: means {jnp.shape(filtered.means)} "
            f"(expected (B, T, n)) and covs {jnp.shape(filtered.covs)} (expected (T, n, n))"
        )
    return _rts_smoother_batch(model, filtered, save=tuple(save), unroll=unroll)


@partial(jax.jit, static_argnames=("save", "unroll"))
def _rts_smoother_batch(model, filtered, *, save, unroll):
    one = filtered._replace(means=filtered.means[0], pred_means=filtered.means[0])  # gains need covariances only
    C, status = smoother_gains(model, one, save, "rts_smoother_batch")
    means = None
    if "means" in save:
        T, n = one.means.shape
        F = jnp.broadcast_to(jnp.asarray(model.F, C.dtype), (T, n, n))
        F_next = jnp.concatenate([F[1:], jnp.zeros_like(F[:1])], axis=0)
        means = _smoothed_means_blocks(C, jnp.eye(n, dtype=C.dtype) - C @ F_next, filtered.means, RTS_BLOCK)
    covs = smoothed_covs(C, filtered.covs, filtered.pred_covs, unroll) if "covs" in save else None
    gains = C if "gains" in save else None
    return SmootherResult(means=means, covs=covs, gains=gains, status=status)


def _smoothed_means_blocks(C, A, xs, L):
    """RTS means of a batch with shared gains, in blocks of epochs: x^s_t = A_t x_t + C_t x^s_t+1.

    With x_t+1|t = F_t+1 x_t (the filter's prediction), x^s_t = x_t + C_t (x^s_t+1 - x_t+1|t)
    reads x^s_t = (I - C_t F_t+1) x_t + C_t x^s_t+1, and C_T = 0 gives x^s_T = x_T. Backwards
    over blocks of L epochs starting at t0, every x^s_t0+j is a fixed linear map of the smoothed
    state after the block and the block's filtered means, formed once from the shared A and C;
    one dense product per block gives the whole batch's L epochs.

    Args:
      C: (T, n, n) shared gains (zero at the last epoch).  A: (T, n, n) shared I - C_t F_t+1.
      xs: (B, T, n) filtered means.  L: static block length.
    Returns:
      (B, T, n) smoothed means.
    """
    B, T, n = xs.shape
    L = max(1, min(L, T))
    nb, tail = divmod(T, L)
    X = xs.reshape(B, T * n)

    def maps(Cb, Ab):  # (k, L', n, n) -> (k, n + L' n, L' n): rows [x^s after the block, x block]
        k, Lk = Cb.shape[:2]
        eye = jnp.eye(Lk * n, dtype=Cb.dtype).reshape(Lk, n, Lk * n)

        def step(carry, inp):
            Phi, Psi = carry  # x^s_j+1 = Phi s + Psi x_block
            Cj, Aj, Sj = inp
            Phi, Psi = Cj @ Phi, Cj @ Psi + Aj @ Sj
            return (Phi, Psi), (Phi, Psi)

        init = (jnp.broadcast_to(jnp.eye(n, dtype=Cb.dtype), (k, n, n)), jnp.zeros((k, n, Lk * n), Cb.dtype))
        lead = lambda a: jnp.swapaxes(a, 0, 1)
        _, out = jax.lax.scan(step, init, (lead(Cb), lead(Ab), eye), reverse=True)
        rows = [jnp.transpose(a, (1, 3, 0, 2)).reshape(k, a.shape[-1], Lk * n) for a in out]
        return jnp.concatenate(rows, axis=1)

    def apply(carry, t0, Lk, M):
        s, out = carry  # out holds the filtered means from t0 on back, the smoothed ones after
        Y = jnp.concatenate([s, jax.lax.dynamic_slice_in_dim(out, t0 * n, Lk * n, axis=1)], axis=1) @ M
        return Y[:, :n], jax.lax.dynamic_update_slice_in_dim(out, Y, t0 * n, axis=1)

    # the smoothed means overwrite the filtered ones block by block: under jit, when the filtered
    # means are not used elsewhere, XLA updates their buffer in place instead of writing a fresh one
    carry = (jnp.zeros((B, n), xs.dtype), X)
    if tail:
        carry = apply(carry, nb * L, tail, maps(C[nb * L :][None], A[nb * L :][None])[0])
    if nb:
        Mb = maps(C[: nb * L].reshape(nb, L, n, n), A[: nb * L].reshape(nb, L, n, n))
        carry, _ = jax.lax.scan(lambda c, k: (apply(c, k * L, L, Mb[k]), None), carry, jnp.arange(nb), reverse=True)
    return carry[1].reshape(B, T, n)


def _broadcast_like(tree, like):
    """Every leaf of ``tree`` broadcast to the shape and cast to the dtype of the matching leaf of ``like``."""
    return jax.tree_util.tree_map(lambda a, s: jnp.broadcast_to(jnp.asarray(a, s.dtype), s.shape), tree, like)


#: the outputs a shared-recursion batch returns once (no batch axis)
_SHARED_FIELDS = ("covs", "pred_covs", "innov_covs", "factors", "noise", "valid", "n_skipped", "P_final")


def _minor_applies(in_batched, args, check_finite) -> bool:
    """Whether a batch runs :func:`._minor.classic_filter_minor`: the classic filter (no plug-ins), a
    model of at most :data:`jaxnav._numerics.SMALL` states and components, and a covariance that may
    differ between the sequences (P0, the mask or model leaves per sequence, or data per sequence
    with NaN/inf masking on)."""
    model, x0, P0, zs, inflation, estimator, mask = args
    classic = isinstance(inflation, (type(None), NoInflation)) and isinstance(estimator, (type(None), NoEstimator))
    shared = not any(jax.tree_util.tree_leaves([in_batched[i] for i in (4, 5)]))
    per_cov = in_batched[2] or in_batched[6] or (in_batched[3] and check_finite) or any(model_batched(in_batched[0]))
    n, m = jnp.shape(x0)[-1], jnp.shape(zs)[-1]
    return classic and shared and bool(per_cov) and max(n, m) <= SMALL


def model_batched(flags) -> tuple:
    """Which leaves (F, H, Q, R, G) of a :class:`LinearGaussian` are batched, from ``vmap``'s flags (None: no G)."""
    return tuple(bool(getattr(flags, name)) for name in LinearGaussian._fields)


def minor_args(args, in_batched, like):
    """The arguments of :func:`._minor.classic_filter_minor` from a filter's vmapped ``args``: the
    initial moments, data and masks with the leading batch axis, the model's leaves as given (those
    batched with it: :func:`model_batched`), cast to the dtype of ``like`` (the plain vmapped result)."""
    model, x0, P0, zs, _, _, mask = args
    B, n = like.x_final.shape
    dtype = like.x_final.dtype
    T, m = jnp.shape(zs)[-2:]

    def batch(a, is_batched, shape):
        a = jnp.asarray(a)
        return jnp.broadcast_to(a if is_batched else a[None], (B,) + shape)

    if mask is None:
        masks = jnp.ones((B, T, m), bool)
    else:
        mk = jnp.asarray(mask, bool)
        if mk.ndim == (2 if in_batched[6] else 1):
            mk = mk[..., None]
        masks = batch(mk, in_batched[6], (T, m))
    return (
        LinearGaussian(*[None if a is None else jnp.asarray(a, dtype) for a in model]),
        batch(x0, in_batched[1], (n,)).astype(dtype),
        batch(P0, in_batched[2], (n, n)).astype(dtype),
        batch(zs, in_batched[3], (T, m)).astype(dtype),
        masks,
    )


def per_sequence_minor(kernel, args, in_batched, like_filter, like, *, save, unroll, check_finite, joseph):
    """A ``vmap`` rule's per-sequence branch run batch-minor (:mod:`._minor`).

    Args:
      kernel: :func:`._minor.classic_filter_minor` or :func:`._minor.classic_filter_rts_minor`.
      args, in_batched: the filter's vmapped arguments and their batch flags.
      like_filter: the shape of the plain vmapped filter's result (batch size, dtype).
      like: the shape of the plain vmapped result this branch stands for (what is returned).
      save, unroll, check_finite, joseph: the kernel's static options.
    """
    out = kernel(
        *minor_args(args, in_batched, like_filter),
        save=save,
        check_finite=check_finite,
        joseph=joseph,
        unroll=unroll,
        batched=model_batched(in_batched[0]),
    )
    return _broadcast_like(out, like)


def vmap_filter_rule(plain, in_batched, args, *, save, unroll, allow_float32, check_finite, joseph):
    """The ``vmap`` rule of :func:`~jaxnav.filters.kalman_filter`: one covariance recursion when the batch allows.

    When the model, P0, mask and plug-ins are shared, the plug-ins are data-independent and NaN
    masking is on, the covariances differ between the sequences only through their non-finite
    elements. ``lax.cond`` on the data then picks: no unmasked non-finite element in the whole
    batch -> :func:`kalman_filter_batch`'s shared recursion (its shared outputs broadcast to B
    copies, as a loop returns them); else the plain per-sequence filters. Either way the result
    equals a loop of single runs. Other batches (P0 or the model per sequence, data-dependent
    rules, ``check_finite=False``) run the plain filters under ``vmap``, which leaves the
    covariance outputs unbatched where they do not depend on the batch; those of the classic
    filter with a covariance per sequence and a small model run batch-minor
    (:func:`._minor.classic_filter_minor`).

    Args:
      plain: the per-sequence filter ``(model, x0, P0, zs, inflation, estimator, mask) -> KalmanResult``.
      in_batched: pytree of bools like ``args``.  args: the batched arguments (batch axis first).
      save, unroll, allow_float32, check_finite, joseph: the filter's static options.
    Returns:
      (KalmanResult, its pytree of bools: which leaves have the leading batch axis).
    """
    model, x0, P0, zs, inflation, estimator, mask = args
    axes = jax.tree_util.tree_map(lambda b: 0 if b else None, in_batched)

    def per_sequence():
        return jax.vmap(plain, in_axes=axes)(*args)

    like = jax.eval_shape(per_sequence)
    minor = _minor_applies(in_batched, args, check_finite)
    if minor:
        per_sequence = partial(
            per_sequence_minor,
            classic_filter_minor,
            args,
            in_batched,
            like,
            like,
            save=save,
            unroll=unroll,
            check_finite=check_finite,
            joseph=joseph,
        )
    shared_args = [in_batched[i] for i in (0, 2, 4, 5, 6)]
    if (
        check_finite
        and in_batched[3]
        and data_independent(inflation, estimator)
        and not any(jax.tree_util.tree_leaves(shared_args))
        and jnp.ndim(zs) == 3
    ):

        def shared():
            out = _kalman_filter_batch(
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
                block="auto",
                joseph=joseph,
            )
            return _broadcast_like(out, like)

        used = True if mask is None else jnp.asarray(mask, bool)
        if jnp.ndim(used) == 1:
            used = used[:, None]
        clean = jnp.all(jnp.isfinite(zs) | ~jnp.asarray(used, bool))
        out = jax.lax.cond(clean, shared, per_sequence)
        return out, jax.tree_util.tree_map(lambda _: True, out)
    if minor:
        out = per_sequence()
        return out, jax.tree_util.tree_map(lambda _: True, out)
    return vmap_sharing(plain, axes, args, _SHARED_FIELDS)
