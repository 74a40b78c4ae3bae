"""Height-anomaly surface fitting: ellipsoidal height H -> normal height h = H - zeta(x, y) (S2 step 3).

The connection survey gives control points with both an ellipsoidal height (GNSS) and a normal
height (levelling); their height anomalies zeta = H - h are fitted by a low-order polynomial
surface in the plane coordinates (the "fitted height model" of S2):

* ``"plane"``:     zeta = a0 + a1 dx + a2 dy                                  (3 parameters)
* ``"quadratic"``: zeta = a0 + a1 dx + a2 dy + a3 dx^2 + a4 dx dy + a5 dy^2  (6 parameters)

with dx, dy the offsets from the control points' centroid divided by a length scale (their RMS
spread), which keeps the normal equations well conditioned for plane coordinates of 10^6 m.
``"auto"`` takes the quadratic surface when there are at least 7 control points (one redundant
observation beyond its 6 parameters), otherwise the plane (at least 3 points).
"""

from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxnav.geodesy._helmert import _lsq_stats, _solve_weighted

SURFACES = {"plane": 3, "quadratic": 6}
AUTO_QUADRATIC_MIN_POINTS = 7


class HeightAnomalyModel(NamedTuple):
    """A fitted height-anomaly surface.

    Attributes:
      coef: (p,) polynomial coefficients, m (in the scaled offsets, see the module docstring).
      center: (2,) centroid (x north, y east) of the control points, m.
      scale: length scale of the offsets, m.
      residuals: (N,) zeta - fitted zeta at the control points, m.
      sigma0: RMS error of unit weight sqrt(v^T W v / (N - p)), m (NaN if N = p).
      cov: (p, p) covariance of ``coef``.
      dof: N - p.
    """

    coef: jax.Array
    center: jax.Array
    scale: jax.Array
    residuals: jax.Array | None = None
    sigma0: jax.Array | None = None
    cov: jax.Array | None = None
    dof: int = 0

    @property
    def kind(self) -> str:
        """``"plane"`` or ``"quadratic"``, from the number of coefficients (a static shape)."""
        return "quadratic" if jnp.shape(self.coef)[-1] == 6 else "plane"


def _design(kind, u, v):
    cols = [jnp.ones_like(u), u, v]
    if kind == "quadratic":
        cols += [u * u, u * v, v * v]
    return jnp.stack(cols, axis=-1)


def choose_surface(n_points: int) -> str:
    """The ``"auto"`` choice: quadratic for >= 7 control points, plane for 3-6 (module docstring)."""
    if n_points >= AUTO_QUADRATIC_MIN_POINTS:
        return "quadratic"
    if n_points >= SURFACES["plane"]:
        return "plane"
    raise ValueError(f"a height-anomaly surface needs at least 3 control points (plane), got {n_points}")


@partial(jax.jit, static_argnames=("kind",))
def fit_height_anomaly(x, y, zeta, *, kind: str = "auto", weights=None) -> HeightAnomalyModel:
    """Fit a plane or quadratic height-anomaly surface to control points by least squares (S2 step 3).

    Args:
      x, y: (N,) plane coordinates of the control points (x north, y east), m.
      zeta: (N,) height anomalies H - h (ellipsoidal minus normal height), m.
      kind: ``"auto"``, ``"plane"`` or ``"quadratic"`` (static).
      weights: optional (N,) weights.
    Returns:
      :class:`HeightAnomalyModel` with residuals and precision.
    Raises:
      ValueError: shapes differ, unknown ``kind``, or fewer control points than parameters.
    """
    x, y, zeta = jnp.asarray(x, float), jnp.asarray(y, float), jnp.asarray(zeta, float)
    if x.ndim != 1 or x.shape != y.shape or x.shape != zeta.shape:
        raise ValueError(f"x, y, zeta must have the same shape (N,); got {x.shape}, {y.shape}, {zeta.shape}")
    n = x.shape[0]
    if kind == "auto":
        kind = choose_surface(n)
    if kind not in SURFACES:
        raise ValueError(f"kind must be 'auto', 'plane' or 'quadratic', got {kind!r}")
    p = SURFACES[kind]
    if n < p:
        raise ValueError(
            f"a {kind} height-anomaly surface has {p} parameters and needs at least {p} control points, got {n}"
        )
    center = jnp.stack([jnp.mean(x), jnp.mean(y)])
    scale = jnp.sqrt(jnp.mean((x - center[0]) ** 2 + (y - center[1]) ** 2))
    scale = jnp.where(scale > 0, scale, 1.0)
    A = _design(kind, (x - center[0]) / scale, (y - center[1]) / scale)
    w = jnp.ones((n, 1)) if weights is None else jnp.asarray(weights, float).reshape(n, 1)
    coef = _solve_weighted(A, zeta[:, None], w)
    v = zeta - A @ coef
    sigma0, cov, dof = _lsq_stats(A, v[:, None], w, p)
    return HeightAnomalyModel(coef=coef, center=center, scale=scale, residuals=v, sigma0=sigma0, cov=cov, dof=dof)


def height_anomaly(model: HeightAnomalyModel, x, y):
    """Evaluate the fitted height anomaly zeta(x, y), m (any broadcast shape of x, y in m)."""
    x, y = jnp.asarray(x), jnp.asarray(y)
    A = _design(model.kind, (x - model.center[0]) / model.scale, (y - model.center[1]) / model.scale)
    return A @ model.coef


def height_anomaly_std(model: HeightAnomalyModel, x, y):
    """Standard deviation of the fitted zeta(x, y) from the coefficient covariance, m."""
    x, y = jnp.asarray(x), jnp.asarray(y)
    A = _design(model.kind, (x - model.center[0]) / model.scale, (y - model.center[1]) / model.scale)
    return jnp.sqrt(jnp.einsum("...i,ij,...j->...", A, model.cov, A))


def normal_height(H, x, y, model: HeightAnomalyModel):
    """Ellipsoidal height -> normal height h = H - zeta(x, y) (S2 step 3).

    Args:
      H: ellipsoidal height, m.  x, y: plane coordinates where zeta is evaluated, m.
      model: :class:`HeightAnomalyModel` fitted in the same plane coordinates.
    Returns:
      normal height, m (broadcast shape).
    """
    return jnp.asarray(H) - height_anomaly(model, x, y)
