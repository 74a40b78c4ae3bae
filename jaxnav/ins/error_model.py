"""INS error-state model in the ENU frame: the 18-state model of S0 eqs. (18)-(19) and its 15-state subset.

Error state (S0 eq. 18), 18 components, in this order::

    X = [phi_E phi_N phi_U,  dV_E dV_N dV_U,  dlat dlon dh,  eps_b (3),  eps_r (3),  nabla (3)]

    phi    attitude error (misalignment) of the computed navigation frame, rad, ENU components
    dV     velocity error, computed - true, m/s, ENU
    dpos   position error, computed - true: latitude rad, longitude rad, height m
    eps_b  gyro random constant (bias), body frame, rad/s
    eps_r  gyro first-order Gauss-Markov drift, body frame, rad/s
    nabla  accelerometer random constant (bias), body frame, m/s^2

Process noise (S0 eq. 19), 9 components::

    W = [w_g (3) gyro white noise, rad/s/sqrt(Hz) density;  w_b (3) Markov driving noise;
         w_a (3) accelerometer white noise]

The 15-state subset drops eps_r (and w_b): X15 = [phi, dV, dpos, eps_b, nabla], W15 = [w_g, w_a].
Each model is an :class:`ErrorModel` record (:data:`ERROR_MODEL_18`, :data:`ERROR_MODEL_15`,
:data:`ERROR_MODEL_21`, :data:`ERROR_MODEL_15GM`, :func:`error_model_for`) chosen once by its user,
whose methods build F, G, Qc (from an :class:`jaxnav.ins.ImuNoise`) and a diagonal P0;
the 15-state one is derived from the 18-state one by :meth:`ErrorModel.drop` (rows and columns
deleted), as larger models can be reduced.

The 21-state model (the layout of KF-GINS-style loosely coupled filters) takes the
sensor errors as a datasheet states them::

    X21 = [phi (3), dV (3), dpos (3), eps_b (3), nabla (3), s_g (3), s_a (3)]
    W21 = [w_g (3) ARW, w_a (3) VRW, w_bg (3), w_ba (3) bias driving noises, w_sg (3), w_sa (3) scale-factor noises]

    eps_b_dot = -eps_b / tau_g + w_bg,  nabla_dot = -nabla / tau_a + w_ba     (first-order Gauss-Markov;
                                                                               tau = inf: random walk)
    s_g_dot = w_sg,  s_a_dot = w_sa                                          (random constants, optional random walk)
    phi_dot += -C_bn (eps_b + diag(w_ib_b) s_g),  dV_dot += C_bn (nabla + diag(f_b) s_a)

s_g, s_a are the scale-factor errors (measured = (1 + s) true + bias, dimensionless). The bias
instability sigma with its correlation time tau and the bias random walk K of a datasheet enter
the bias driving density as q = 2 sigma^2 / tau + K^2 (:meth:`ErrorModel.Qc`). The gyro Markov
drift eps_r of S0 is not a separate state here (a second first-order process per axis would make
27 states): the bias state is itself the Gauss-Markov process. :data:`ERROR_MODEL_15GM` is this
model without the scale factors (15 states, Gauss-Markov / random-walk biases).

Conventions (jaxnav-wide): navigation frame n = ENU, body frame b = right-forward-up,
``C_bn`` = body -> nav DCM, ``pos = [lat rad, lon rad, h m]``.

Attitude-error convention (the "phi-angle" form)::

    C_bn_computed = (I - [phi x]) C_bn_true            (to first order; exactly exp(-[phi x]) C_bn_true)

i.e. phi is the small rotation that takes the true navigation frame to the computed one. With it
the sensor errors enter as ``phi_dot = ... - C_bn (eps_b + eps_r + w_g)`` and
``dV_dot = f_n x phi + ... + C_bn (nabla + w_a)``. Sensor errors are defined as
measured - true (a positive eps_b means the gyro reads too high).

Continuous model: ``X_dot = F X + G W``, ``E[W(t) W(s)^T] = Qc delta(t - s)``; discretised to the
``Phi_{k,k-1}`` and ``Gamma Q Gamma^T`` of S0 eqs. (1), (8) by :func:`discretize_van_loan` (exact)
or :func:`discretize_series` (truncated series, stated order).

All functions are pure JAX (jit / vmap / grad), single-point shapes (batch with ``jax.vmap``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax.scipy.linalg import expm

from jaxnav.geodesy import WGS84, Ellipsoid, check_float64, enu_to_curvilinear, meridian_radius, prime_vertical_radius
from jaxnav.ins.attitude import skew
from jaxnav.ins.earth import normal_gravity
from jaxnav.ins.noise import ImuNoise


class ErrorStateIndex(NamedTuple):
    """Slices of the error-state components (None for blocks a model lacks: ``eps_r`` in the 15- and
    21-state models, the scale factors ``s_g``, ``s_a`` outside the 21-state model, the odometer
    scale-factor error ``s_odo`` outside models made by :meth:`ErrorModel.with_odometer_scale`)."""

    phi: slice
    dv: slice
    dpos: slice
    eps_b: slice
    eps_r: slice | None
    nabla: slice
    s_g: slice | None = None
    s_a: slice | None = None
    s_odo: slice | None = None


#: Layout of the 18-state vector (S0 eq. 18).
IDX18 = ErrorStateIndex(slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12), slice(12, 15), slice(15, 18))
#: Layout of the 15-state vector (no Markov drift).
IDX15 = ErrorStateIndex(slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12), None, slice(12, 15))

#: Names of the 18 error states, in order.
STATE_NAMES18 = (
    "phi_E",
    "phi_N",
    "phi_U",
    "dV_E",
    "dV_N",
    "dV_U",
    "dlat",
    "dlon",
    "dh",
    "eps_bx",
    "eps_by",
    "eps_bz",
    "eps_rx",
    "eps_ry",
    "eps_rz",
    "nabla_x",
    "nabla_y",
    "nabla_z",
)
#: Names of the 15 error states, in order.
STATE_NAMES15 = STATE_NAMES18[:12] + STATE_NAMES18[15:]
#: Layout of the 21-state vector [phi, dV, dpos, eps_b, nabla, s_g, s_a].
IDX21 = ErrorStateIndex(
    slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12), None, slice(12, 15), slice(15, 18), slice(18, 21)
)
#: Names of the 21 error states, in order.
STATE_NAMES21 = STATE_NAMES15 + ("s_gx", "s_gy", "s_gz", "s_ax", "s_ay", "s_az")


def _vec3(x, dtype):
    """Scalar or (3,) -> (3,) array."""
    return jnp.broadcast_to(jnp.asarray(x, dtype), (3,))


def nav_error_F(pos, v_n, f_n, *, ellipsoid: Ellipsoid = WGS84, earth_rate_sign=1.0):
    """Navigation-error block (9x9) of the INS error model: rows/cols [phi, dV, dpos] (S0 eq. 18).

    phi_dot  = -w_in x phi + dw_in                                   (w_in = w_ie + w_en)
    dV_dot   = f_n x phi - (2 w_ie + w_en) x dV + v x (2 dw_ie + dw_en) + dg
    dpos_dot = d[V_N/(R_M+h), V_E/((R_N+h) cos L), V_U]
    where dw_ie, dw_en, dg are the first-order changes of the Earth rate, transport rate and normal
    gravity with the velocity and position errors (the exact partials of
    :func:`jaxnav.ins.earth.earth_params`, including dR_M/dL, dR_N/dL and the height/latitude
    dependence of gravity, dgamma/dh ~ -2 gamma / R, by ``jax.jacfwd`` of the normal gravity).

    Args:
      pos: (3,) [lat rad, lon rad, h m], float64.  v_n: (3,) ENU velocity, m/s.
      f_n: (3,) specific force in n (= C_bn f_b), m/s^2.
      ellipsoid: static Earth model.
      earth_rate_sign: +1, or -1 for reverse navigation (as :func:`jaxnav.ins.earth.earth_params`).
    Returns:
      (9, 9) array; units follow the state (rad, m/s, rad/rad/m).

    Notes:
      Singular at the poles (tan L, sec L), as any latitude/longitude error state.
      Textbook forms usually treat R_M, R_N as constants in the position partials; the terms kept
      here are of relative size e^2 ~ 0.7 % and make F the exact Jacobian of the continuous
      navigation equations. The sensor errors are not part of this block.
    """
    check_float64(pos, what="pos (absolute latitude/longitude/height)")
    pos = jnp.asarray(pos)
    dtype = pos.dtype
    v_n = jnp.asarray(v_n, dtype)
    f_n = jnp.asarray(f_n, dtype)
    lat, h = pos[0], pos[2]
    ve, vn = v_n[0], v_n[1]
    w = earth_rate_sign * ellipsoid.omega
    e2 = ellipsoid.e2
    sL, cL = jnp.sin(lat), jnp.cos(lat)
    tL = sL / cL
    RM = meridian_radius(lat, ellipsoid)
    RN = prime_vertical_radius(lat, ellipsoid)
    W2 = 1.0 - e2 * sL * sL
    dRM = 3.0 * RM * e2 * sL * cL / W2  # dR_M/dlat, m/rad
    dRN = RN * e2 * sL * cL / W2  # dR_N/dlat, m/rad
    RMh, RNh = RM + h, RN + h
    z = jnp.zeros((), dtype)

    w_ie = jnp.stack([z, w * cL, w * sL])
    w_en = jnp.stack([-vn / RMh, ve / RNh, ve * tL / RNh])
    w_in = w_ie + w_en

    # d w_en / d v_n  (= d w_in / d v_n)
    dwen_dv = jnp.stack(
        [
            jnp.stack([z, -1.0 / RMh, z]),
            jnp.stack([1.0 / RNh, z, z]),
            jnp.stack([tL / RNh, z, z]),
        ]
    )
    # d w_ie / d[lat, lon, h]
    dwie_dp = jnp.stack(
        [
            jnp.stack([z, z, z]),
            jnp.stack([-w * sL, z, z]),
            jnp.stack([w * cL, z, z]),
        ]
    )
    # d w_en / d[lat, lon, h]
    dwen_dp = jnp.stack(
        [
            jnp.stack([vn * dRM / RMh**2, z, vn / RMh**2]),
            jnp.stack([-ve * dRN / RNh**2, z, -ve / RNh**2]),
            jnp.stack([ve / (RNh * cL * cL) - ve * tL * dRN / RNh**2, z, -ve * tL / RNh**2]),
        ]
    )
    dg_dlat, dg_dh = jax.jacfwd(normal_gravity, argnums=(0, 1))(lat, h, ellipsoid)
    # g_n = [0, 0, -gamma(lat, h)]
    dg_dp = jnp.stack([jnp.stack([z, z, z]), jnp.stack([z, z, z]), jnp.stack([-dg_dlat, z, -dg_dh])])

    V = skew(v_n)
    F_aa = -skew(w_in)
    F_av = dwen_dv
    F_ap = dwie_dp + dwen_dp
    F_va = skew(f_n)
    F_vv = -skew(2.0 * w_ie + w_en) + V @ dwen_dv
    F_vp = V @ (2.0 * dwie_dp + dwen_dp) + dg_dp
    F_pa = jnp.zeros((3, 3), dtype)
    F_pv = jnp.stack(
        [
            jnp.stack([z, 1.0 / RMh, z]),
            jnp.stack([1.0 / (RNh * cL), z, z]),
            jnp.stack([z, z, jnp.ones((), dtype)]),
        ]
    )
    F_pp = jnp.stack(
        [
            jnp.stack([-vn * dRM / RMh**2, z, -vn / RMh**2]),
            jnp.stack([ve / (RNh * cL) * (tL - dRN / RNh), z, -ve / (RNh**2 * cL)]),
            jnp.stack([z, z, z]),
        ]
    )
    return jnp.block([[F_aa, F_av, F_ap], [F_va, F_vv, F_vp], [F_pa, F_pv, F_pp]])


def _F18(pos, v_n, f_n, C_bn, tau, *, ellipsoid: Ellipsoid = WGS84, earth_rate_sign=1.0):
    """F (18, 18) of S0 eqs. (18)-(19): the navigation block of :func:`nav_error_F` and
    phi_dot += -C_bn (eps_b + eps_r);  dV_dot += C_bn nabla;  eps_b_dot = 0;  eps_r_dot = -eps_r / tau;
    nabla_dot = 0 (tau: scalar or (3,) gyro Markov correlation times, s)."""
    Fn = nav_error_F(pos, v_n, f_n, ellipsoid=ellipsoid, earth_rate_sign=earth_rate_sign)
    dtype = Fn.dtype
    C = jnp.asarray(C_bn, dtype)
    tau = _vec3(tau, dtype)
    F = jnp.zeros((18, 18), dtype)
    F = F.at[0:9, 0:9].set(Fn)
    F = F.at[IDX18.phi, IDX18.eps_b].set(-C)
    F = F.at[IDX18.phi, IDX18.eps_r].set(-C)
    F = F.at[IDX18.dv, IDX18.nabla].set(C)
    F = F.at[IDX18.eps_r, IDX18.eps_r].set(jnp.diag(-1.0 / tau))
    return F


def _G18(C_bn):
    """G (18, 9) for W = [w_g, w_b, w_a] (S0 eq. 19): phi_dot gets -C_bn w_g, eps_r_dot w_b, dV_dot C_bn w_a."""
    C = jnp.asarray(C_bn)
    G = jnp.zeros((18, 9), C.dtype)
    G = G.at[IDX18.phi, 0:3].set(-C)
    G = G.at[IDX18.eps_r, 3:6].set(jnp.eye(3, dtype=C.dtype))
    G = G.at[IDX18.dv, 6:9].set(C)
    return G


def _Qc18(noise: ImuNoise):
    """Qc (9, 9) of W = [w_g, w_b, w_a] (S0 eq. 19): diag(ARW^2, 2 sigma^2 / tau, VRW^2) (x3 each), with the
    gyro bias instability as the Markov drift's sigma and its correlation time as tau."""
    dtype = jnp.result_type(noise.gyro_arw, noise.accel_vrw, noise.gyro_bias_instability, noise.gyro_bias_tau, float)
    return jnp.diag(
        jnp.concatenate(
            [
                jnp.square(_vec3(noise.gyro_arw, dtype)),
                markov_psd(_vec3(noise.gyro_bias_instability, dtype), _vec3(noise.gyro_bias_tau, dtype)),
                jnp.square(_vec3(noise.accel_vrw, dtype)),
            ]
        )
    )


