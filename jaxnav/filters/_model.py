"""The linear Gaussian state-space model (S0 eqs. (1)-(3); S1 eqs. (3)-(6)) and its checks."""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np


class LinearGaussian(NamedTuple):
    """Linear Gaussian model X_k = F X_{k-1} + G W_{k-1},  Z_k = H X_k + V_k  (S0 eqs. (1)-(3)).

    Each leaf is static, shaped as below, or time-varying with a leading axis T (one per
    measurement epoch). A time-varying ``F[t]`` is the transition *into* epoch t + 1, i.e. it maps
    the estimate saved at output index t - 1 (or x0 for t = 0) to the prediction at index t, the
    same convention as filterpy's ``predict(F=Fs[t])`` followed by ``update(zs[t])``.

    Attributes:
      F: (n, n) or (T, n, n) state transition Phi_{k,k-1}.
      H: (m, n) or (T, m, n) measurement matrix.
      Q: (p, p) or (T, p, p) process-noise covariance of W (p = n when G is None).
      R: (m, m) or (T, m, m) measurement-noise covariance.
      G: None, (n, p) or (T, n, p) noise input matrix Gamma; process noise is G Q G^T when given,
        else Q itself.
    """

    F: jnp.ndarray
    H: jnp.ndarray
    Q: jnp.ndarray
    R: jnp.ndarray
    G: jnp.ndarray | None = None


def _leaf_shape(name, a, base, T):
    """Return whether leaf ``a`` is time-varying; raise ValueError naming shapes otherwise."""
    shape = tuple(jnp.shape(a))
    if shape == tuple(base):
        return False
    if len(shape) == len(base) + 1 and shape[1:] == tuple(base) and shape[0] == T:
        return True
    raise ValueError(
        f"model.{name} has shape {shape}; expected {tuple(base)} (static) or "
        f"{(T,) + tuple(base)} (time-varying over T={T} epochs)"
    )


def check_shapes(model: LinearGaussian, x0, P0, zs, mask=None):
    """Check shapes at trace time and return (n, m, p, T, time_varying dict).

    Raises:
      ValueError: naming the offending argument, its shape and the expected shape.
    """
    if not isinstance(model, LinearGaussian):
        raise ValueError(f"model must be a jaxnav.filters.LinearGaussian, got {type(model).__name__}")
    xs = jnp.shape(x0)
    if len(xs) != 1:
        raise ValueError(f"x0 has shape {xs}; expected (n,)")
    n = xs[0]
    if tuple(jnp.shape(P0)) != (n, n):
        raise ValueError(f"P0 has shape {tuple(jnp.shape(P0))}; expected {(n, n)} to match x0 {xs}")
    zsh = tuple(jnp.shape(zs))
    if len(zsh) != 2:
        raise ValueError(f"zs has shape {zsh}; expected (T, m)")
    T, m = zsh
    tv = {}
    tv["F"] = _leaf_shape("F", model.F, (n, n), T)
    tv["H"] = _leaf_shape("H", model.H, (m, n), T)
    tv["R"] = _leaf_shape("R", model.R, (m, m), T)
    if model.G is None:
        p = n
        tv["G"] = False
    else:
        gs = tuple(jnp.shape(model.G))
        if len(gs) not in (2, 3) or gs[-2] != n:
            raise ValueError(f"model.G has shape {gs}; expected ({n}, p) or ({T}, {n}, p)")
        p = gs[-1]
        tv["G"] = _leaf_shape("G", model.G, (n, p), T)
    tv["Q"] = _leaf_shape("Q", model.Q, (p, p), T)
    if mask is not None:
        ms = tuple(jnp.shape(mask))
        if ms not in ((T,), (T, m)):
            raise ValueError(f"mask has shape {ms}; expected {(T,)} or {(T, m)} to match zs {zsh}")
    return n, m, p, T, tv


def validate_model(model: LinearGaussian, P0=None, *, rtol: float = 1e-9, atol: float = 0.0):
    """Host-side check that Q, R and P0 are symmetric and positive semi-definite (R definite).

    Call it on concrete arrays before a run (it cannot look inside ``jit``/``vmap``).

    Args:
      model: the model; time-varying Q or R are checked at every epoch.
      P0: optional (n, n) initial covariance.
      rtol, atol: tolerance of the symmetry and eigenvalue tests, relative to the matrix norm.

    Raises:
      ValueError: naming the matrix (and epoch) that is non-symmetric or indefinite.
    """
    checks = [("Q", model.Q, False), ("R", model.R, True)]
    if P0 is not None:
        checks.append(("P0", P0, False))
    for name, A, definite in checks:
        A = np.asarray(A, dtype=np.float64)
        if A.ndim < 2 or A.shape[-1] != A.shape[-2]:
            raise ValueError(f"{name} has shape {A.shape}; expected square matrices")
        mats = A.reshape((-1,) + A.shape[-2:])
        for t, M in enumerate(mats):
            where = f"{name}" if A.ndim == 2 else f"{name}[{t}]"
            if not np.all(np.isfinite(M)):
                raise ValueError(f"{where} contains NaN or inf")
            scale = max(np.max(np.abs(M)), np.finfo(float).tiny)
            asym = np.max(np.abs(M - M.T))
            if asym > rtol * scale + atol:
                raise ValueError(f"{where} is not symmetric (max |A - A^T| = {asym:.3g})")
            w = np.linalg.eigvalsh(0.5 * (M + M.T))
            tol = rtol * scale * M.shape[0] + atol
            if definite and w.min() <= 0.0:
                raise ValueError(f"{where} is not positive definite (smallest eigenvalue {w.min():.3g})")
            if w.min() < -tol:
                raise ValueError(f"{where} is indefinite (smallest eigenvalue {w.min():.3g})")
