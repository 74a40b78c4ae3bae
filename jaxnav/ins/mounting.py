"""IMU mounting rotations: sensor axes -> vehicle axes -> jaxnav body axes (host side, numpy, float64).

Conventions (stated once, tested in ``tests/ins/test_mounting.py``):

* The *vehicle* frame v is forward-right-down (FRD), as in most configs and datasheets.
* A mounting is the attitude (roll, pitch, yaw) of the sensor frame s relative to v, so that a
  vector in sensor axes maps to vehicle axes by

      C_vs = Rz(yaw) Ry(pitch) Rx(roll),       x_v = C_vs x_s,

  with the active right-handed rotations Rx(a) = [[1, 0, 0], [0, c, -s], [0, s, c]] etc. This is
  the usual aerospace z-y-x Euler sequence (Groves 2013, *Principles of GNSS, Inertial, and
  Multisensor Integrated Navigation Systems*, 2nd ed., ch. 2: body-to-navigation C_b^n from the
  attitude (roll, pitch, yaw) of b relative to n has this form).
* Groves-style configurations (Groves' MATLAB ``Euler_to_CTM`` and the Python port used by the
  walk set's upstream project, key ``imu_misalign``) build ``Euler_to_CTM(angles)`` =
  (Rz Ry Rx)^T -- a coordinate transformation matrix *from* the reference frame *to* the rotated
  frame -- and apply it as sensor -> body. Their angles therefore describe the inverse rotation:
  :func:`mounting_from_groves` gives C_vs = (Rz Ry Rx)^T. To turn such a mounting into the
  convention above: ``mounting_to_rpy(mounting_from_groves(r, p, y))``.
* jaxnav's body frame b is right-forward-up (RFU); :func:`sensor_to_body` returns
  C_bs = C_RFU_FRD C_vs, the rotation :func:`jaxnav.io.imu_increments` takes.
"""

from __future__ import annotations

import math

import numpy as np

#: FRD vehicle -> RFU body: right = y_v, forward = x_v, up = -z_v.
C_RFU_FRD = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


def _angle(x, name):
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise ValueError(f"mounting angle {name} must be a number, got {x!r}") from None
    if not math.isfinite(v):
        raise ValueError(f"mounting angle {name} must be finite, got {v}")
    return v


def _rz_ry_rx(roll, pitch, yaw):
    r, p, y = _angle(roll, "roll"), _angle(pitch, "pitch"), _angle(yaw, "yaw")
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    return rz @ ry @ rx


def mounting_from_rpy(roll, pitch, yaw) -> np.ndarray:
    """C_vs (sensor -> FRD vehicle) from the sensor's attitude in the vehicle frame.

    C_vs = Rz(yaw) Ry(pitch) Rx(roll) (z-y-x Euler sequence, active rotations; module docstring).

    Args:
      roll, pitch, yaw: rad.
    Returns:
      (3, 3) float64 rotation matrix.
    """
    return _rz_ry_rx(roll, pitch, yaw)


def mounting_from_rpy_deg(roll_deg, pitch_deg, yaw_deg) -> np.ndarray:
    """:func:`mounting_from_rpy` with the angles in degrees (config key ``mounting_rpy_deg``)."""
    return _rz_ry_rx(
        *(
            math.radians(_angle(a, n))
            for a, n in ((roll_deg, "roll_deg"), (pitch_deg, "pitch_deg"), (yaw_deg, "yaw_deg"))
        )
    )


def mounting_from_groves(roll, pitch, yaw) -> np.ndarray:
    """C_vs from a Groves-style mounting (``Euler_to_CTM`` applied as sensor -> body).

    C_vs = (Rz(yaw) Ry(pitch) Rx(roll))^T: Groves' coordinate transformation matrix
    ``Euler_to_CTM`` (Groves 2013, ch. 2: C_alpha^beta, the transpose of C_beta^alpha for the
    attitude of beta relative to alpha), which the walk set's upstream project applies to sensor
    vectors as its ``imu_misalign``.

    Args:
      roll, pitch, yaw: rad, as written in the Groves-style config.
    Returns:
      (3, 3) float64 rotation matrix, sensor -> FRD vehicle.
    """
    return _rz_ry_rx(roll, pitch, yaw).T


def mounting_from_groves_deg(roll_deg, pitch_deg, yaw_deg) -> np.ndarray:
    """:func:`mounting_from_groves` with the angles in degrees."""
    return mounting_from_groves(
        *(
            math.radians(_angle(a, n))
            for a, n in ((roll_deg, "roll_deg"), (pitch_deg, "pitch_deg"), (yaw_deg, "yaw_deg"))
        )
    )