def markov_psd(sigma, tau):
    """Driving-noise density of a first-order Gauss-Markov process: q = 2 sigma^2 / tau.

    x_dot = -x / tau + w, E[w(t) w(s)] = q delta(t - s) has stationary variance q tau / 2 = sigma^2.

    Args:
      sigma: stationary standard deviation (any unit u).  tau: correlation time, s.
    Returns:
      q in u^2/s.
    """
    return 2.0 * jnp.square(sigma) / tau


def _F21(pos, v_n, f_n, C_bn, tau, *, Cw=None, Cf=None, ellipsoid: Ellipsoid = WGS84, earth_rate_sign=1.0):
    """F (21, 21) of the 21-state model (module docstring): the navigation block of :func:`nav_error_F`;
    phi_dot += -C_bn eps_b - Cw s_g; dV_dot += C_bn nabla + Cf s_a; eps_b_dot = -eps_b / tau_g;
    nabla_dot = -nabla / tau_a; s_g_dot = s_a_dot = 0 (tau: scalar or (6,) = [tau_g (3), tau_a (3)], s;
    inf: a random walk; Cw, Cf: (3, 3) C_bn diag(w_ib_b), C_bn diag(f_b), None: zeros)."""
    Fn = nav_error_F(pos, v_n, f_n, ellipsoid=ellipsoid, earth_rate_sign=earth_rate_sign)
    dtype = Fn.dtype
    C = jnp.asarray(C_bn, dtype)
    tau = jnp.broadcast_to(jnp.asarray(tau, dtype), (6,))
    z33 = jnp.zeros((3, 3), dtype)
    Cw = z33 if Cw is None else jnp.asarray(Cw, dtype)
    Cf = z33 if Cf is None else jnp.asarray(Cf, dtype)
    F = jnp.zeros((21, 21), dtype)
    F = F.at[0:9, 0:9].set(Fn)
    F = F.at[IDX21.phi, IDX21.eps_b].set(-C).at[IDX21.dv, IDX21.nabla].set(C)
    F = F.at[IDX21.phi, IDX21.s_g].set(-Cw).at[IDX21.dv, IDX21.s_a].set(Cf)
    F = F.at[IDX21.eps_b, IDX21.eps_b].set(jnp.diag(-1.0 / tau[:3]))
    F = F.at[IDX21.nabla, IDX21.nabla].set(jnp.diag(-1.0 / tau[3:]))
    return F


