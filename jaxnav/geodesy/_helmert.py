"""Similarity transformations between datums: 7-parameter Bursa-Wolf (3-D) and 4-parameter plane.

S2 step 3 transforms each filtered epoch into the reference frame of the connection survey
(e.g. Beijing 1954) "with the coordinate-transformation model from the connection survey"; that
model is either a 7-parameter spatial similarity (ECEF to ECEF) or, over a mining area of a few
km, the 4-parameter plane similarity between two Gauss-Krüger grids. Both are applied, inverted
and estimated from common points by least squares here, with residuals and precision.

Rotation conventions of the 7-parameter model (both offered, as in EPSG and PROJ):

* ``"position_vector"`` (EPSG 9606/1033, the Bursa-Wolf convention of most Chinese texts):
  X' = T + (1 + s) R X with, to first order, R = [[1, -rz, ry], [rz, 1, -rx], [-ry, rx, 1]];
  a positive rz turns the position vector counter-clockwise seen from +Z.
* ``"coordinate_frame"`` (EPSG 9607/1032): the same with R transposed (rotations of the axes).

``exact=False`` (the default, as in EPSG and PROJ) uses the first-order matrix above; ``exact=True``
uses the orthogonal product of the three axis rotations (coordinate frame: R = R3(rz) R2(ry) R1(rx)).

4-parameter plane similarity (x north, y east, the Chinese survey convention):
x' = tx + (1 + m)(x cos(theta) - y sin(theta)),  y' = ty + (1 + m)(x sin(theta) + y cos(theta)).
PROJ's 2-D helmert (``theta=`` in arc-seconds, ``s=`` the factor itself) is the same model with
theta_PROJ = -theta and s_PROJ = 1 + m.
"""

from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp

CONVENTIONS = ("position_vector", "coordinate_frame")


class Helmert7(NamedTuple):
    """7-parameter similarity (Bursa-Wolf).

    Attributes:
      t: (3,) translation, m.  r: (3,) rotations rx, ry, rz, rad.
      s: scalar scale deviation (unitless; 1 ppm = 1e-6), the factor is 1 + s.
    """

    t: jax.Array
    r: jax.Array
    s: jax.Array


class Similarity2D(NamedTuple):
    """4-parameter plane similarity.

    Attributes:
      t: (2,) translation (tx north, ty east), m.  theta: rotation, rad.
      m: scale deviation (unitless), the factor is 1 + m.
    """

    t: jax.Array
    theta: jax.Array
    m: jax.Array


class HelmertFit(NamedTuple):
    """Least-squares estimate of a similarity from common points.

    Attributes:
      params: :class:`Helmert7` or :class:`Similarity2D`.
      residuals: (N, d) v = dst - transform(src), m.
      sigma0: a-posteriori standard deviation of unit weight sqrt(v^T W v / dof), m (NaN if dof = 0).
      cov: (p, p) covariance of the parameters in the order of ``std`` (sigma0^2 N^-1).
      std: (p,) standard deviations: Helmert7 [tx, ty, tz (m), rx, ry, rz (rad), s];
        Similarity2D [tx, ty (m), theta (rad), m].
      dof: redundancy d N - p.
      rms: (d,) RMS of the residuals per axis, m.
    """

    params: Helmert7 | Similarity2D
    residuals: jax.Array
    sigma0: jax.Array
    cov: jax.Array
    std: jax.Array
    dof: int
    rms: jax.Array


def _check_convention(convention):
    if convention not in CONVENTIONS:
        raise ValueError(f"convention must be one of {CONVENTIONS}, got {convention!r}")