def mounting_from_dcm(C, *, tol: float = 1e-6) -> np.ndarray:
    """A direct C_vs (sensor -> FRD vehicle), validated.

    Args:
      C: (3, 3) rotation matrix.
      tol: largest accepted |C^T C - I| entry and |det C - 1|.
    Returns:
      (3, 3) float64 copy of ``C``.
    Raises:
      ValueError: for a wrong shape, non-finite entries, a matrix that is not orthonormal, or a
        reflection (det -1: e.g. FRD written as FLU without flipping an axis).
    """
    a = np.array(C, dtype=np.float64)
    if a.shape != (3, 3):
        raise ValueError(f"a mounting DCM must have shape (3, 3), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError("a mounting DCM must be finite")
    err = float(np.max(np.abs(a.T @ a - np.eye(3))))
    if err > tol:
        raise ValueError(f"a mounting DCM must be orthonormal: max |C^T C - I| = {err:.3g} > {tol:g}")
    det = float(np.linalg.det(a))
    if abs(det - 1.0) > tol:
        raise ValueError(
            f"a mounting DCM must be a rotation (det +1), got det = {det:.6g} (a reflection: an axis "
            "is flipped, e.g. left instead of right)"
        )
    return a


def mounting_to_rpy(C_vs) -> tuple:
    """(roll, pitch, yaw), rad, of a C_vs: the inverse of :func:`mounting_from_rpy`.

    pitch = -asin(C[2, 0]) in [-pi/2, pi/2], roll = atan2(C[2, 1], C[2, 2]), yaw = atan2(C[1, 0], C[0, 0]);
    at |pitch| = pi/2 (gimbal lock) roll is set to 0.
    """
    C = mounting_from_dcm(C_vs)
    pitch = -math.asin(max(-1.0, min(1.0, C[2, 0])))
    if math.hypot(C[2, 1], C[2, 2]) < 1e-12:
        return 0.0, pitch, math.atan2(-C[0, 1], C[1, 1])
    return math.atan2(C[2, 1], C[2, 2]), pitch, math.atan2(C[1, 0], C[0, 0])


def sensor_to_body(C_vs) -> np.ndarray:
    """C_bs (sensor -> jaxnav right-forward-up body) = C_RFU_FRD C_vs.

    Args:
      C_vs: (3, 3) sensor -> FRD vehicle (from :func:`mounting_from_rpy` & co.).
    Returns:
      (3, 3) float64; entries below 1e-12 in magnitude set to zero (exact axis permutations stay exact).
    """
    C = C_RFU_FRD @ mounting_from_dcm(C_vs)
    C[np.abs(C) < 1e-12] = 0.0
    return C


def gyro_course_rate_correlation(t_imu, w_up, t_gnss, v_enu, *, min_speed=0.5, bin_s=1.0, max_gap=0.3) -> float:
    """Correlation of the body-up gyro rate with the GNSS course rate while moving: a check of a sensor -> body rotation.

    Over bins of ``bin_s`` s holding at least 3 GNSS epochs (steps < ``max_gap`` s) at horizontal speed
    above ``min_speed`` inside the IMU span: the bin's mean body-up rate against minus the slope of the
    unwrapped course atan2(v_E, v_N) (a counter-clockwise yaw rate is minus the heading rate). With the
    device held roughly level and the right axes the correlation is close to +1; a wrong up axis or sign
    makes it small or negative.

    Args:
      t_imu: (N,) s.  w_up: (N,) body-up angular rate, rad/s.  t_gnss: (M,) s.  v_enu: (M, 3) m/s.
    Returns:
      The Pearson correlation over the bins (NaN with fewer than 2).
    """
    ti, w_up = np.asarray(t_imu, float), np.asarray(w_up, float)
    gt, v = np.asarray(t_gnss, float), np.asarray(v_enu, float)
    walk = (np.hypot(v[:, 0], v[:, 1]) > min_speed) & (gt > ti[0]) & (gt < ti[-1])
    course = np.unwrap(np.arctan2(v[walk, 0], v[walk, 1]))
    tw = gt[walk]
    g_rate, c_rate = [], []
    for a in np.arange(tw[0], tw[-1], bin_s)[:-1]:
        si = (ti >= a) & (ti < a + bin_s)
        sg = (tw >= a) & (tw < a + bin_s)
        if sg.sum() >= 3 and np.all(np.diff(tw[sg]) < max_gap) and si.any():
            g_rate.append(w_up[si].mean())
            c_rate.append(-np.polyfit(tw[sg] - a, course[sg], 1)[0])
    return float(np.corrcoef(g_rate, c_rate)[0, 1])
