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


def cholesky(A):
    """Lower Cholesky factor of a symmetric positive-definite matrix (NaN if it is not)."""
    return jnp.linalg.cholesky(A)


def cho_solve(L, B):
    """Solve (L L^T) X = B given the lower factor L; B is (m,) or (m, k)."""
    y = solve_triangular(L, B, lower=True)
    return solve_triangular(L, y, lower=True, trans=1)


def whiten(L, v):
    """L^{-1} v, so that |L^{-1} v|^2 = v^T (L L^T)^{-1} v."""
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
