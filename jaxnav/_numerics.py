"""Safe small linear algebra shared by the filters: symmetrisation, Cholesky solves, masked
measurements, the Gaussian log-likelihood, kinks, and the package's one float64 guard."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
from jax.custom_batching import custom_vmap
from jax.custom_derivatives import SymbolicZero
from jax.scipy.linalg import solve_triangular

#: log(2 pi), the constant of the Gaussian log-density
LOG_2PI = math.log(2.0 * math.pi)


def check_float64(*arrays, what: str = "absolute coordinates", allow_float32: bool = False) -> None:
    """The package's float64 guard: raise ValueError if a floating array is narrower than float64.

    float32 spacing is ~0.5 m at ECEF magnitude and ~4 m for a Gauss-Krueger y with its zone
    prefix, so navigation states and absolute coordinates must be float64 (DESIGN.md).

    Args:
      arrays: arrays, dtypes or anything ``jnp.result_type`` accepts.
      what: what the arrays are, for the message.
      allow_float32: the caller's opt-in to a float32 path (then nothing is checked).
    Raises:
      ValueError: naming ``what``, the dtype and the fix (``jaxnav.enable_x64()``).
    """
    if allow_float32:
        return
    for a in arrays:
        dt = jnp.result_type(a)
        if jnp.issubdtype(dt, jnp.floating) and jnp.finfo(dt).bits < 64:
            raise ValueError(
                f"{what} given as {jnp.dtype(dt).name}: float32 spacing is ~0.5 m at Earth radius and "
                "loses mm-level variances; call jaxnav.enable_x64() before creating arrays"
                + ("" if what.startswith("absolute") else ", or pass allow_float32=True to opt in to float32")
            )


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


def cholesky_elements(a, n: int, *, reciprocal: bool = True) -> list:
    """Lower Cholesky factor of an n x n matrix, element by element (the unrolled algorithm of every small factor).

    Args:
      a: ``a(i, j)`` -> element (i, j) of the matrix: an array over whatever batch the caller lays
        out (trailing matrix axes here, leading ones in :mod:`jaxnav.filters._minor`).  n: static size.
      reciprocal: static; divide each column by its diagonal element as one reciprocal and
        multiplications (below), or element by element. In the batch-minor layout every division is
        already one vector operation and the extra reciprocal cost 2-9 % (case (d) of
        benchmarks/bench_filters.py, 485-488 against 501-532 ms in side runs), so it passes False.
    Returns:
      rows of elements, ``L[i][j]`` for j <= i (NaN where the matrix is not positive definite, as
      LAPACK's potrf reports).
    """
    L = [[None] * n for _ in range(n)]
    for j in range(n):
        s = a(j, j)
        for k in range(j):
            s = s - L[j][k] * L[j][k]
        d = jnp.sqrt(s)
        L[j][j] = d
        # one division per column, then multiplications: XLA re-evaluates cheap multiply-adds inside
        # its fused kernels but keeps a division with several consumers as a kernel of its own (a 5 x 5
        # factor divided element by element is 15 kernels; the UKF's epoch, with two, runs 36 in all)
        r = 1.0 / d if reciprocal else None
        for i in range(j + 1, n):
            s = a(i, j)
            for k in range(j):
                s = s - L[i][k] * L[j][k]
            L[i][j] = s * r if reciprocal else s / d
    return L


def solve_lower_rows(l, y, n: int) -> list:
    """Rows of L^-1 Y by forward substitution: ``l(i, k)`` the elements of the lower factor, broadcast
    against ``y(i)``, the rows of Y (see :func:`cholesky_elements` for the layouts)."""
    x = []
    for i in range(n):
        s = y(i)
        for k in range(i):
            s = s - l(i, k) * x[k]
        x.append(s / l(i, i))
    return x


def solve_upper_t_rows(l, y, n: int) -> list:
    """Rows of L^-T Y by back substitution, with ``l`` and ``y`` as in :func:`solve_lower_rows`."""
    x = [None] * n
    for i in reversed(range(n)):
        s = y(i)
        for k in range(i + 1, n):
            s = s - l(k, i) * x[k]
        x[i] = s / l(i, i)
    return x


def _cholesky_unrolled(A):
    n = A.shape[-1]
    L = cholesky_elements(lambda i, j: A[..., i, j], n)
    zero = jnp.zeros_like(A[..., 0, 0])
    rows = [jnp.stack([L[i][j] if j <= i else zero for j in range(n)], axis=-1) for i in range(n)]
    return jnp.stack(rows, axis=-2)


def _solve_lower_unrolled(L, B):
    rows = solve_lower_rows(lambda i, k: L[..., i, k, None], lambda i: B[..., i, :], L.shape[-1])
    return jnp.stack(rows, axis=-2)


def _solve_upper_t_unrolled(L, Y):
    rows = solve_upper_t_rows(lambda i, k: L[..., i, k, None], lambda i: Y[..., i, :], L.shape[-1])
    return jnp.stack(rows, axis=-2)


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


def solve_lower_t(L, B):
    """Solve L^T X = B given the lower factor L (one triangular solve); B is (m,) or (m, k)."""
    if L.shape[-1] <= SMALL:
        Bm, vec = _as_matrix(B)
        X = _solve_upper_t_unrolled(L, Bm)
        return X[..., 0] if vec else X
    return solve_triangular(L, B, lower=True, trans=1)


def whiten(L, v):
    """L^{-1} v, so that |L^{-1} v|^2 = v^T (L L^T)^{-1} v."""
    if L.shape[-1] <= SMALL:
        Bm, vec = _as_matrix(v)
        X = _solve_lower_unrolled(L, Bm)
        return X[..., 0] if vec else X
    return solve_triangular(L, v, lower=True)


def masked_measurement(H, R, valid):
    """Measurement matrices with invalid components removed exactly (S0 eqs. (5), (7)).

    The rows of H of invalid components are zeroed and R is replaced on their rows and columns by
    the identity, so H P H^T + R stays positive definite, the gain has zero columns for them and
    they add nothing to the log-likelihood but log 1 = 0.

    Args:
      H: (..., m, n).  R: (..., m, m).  valid: (..., m) bool.
    Returns:
      (Hm (..., m, n), Rm (..., m, m)).
    """
    Hm = jnp.where(valid[..., :, None], H, 0.0)
    both = valid[..., :, None] & valid[..., None, :]
    eye = jnp.eye(valid.shape[-1], dtype=jnp.result_type(R))
    Rm = jnp.where(both, R, 0.0) + jnp.where(valid, 0.0, 1.0)[..., :, None] * eye
    return Hm, Rm


def safe_cholesky(S):
    """Lower Cholesky factor of S with a flag: (L, ok), L the identity where S is not positive definite.

    The identity keeps every later solve finite (and their gradients, double-where style); callers
    use ``ok`` to discard what was computed with it.

    Args:
      S: (..., m, m) symmetric.
    Returns:
      (L (..., m, m), ok (...) bool).
    """
    L = cholesky(S)
    ok = jnp.all(jnp.isfinite(L), axis=(-2, -1))
    return jnp.where(ok[..., None, None], L, jnp.eye(S.shape[-1], dtype=S.dtype)), ok


def gaussian_loglik(w, L, n_valid):
    """log N(v; 0, S) from the whitened v, w = L^-1 v, and S = L L^T (S0 eq. (17) innovations).

    -(|w|^2 + 2 sum_i log L_ii + n_valid log 2 pi) / 2; components removed by
    :func:`masked_measurement` have w_i = 0 and L_ii = 1, so they contribute nothing.

    Args:
      w: (..., m) whitened innovation.  L: (..., m, m) lower factor.  n_valid: (...) count of valid components.
    Returns:
      (...) log-density.
    """
    logdet = 2.0 * jnp.sum(jnp.log(jnp.diagonal(L, axis1=-2, axis2=-1)), axis=-1)
    return -0.5 * (jnp.sum(w * w, axis=-1) + logdet + n_valid * LOG_2PI)


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


def _fused_mm(A, B):
    """A B as one broadcast multiply and a sum over k (a 1-D B: over the last axis), which XLA fuses
    with its neighbours; its transpose (reverse mode) is a broadcast and a multiply."""
    if B.ndim == 1:
        return jnp.sum(A * B, axis=-1)
    return jnp.sum(A[..., :, :, None] * B[..., None, :, :], axis=-2)


def _loop_sum(x, axis: int):
    """Sum of ``x`` over ``axis``, as a reduction XLA:CPU compiles into its own fused loops.

    XLA:CPU (jax 0.10) hands add-reductions with 4096 or more elements to YNNPACK, whose per-call
    cost is several times the arithmetic of the (B, n, k, n) products of small matrices under
    ``vmap``. Its matcher takes only a reducer that is exactly ``add(a, b)``; this one is
    ``a - (-b)``, equal to ``a + b`` in IEEE arithmetic (negation is exact), so the product stays in
    XLA's loop fusions. JAX differentiates the generic reduction in both modes (gradients equal
    ``jnp.sum``'s), at more cost: used for values computed under ``vmap`` whose derivatives are
    defined elsewhere (:func:`_mm`'s rule, the log-likelihood's gradient pass).
    """
    zero = jnp.zeros((), x.dtype)
    return jax.lax.reduce(x, zero, lambda a, b: a - (-b), (axis % x.ndim,))


def _batched_mm(A, B):
    """One sequence's A B as :func:`_fused_mm`, summed by :func:`_loop_sum`: the kernel ``vmap`` runs."""
    if B.ndim == 1:
        return _loop_sum(A * B, -1)
    return _loop_sum(A[..., :, :, None] * B[..., None, :, :], -2)


def mm(A, B):
    """Matrix product over the last two axes (leading axes broadcast), fast for small sizes.

    For inner dimensions up to :data:`SMALL` one sequence's product is written out elementwise
    (:func:`_fused_mm`), which XLA fuses with its neighbours; on CPU each ``dot`` of tiny matrices
    is a separate kernel costing ~0.5 us, several times the arithmetic (the 6-state filter,
    T = 3600, runs about twice as fast as with ``dot``; benchmarks/bench_filters.py case (a)).
    Under ``jax.vmap`` with their own matrices per sequence the product runs the same elementwise
    form summed by :func:`_loop_sum` (``jax.custom_batching.custom_vmap``: the same product,
    another reduction; whatever the nesting of ``jit``, ``vmap`` and ``grad``): a plain sum of
    B x 216 or more products goes to YNNPACK on XLA:CPU, and a batched ``dot`` of tiny matrices
    is slower still (6-state filter with a covariance per sequence, T = 3600: B = 32 153 -> 87 ms,
    B = 256 1.11 -> 0.70 s; benchmarks/bench_filters.py case (d)). Derivatives (``custom_jvp``)
    are dA B + A dB in the elementwise form. A 1-D ``B`` is a vector: ``mm(A, v) = A v``.
    """
    if A.shape[-1] > SMALL:
        return A @ B
    return _mm(A, B)


@jax.custom_jvp
def _mm(A, B):
    return _mm_batchable(A, B)


def _mm_jvp(primals, tangents):
    # symbolic zeros: a constant factor (F, H of a fixed model) costs no tangent product
    (A, B), (dA, dB) = primals, tangents
    parts = [_fused_mm(dA, B)] if not isinstance(dA, SymbolicZero) else []
    parts += [_fused_mm(A, dB)] if not isinstance(dB, SymbolicZero) else []
    out = _mm_batchable(A, B)
    return out, (sum(parts[1:], parts[0]) if parts else jnp.zeros_like(out))


_mm.defjvp(_mm_jvp, symbolic_zeros=True)


@custom_vmap
def _mm_batchable(A, B):
    return _fused_mm(A, B)


@_mm_batchable.def_vmap
def _mm_batched(axis_size, in_batched, A, B):
    if not any(in_batched):  # nested transforms (jacfwd of vmap) may call the rule with nothing batched
        return _fused_mm(A, B), False
    return jax.vmap(_batched_mm, in_axes=tuple(0 if b else None for b in in_batched))(A, B), True


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