def _G21(C_bn):
    """G (21, 18) for W21 = [w_g, w_a, w_bg, w_ba, w_sg, w_sa]: phi_dot gets -C_bn w_g, dV_dot C_bn w_a; the
    bias and scale-factor states their driving noises directly (body frame)."""
    C = jnp.asarray(C_bn)
    I3 = jnp.eye(3, dtype=C.dtype)
    G = jnp.zeros((21, 18), C.dtype)
    G = G.at[IDX21.phi, 0:3].set(-C).at[IDX21.dv, 3:6].set(C)
    G = G.at[IDX21.eps_b, 6:9].set(I3).at[IDX21.nabla, 9:12].set(I3)
    G = G.at[IDX21.s_g, 12:15].set(I3).at[IDX21.s_a, 15:18].set(I3)
    return G


def _Qc21(noise: ImuNoise):
    """Qc (18, 18) of W21: diag(ARW^2, VRW^2, 2 sg^2 / tau_g + Kg^2, 2 sa^2 / tau_a + Ka^2, rw_sg^2, rw_sa^2)
    (x3 each): the bias instability with its correlation time is a first-order Gauss-Markov process of
    that stationary sigma (:func:`markov_psd`); the bias random walk K adds its density (tau = inf: only K)."""
    dtype = jnp.result_type(noise.gyro_arw, noise.accel_vrw, float)
    v = lambda x: _vec3(x, dtype)

    def gm(sigma, tau):
        tau = v(tau)
        return jnp.where(jnp.isinf(tau), 0.0, 2.0 * jnp.square(v(sigma)) / jnp.where(jnp.isinf(tau), 1.0, tau))

    return jnp.diag(
        jnp.concatenate(
            [
                jnp.square(v(noise.gyro_arw)),
                jnp.square(v(noise.accel_vrw)),
                gm(noise.gyro_bias_instability, noise.gyro_bias_tau) + jnp.square(v(noise.gyro_bias_rw)),
                gm(noise.accel_bias_instability, noise.accel_bias_tau) + jnp.square(v(noise.accel_bias_rw)),
                jnp.square(v(noise.gyro_sf_rw)),
                jnp.square(v(noise.accel_sf_rw)),
            ]
        )
    )


