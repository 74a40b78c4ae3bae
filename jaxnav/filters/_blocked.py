"""The batched filter when the batch shares its covariance recursion: blocks of epochs as dense products.

Under ``vmap`` with the model, P0, the mask and a data-independent rule shared by the batch (see
:func:`jaxnav.filters._kalman._batched_filter`), every sequence has the same gains K_t, and its
moments follow a linear recursion (S0 eqs. (4)-(7)):

    x_t|t-1 = F_t x_t-1,   v_t = z_t - H_t x_t|t-1,   x_t = x_t|t-1 + K_t v_t,   w_t = L_t^-1 v_t,

with S_t = L_t L_t^T (w_t gives the NIS |w_t|^2 and the log-likelihood). Over a block of L
epochs each of these is a fixed linear map of the state s before the block and the block's
measurements, so for the whole batch one dense product

    Y = s M_s + z_block M_z,     (B, n) x (n, R)  +  (B, L m) x (L m, R),

gives every requested output of the L epochs, and each is written once, in place, into the
(B, T, ...) result. The per-sequence scan that ``vmap`` would make instead steps B small
vectors through T tiny kernels and writes its stacked outputs time-major, then transposes them
to the batch-major layout ``vmap`` returns; those writes bound it (benchmarks/RESULTS.md,
case (c)).

The covariance recursion, gains and everything shared (covariances, factors, counts, flags)
come from one run of :func:`jaxnav.filters._kalman._filter_step` on zero data with the shared
mask, so the rules, masks, time-varying models and status flags are the sequential filter's
own. Results equal the per-sequence filter to rounding (products of up to L transition
matrices are formed once per block).
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp

from jaxnav import _status
from jaxnav._numerics import cholesky, whiten
from jaxnav.filters._kalman import KalmanResult, _filter_step, _fused_products, scan_setup

#: epochs per block: the products' width grows with L and their count falls with it; 8 was the
#: fastest of 4, 6, 8, 12, 16, 24 and 40 for the 6-state model at B = 256, T = 3600 (case (c) of
#: benchmarks/bench_filters.py, timed in this module's development)
BLOCK = 8

#: per-epoch outputs that differ between the sequences; the rest are shared and broadcast
_PER_SEQUENCE = ("means", "pred_means", "innovations", "nis", "logliks")


def _groups(save, n, m, block):
    """The column groups of the block maps for ``save`` and their total width R (static)."""
    want = tuple(g for g in ("means", "pred_means", "innovations") if g in save)
    groups = want + ("w",) + (() if "means" in save else ("end",))
    width = dict(means=n, pred_means=n, innovations=m, w=m, end=n)
    return groups, width, sum(width[g] * (1 if g == "end" else block) for g in groups)


#: smallest batch size x epochs for which the blocks are used. Below it the per-sequence scan
#: costs a few ms at most, and the blocks' extra program (maps, block loop, and their
#: derivatives) would double the compile time (measured 2.0 -> 5.2 s for grad(vmap) at B = 4,
#: T = 120) for nothing. At B = 8, T = 3600 (28 800) the blocks already run 12.3 vs 15.8 ms.
MIN_BATCH_EPOCHS = 2**14


def worth_blocking(B, T, n, m, save, itemsize=8, block=BLOCK, floor_bytes=256 * 2**20) -> bool:
    """Whether to run a shared-recursion batch in blocks: the batch is large enough
    (B T >= :data:`MIN_BATCH_EPOCHS`) and the block maps (T / L blocks of (n + L m) x R, a few
    copies while built) stay small next to what the batch writes anyway: below ``floor_bytes``
    or below the batch's per-epoch outputs. A long series with few sequences (e.g. B = 2,
    T = 86 400: ~0.5 GB of maps for 11 MB of means) keeps the per-sequence scan."""
    if B * T < MIN_BATCH_EPOCHS:
        return False
    L = max(1, min(block, T))
    _, width, R = _groups(save, n, m, L)
    maps = 3 * -(-T // L) * (n + L * m) * R * itemsize
    out = B * T * (2 + sum(width[g] for g in ("means", "pred_means", "innovations") if g in save)) * itemsize
    return maps <= max(floor_bytes, out)


def _block_maps(F, Hm, K, Linv, valid, groups):
    """The linear maps from (state before the block, block measurements) to each output group.

    Args (leading axes (nb, L): nb blocks of L epochs):
      F: (nb, L, n, n) transitions.  Hm: (nb, L, m, n) measurement matrices with masked rows zeroed.
      K: (nb, L, n, m) gains (zero columns where masked, zero where S failed).
      Linv: (nb, L, m, m) inverse Cholesky factors of S.  valid: (nb, L, m) 0/1 float.
      groups: static names in column order, from "means", "pred_means", "innovations", "w", "end".
    Returns:
      Ms (nb, n, R), Mz (nb, L m, R): group g of an epoch j occupies r_g columns at the group's
      offset + j r_g ("end", the state after the block, n columns).
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
        maps = dict(means=(xPhi, xPsi), pred_means=(pPhi, pPsi), innovations=(vPhi, vPsi),
                    w=(Lj @ vPhi, Lj @ vPsi))
        return (xPhi, xPsi), tuple(maps[g] for g in groups if g != "end")

    lead = lambda a: jnp.swapaxes(a, 0, 1)  # noqa: E731  (L, nb, ...) for the scan
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
    return jnp.concatenate(Ms, axis=-1), jnp.concatenate(Mz, axis=-1)


