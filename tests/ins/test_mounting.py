"""IMU mounting conventions (issue 18): rpy -> C_vs, Groves' Euler_to_CTM convention, direct DCM,
the RFU body rotation; independent references built with scipy's Rotation."""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from jaxnav import ins
from jaxnav.io import imu_increments

ANGLES = [(180.0, -6.79, 185.35), (10.0, 20.0, 30.0), (-35.0, 60.0, -120.0), (3.0, -89.0, 45.0)]


def _angle_deg(A, B):
    return math.degrees(Rotation.from_matrix(A.T @ B).magnitude())


@pytest.mark.parametrize("rpy", ANGLES)
def test_rpy_is_intrinsic_zyx(rpy):
    """C_vs = Rz(yaw) Ry(pitch) Rx(roll): scipy's intrinsic 'ZYX' sequence (yaw, pitch, roll)."""
    r, p, y = rpy
    ref = Rotation.from_euler("ZYX", [y, p, r], degrees=True).as_matrix()
    np.testing.assert_allclose(ins.mounting_from_rpy_deg(r, p, y), ref, atol=1e-14)
    np.testing.assert_allclose(ins.mounting_from_rpy(*np.radians(rpy)), ref, atol=1e-14)
    # a sensor yawed +90 deg (x_s along the vehicle's right): x_s maps to the vehicle's right (+y_v)
    np.testing.assert_allclose(ins.mounting_from_rpy_deg(0, 0, 90) @ [1, 0, 0], [0, 1, 0], atol=1e-15)


@pytest.mark.parametrize("rpy", ANGLES)
def test_groves_is_the_transpose_and_round_trips(rpy):
    r, p, y = rpy
    ref = Rotation.from_euler("ZYX", [y, p, r], degrees=True).as_matrix().T  # Euler_to_CTM, from scratch
    G = ins.mounting_from_groves_deg(r, p, y)
    np.testing.assert_allclose(G, ref, atol=1e-14)
    # the conversion documented in the module: the equivalent rpy of a Groves-style mounting
    r2, p2, y2 = ins.mounting_to_rpy(G)
    np.testing.assert_allclose(ins.mounting_from_rpy(r2, p2, y2), G, atol=1e-12)
    np.testing.assert_allclose(
        ins.mounting_from_rpy(*ins.mounting_to_rpy(ins.mounting_from_rpy_deg(r, p, y))),
        ins.mounting_from_rpy_deg(r, p, y),
        atol=1e-12,
    )


def test_the_issue_case_is_13_6_deg_off():
    """(180, -6.79, 185.35) deg read as Rz Ry Rx (the old code) vs Euler_to_CTM (what upstream applies)."""
    old = Rotation.from_euler("ZYX", [185.35, -6.79, 180.0], degrees=True).as_matrix()
    new = ins.mounting_from_groves_deg(180.0, -6.79, 185.35)
    assert abs(_angle_deg(old, new) - 13.6) < 0.05
    C_bs = ins.sensor_to_body(ins.mounting_from_groves_deg(180.0, -6.79, 185.35))
    np.testing.assert_allclose(C_bs, ins.C_RFU_FRD @ new, atol=1e-12)
    assert _angle_deg(C_bs, ins.C_RFU_FRD @ old) > 13.5


def test_walk_mounting_unchanged():
    """The walk set's (180, 0, -90) is symmetric: diag(-1, -1, 1), as the walk pipeline uses today."""
    from jaxnav.experiments.walk import WALK_SENSOR_TO_BODY

    new = ins.sensor_to_body(ins.mounting_from_groves_deg(180.0, 0.0, -90.0))
    for C in (new, ins.sensor_to_body(ins.mounting_from_rpy_deg(180.0, 0.0, -90.0)), WALK_SENSOR_TO_BODY):
        np.testing.assert_array_equal(C, np.diag([-1.0, -1.0, 1.0]))


def test_sensor_to_body_maps_vehicle_axes_to_rfu():
    """Identity mounting: sensor = FRD vehicle; forward -> body y, right -> body x, down -> -body z."""
    C = ins.sensor_to_body(np.eye(3))
    np.testing.assert_array_equal(C @ [1, 0, 0], [0, 1, 0])
    np.testing.assert_array_equal(C @ [0, 1, 0], [1, 0, 0])
    np.testing.assert_array_equal(C @ [0, 0, 1], [0, 0, -1])
    # a vehicle at rest, level: an FRD accelerometer reads -g on z (up force); in the body: +g on up
    imu = type("I", (), {"t": np.arange(3.0), "w_b": np.zeros((3, 3)), "f_b": np.tile([0.0, 0.0, -9.8], (3, 1))})
    _, _, dv, dt = imu_increments(imu, C)
    np.testing.assert_allclose(dv / dt[:, None], np.tile([0.0, 0.0, 9.8], (3, 1)))


def test_direct_dcm_is_validated():
    good = Rotation.from_euler("xyz", [0.1, 0.2, 0.3]).as_matrix()
    np.testing.assert_array_equal(ins.mounting_from_dcm(good), good)
    with pytest.raises(ValueError, match=r"shape \(3, 3\)"):
        ins.mounting_from_dcm(np.eye(2))
    with pytest.raises(ValueError, match="orthonormal"):
        ins.mounting_from_dcm(good * 1.01)
    with pytest.raises(ValueError, match="det"):
        ins.mounting_from_dcm(np.diag([1.0, 1.0, -1.0]))  # a left-handed frame
    with pytest.raises(ValueError, match="finite"):
        ins.mounting_from_dcm(np.full((3, 3), np.nan))
    with pytest.raises(ValueError, match="yaw"):
        ins.mounting_from_rpy(0.0, 0.0, float("inf"))
    with pytest.raises(ValueError, match="roll_deg"):
        ins.mounting_from_rpy_deg("x", 0.0, 0.0)


def test_gyro_course_rate_correlation_sees_the_up_axis_sign():
    """A walk whose course turns: the body-up rate (minus the heading rate) correlates +1 with the course rate;
    a flipped up axis gives -1."""
    from jaxnav.ins import gyro_course_rate_correlation

    psi = lambda t: 0.3 * np.sin(0.2 * t) + 0.1 * t
    dpsi = lambda t: 0.06 * np.cos(0.2 * t) + 0.1
    t_g = np.arange(0.0, 60.0, 0.1)
    v = 1.2 * np.stack([np.sin(psi(t_g)), np.cos(psi(t_g)), 0.0 * t_g], -1)
    t_i = np.arange(-1.0, 61.0, 0.01)
    w_up = -dpsi(t_i)
    assert gyro_course_rate_correlation(t_i, w_up, t_g, v) > 0.99
    assert gyro_course_rate_correlation(t_i, -w_up, t_g, v) < -0.99