def discretize_van_loan(F, G, Qc, dt):
    """Exact discretisation of X_dot = F X + G W (F, G, Qc constant over dt) by Van Loan's method.

    A = [[-F, G Qc G^T], [0, F^T]] dt,  B = expm(A) = [[., B12], [0, B22]];
    Phi = B22^T = expm(F dt),  Qd = Phi B12 = int_0^dt expm(F s) G Qc G^T expm(F s)^T ds
    (C. F. Van Loan, IEEE TAC 23(3), 1978). Qd is the Gamma Q Gamma^T of S0 eq. (8); it is
    returned symmetrised.

    Args:
      F: (n, n) continuous system matrix.  G: (n, m) noise input.  Qc: (m, m) noise density.
      dt: scalar interval, s.
    Returns:
      (Phi (n, n), Qd (n, n)).
    """
    n = F.shape[-1]
    GQG = G @ Qc @ G.T
    top = jnp.concatenate([-F, GQG], axis=1)
    bot = jnp.concatenate([jnp.zeros_like(F), F.T], axis=1)
    B = expm(jnp.concatenate([top, bot], axis=0) * dt)
    Phi = B[n:, n:].T
    Qd = Phi @ B[:n, n:]
    return Phi, 0.5 * (Qd + Qd.T)


def discretize_series(F, G, Qc, dt, *, order: int = 2):
    """Truncated-series discretisation: Phi = sum_{k<=order} (F dt)^k / k!, Qd by the trapezoid rule.

    Qd = (Phi G Qc G^T Phi^T + G Qc G^T) dt / 2.
    Local (one-step) errors: Phi is O(dt^(order+1)); Qd is O(dt^3) for any order >= 1 (the trapezoid
    rule's error dominates), so the accumulated errors over a fixed horizon are O(dt^order) for Phi
    and O(dt^2) for Qd. order = 1 is the common Phi = I + F dt; use :func:`discretize_van_loan`
    where dt |F| is not small.

    Args:
      F: (n, n).  G: (n, m).  Qc: (m, m).  dt: scalar interval, s.
      order: static int >= 1, number of series terms after I.
    Returns:
      (Phi (n, n), Qd (n, n)), Qd symmetric.
    """
    if not isinstance(order, int) or order < 1:
        raise ValueError(f"order must be an int >= 1, got {order!r}")
    Fdt = F * dt
    Phi = jnp.eye(F.shape[-1], dtype=F.dtype)
    term = Phi
    for k in range(1, order + 1):
        term = term @ Fdt / k
        Phi = Phi + term
    GQG = G @ Qc @ G.T
    Qd = 0.5 * dt * (Phi @ GQG @ Phi.T + GQG)
    return Phi, 0.5 * (Qd + Qd.T)