def _shared_pass(params, init, xs, unroll):
    """The covariance recursion once, on zero data with the shared mask: per-epoch shared outputs and gains."""
    zero = init._replace(x=jnp.zeros_like(init.x))

    def body(state, inp):
        new, allv, K = _filter_step(state, inp._replace(z=jnp.zeros_like(inp.z)), params, False)
        return new, (allv, K)

    with _fused_products(True):
        return jax.lax.scan(body, zero, xs, unroll=unroll)


@partial(jax.jit, static_argnames=("save", "unroll", "allow_float32", "block"))
def blocked_batch_filter(model, x0s, P0, zs, mask, inflation, estimator, *, save, unroll, allow_float32,
                         block=BLOCK) -> KalmanResult:
    """The Kalman filter for a batch sharing model, P0, mask and a data-independent rule, by blocks.

    Equal to ``jax.vmap`` of :func:`~jaxnav.filters.kalman_filter` with ``check_finite=False``
    for measurements that are finite wherever the mask is True: what the batch switch passes,
    once it has masked the batch's common non-finite elements. Masked elements are ignored
    whatever their value; an unmasked NaN/inf would be read as 0 (not propagated), so callers
    must mask them first.

    Args:
      model: shared :class:`LinearGaussian` (static or (T, ...) leaves).
      x0s: (B, n) initial means.  P0: (n, n) shared initial covariance.
      zs: (B, T, m) measurements.  mask: None, (T,) or (T, m) shared bool mask.
      inflation, estimator: shared data-independent plug-ins (or None).
      save, unroll, allow_float32: as in :func:`~jaxnav.filters.kalman_filter` (static).
      block: static epochs per block.
    Returns:
      :class:`KalmanResult` with a leading batch axis B on every field.
    """
    Bn = zs.shape[0]
    model, params, init, xs, save, (n, m, _, T), tv, dtype = scan_setup(
        model, x0s[0], P0, zs[0], inflation, estimator, mask, save, allow_float32)
    final, (allv, K) = _shared_pass(params, init, xs, unroll)

    valid = xs.mask  # (T, m); masked elements are ignored whatever their value
    observed = jnp.any(valid, axis=-1)
    L = cholesky(allv["innov_covs"])
    ok = jnp.all(jnp.isfinite(L), axis=(-2, -1))
    eye_m = jnp.eye(m, dtype=dtype)
    Lsafe = jnp.where(ok[:, None, None], L, eye_m)
    Linv = whiten(Lsafe, jnp.broadcast_to(eye_m, (T, m, m)))
    F = model.F if tv["F"] else jnp.broadcast_to(model.F, (T, n, n))
    H = model.H if tv["H"] else jnp.broadcast_to(model.H, (T, m, n))
    Hm = jnp.where(valid[:, :, None], H, 0.0)
    vf = valid.astype(dtype)
    c_ll = allv["logliks"]  # -(log det S + m log 2 pi) / 2 where observed and S factored, else 0
    okf, obsf = (observed & ok).astype(dtype), observed.astype(dtype)

    Lb = max(1, min(block, T))
    groups, width, _ = _groups(save, n, m, Lb)
    want = [g for g in groups if g in save]
    nb, tail = divmod(T, Lb)

    zs = jnp.asarray(zs, dtype)
    Z = zs.reshape(Bn, T * m)
    vflat = vf.reshape(T * m)
    bufs0 = {g: jnp.zeros((Bn, T * width[g]), dtype) for g in want}
    for g in ("nis", "logliks"):
        if g in save:
            bufs0[g] = jnp.zeros((Bn, T), dtype)

    def apply(carry, t0, Lk, Msz):
        s, bufs, ll, fin = carry
        # masked elements may hold NaN/inf: zero them. Multiply-then-clean is a plain vector
        # operation here; a select on the mask costs ~10 us per block (measured)
        zb = jax.lax.dynamic_slice_in_dim(Z, t0 * m, Lk * m, axis=1)
        zb = jnp.nan_to_num(zb * jax.lax.dynamic_slice_in_dim(vflat, t0 * m, Lk * m), nan=0.0, posinf=0.0,
                            neginf=0.0)
        Y = jnp.concatenate([s, zb], axis=1) @ Msz
        cols, off = {}, 0
        for g in groups:
            w = width[g] * (1 if g == "end" else Lk)
            cols[g] = Y[:, off:off + w]
            off += w
        wv = cols["w"].reshape(Bn, Lk, m)
        nis = jnp.sum(wv * wv, axis=-1)
        sl = lambda a: jax.lax.dynamic_slice_in_dim(a, t0, Lk)  # noqa: E731
        lls = sl(okf) * (sl(c_ll) - 0.5 * nis)
        vals = dict(cols, nis=sl(obsf) * nis, logliks=lls)
        bufs = {g: jax.lax.dynamic_update_slice_in_dim(b, vals[g], t0 * (b.shape[1] // T), axis=1)
                for g, b in bufs.items()}
        state = cols["means"] if "means" in cols else cols["end"]
        fin = fin & jnp.all(jnp.isfinite(state), axis=1)
        return state[:, -n:], bufs, ll + jnp.sum(lls, axis=1), fin

    carry = (jnp.broadcast_to(jnp.asarray(x0s, dtype), (Bn, n)), bufs0, jnp.zeros((Bn,), dtype),
             jnp.ones((Bn,), bool))
    per_epoch = (F, Hm, K, Linv, vf)
    if nb:
        blk = [a[:nb * Lb].reshape((nb, Lb) + a.shape[1:]) for a in per_epoch]
        Msz = jnp.concatenate(_block_maps(*blk, groups), axis=1)

        def body(c, k):
            return apply(c, k * Lb, Lb, Msz[k]), None

        carry, _ = jax.lax.scan(body, carry, jnp.arange(nb))
    if tail:
        blk = [a[nb * Lb:][None] for a in per_epoch]
        carry = apply(carry, nb * Lb, tail, jnp.concatenate(_block_maps(*blk, groups), axis=1)[0])
    x_final, bufs, ll, fin = carry

    shape = {g: (Bn, T, width[g]) for g in ("means", "pred_means", "innovations")}
    out = {}
    for g in save:
        if g in _PER_SEQUENCE:
            out[g] = bufs[g].reshape(shape.get(g, (Bn, T)))
        else:
            out[g] = jax.tree_util.tree_map(lambda a: jnp.broadcast_to(a, (Bn,) + a.shape), allv[g])
    batch = lambda a: jnp.broadcast_to(a, (Bn,) + jnp.shape(a))  # noqa: E731
    status = final.status | jnp.where(fin, 0, _status.NONFINITE_STATE).astype(jnp.int32)
    return KalmanResult(**out, loglik=ll, n_nonfinite=batch(final.n_nonfinite),
                        n_skipped=batch(final.n_skipped), status=status, x_final=x_final,
                        P_final=batch(final.P))
