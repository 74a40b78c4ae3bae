"""Tuning losses that work with every filter variant of jaxnav.

* :func:`rms`: error RMS against a known truth (simulation studies; S0's Table 1 criterion);
* :func:`innovation_nll`: negative innovation log-likelihood (real data, no truth needed);
* :func:`nis_consistency`, :func:`nees_consistency`: squared log-ratio of the average
  normalised innovation / estimation error squared to its expectation (0 when consistent).

Each accepts the result of :func:`jaxnav.filters.kalman_filter` (any inflation rule or noise
estimator) or of :func:`jaxnav.ins.loosely_coupled` (per-epoch fields are looked up in
``result.epochs`` there). All are differentiable and reduce over the leading time axis only,
so they ``vmap`` over Monte Carlo runs.
"""

from __future__ import annotations

import jax.numpy as jnp

from jaxnav._numerics import cholesky, whiten


def _field(result, name):
    v = getattr(result, name, None)
    if v is None and hasattr(result, "epochs"):
        v = getattr(result.epochs, name, None)
    if v is None:
        raise ValueError(f"the result has no saved '{name}': add it to save=(...) of the filter call")
    return v


def rms(errors, mask=None):
    """Per-component RMS over the time axis: sqrt(mean_t e_t^2).

    Args:
      errors: (T, d) estimate minus truth (any unit).  mask: optional (T,) bool of epochs to use.
    Returns:
      (d,) RMS.
    """
    e = jnp.asarray(errors)
    if e.ndim != 2:
        raise ValueError(f"rms(): errors must be (T, d), got shape {e.shape}")
    if mask is None:
        return jnp.sqrt(jnp.mean(e**2, axis=0))
    m = jnp.asarray(mask, e.dtype)
    if m.shape != e.shape[:1]:
        raise ValueError(f"rms(): mask must be ({e.shape[0]},) for errors {e.shape}, got {m.shape}")
    return jnp.sqrt(jnp.sum(m[:, None] * e**2, axis=0) / jnp.maximum(jnp.sum(m), 1.0))


def innovation_nll(result, *, per_component: bool = True):
    """Negative innovation log-likelihood -sum_k log N(v_k; 0, S_k) (S1 eq. (10) residuals).

    With ``per_component`` it is divided by the number of valid measurement components, so
    values compare across series lengths and masks (needs ``valid`` saved; it is by default).
    """
    ll = _field(result, "loglik")
    if not per_component:
        return -ll
    return -ll / jnp.maximum(jnp.sum(_field(result, "valid")), 1)


def nis_consistency(result):
    """(log(sum_k NIS_k / sum_k m_k))^2: 0 when the average NIS equals its expectation m_k.

    NIS_k = v_k^T S_k^{-1} v_k over the valid components m_k (saved ``nis`` and ``valid``).
    """
    nis = _field(result, "nis")
    m = _field(result, "valid")
    return jnp.log(jnp.sum(nis) / jnp.maximum(jnp.sum(m), 1)) ** 2


def nees(errors, covs):
    """(T,) NEES e_k^T P_k^{-1} e_k by Cholesky solves.

    Args:
      errors: (T, n) estimate minus truth.  covs: (T, n, n) the filter's covariance.
    """
    e, P = jnp.asarray(errors), jnp.asarray(covs)
    if e.ndim != 2 or P.shape != e.shape + e.shape[-1:]:
        raise ValueError(f"nees(): errors (T, n) and covs (T, n, n) expected, got {e.shape} and {P.shape}")
    import jax

    def one(ek, Pk):
        w = whiten(cholesky(Pk), ek)
        return w @ w

    return jax.vmap(one)(e, P)


def nees_consistency(errors, covs):
    """(log(mean_k NEES_k / n))^2: 0 when the filter's covariance matches its actual errors."""
    n = jnp.asarray(errors).shape[-1]
    return jnp.log(jnp.mean(nees(errors, covs)) / n) ** 2
