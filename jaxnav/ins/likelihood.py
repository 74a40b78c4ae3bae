"""Predictive log-likelihood of GNSS fixes withheld from an INS/GNSS filter (pure jnp, differentiable).

A fix withheld from the filter scores its prediction honestly: the horizontal antenna position the
filter predicts at the fix epoch (its navigation state carried to the fix time by its velocity,
plus the lever arm rotated into ENU) against the fix, with the filter's predicted horizontal
position variance plus the fix's own covariance,

    nll_m = 1/2 (e_m^T S_m^-1 e_m + log det S_m + 2 log 2 pi),   S_m = R_m + diag(var_E, var_N),

the Gaussian negative log predictive density of the 2-D error e_m (Bar-Shalom, Li, Kirubarajan,
*Estimation with Applications to Tracking and Navigation*, 2001, sect. 5.2.5). Summed over withheld
fixes it is the loss for fitting noise densities to bridge GNSS outages.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from jaxnav.geodesy import curvilinear_to_enu
from jaxnav.ins.attitude import quat_to_dcm


def antenna_enu(nav, t_nav, t, lever_b, pos0):
    """(M, 3) antenna position in local ENU, m, of per-epoch navigation states extrapolated to times ``t``.

    ENU(nav.pos) + (t - t_nav) v_n + C_bn lever_b: the IMU position in the ENU frame at ``pos0``, moved on
    with the epoch's velocity to ``t`` and out to the antenna. Differentiable.

    Args:
      nav: :class:`jaxnav.ins.NavState` with (M, ...) leaves (pos [lat rad, lon rad, h m], v_n ENU m/s, q_bn).
      t_nav: (M,) times of ``nav``, s.  t: (M,) target times, s.
      lever_b: (3,) or (M, 3) antenna minus IMU in the body frame, m.
      pos0: (3,) origin of the ENU frame [lat rad, lon rad, h m].
    """
    M = jnp.shape(t_nav)[0]
    C = quat_to_dcm(nav.q_bn)
    dt = jnp.asarray(t) - t_nav
    lev = jnp.broadcast_to(jnp.asarray(lever_b, C.dtype), (M, 3))
    return curvilinear_to_enu(pos0, nav.pos - pos0) + dt[:, None] * nav.v_n + jnp.einsum("mij,mj->mi", C, lev)


def horizontal_fix_nll(nav, covs, t_nav, t_fix, pos_fix, R_h, lever_b, pos0, idx):
    """(M,) negative log predictive density of M horizontal GNSS fixes given the filter's predictions.

    Args:
      nav: :class:`jaxnav.ins.NavState` with (M, ...) leaves: the filter's state at each fix's epoch
        (pos [lat rad, lon rad, h m], v_n ENU m/s, q_bn).  covs: (M, n, n) its error covariances.
      t_nav: (M,) times of ``nav``, s.  t_fix: (M,) fix times, s.  pos_fix: (M, 3) fixes [lat rad, lon rad, h m].
      R_h: (M, 2, 2) the fixes' east/north covariance, m^2.  lever_b: (3,) antenna minus IMU, body frame, m.
      pos0: (3,) origin of the local ENU frame [lat rad, lon rad, h m].
      idx: :class:`jaxnav.ins.error_model.ErrorStateIndex` of the covariances (``dpos`` = dlat, dlon, dh).
    """
    M = jnp.shape(t_fix)[0]
    for name, a, shp in (
        ("covs", covs, None),
        ("t_nav", t_nav, (M,)),
        ("pos_fix", pos_fix, (M, 3)),
        ("R_h", R_h, (M, 2, 2)),
    ):
        if (shp is not None and jnp.shape(a) != shp) or (shp is None and jnp.shape(a)[0] != M):
            raise ValueError(f"horizontal_fix_nll: {name} has shape {jnp.shape(a)}, expected {shp or (M, 'n', 'n')}")
    ilat, ilon = idx.dpos.start, idx.dpos.start + 1
    ant = antenna_enu(nav, t_nav, t_fix, lever_b, pos0)
    e = ant[:, :2] - curvilinear_to_enu(pos0, pos_fix - pos0)[:, :2]
    sc = jnp.abs(curvilinear_to_enu(nav.pos, jnp.ones(3)))  # metres per (rad, rad, m)
    var = jnp.stack([covs[:, ilon, ilon] * sc[:, 0] ** 2, covs[:, ilat, ilat] * sc[:, 1] ** 2], -1)
    S = R_h + jax.vmap(jnp.diag)(var)
    return 0.5 * (
        jnp.einsum("mi,mi->m", e, jnp.linalg.solve(S, e[..., None])[..., 0])
        + jnp.linalg.slogdet(S)[1]
        + 2 * jnp.log(2 * jnp.pi)
    )


def withheld_fix_loss(result, meas, scored, lever_b, pos0, idx, *, R_scale=1.0):
    """Sum of :func:`horizontal_fix_nll` over the GNSS fixes ``scored`` of a loosely coupled run: the loss for
    fitting noise to bridge outages (fixes withheld from the filter, predicted by it).

    Args:
      result: :class:`jaxnav.ins.LCResult` saving ``nav`` and ``covs`` (the scored fixes withheld from it).
      meas: its :class:`jaxnav.ins.PVMeasurements` (M epochs; ``pos`` the fixes, ``R`` their covariance, m^2).
      scored: (M,) bool the fixes scored.  lever_b: (3,) antenna minus IMU, body frame, m.
      pos0: (3,) ENU origin [lat rad, lon rad, h m].  idx: the error model's state indices.
      R_scale: factor on the fixes' variances (the noise's ``pos_sigma_scale`` squared).
    Returns:
      scalar, differentiable in the run's parameters and ``lever_b``.
    """
    ep = result.epochs
    g = np.nonzero(np.asarray(ep.gnss_row) >= 0)[0]  # the GNSS epochs among the filter's
    nav = jax.tree_util.tree_map(lambda a: a[g], ep.nav)
    R_h = jnp.asarray(np.asarray(meas.R, float)[:, :2, :2]) * R_scale
    nll = horizontal_fix_nll(
        nav,
        ep.covs[g],
        ep.t_nav[g],
        jnp.asarray(np.asarray(meas.t)),
        jnp.asarray(np.asarray(meas.pos, float)),
        R_h,
        lever_b,
        pos0,
        idx,
    )
    return jnp.sum(jnp.where(jnp.asarray(scored), nll, 0.0))