def discretize_taylor(F, G, Qc, dt, *, order: int = 8):
    """Discretisation of X_dot = F X + G W by the Taylor series of Phi and of the Van Loan integral.

    Phi = sum_{k<=K} (F dt)^k / k!;  Qd = int_0^dt Phi(s) G Qc G^T Phi(s)^T ds
        = sum_{k<=K} dt^(k+1) / (k+1)! M_k,  M_0 = G Qc G^T,  M_k = F M_{k-1} + M_{k-1} F^T
    (M_k is the k-th derivative of Phi(s) GQG^T Phi(s)^T at s = 0). Both series are those of
    :func:`discretize_van_loan`'s exact result, truncated after K terms: 2K + 1 small products
    instead of a 2n x 2n matrix exponential. For INS error models the large entries of F (the
    specific-force coupling) form a nilpotent chain, so the series converge like dt / tau and
    dt x (Schuler, Earth rates), not like |F dt|: with the GPS epochs of S0 (dt = 1 s, tau >= 300 s)
    K = 8 agrees with Van Loan to 2e-15 (Phi) and 2e-15 (Qd) relative; dt = 10 s with tau = 10 s
    needs Van Loan. ``err`` reports the size of the last Phi term relative to Phi, an estimate of
    the truncation error.

    Args:
      F: (n, n).  G: (n, m).  Qc: (m, m).  dt: scalar interval, s.
      order: static int >= 1, K.
    Returns:
      (Phi (n, n), Qd (n, n) symmetric, err scalar).
    """
    if not isinstance(order, int) or order < 1:
        raise ValueError(f"order must be an int >= 1, got {order!r}")
    Fdt = F * dt
    Phi = jnp.eye(F.shape[-1], dtype=F.dtype)
    term = Phi
    M = G @ Qc @ G.T
    c = dt
    Qd = c * M
    for k in range(1, order + 1):
        term = term @ Fdt / k
        Phi = Phi + term
        M = F @ M + M @ F.T
        c = c * dt / (k + 1)
        Qd = Qd + c * M
    err = jnp.max(jnp.abs(term)) / jnp.max(jnp.abs(Phi))
    return Phi, 0.5 * (Qd + Qd.T), err