def rotation_matrix(r, *, convention: str = "position_vector", exact: bool = False):
    """Rotation matrix of the 7-parameter model for rotations ``r`` = (rx, ry, rz), rad.

    Args:
      r: (3,) rotations, rad.
      convention: ``"position_vector"`` or ``"coordinate_frame"`` (see the module docstring).
      exact: orthogonal product of axis rotations instead of the first-order matrix.
    Returns:
      (3, 3) matrix R with X' = T + (1 + s) R X.
    """
    _check_convention(convention)
    r = jnp.asarray(r)
    rx, ry, rz = r[0], r[1], r[2]
    if exact:
        cx, sx, cy, sy, cz, sz = jnp.cos(rx), jnp.sin(rx), jnp.cos(ry), jnp.sin(ry), jnp.cos(rz), jnp.sin(rz)
        one, zero = jnp.ones_like(rx), jnp.zeros_like(rx)
        R1 = jnp.array([[one, zero, zero], [zero, cx, sx], [zero, -sx, cx]])
        R2 = jnp.array([[cy, zero, -sy], [zero, one, zero], [sy, zero, cy]])
        R3 = jnp.array([[cz, sz, zero], [-sz, cz, zero], [zero, zero, one]])
        Rcf = R3 @ R2 @ R1
    else:
        one = jnp.ones_like(rx)
        Rcf = jnp.array([[one, rz, -ry], [-rz, one, rx], [ry, -rx, one]])
    return Rcf if convention == "coordinate_frame" else Rcf.T


def _check_last(name, a, d):
    if jnp.ndim(a) < 1 or jnp.shape(a)[-1] != d:
        raise ValueError(f"{name} has shape {jnp.shape(a)}; expected (..., {d})")


def helmert7(params: Helmert7, X, *, convention: str = "position_vector", exact: bool = False):
    """Apply a 7-parameter similarity X' = T + (1 + s) R X (Bursa-Wolf; S2 step 3).

    Args:
      params: :class:`Helmert7` (t m, r rad, s unitless).
      X: (..., 3) Cartesian (ECEF) coordinates, m.
      convention, exact: see :func:`rotation_matrix`.
    Returns:
      (..., 3) transformed coordinates, m.
    """
    _check_last("X", X, 3)
    R = rotation_matrix(params.r, convention=convention, exact=exact)
    return jnp.asarray(params.t) + (1.0 + params.s) * jnp.einsum("ij,...j->...i", R, X)


def helmert7_inverse(params: Helmert7, Xp, *, convention: str = "position_vector", exact: bool = False):
    """Invert :func:`helmert7`: X = ((1 + s) R)^-1 (X' - T), a 3x3 solve (exact also for the first-order R).

    Args:
      params: the forward :class:`Helmert7`.  Xp: (..., 3) transformed coordinates, m.
      convention, exact: as used forward.
    Returns:
      (..., 3) source coordinates, m.
    """
    _check_last("Xp", Xp, 3)
    M = (1.0 + params.s) * rotation_matrix(params.r, convention=convention, exact=exact)
    d = jnp.asarray(Xp) - jnp.asarray(params.t)
    flat = d.reshape(-1, 3)
    return jnp.linalg.solve(M, flat.T).T.reshape(d.shape)


def similarity2d(params: Similarity2D, xy):
    """Apply the 4-parameter plane similarity (module docstring; S2 step 3).

    Args:
      params: :class:`Similarity2D`.
      xy: (..., 2) plane coordinates (x north, y east), m.
    Returns:
      (..., 2) transformed coordinates, m.
    """
    _check_last("xy", xy, 2)
    xy = jnp.asarray(xy)
    k = 1.0 + params.m
    c, s = jnp.cos(params.theta), jnp.sin(params.theta)
    x, y = xy[..., 0], xy[..., 1]
    t = jnp.asarray(params.t)
    return jnp.stack([t[0] + k * (c * x - s * y), t[1] + k * (s * x + c * y)], axis=-1)


