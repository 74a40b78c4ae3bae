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