def _runs(keep):
    """Sorted indices -> tuple of contiguous slices (static: selecting by slices keeps the XLA graph simple)."""
    runs, start = [], None
    for i, j in zip(keep, keep[1:] + (None,)):
        start = i if start is None else start
        if j != i + 1:
            runs.append(slice(start, i + 1))
            start = None
    return tuple(runs)


def _take(A, runs, axis):
    return jnp.concatenate([A[(slice(None),) * axis + (r,)] for r in runs], axis=axis)


@dataclasses.dataclass(frozen=True, eq=False)
class ErrorModel:
    """An INS error-state model chosen once: its layout and the builders of F, G and Qc.

    Static data plus pure builders, hashed by identity so that a model can be a ``jax.jit`` static
    argument; the array inputs (position, velocity, specific force, C_bn, correlation times, noise
    densities) are arguments of its methods.

    Attributes:
      names: the n state names, in order.  noise_names: the p noise-input names, in order.
      idx: :class:`ErrorStateIndex` of the blocks (None for blocks the model lacks).
      build_F: (pos, v_n, f_n, C_bn, tau, *, ellipsoid, earth_rate_sign[, Cw, Cf]) -> (n, n).
      build_G: (C_bn) -> (n, p).
      build_Qc: (:class:`jaxnav.ins.ImuNoise`) -> (p, p).
      bias_gm: the bias states are first-order Gauss-Markov processes whose correlation times are
        the ``tau`` argument, (6,) = [gyro (3), accelerometer (3)] (the 21-state family); False:
        random constants, and ``tau`` (3,) is the gyro Markov drift's (18-state model) or unused.
    """

    names: tuple
    noise_names: tuple
    idx: ErrorStateIndex
    build_F: Callable
    build_G: Callable
    build_Qc: Callable
    bias_gm: bool = False

    @property
    def scale_factors(self) -> bool:
        """Whether the model has gyro/accelerometer scale-factor states (then F needs ``Cw``, ``Cf``)."""
        return self.idx.s_g is not None

    @property
    def tau_size(self) -> int:
        """Length of the ``tau`` argument: 6 for Gauss-Markov biases, else 3."""
        return 6 if self.bias_gm else 3

    @property
    def n(self) -> int:
        """Number of error states."""
        return len(self.names)

    @property
    def p(self) -> int:
        """Number of noise inputs (the size of Qc)."""
        return len(self.noise_names)

    def F(self, pos, v_n, f_n, C_bn, tau, *, ellipsoid: Ellipsoid = WGS84, earth_rate_sign=1.0, Cw=None, Cf=None):
        """Continuous system matrix F (n, n) of X_dot = F X + G W (module docstring).

        Args:
          pos: (3,) [lat rad, lon rad, h m], float64.  v_n: (3,) ENU velocity, m/s.
          f_n: (3,) specific force in n (= C_bn f_b), m/s^2.  C_bn: (3, 3) body -> nav DCM.
          tau: correlation times, s: scalar or (3,) of the gyro Markov drift (18 states; unused
            without it), or scalar or (6,) [gyro bias (3), accelerometer bias (3)] for Gauss-Markov
            biases (``bias_gm``; inf: a random walk).
          ellipsoid: static Earth model.  earth_rate_sign: +1, or -1 for reverse navigation.
          Cw, Cf: (3, 3) C_bn diag(w_ib_b) (rad/s) and C_bn diag(f_b) (m/s^2), over an interval their
            time averages: the scale-factor couplings (models with scale factors; None: zeros).
        Returns:
          (n, n) F in the order of ``names``.
        """
        kw = dict(Cw=Cw, Cf=Cf) if self.scale_factors else {}
        return self.build_F(pos, v_n, f_n, C_bn, tau, ellipsoid=ellipsoid, earth_rate_sign=earth_rate_sign, **kw)

    def G(self, C_bn):
        """Noise input matrix G (n, p) for C_bn (3, 3), body -> nav DCM."""
        return self.build_G(C_bn)

    def Qc(self, noise: ImuNoise):
        """Continuous noise density Qc (p, p), diagonal, of the model's noise inputs from an :class:`ImuNoise` (SI).

        18 states (S0 eq. 19): ARW^2, 2 sigma^2 / tau of the gyro Markov drift (sigma = the gyro bias
        instability, tau its correlation time), VRW^2. 15 states: ARW^2, VRW^2. 21 states: ARW^2,
        VRW^2, the bias driving densities 2 sigma^2 / tau + K^2 (instability sigma, correlation time
        tau, random walk K) of gyro and accelerometer, the scale-factor random walks squared.
        """
        return self.build_Qc(noise)

    def tau(self, noise: ImuNoise):
        """The ``tau`` argument of :meth:`F` (and ``LCParams.tau_markov``) from an :class:`ImuNoise`, s: the
        gyro bias correlation time (as given: scalar or (3,)), or (6,) [gyro (3), accelerometer (3)]
        for Gauss-Markov biases."""
        if not self.bias_gm:
            return jnp.asarray(noise.gyro_bias_tau)
        dtype = jnp.result_type(noise.gyro_bias_tau, noise.accel_bias_tau, float)
        return jnp.concatenate([_vec3(noise.gyro_bias_tau, dtype), _vec3(noise.accel_bias_tau, dtype)])

    def P0(
        self,
        pos,
        *,
        att,
        vel,
        pos_enu,
        gyro_bias=0.0,
        accel_bias=0.0,
        gyro_markov=0.0,
        gyro_scale=0.0,
        accel_scale=0.0,
        odo_scale=0.0,
    ):
        """Diagonal initial covariance (n, n) from 1-sigma values (SI; scalars or (3,)).

        Args:
          pos: (3,) [lat rad, lon rad, h m] where the ENU position sigmas are converted to
            latitude/longitude.
          att: attitude (phi E, N, U), rad.  vel: ENU velocity, m/s.  pos_enu: ENU position, m.
          gyro_bias: rad/s.  accel_bias: m/s^2.  gyro_markov: Markov drift (models with ``idx.eps_r``), rad/s.
          gyro_scale, accel_scale: scale-factor errors (models with scale factors), dimensionless.
          odo_scale: odometer scale-factor error (models with ``idx.s_odo``), dimensionless.
        Returns:
          (n, n) diagonal P0 in the order of ``names``; sigmas of blocks the model lacks are ignored.
        """
        pos = jnp.asarray(pos)
        dtype = jnp.result_type(pos, float)
        v = lambda x: _vec3(x, dtype)
        dpos = enu_to_curvilinear(pos, v(pos_enu))
        blocks = dict(
            phi=v(att),
            dv=v(vel),
            dpos=dpos,
            eps_b=v(gyro_bias),
            eps_r=v(gyro_markov),
            nabla=v(accel_bias),
            s_g=v(gyro_scale),
            s_a=v(accel_scale),
            s_odo=jnp.reshape(jnp.asarray(odo_scale, dtype), (1,)),
        )
        sd = jnp.zeros(self.n, dtype)
        for name, sl in self.idx._asdict().items():
            if sl is not None:
                sd = sd.at[sl].set(blocks[name])
        return jnp.diag(sd * sd)

    def drop(self, states, noises, idx: ErrorStateIndex) -> ErrorModel:
        """The model without some states and noise inputs.

        F loses the states' rows (their dynamics) and columns (the kept states then take them as
        zero: a sensor error no longer modelled); G loses the states' rows and the noises'
        columns; Qc the noises' rows and columns. Exact selections of the parent's matrices, no new
        algebra.

        Args:
          states, noises: names to remove.  idx: the layout of the result.
        """
        keep = tuple(i for i, nm in enumerate(self.names) if nm not in states)
        nkeep = tuple(i for i, nm in enumerate(self.noise_names) if nm not in noises)
        rs, rn = _runs(keep), _runs(nkeep)
        parent = self

        def build_F(*args, **kwargs):
            return _take(_take(parent.build_F(*args, **kwargs), rs, 0), rs, 1)

        def build_G(C_bn):
            return _take(_take(parent.build_G(C_bn), rs, 0), rn, 1)

        def build_Qc(noise):
            return _take(_take(parent.build_Qc(noise), rn, 0), rn, 1)

        return ErrorModel(
            names=tuple(self.names[i] for i in keep),
            noise_names=tuple(self.noise_names[i] for i in nkeep),
            idx=idx,
            build_F=build_F,
            build_G=build_G,
            build_Qc=build_Qc,
            bias_gm=self.bias_gm,
        )

    def with_odometer_scale(self) -> ErrorModel:
        """The model with one more state appended: the odometer scale-factor error s_odo (dimensionless).

        An odometer reads s_meas = (1 + k) v_fwd; s_odo = k - k_applied is a random constant
        (s_odo_dot = 0, no driving noise): F gains a zero row and column, G a zero row, the noise
        inputs (and Qc) are unchanged. The state enters only through the odometer measurement
        (:data:`jaxnav.ins.measurements.ODOMETER`), whose estimate is fed back to
        ``SensorBiases.odo_scale``.

        Raises:
          ValueError: the model already has the state.
        """
        if self.idx.s_odo is not None:
            raise ValueError("the model already has the odometer scale-factor state")
        parent, n = self, self.n

        def build_F(*args, **kwargs):
            return jnp.pad(parent.build_F(*args, **kwargs), ((0, 1), (0, 1)))

        def build_G(C_bn):
            return jnp.pad(parent.build_G(C_bn), ((0, 1), (0, 0)))

        return ErrorModel(
            names=self.names + ("s_odo",),
            noise_names=self.noise_names,
            idx=self.idx._replace(s_odo=slice(n, n + 1)),
            build_F=build_F,
            build_G=build_G,
            build_Qc=self.build_Qc,
            bias_gm=self.bias_gm,
        )


