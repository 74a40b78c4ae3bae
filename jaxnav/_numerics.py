"""Safe small linear algebra shared by the filters: symmetrisation, Cholesky solves, kinks."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax.scipy.linalg import solve_triangular


def as_leaf(x):
    """A tunable number as a strongly typed float array leaf (default float dtype).

    Python floats would be weakly typed and ``np.float64`` strongly typed; normalising both
    keeps one jit cache entry for every value a user sweeps.
    """
    return jnp.asarray(x, dtype=jnp.result_type(float))


def symmetrize(P):
    """(P + P^T) / 2 over the last two axes."""
    return 0.5 * (P + jnp.swapaxes(P, -1, -2))


#: matrices up to this size are factored and solved by unrolled elementwise code, which runs
#: at vector speed under ``vmap`` (batched LAPACK calls on CPU cost ~0.1 us per tiny matrix).
SMALL = 8


def _cholesky_unrolled(A):
    n = A.shape[-1]
    L = [[None] * n for _ in range(n)]
    for j in range(n):
        s = A[..., j, j]
        for k in range(j):
            s = s - L[j][k] * L[j][k]
        d = jnp.sqrt(s)  # NaN when A is not positive definite, as LAPACK's potrf reports
        L[j][j] = d
        for i in range(j + 1, n):
            s = A[..., i, j]
            for k in range(j):
                s = s - L[i][k] * L[j][k]
            L[i][j] = s / d
    zero = jnp.zeros_like(A[..., 0, 0])
    rows = [jnp.stack([L[i][j] if j <= i else zero for j in range(n)], axis=-1) for i in range(n)]
    return jnp.stack(rows, axis=-2)


def _solve_lower_unrolled(L, B):
    n = L.shape[-1]
    y = []
    for i in range(n):
        s = B[..., i, :]
        for k in range(i):
            s = s - L[..., i, k, None] * y[k]
        y.append(s / L[..., i, i, None])
    return jnp.stack(y, axis=-2)


def _solve_upper_t_unrolled(L, Y):
    n = L.shape[-1]
    x = [None] * n
    for i in reversed(range(n)):
        s = Y[..., i, :]
        for k in range(i + 1, n):
            s = s - L[..., k, i, None] * x[k]
        x[i] = s / L[..., i, i, None]
    return jnp.stack(x, axis=-2)


def cholesky(A):
    """Lower Cholesky factor of a symmetric positive-definite matrix (NaN if it is not)."""
    if A.shape[-1] <= SMALL:
        return _cholesky_unrolled(A)
    return jnp.linalg.cholesky(A)


def _as_matrix(B):
    return (B[..., None], True) if B.ndim == 1 else (B, False)


def cho_solve(L, B):
    """Solve (L L^T) X = B given the lower factor L; B is (m,) or (m, k)."""
    if L.shape[-1] <= SMALL:
        Bm, vec = _as_matrix(B)
        X = _solve_upper_t_unrolled(L, _solve_lower_unrolled(L, Bm))
        return X[..., 0] if vec else X
    y = solve_triangular(L, B, lower=True)
    return solve_triangular(L, y, lower=True, trans=1)


def whiten(L, v):
    """L^{-1} v, so that |L^{-1} v|^2 = v^T (L L^T)^{-1} v."""
    if L.shape[-1] <= SMALL:
        Bm, vec = _as_matrix(v)
        X = _solve_lower_unrolled(L, Bm)
        return X[..., 0] if vec else X
    return solve_triangular(L, v, lower=True)


def all_finite(*arrays):
    """Scalar bool: every element of every array is finite."""
    ok = jnp.array(True)
    for a in arrays:
        ok = ok & jnp.all(jnp.isfinite(a))
    return ok


def smooth_max1(x, tau):
    """Smooth surrogate of max(1, x): 1 + tau * softplus((x - 1) / tau).

    Tends to max(1, x) as tau -> 0 and has a continuous gradient everywhere (S0 eq. (14) kink).
    """
    return 1.0 + tau * jax.nn.softplus((x - 1.0) / tau)


def mm(A, B):
    """Matrix product over the last two axes (leading axes broadcast), fusable for small sizes.

    For inner dimensions up to :data:`SMALL` the product is written as an elementwise
    multiply and a sum, which XLA fuses with its neighbours; on CPU each ``dot`` of tiny
    matrices is a separate kernel costing ~0.5 us, several times the arithmetic, so this
    halves a single-sequence filter step (6x6: 12 -> 6 ms for T = 3600, measured in
    ``benchmarks/bench_filters.py``). Under ``vmap`` with one matrix per sequence it is
    about as fast as the batched ``dot``; for wide batched operands prefer ``jnp.matmul``
    (the parallel filter does). A 1-D ``B`` is a vector: ``mm(A, v) = A v``.
    """
    if B.ndim == 1:
        if A.shape[-1] <= SMALL:
            return jnp.sum(A * B, axis=-1)
        return A @ B
    if A.shape[-1] <= SMALL:
        return jnp.sum(A[..., :, :, None] * B[..., None, :, :], axis=-2)
    return A @ B


def mT(A):
    """Swap the last two axes."""
    return jnp.swapaxes(A, -1, -2)


def solve_small(A, B):
    """Solve A X = B for a general (non-symmetric) small A by Gauss-Jordan with partial pivoting.

    Elementwise operations in a ``lax.fori_loop`` over the n columns (no LAPACK call), for
    matrices up to a few dozen rows with leading batch axes. Used in the associative-scan
    combine of the parallel filter, where ``jnp.linalg.solve`` (LU through LAPACK) hung
    intermittently on this machine (see DESIGN.md, pitfalls); the loop keeps the compiled
    program small where the combine is inlined many times. A singular A gives inf/NaN.

    Args:
      A: (..., n, n).  B: (..., n, k) or (..., n).
    Returns:
      X with the shape of B.
    """
    vec = B.ndim == A.ndim - 1
    if vec:
        B = B[..., None]
    n = A.shape[-1]
    rows = jnp.arange(n)
    batch = jnp.broadcast_shapes(A.shape[:-2], B.shape[:-2])
    A = jnp.broadcast_to(A, batch + A.shape[-2:])
    B = jnp.broadcast_to(B, batch + B.shape[-2:])

    def row(M, i):
        return jax.lax.dynamic_index_in_dim(M, i, axis=M.ndim - 2, keepdims=False)

    def col(M, j):
        return jax.lax.dynamic_index_in_dim(M, j, axis=M.ndim - 1, keepdims=False)

    def body(j, AB):
        A, B = AB
        c = jnp.where(rows >= j, jnp.abs(col(A, j)), -1.0)
        p = jnp.argmax(c, axis=-1)
        onehot = (rows == p[..., None]).astype(A.dtype)
        d = ((rows == j).astype(A.dtype) - onehot)[..., :, None]
        rowA_p = jnp.sum(onehot[..., :, None] * A, axis=-2)
        rowB_p = jnp.sum(onehot[..., :, None] * B, axis=-2)
        A = A + d * (rowA_p - row(A, j))[..., None, :]  # swap rows j and p
        B = B + d * (rowB_p - row(B, j))[..., None, :]
        rj = row(A, j)
        f = col(A, j) / col(rj, j)[..., None]
        f = jnp.where(rows == j, 0.0, f)[..., :, None]
        return A - f * rj[..., None, :], B - f * row(B, j)[..., None, :]

    A, B = jax.lax.fori_loop(0, n, body, (A, B))
    X = B / jnp.diagonal(A, axis1=-2, axis2=-1)[..., :, None]
    return X[..., 0] if vec else X