def similarity2d_inverse(params: Similarity2D, xy):
    """Invert :func:`similarity2d` in closed form: xy = R(-theta) (xy' - t) / (1 + m).

    Args:
      params: the forward :class:`Similarity2D`.  xy: (..., 2) transformed coordinates, m.
    Returns:
      (..., 2) source coordinates, m.
    """
    _check_last("xy", xy, 2)
    xy = jnp.asarray(xy)
    t = jnp.asarray(params.t)
    dx, dy = xy[..., 0] - t[0], xy[..., 1] - t[1]
    c, s = jnp.cos(params.theta), jnp.sin(params.theta)
    k = 1.0 + params.m
    return jnp.stack([(c * dx + s * dy) / k, (-s * dx + c * dy) / k], axis=-1)


def _check_pairs(src, dst, d, p, what):
    ss, sd = jnp.shape(src), jnp.shape(dst)
    if len(ss) != 2 or ss[1] != d or ss != sd:
        raise ValueError(f"{what}: src and dst must both have shape (N, {d}); got {ss} and {sd}")
    n = ss[0]
    need = -(-p // d)
    if n * d < p:
        raise ValueError(
            f"{what}: {p} parameters need at least {need} common points ({n * d} coordinates "
            f"from {n} points are fewer than the {p} parameters)"
        )
    return n


def _weights(weights, n, d):
    if weights is None:
        return jnp.ones((n, d))
    w = jnp.asarray(weights, float)
    if w.shape == (n,):
        return jnp.broadcast_to(w[:, None], (n, d))
    if w.shape == (n, d):
        return w
    raise ValueError(f"weights has shape {w.shape}; expected ({n},) or ({n}, {d})")


def _lsq_stats(J, v, w, p):
    """sigma0, parameter covariance (column-scaled Cholesky of the normal matrix), dof."""
    n_obs = v.size
    dof = n_obs - p
    vw = (v.reshape(-1) ** 2 * w.reshape(-1)).sum()
    sigma0 = jnp.sqrt(vw / dof) if dof > 0 else jnp.asarray(jnp.nan)
    scale = jnp.sqrt(jnp.sum(J**2 * w.reshape(-1)[:, None], axis=0))
    Js = J / scale
    N = Js.T @ (w.reshape(-1)[:, None] * Js)
    L = jnp.linalg.cholesky(N)
    Ninv = jax.scipy.linalg.cho_solve((L, True), jnp.eye(p))
    cov = sigma0**2 * Ninv / jnp.outer(scale, scale)
    return sigma0, cov, dof


def _solve_weighted(J, r, w):
    sw = jnp.sqrt(w.reshape(-1))
    return jnp.linalg.lstsq(J * sw[:, None], r.reshape(-1) * sw)[0]


@partial(jax.jit, static_argnames=("convention", "exact", "iterations"))
def estimate_helmert7(
    src, dst, *, convention: str = "position_vector", exact: bool = False, weights=None, iterations: int = 4
) -> HelmertFit:
    """Estimate a 7-parameter similarity from N >= 3 common points by (weighted) least squares.

    Gauss-Newton on the full model (``iterations`` fixed; from zero, two already reach float64
    for realistic datum shifts), about the centroid of ``src`` so that the translation and
    rotations decorrelate numerically; the reported parameters refer to the origin.

    Args:
      src: (N, 3) source Cartesian coordinates, m.  dst: (N, 3) target coordinates, m.
      convention, exact: see :func:`rotation_matrix`.
      weights: optional (N,) or (N, 3) weights (inverse variances up to a common factor).
      iterations: Gauss-Newton iterations (static).
    Returns:
      :class:`HelmertFit` with :class:`Helmert7` parameters; ``std`` order [t (m), r (rad), s].
    Raises:
      ValueError: shapes differ or fewer than 3 points (7 parameters need 3 points' 9 coordinates).
    """
    _check_convention(convention)
    n = _check_pairs(src, dst, 3, 7, "estimate_helmert7")
    src, dst = jnp.asarray(src, float), jnp.asarray(dst, float)
    w = _weights(weights, n, 3)
    c = jnp.mean(src, axis=0)

    def model(theta):
        # about the centroid: X' = T_c + (1+s) R (X - c), T = T_c - (1+s) R c
        R = rotation_matrix(theta[3:6], convention=convention, exact=exact)
        return theta[:3] + (1.0 + theta[6]) * (src - c) @ R.T

    theta = jnp.concatenate([jnp.mean(dst, axis=0), jnp.zeros(4)])
    for _ in range(iterations):
        J = jax.jacfwd(lambda th: model(th).reshape(-1))(theta)
        theta = theta + _solve_weighted(J, dst - model(theta), w)
    v = dst - model(theta)
    J = jax.jacfwd(lambda th: model(th).reshape(-1))(theta)
    sigma0, cov_c, dof = _lsq_stats(J, v, w, 7)

    def to_origin(th):
        R = rotation_matrix(th[3:6], convention=convention, exact=exact)
        return jnp.concatenate([th[:3] - (1.0 + th[6]) * R @ c, th[3:]])

    A = jax.jacfwd(to_origin)(theta)
    cov = A @ cov_c @ A.T
    th0 = to_origin(theta)
    params = Helmert7(t=th0[:3], r=th0[3:6], s=th0[6])
    return HelmertFit(
        params=params,
        residuals=v,
        sigma0=sigma0,
        cov=cov,
        std=jnp.sqrt(jnp.diag(cov)),
        dof=dof,
        rms=jnp.sqrt(jnp.mean(v**2, axis=0)),
    )


@jax.jit
def estimate_similarity2d(src, dst, *, weights=None) -> HelmertFit:
    """Estimate a 4-parameter plane similarity from N >= 2 common points by (weighted) least squares.

    The model is linear in (tx, ty, a, b) with a = (1+m) cos(theta), b = (1+m) sin(theta); it is
    solved about the centroids of both point sets and converted, with its covariance, to
    (tx, ty, theta, m).

    Args:
      src: (N, 2) source plane coordinates (x north, y east), m.  dst: (N, 2) target, m.
      weights: optional (N,) or (N, 2) weights.
    Returns:
      :class:`HelmertFit` with :class:`Similarity2D` parameters; ``std`` order [tx, ty (m), theta (rad), m].
    Raises:
      ValueError: shapes differ or fewer than 2 points.
    """
    n = _check_pairs(src, dst, 2, 4, "estimate_similarity2d")
    src, dst = jnp.asarray(src, float), jnp.asarray(dst, float)
    w = _weights(weights, n, 2)
    cs, cd = jnp.mean(src, axis=0), jnp.mean(dst, axis=0)
    x, y = src[:, 0] - cs[0], src[:, 1] - cs[1]
    one, zero = jnp.ones(n), jnp.zeros(n)
    # rows interleaved (x'_0, y'_0, x'_1, ...); unknowns (dtx, dty, a, b)
    J = jnp.stack([jnp.stack([one, zero, x, -y], axis=1), jnp.stack([zero, one, y, x], axis=1)], axis=1)
    J = J.reshape(2 * n, 4)
    sol = _solve_weighted(J, dst - cd, w)
    v = (dst - cd) - (J @ sol).reshape(n, 2)
    sigma0, cov_c, dof = _lsq_stats(J, v, w, 4)

    def convert(u):
        a, b = u[2], u[3]
        k = jnp.hypot(a, b)
        t = cd + u[:2] - jnp.array([a * cs[0] - b * cs[1], b * cs[0] + a * cs[1]])
        return jnp.stack([t[0], t[1], jnp.arctan2(b, a), k - 1.0])

    A = jax.jacfwd(convert)(sol)
    cov = A @ cov_c @ A.T
    p = convert(sol)
    params = Similarity2D(t=p[:2], theta=p[2], m=p[3])
    return HelmertFit(
        params=params,
        residuals=v,
        sigma0=sigma0,
        cov=cov,
        std=jnp.sqrt(jnp.diag(cov)),
        dof=dof,
        rms=jnp.sqrt(jnp.mean(v**2, axis=0)),
    )