#: Names of the 9 noise inputs of the 18-state model (S0 eq. 19).
NOISE_NAMES18 = ("w_gx", "w_gy", "w_gz", "w_bx", "w_by", "w_bz", "w_ax", "w_ay", "w_az")

#: The 18-state model of S0 eqs. (18)-(19).
ERROR_MODEL_18 = ErrorModel(
    names=STATE_NAMES18, noise_names=NOISE_NAMES18, idx=IDX18, build_F=_F18, build_G=_G18, build_Qc=_Qc18
)
#: The 15-state model: the 18-state one without the gyro Markov drift eps_r and its driving noise w_b.
ERROR_MODEL_15 = ERROR_MODEL_18.drop(STATE_NAMES18[12:15], NOISE_NAMES18[3:6], IDX15)

#: Names of the 18 noise inputs of the 21-state model.
NOISE_NAMES21 = (
    "w_gx",
    "w_gy",
    "w_gz",
    "w_ax",
    "w_ay",
    "w_az",
    "w_bgx",
    "w_bgy",
    "w_bgz",
    "w_bax",
    "w_bay",
    "w_baz",
    "w_sgx",
    "w_sgy",
    "w_sgz",
    "w_sax",
    "w_say",
    "w_saz",
)
#: The 21-state model: Gauss-Markov / random-walk biases and scale factors (module docstring).
ERROR_MODEL_21 = ErrorModel(
    names=STATE_NAMES21, noise_names=NOISE_NAMES21, idx=IDX21, build_F=_F21, build_G=_G21, build_Qc=_Qc21, bias_gm=True
)
#: The 21-state model without the scale factors: 15 states [phi, dV, dpos, eps_b, nabla] with Gauss-Markov /
#: random-walk biases (tau (6,)), noise [w_g, w_a, w_bg, w_ba] (12).
ERROR_MODEL_15GM = ERROR_MODEL_21.drop(STATE_NAMES21[15:], NOISE_NAMES21[12:], IDX15)

_MODELS = {18: ERROR_MODEL_18, 15: ERROR_MODEL_15, 21: ERROR_MODEL_21}


def error_model_for(n_states: int) -> ErrorModel:
    """The :class:`ErrorModel` with ``n_states`` states (18: S0's model; 15: without the Markov drift;
    21: Gauss-Markov / random-walk biases and scale factors).

    Raises:
      ValueError: no such model.
    """
    if n_states not in _MODELS:
        raise ValueError(f"n_states must be one of {sorted(_MODELS)}, got {n_states!r}")
    return _MODELS[n_states]


__all__ = [
    "ERROR_MODEL_15",
    "ERROR_MODEL_15GM",
    "ERROR_MODEL_18",
    "ERROR_MODEL_21",
    "ErrorModel",
    "ErrorStateIndex",
    "IDX15",
    "IDX18",
    "IDX21",
    "NOISE_NAMES18",
    "NOISE_NAMES21",
    "STATE_NAMES15",
    "STATE_NAMES18",
    "STATE_NAMES21",
    "discretize_series",
    "discretize_taylor",
    "discretize_van_loan",
    "error_model_for",
    "markov_psd",
    "nav_error_F",
]
