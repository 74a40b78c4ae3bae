"""Nonlinear filters on the shared step: extended (and iterated), unscented and cubature Kalman
filters and their RTS smoothers.

Each filter linearises the model at every epoch into an affine Gaussian one and hands it to
:func:`~jaxnav.filters._step.step_with_gain`, so the plug-ins (inflation rules, noise
estimators, robust reweighting), masking, the Joseph update, status flags and the
log-likelihood are the linear filter's:

* Taylor (EKF): F = df/dx at x_{k-1}, H = dh/dx at x_{k,k-1}, b = h(x_{k,k-1}) - H x_{k,k-1}
  (the iterated EKF re-expands h at each Gauss-Newton iterate, Bell & Cathey 1993).
* Sigma points (UKF, CKF): statistical linear regression of f and h on the sigma points
  (Van der Merwe 2004 scaled points; Arasaratnam & Haykin 2009 third-degree cubature):
  F P F^T is the points' covariance of f, H = P_xz^T P^{-1}, and the regression residual
  P_zz - H P_xz is added to R, so that S = P_zz + R and K = P_xz S^{-1} as in the UKF.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from jaxnav import _status
from jaxnav._numerics import (
    cho_solve,
    masked_measurement,
    mm,
    safe_cholesky,
    solve_lower_t,
    symmetrize,
)
from jaxnav.filters._kalman import KalmanResult
from jaxnav.filters._model import LinearGaussian
from jaxnav.filters._plugins import pytree_dataclass, static_field
from jaxnav.filters._rts import rts_smoother
from jaxnav.filters._smoother import SMOOTHER_OUTPUTS, SmootherResult, smoothed_covs, smoothed_means
from jaxnav.filters._step import ALL_OUTPUTS, StepInfo, scan_setup, step_with_gain, update, update_result


@pytree_dataclass
class NonlinearGaussian:
    """Nonlinear Gaussian model X_k = f(X_{k-1}, t) + W_{k-1},  Z_k = h(X_k, t) + V_k.

    ``t`` is the epoch index (0 for ``zs[0]``; ``f(x, t)`` predicts into epoch t), or the t-th
    slice of the ``inputs`` pytree given to the filter. f and h are pure JAX functions; model
    parameters they close over (or take from ``inputs``) may be traced (``grad``, ``vmap``).

    Attributes:
      f: (n,), t -> (n,) transition.  h: (n,), t -> (m,) measurement.
      Q: (n, n) or (T, n, n) process-noise covariance.  R: (m, m) or (T, m, m) measurement noise.
      F_jac, H_jac: optional Jacobians (x, t) -> (n, n), (m, n); None: ``jax.jacfwd`` of f, h
        (:meth:`jacobian_f`, :meth:`jacobian_h` give the one in use).
    """

    f: Callable = static_field()
    h: Callable = static_field()
    Q: jax.Array
    R: jax.Array
    F_jac: Callable | None = static_field(None)
    H_jac: Callable | None = static_field(None)

    @property
    def jacobian_f(self) -> Callable:
        """(x (n,), t) -> (n, n) df/dx: ``F_jac`` if given, else ``jax.jacfwd(f)``."""
        return jax.jacfwd(self.f) if self.F_jac is None else self.F_jac

    @property
    def jacobian_h(self) -> Callable:
        """(x (n,), t) -> (m, n) dh/dx: ``H_jac`` if given, else ``jax.jacfwd(h)``."""
        return jax.jacfwd(self.h) if self.H_jac is None else self.H_jac

    def __repr__(self):
        return f"NonlinearGaussian(f={self.f!r}, h={self.h!r}, Q={self.Q!r}, R={self.R!r})"


# ---------------------------------------------------------------------------------------------
# per-epoch algebra, written as unrolled multiply-adds


def _mul(A, B):
    """A B for one sequence's small matrices: A (i, k), B (k, j) or (k,), as k multiply-adds.

    Elementwise code with no reduction: XLA fuses it with its neighbours into a few loop kernels,
    single or under ``vmap`` (where a batched ``dot`` of tiny matrices costs a kernel each). Used
    for the sigma-point algebra. The EKF's covariance products (F P F^T, the Joseph update) use
    :func:`jaxnav._numerics.mm` instead: fused here, a product of products is re-evaluated for every
    element of the outer one (and twice more by the symmetrisation), and under ``vmap`` that
    recomputation dominated the step (EKF, n = 5, B = 256, T = 1000: 233 -> 151 ms with ``mm``; the
    UKF's products measured faster as they are, 295 against 345 ms).
    """
    K = A.shape[-1]
    if B.ndim == 1:
        return sum(A[:, k] * B[k] for k in range(K))
    return sum(A[:, k, None] * B[None, k, :] for k in range(K))


# ---------------------------------------------------------------------------------------------
# sigma points


def merwe_weights(n: int, alpha, beta, kappa, dtype):
    """Van der Merwe scaled sigma-point weights (Wm, Wc) (2n+1,) and the scale c = n + lambda.

    lambda = alpha^2 (n + kappa) - n; Wm_0 = lambda / c, Wc_0 = Wm_0 + 1 - alpha^2 + beta,
    W_i = 1 / (2c). alpha = 1, beta = kappa = 0 is the third-degree cubature rule (zero centre weight).
    """
    lam = alpha**2 * (n + kappa) - n
    c = n + lam
    w = jnp.full((2 * n + 1,), 0.5 / c, dtype)
    Wm = w.at[0].set(lam / c)
    Wc = w.at[0].set(lam / c + 1.0 - alpha**2 + beta)
    return Wm, Wc, c


def sigma_points(x, P, c):
    """The 2n+1 points x, x + sqrt(c) L_i, x - sqrt(c) L_i (L the lower Cholesky factor of P).

    Returns:
      (points (2n+1, n), L (n, n)).
    """
    return _points(x, P, jnp.sqrt(c))


def _points(x, P, sc):
    """:func:`sigma_points` given sqrt(c) (the same scale as :func:`_moments`' M)."""
    L, _ = safe_cholesky(P)
    U = sc * L.T  # row i: the i-th column of sqrt(c) L
    return jnp.concatenate([x[None], x[None] + U, x[None] - U], axis=0), L


def _moments(fx, weights):
    """Moments of the values fx (2n+1, d) of a function at :func:`sigma_points` (centre, +, - points).

    With the Van der Merwe weights (centre Wm_0, Wc_0; all others w = 1/(2c); the Wm sum to 1), about
    the centre value f_0: mean = f_0 + mu with mu = w sum_i (f_i - f_0), and
    cov = Wc_0 mu mu^T + w sum_i (f_i - f_0 - mu)(f_i - f_0 - mu)^T. Equal to the textbook
    sum_i W_i f_i and sum_i Wc_i (f_i - mean)(f_i - mean)^T, without its cancellation: at alpha = 1e-3
    the weights are ~1e6 and sum_i W_i f_i rounds at ~1e-16 |W| |f| (4e-8 m on a 364 m range), an
    error the textbook covariance cancels only if every use of the mean rounds alike, which XLA's
    fusions do not guarantee (one recomputing it with FMA, another not, moved S by 5e-4 at alpha = 1e-3);
    here the weighted sums run over differences of size sqrt(c) |J L|.
    The cross-covariance with the points, sum_i W_i (X_i - x)(f_i - mean)^T, is L M with
    M = w sqrt(c) (f_+ - f_-)^T (n, d) (the +/- points are x +/- sqrt(c) L_i; the mean cancels); it is
    returned as M, so that P^{-1} L M = L^{-T} M is one triangular solve and H P H^T, (I - K H) L
    are products of M (:func:`_update_factored`). Only the distinct weights enter (a per-point
    weight vector is sliced into one scalar kernel per point on CPU).

    Returns:
      (mean (d,), cov (d, d), M (n, d)).
    """
    wc0, w, sc = weights
    n = (fx.shape[0] - 1) // 2
    f0, fp, fm = fx[0], fx[1 : n + 1], fx[n + 1 :]
    dp, dm = fp - f0, fm - f0
    mu = w * sum(dp[i] + dm[i] for i in range(n))
    ep, em = dp - mu, dm - mu
    cov = wc0 * (mu[:, None] * mu[None, :]) + w * (_mul(ep.T, ep) + _mul(em.T, em))
    return f0 + mu, cov, (w * sc) * (fp - fm)


def _update_factored(x_pred, P_pred, L, M, v, R, valid, joseph):
    """:func:`~jaxnav.filters._step.update` of the sigma-point regression H = M^T L^{-1}, P_pred = L L^T,
    without forming H: P H^T = L M, H P H^T = M^T M, and the Joseph congruence
    (I - K H) P (I - K H)^T = A A^T with A = (I - K H) L = L - K M^T, plus K R K^T (symmetric
    positive semi-definite by construction, as the Joseph form). ``v`` (m,) is the innovation
    z - z_hat; invalid components are removed as in ``update`` (zero columns of M, identity R)."""
    Mt, Rm = masked_measurement(M.T, R, valid)  # Mt (m, n): H_m L
    v = jnp.where(valid, v, 0.0)
    PHt = _mul(L, Mt.T)
    S = symmetrize(_mul(Mt, Mt.T) + Rm)
    Ls, ok = safe_cholesky(S)
    K = cho_solve(Ls, PHt.T).T
    x = x_pred + _mul(K, v)
    if joseph:
        A = L - _mul(K, Mt)
        P = symmetrize(_mul(A, A.T) + _mul(_mul(K, Rm), K.T))
    else:
        P = symmetrize(P_pred - _mul(K, PHt.T))
    return update_result(x_pred, P_pred, x, P, v, S, K, Ls, valid, ok)


# ---------------------------------------------------------------------------------------------
# linearisations (one per epoch; the shared step calls predict, measure, update)


class _Taylor(NamedTuple):
    model: Any
    t: Any
    iterations: int

    def predict(self, x, P):
        F = self.model.jacobian_f(x, self.t)
        return F, self.model.f(x, self.t), mm(mm(F, P), F.T)

    def measure(self, x, P):
        return self.model.jacobian_h(x, self.t), self.model.h(x, self.t)

    def update(self, x_pred, P_pred, z, R, valid, joseph, first, redo):
        H, z_hat = first
        xi = x_pred
        for it in range(self.iterations):
            if it > 0:  # Gauss-Newton: re-expand h at the last iterate
                H, z_hat = self.measure(xi, P_pred)
            z_lin = jnp.where(valid, z - z_hat + _mul(H, xi), 0.0)
            up = update(x_pred, P_pred, z_lin, H, R, valid, joseph)
            xi = up.x
        return up, jnp.where(valid[:, None], H, 0.0), z_lin


class _SigmaPoints(NamedTuple):
    model: Any
    t: Any
    weights: Any  # (Wc_0, w, sqrt(c)): _weights

    def predict(self, x, P):
        pts, L = _points(x, P, self.weights[2])
        fx = jax.vmap(lambda p: self.model.f(p, self.t))(pts)
        mean, FPF, M = _moments(fx, self.weights)
        return solve_lower_t(L, M).T, mean, FPF  # F = P_xf^T P^{-1} = M^T L^{-1}, only for the plug-ins

    def measure(self, x, P):
        pts, L = _points(x, P, self.weights[2])
        hx = jax.vmap(lambda p: self.model.h(p, self.t))(pts)
        z_hat, Pzz, M = _moments(hx, self.weights)
        H = solve_lower_t(L, M).T  # P_xz^T P^{-1} = M^T L^T L^{-T} L^{-1}: the plug-ins' H (dead code without them)
        # the regression residual P_zz - H P_xz, with H P_xz = M^T M
        return H, z_hat, symmetrize(Pzz - _mul(M.T, M)), L, M

    def update(self, x_pred, P_pred, z, R, valid, joseph, first, redo):
        H, z_hat, Om, L, M = self.measure(x_pred, P_pred) if redo else first
        up = _update_factored(x_pred, P_pred, L, M, z - z_hat, R + Om, valid, joseph)
        z_lin = jnp.where(valid, z - z_hat + _mul(H, x_pred), 0.0)  # the affine model's z - b (plug-ins only)
        return up, jnp.where(valid[:, None], H, 0.0), z_lin


# ---------------------------------------------------------------------------------------------
# drivers


def _epochs(inputs, T):
    return jnp.arange(T) if inputs is None else inputs


def _check_model(model, x0, zs, inputs):
    """Trace-time checks of f, h (and user Jacobians) against x0 (n,) and zs (T, m)."""
    if not isinstance(model, NonlinearGaussian):
        raise ValueError(f"model must be a jaxnav.filters.NonlinearGaussian, got {type(model).__name__}")
    xs, zsh = tuple(jnp.shape(x0)), tuple(jnp.shape(zs))
    if len(xs) != 1:
        raise ValueError(f"x0 has shape {xs}; expected (n,)")
    if len(zsh) != 2:
        raise ValueError(f"zs has shape {zsh}; expected (T, m)")
    (n,), (T, m) = xs, zsh
    t0 = jax.tree_util.tree_map(lambda a: a[0], _epochs(inputs, T))
    x = jax.ShapeDtypeStruct((n,), jnp.result_type(x0, float))
    for name, fn, want in (
        ("f", model.f, (n,)),
        ("h", model.h, (m,)),
        ("F_jac", model.jacobian_f, (n, n)),
        ("H_jac", model.jacobian_h, (m, n)),
    ):
        got = tuple(jax.eval_shape(fn, x, t0).shape)
        if got != want:
            raise ValueError(f"model.{name}(x, t) has shape {got}; expected {want} for x0 {xs} and zs {zsh}")
    return n, m, T


def _run(
    model, x0, P0, zs, lin_of, *, inflation, estimator, mask, save, inputs, unroll, allow_float32, check_finite, joseph
):
    n, m, T = _check_model(model, x0, zs, inputs)
    lg = LinearGaussian(F=jnp.eye(n), H=jnp.zeros((m, n)), Q=model.Q, R=model.R)
    params, init, xs, save, _, _, dtype = scan_setup(lg, x0, P0, zs, inflation, estimator, mask, save, allow_float32)
    params = params._replace(model=params.model._replace(F=None, H=None))
    ts = _epochs(inputs, T)

    def body(state, inp):
        step_in, t = inp
        new, allv, _ = step_with_gain(state, step_in, params, check_finite, joseph, lin=lin_of(t, dtype))
        return new, StepInfo(**{name: allv[name] for name in save})

    final, info = jax.lax.scan(jax.checkpoint(body, prevent_cse=False), init, (xs, ts), unroll=unroll)
    return KalmanResult(
        **info._asdict(),
        loglik=final.loglik,
        n_nonfinite=final.n_nonfinite,
        n_skipped=final.n_skipped,
        status=final.status,
        x_final=final.x,
        P_final=final.P,
    )


_STATIC = ("save", "unroll", "allow_float32", "check_finite", "joseph")


@partial(jax.jit, static_argnames=_STATIC + ("iterations",))
def _ekf(model, x0, P0, zs, *, iterations, **kw):
    return _run(model, x0, P0, zs, lambda t, dt: _Taylor(model, t, iterations), **kw)


def _weights(n, alpha, beta, kappa, dtype):
    """The weights :func:`_moments` uses, (Wc_0, w, sqrt(c)), of :func:`merwe_weights` (Wm_0 = 1 - 2 n w)."""
    Wm, Wc, c = merwe_weights(n, alpha, beta, kappa, dtype)
    return Wc[0], Wm[1], jnp.sqrt(jnp.asarray(c, dtype))


@partial(jax.jit, static_argnames=_STATIC)
def _spkf(model, x0, P0, zs, alpha, beta, kappa, **kw):
    n = jnp.shape(x0)[0]
    return _run(model, x0, P0, zs, lambda t, dt: _SigmaPoints(model, t, _weights(n, alpha, beta, kappa, dt)), **kw)


_COMMON_DOC = """
    Args:
      model: :class:`NonlinearGaussian`.
      x0: (n,) initial mean.  P0: (n, n) initial covariance.
      zs: (T, m) measurements; NaN/inf elements are masked and counted.
      inflation, estimator, mask, save, unroll, allow_float32, check_finite, joseph: as for
        :func:`~jaxnav.filters.kalman_filter` (the plug-ins see the linearised model: F, H and the
        innovation z - h at the prior).
      inputs: optional pytree of (T, ...) arrays; its t-th slice is the ``t`` given to f and h
        (default: the epoch index t).
    Returns:
      :class:`~jaxnav.filters.KalmanResult` (pred_means are f(x_{k-1}) or the sigma-point means).
    Raises:
      ValueError: at trace time, for inconsistent shapes of x0, P0, zs, Q, R, mask or of the
        outputs of f, h and their Jacobians (naming them).
"""


def extended_kalman_filter(
    model: NonlinearGaussian,
    x0,
    P0,
    zs,
    *,
    iterations: int = 1,
    inflation=None,
    estimator=None,
    mask=None,
    save=ALL_OUTPUTS,
    inputs=None,
    unroll: int = 1,
    allow_float32: bool = False,
    check_finite: bool = True,
    joseph: bool = True,
) -> KalmanResult:
    """Extended Kalman filter: the shared step on the first-order Taylor expansion of f and h.

    x_{k,k-1} = f(x_{k-1}), P_{k,k-1} = F P F^T + Q with F = df/dx(x_{k-1}); the update uses
    v = z - h(x_{k,k-1}) and H = dh/dx(x_{k,k-1}). ``iterations`` > 1 (static) is the iterated
    EKF: Gauss-Newton on the update, x_{i+1} = x_pred + K_i (z - h(x_i) - H_i (x_pred - x_i)),
    with H_i, K_i at the iterate x_i; the saved innovations, NIS and log-likelihood are those of
    the last linearisation.
    """
    return _ekf(
        model,
        x0,
        P0,
        zs,
        iterations=int(iterations),
        inflation=inflation,
        estimator=estimator,
        mask=mask,
        save=tuple(save),
        inputs=inputs,
        unroll=unroll,
        allow_float32=allow_float32,
        check_finite=check_finite,
        joseph=joseph,
    )


def unscented_kalman_filter(
    model: NonlinearGaussian,
    x0,
    P0,
    zs,
    *,
    alpha=1e-3,
    beta=2.0,
    kappa=0.0,
    inflation=None,
    estimator=None,
    mask=None,
    save=ALL_OUTPUTS,
    inputs=None,
    unroll: int = 1,
    allow_float32: bool = False,
    check_finite: bool = True,
    joseph: bool = True,
) -> KalmanResult:
    """Unscented Kalman filter with Van der Merwe's scaled sigma points (alpha, beta, kappa as in
    filterpy's ``MerweScaledSigmaPoints``; array leaves, so they may be traced).

    Prediction: points of (x_{k-1}, P_{k-1}) through f give x_{k,k-1} and P_{k,k-1} (+ Q); update:
    new points of (x_{k,k-1}, P_{k,k-1}) through h give z_hat, P_zz, P_xz; K = P_xz (P_zz + R)^{-1}.
    With alpha = 1e-3 the centre weight is about -1e6 and the moments lose about 6-7 digits to
    cancellation (7e-7 m against filterpy on a 1 km track); alpha in 0.1-1 is better conditioned.
    """
    return _spkf(
        model,
        x0,
        P0,
        zs,
        alpha,
        beta,
        kappa,
        inflation=inflation,
        estimator=estimator,
        mask=mask,
        save=tuple(save),
        inputs=inputs,
        unroll=unroll,
        allow_float32=allow_float32,
        check_finite=check_finite,
        joseph=joseph,
    )


def cubature_kalman_filter(model: NonlinearGaussian, x0, P0, zs, **kwargs) -> KalmanResult:
    """Cubature Kalman filter (third-degree spherical-radial rule, Arasaratnam & Haykin 2009).

    The 2n points x +/- sqrt(n) L e_i with weights 1/(2n): the scaled unscented filter with
    alpha = 1, beta = 0, kappa = 0 (whose centre point has zero weight). Keywords as for
    :func:`unscented_kalman_filter` (without alpha, beta, kappa).
    """
    for bad in ("alpha", "beta", "kappa"):
        if bad in kwargs:
            raise ValueError(f"cubature_kalman_filter has no '{bad}' (the rule fixes alpha=1, beta=0, kappa=0)")
    return unscented_kalman_filter(model, x0, P0, zs, alpha=1.0, beta=0.0, kappa=0.0, **kwargs)


for _fn in (extended_kalman_filter, unscented_kalman_filter):
    _fn.__doc__ += _COMMON_DOC


# ---------------------------------------------------------------------------------------------
# smoothers


def extended_rts_smoother(
    model: NonlinearGaussian, filtered, *, inputs=None, unroll: int = 1, save=SMOOTHER_OUTPUTS
) -> SmootherResult:
    """Extended RTS smoother: :func:`~jaxnav.filters.rts_smoother` with F_{t+1} = df/dx at the
    filtered mean x_t, over the filter's saved moments.

    Args:
      model: the :class:`NonlinearGaussian` given to the filter (only f's Jacobian is used).
      filtered: a :class:`~jaxnav.filters.KalmanResult` with means, covs, pred_means, pred_covs.
      inputs: the filter's ``inputs`` (if any).  unroll, save: as for ``rts_smoother``.
    Returns:
      :class:`~jaxnav.filters.SmootherResult`.
    """
    return _erts(model, filtered, inputs=inputs, unroll=unroll, save=tuple(save))


@partial(jax.jit, static_argnames=("unroll", "save"))
def _erts(model, filtered, *, inputs, unroll, save):
    T, n = filtered.means.shape
    ts = _epochs(inputs, T)
    t_next = jax.tree_util.tree_map(lambda a: a[1:], ts)
    Fn = jax.vmap(model.jacobian_f)(filtered.means[:-1], t_next)
    Fs = jnp.concatenate([jnp.eye(n, dtype=Fn.dtype)[None], Fn], axis=0)
    return rts_smoother(LinearGaussian(F=Fs, H=None, Q=None, R=None), filtered, unroll=unroll, save=save)


def unscented_rts_smoother(
    model: NonlinearGaussian,
    filtered,
    *,
    alpha=1e-3,
    beta=2.0,
    kappa=0.0,
    inputs=None,
    unroll: int = 1,
    save=SMOOTHER_OUTPUTS,
) -> SmootherResult:
    """Unscented RTS smoother (Saerkkae 2008): C_t = P_{x,f} P_{t+1|t}^{-1} from sigma points of
    (x_t, P_t) through f, then the RTS recursions over the saved predicted moments.

    For a :func:`cubature_kalman_filter` result pass alpha=1, beta=0, kappa=0.

    Args:
      model: the :class:`NonlinearGaussian` given to the filter.
      filtered: a :class:`~jaxnav.filters.KalmanResult` with means, covs, pred_means, pred_covs.
      alpha, beta, kappa: the filter's sigma-point parameters.
      inputs: the filter's ``inputs`` (if any).  unroll, save: as for ``rts_smoother``.
    Returns:
      :class:`~jaxnav.filters.SmootherResult`.
    """
    return _urts(model, filtered, alpha, beta, kappa, inputs=inputs, unroll=unroll, save=tuple(save))


@partial(jax.jit, static_argnames=("unroll", "save"))
def _urts(model, filtered, alpha, beta, kappa, *, inputs, unroll, save):
    for name in ("means", "covs", "pred_means", "pred_covs"):
        if getattr(filtered, name, None) is None:
            raise ValueError(
                f"unscented_rts_smoother needs the filter output '{name}': run the filter with it in save="
            )
    T, n = filtered.means.shape
    dt = filtered.means.dtype
    weights = _weights(n, alpha, beta, kappa, dt)
    t_next = jax.tree_util.tree_map(lambda a: a[1:], _epochs(inputs, T))

    def cross(x, P, t):
        pts, L = _points(x, P, weights[2])
        return _mul(L, _moments(jax.vmap(lambda p: model.f(p, t))(pts), weights)[2])

    Pxf = jax.vmap(cross)(filtered.means[:-1], filtered.covs[:-1], t_next)
    L, ok = safe_cholesky(filtered.pred_covs[1:])
    C = jnp.where(ok[:, None, None], jnp.swapaxes(cho_solve(L, jnp.swapaxes(Pxf, -1, -2)), -1, -2), 0.0)
    C = jnp.concatenate([C, jnp.zeros((1, n, n), dt)], axis=0)
    status = jnp.where(jnp.all(ok), 0, _status.SMOOTHER_FAILED).astype(jnp.int32)
    means = smoothed_means(C, filtered.means, filtered.pred_means, unroll) if "means" in save else None
    covs = smoothed_covs(C, filtered.covs, filtered.pred_covs, unroll) if "covs" in save else None
    return SmootherResult(means=means, covs=covs, gains=C if "gains" in save else None, status=status)
