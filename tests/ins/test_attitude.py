"""Attitude: scipy's Rotation as the outside reference, round trips (hypothesis), conventions, small angles.

Conventions under test (jaxnav.ins.attitude docstring): Hamilton scalar-first quaternions,
q_bn body -> nav; Euler [pitch, roll, yaw] with C_bn = Rz(yaw) Rx(pitch) Ry(roll); nav ENU,
body right-forward-up; heading = -yaw, clockwise from north; positive pitch = nose up,
positive roll = right wing down.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from jaxnav.ins import attitude as A

TOL = 1e-12
HYP = settings(max_examples=60, deadline=None, derandomize=True)


def _wrap(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def _same_quat(p, q, atol):
    """q and -q are the same rotation."""
    p, q = np.asarray(p), np.asarray(q)
    return min(np.max(np.abs(p - q)), np.max(np.abs(p + q))) <= atol


# -- hypothesis strategies (fixed shapes, bounded values) ------------------------------------

angle = st.floats(-np.pi, np.pi, allow_nan=False)
# |pitch| <= 1.5 rad (86 deg): away from gimbal lock, where roll and yaw are ill-conditioned
euler = st.tuples(st.floats(-1.5, 1.5), angle, angle).map(np.array)
unit3 = (
    st.tuples(*[st.floats(-1, 1)] * 3)
    .filter(lambda v: np.linalg.norm(v) > 1e-3)
    .map(lambda v: np.array(v) / np.linalg.norm(v))
)
# rotation vectors: |phi| < pi - 1e-3 (at pi, phi and -phi are the same rotation)
rotvec = st.tuples(unit3, st.floats(0.0, np.pi - 1e-3)).map(lambda t: t[0] * t[1])
quat = (
    st.tuples(*[st.floats(-1, 1)] * 4)
    .filter(lambda v: np.linalg.norm(v) > 1e-2)
    .map(lambda v: np.array(v) / np.linalg.norm(v))
)
vec3 = st.tuples(*[st.floats(-100, 100)] * 3).map(np.array)

# compiled once: every hypothesis example reuses them (shape (3,) / (4,): no retrace)
_euler_dcm_euler = jax.jit(lambda a: A.dcm_to_euler(A.euler_to_dcm(a)))
_euler_quat_euler = jax.jit(lambda a: A.quat_to_euler(A.euler_to_quat(a)))
_quat_dcm_quat = jax.jit(lambda q: A.dcm_to_quat(A.quat_to_dcm(q)))
_rv_quat_rv = jax.jit(lambda p: A.quat_to_rv(A.rv_to_quat(p)))
_rv_dcm_rv = jax.jit(lambda p: A.quat_to_rv(A.dcm_to_quat(A.rv_to_dcm(p))))
_dcms = jax.jit(lambda a, p, q: jnp.stack([A.euler_to_dcm(a), A.rv_to_dcm(p), A.quat_to_dcm(q)]))
_rotate = jax.jit(
    lambda q, v: (
        A.quat_rotate(q, v),
        A.quat_to_dcm(q) @ v,
        A.quat_mul(A.quat_mul(q, jnp.concatenate([jnp.zeros(1), v])), A.quat_conj(q)),
    )
)


@jax.jit
def _batch(att, phi, q1, q2):
    """Everything the batch tests need, computed in one compiled call."""
    return dict(
        e2d=A.euler_to_dcm(att),
        rv2d=A.rv_to_dcm(phi),
        rv2q=A.rv_to_quat(phi),
        q2d1=A.quat_to_dcm(q1),
        q2d2=A.quat_to_dcm(q2),
        q2dneg=A.quat_to_dcm(-q1),
        mul=A.quat_mul(q1, q2),
        q1q1c=A.quat_mul(q1, A.quat_conj(q1)),
        norm=A.quat_normalize(3.0 * q1),
        q2rv=A.quat_to_rv(q1),
        q2rvneg=A.quat_to_rv(-q1),
        skew=A.skew(q1[:, 1:]),
        q2dmul=A.quat_to_dcm(A.quat_mul(q1, q2)),
        d2q=A.dcm_to_quat(A.quat_to_dcm(q1)),
        e2q2d=A.quat_to_dcm(A.euler_to_quat(att)),
    )


# -- 1. outside reference: scipy.spatial.transform.Rotation ----------------------------------


@pytest.fixture(scope="module")
def rand():
    rng = np.random.default_rng(0)
    n = 200
    att = np.c_[rng.uniform(-1.5, 1.5, n), rng.uniform(-np.pi, np.pi, n), rng.uniform(-np.pi, np.pi, n)]
    phi = rng.normal(size=(n, 3))
    q1 = Rotation.random(n, random_state=1).as_quat(scalar_first=True)
    q2 = Rotation.random(n, random_state=2).as_quat(scalar_first=True)
    out = {k: np.array(v) for k, v in _batch(*(jnp.array(x) for x in (att, phi, q1, q2))).items()}
    return att, phi, q1, q2, out


def test_matches_scipy(rand):
    att, phi, q1, q2, out = rand
    # C_bn = Rz(yaw) Rx(pitch) Ry(roll) is scipy's intrinsic 'ZXY' sequence (yaw, pitch, roll)
    ref = Rotation.from_euler("ZXY", att[:, [2, 0, 1]]).as_matrix()
    np.testing.assert_allclose(out["e2d"], ref, rtol=0, atol=1e-15)
    np.testing.assert_allclose(out["rv2d"], Rotation.from_rotvec(phi).as_matrix(), rtol=0, atol=1e-15)
    qs = Rotation.from_rotvec(phi).as_quat(scalar_first=True, canonical=True)
    q = out["rv2q"]
    np.testing.assert_allclose(q * np.sign(q[:, :1]), qs, rtol=0, atol=1e-15)
    np.testing.assert_allclose(out["q2d1"], Rotation.from_quat(q1, scalar_first=True).as_matrix(), rtol=0, atol=1e-15)
    # Hamilton product = scipy composition (apply q2 first, then q1)
    ref = (Rotation.from_quat(q1, scalar_first=True) * Rotation.from_quat(q2, scalar_first=True)).as_quat(
        scalar_first=True
    )
    assert all(_same_quat(p, r, 1e-15) for p, r in zip(out["mul"], ref))
    # dcm_to_quat returns w >= 0 and matches scipy's quaternion of the same matrix (up to sign)
    C = out["q2d1"]
    assert np.all(out["d2q"][:, 0] >= 0)
    assert all(_same_quat(p, r, 1e-15) for p, r in zip(out["d2q"], Rotation.from_matrix(C).as_quat(scalar_first=True)))
    # rotation vectors back
    np.testing.assert_allclose(out["q2rv"], Rotation.from_quat(q1, scalar_first=True).as_rotvec(), rtol=0, atol=1e-14)


# -- 2. round trips and invariants (hypothesis) ------------------------------------------------


@HYP
@given(euler)
def test_euler_dcm_quat_round_trips(att):
    a = jnp.array(att)
    assert np.max(np.abs(_wrap(_euler_dcm_euler(a) - att))) < TOL
    assert np.max(np.abs(_wrap(_euler_quat_euler(a) - att))) < TOL


@HYP
@given(quat)
def test_quat_dcm_quat_round_trip(q):
    assert _same_quat(_quat_dcm_quat(jnp.array(q)), q, TOL)


@HYP
@given(rotvec)
def test_rv_round_trips(phi):
    p = jnp.array(phi)
    np.testing.assert_allclose(_rv_quat_rv(p), phi, rtol=0, atol=TOL)
    np.testing.assert_allclose(_rv_dcm_rv(p), phi, rtol=0, atol=TOL)


@HYP
@given(euler, rotvec, quat)
def test_dcms_are_rotations(att, phi, q):
    Cs = np.array(_dcms(jnp.array(att), jnp.array(phi), jnp.array(q)))
    for C in Cs:
        np.testing.assert_allclose(C @ C.T, np.eye(3), rtol=0, atol=TOL)
        assert abs(np.linalg.det(C) - 1.0) < TOL


@HYP
@given(quat, vec3)
def test_quat_rotate_equals_dcm_and_sandwich(q, v):
    r, Cv, sandwich = (np.array(x) for x in _rotate(jnp.array(q), jnp.array(v)))
    np.testing.assert_allclose(r, Cv, rtol=0, atol=1e-12)
    np.testing.assert_allclose(sandwich[1:], Cv, rtol=0, atol=1e-12)
    assert abs(sandwich[0]) < 1e-12
    assert abs(np.linalg.norm(r) - np.linalg.norm(v)) < 1e-12


def test_quaternion_algebra(rand):
    att, _, q1, q2, out = rand
    # dcm(p (x) q) = dcm(p) dcm(q); q (x) q* = identity; normalisation
    np.testing.assert_allclose(out["q2dmul"], out["q2d1"] @ out["q2d2"], rtol=0, atol=1e-15)
    np.testing.assert_allclose(out["q1q1c"], np.broadcast_to([1.0, 0, 0, 0], q1.shape), rtol=0, atol=1e-15)
    np.testing.assert_allclose(out["norm"], q1, rtol=0, atol=1e-15)
    # the sign of q does not change the rotation
    np.testing.assert_allclose(out["q2dneg"], out["q2d1"], rtol=0, atol=1e-15)
    np.testing.assert_allclose(out["q2rvneg"], out["q2rv"], rtol=0, atol=1e-15)
    # skew(a) b = a x b
    np.testing.assert_allclose(
        np.einsum("nij,nj->ni", out["skew"], q2[:, 1:]), np.cross(q1[:, 1:], q2[:, 1:]), rtol=0, atol=1e-15
    )
    # euler_to_quat is the quaternion of euler_to_dcm
    np.testing.assert_allclose(out["e2q2d"], out["e2d"], rtol=0, atol=1e-15)


def test_dcm_to_quat_half_turns():
    """180-degree rotations take the branches of dcm_to_quat with w ~ 0."""
    axes = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0], [1, 1, 1], [0, 1, -1], [-2, 1, 3]], float)
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    d2q2d = jax.jit(lambda C: (A.dcm_to_quat(C), A.quat_to_dcm(A.dcm_to_quat(C))))
    for angle_ in (np.pi, np.pi - 1e-9, np.pi - 1e-3):
        C = jnp.array(Rotation.from_rotvec(angle_ * axes).as_matrix())
        q, C2 = d2q2d(C)
        np.testing.assert_allclose(C2, C, rtol=0, atol=1e-15)
        np.testing.assert_allclose(np.linalg.norm(q, axis=-1), 1.0, rtol=0, atol=1e-15)
        assert np.all(np.array(q)[:, 0] >= 0)


# -- 3. conventions ----------------------------------------------------------------------------

FWD, RIGHT, UP = np.array([0.0, 1.0, 0.0]), np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])


_euler_to_dcm = jax.jit(A.euler_to_dcm)


def _C(pitch=0.0, roll=0.0, heading=None, yaw=0.0):
    if heading is not None:
        yaw = float(A.heading_to_yaw(np.radians(heading)))
    return np.array(_euler_to_dcm(jnp.array([np.radians(pitch), np.radians(roll), yaw])))


def test_heading_convention():
    # heading 30 deg (clockwise from north): the forward axis points east 0.5, north 0.866
    np.testing.assert_allclose(_C(heading=30.0) @ FWD, [0.5, np.sqrt(3) / 2, 0.0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(_C(heading=90.0) @ FWD, [1.0, 0.0, 0.0], rtol=0, atol=1e-15)  # east
    np.testing.assert_allclose(_C(heading=0.0) @ FWD, [0.0, 1.0, 0.0], rtol=0, atol=1e-15)  # north
    np.testing.assert_allclose(_C(heading=0.0) @ RIGHT, [1.0, 0.0, 0.0], rtol=0, atol=1e-15)  # level, right = east
    np.testing.assert_allclose(_C(heading=0.0) @ UP, [0.0, 0.0, 1.0], rtol=0, atol=1e-15)
    # yaw is counter-clockwise about up: yaw +90 deg points forward to the west
    np.testing.assert_allclose(_C(yaw=np.pi / 2) @ FWD, [-1.0, 0.0, 0.0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(float(A.heading_to_yaw(np.radians(30.0))), -np.radians(30.0), rtol=0, atol=1e-15)
    h = np.linspace(0.0, 2 * np.pi, 73, endpoint=False)
    np.testing.assert_allclose(A.yaw_to_heading(A.heading_to_yaw(jnp.array(h))), h, rtol=0, atol=1e-13)
    y = np.array(A.heading_to_yaw(jnp.array(h)))
    assert np.all(y > -np.pi - 1e-15) and np.all(y <= np.pi)  # wrapped
    np.testing.assert_allclose(float(A.yaw_to_heading(-np.radians(30.0))), np.radians(30.0), rtol=0, atol=1e-15)
    assert 0.0 <= float(A.yaw_to_heading(np.radians(30.0))) < 2 * np.pi  # 330 deg


def test_pitch_and_roll_conventions():
    # positive pitch raises the forward axis (nose up), at any heading
    for hdg in (0.0, 30.0, 200.0):
        fwd = _C(pitch=10.0, heading=hdg) @ FWD
        np.testing.assert_allclose(fwd[2], np.sin(np.radians(10.0)), rtol=0, atol=1e-15)
        # positive roll lowers the right wing: body x gets a negative up component (docstring)
        right = _C(roll=10.0, heading=hdg) @ RIGHT
        np.testing.assert_allclose(right[2], -np.sin(np.radians(10.0)), rtol=0, atol=1e-15)
        # and roll leaves the forward axis level, pitch leaves the right axis level
        assert abs((_C(roll=10.0, heading=hdg) @ FWD)[2]) < 1e-15
        assert abs((_C(pitch=10.0, heading=hdg) @ RIGHT)[2]) < 1e-15
    # the Euler angles come back as [pitch, roll, yaw] in their documented ranges
    e = np.array(jax.jit(A.dcm_to_euler)(jnp.array(_C(pitch=10.0, roll=-20.0, heading=200.0))))
    np.testing.assert_allclose(e, [np.radians(10.0), np.radians(-20.0), np.radians(160.0)], rtol=0, atol=1e-15)
    # rotation vector about up = yaw; quaternion of a 90 deg yaw
    np.testing.assert_allclose(jax.jit(A.rv_to_dcm)(jnp.array([0.0, 0.0, 0.3])), _C(yaw=0.3), rtol=0, atol=1e-15)
    s = np.sqrt(0.5)
    np.testing.assert_allclose(
        jax.jit(A.euler_to_quat)(jnp.array([0.0, 0.0, np.pi / 2])), [s, 0, 0, s], rtol=0, atol=1e-15
    )
    np.testing.assert_allclose(
        jax.jit(A.rv_to_quat)(jnp.array([0.0, 0.0, np.pi / 2])), [s, 0, 0, s], rtol=0, atol=1e-15
    )


def test_dcm_to_euler_accurate_near_gimbal_lock():
    back = jax.jit(lambda C: A.euler_to_dcm(A.dcm_to_euler(C)))
    for d in (1e-4, 1e-6, 1e-8):
        for sgn in (1.0, -1.0):
            C = _euler_to_dcm(jnp.array([sgn * (np.pi / 2 - d), 0.3, -1.0]))
            np.testing.assert_allclose(back(C), C, rtol=0, atol=1e-14)


def test_gimbal_lock_is_finite_and_consistent():
    for sgn in (1.0, -1.0):
        C = _euler_to_dcm(jnp.array([sgn * np.pi / 2, 0.3, -1.0]))
        e = jax.jit(A.dcm_to_euler)(C)
        assert bool(jnp.all(jnp.isfinite(e)))
        np.testing.assert_allclose(_euler_to_dcm(e), C, rtol=0, atol=1e-14)


# -- 4. rotation vector <-> quaternion at and near zero ---------------------------------------

U = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])


def _rvq_closed(p):
    t = jnp.linalg.norm(p)
    return jnp.concatenate([jnp.cos(0.5 * t)[None], jnp.sin(0.5 * t) / t * p])


def _qrv_closed(q):
    n = jnp.linalg.norm(q[1:])
    return 2.0 * jnp.arctan2(n, q[0]) / n * q[1:]


def _q_of(n):
    """Unit quaternion with |vector part| = n along U."""
    return jnp.array(np.r_[np.sqrt(1.0 - n * n), n * U])


@jax.jit
def _derivatives_at_zero(z, q0, v):
    return dict(
        q=A.rv_to_quat(z),
        C=A.rv_to_dcm(z),
        Jf=jax.jacfwd(A.rv_to_quat)(z),
        Jr=jax.jacrev(A.rv_to_quat)(z),
        H=jax.hessian(A.rv_to_quat)(z),
        rv=A.quat_to_rv(q0),
        rvneg=A.quat_to_rv(-q0),
        Kf=jax.jacfwd(A.quat_to_rv)(q0),
        Kr=jax.jacrev(A.quat_to_rv)(q0),
        K2=jax.hessian(A.quat_to_rv)(q0),
        dCv=jax.jacfwd(lambda p: A.rv_to_dcm(p) @ v)(z),
        skew=A.skew(v),
    )


def test_rv_quat_at_exactly_zero():
    d = {
        k: np.array(x)
        for k, x in _derivatives_at_zero(
            jnp.zeros(3), jnp.array([1.0, 0.0, 0.0, 0.0]), jnp.array([1.0, 2.0, 3.0])
        ).items()
    }
    np.testing.assert_array_equal(d["q"], [1.0, 0.0, 0.0, 0.0])
    np.testing.assert_array_equal(d["C"], np.eye(3))
    J_ref = np.r_[np.zeros((1, 3)), 0.5 * np.eye(3)]
    np.testing.assert_array_equal(d["Jf"], J_ref)
    np.testing.assert_array_equal(d["Jr"], J_ref)
    assert np.all(np.isfinite(d["H"]))
    np.testing.assert_allclose(d["H"][0], -0.25 * np.eye(3), rtol=0, atol=1e-15)  # cos(|phi|/2) ~ 1 - |phi|^2/8
    np.testing.assert_array_equal(d["H"][1:], 0.0)

    np.testing.assert_array_equal(d["rv"], np.zeros(3))
    np.testing.assert_array_equal(d["rvneg"], np.zeros(3))  # -identity is the same rotation
    K_ref = np.c_[np.zeros((3, 1)), 2.0 * np.eye(3)]
    np.testing.assert_array_equal(d["Kf"], K_ref)
    np.testing.assert_array_equal(d["Kr"], K_ref)
    assert np.all(np.isfinite(d["K2"]))
    # the DCM's gradient at zero: d(R v)/d phi = -[v x]
    np.testing.assert_allclose(d["dCv"], -d["skew"], rtol=0, atol=1e-15)


def test_rv_to_quat_near_the_small_angle_switch():
    """|phi|^2 < 1e-8 switches to the series: values and Jacobians match the closed form on both sides."""
    jac = jax.jit(jax.jacfwd(A.rv_to_quat))
    jac_ref = jax.jit(jax.jacfwd(_rvq_closed))
    f = jax.jit(A.rv_to_quat)
    for t in np.r_[1e-4 * (1 + np.linspace(-1e-3, 1e-3, 11)), 3e-5, 3e-4, 1e-6]:
        p = jnp.array(t * U)
        np.testing.assert_allclose(f(p), _rvq_closed(p), rtol=0, atol=1e-15)
        np.testing.assert_allclose(jac(p), jac_ref(p), rtol=0, atol=1e-15)
    lo, hi = jnp.array(1e-4 * (1 - 1e-12) * U), jnp.array(1e-4 * (1 + 1e-12) * U)
    np.testing.assert_allclose(f(hi), f(lo), rtol=0, atol=1e-15)  # no jump across the switch
    np.testing.assert_allclose(jac(hi), jac(lo), rtol=0, atol=1e-15)


def test_quat_to_rv_near_the_small_angle_switch():
    """|q_vec|^2 < 1e-12 (|phi| < 2e-6) switches to the series."""
    jac = jax.jit(jax.jacfwd(A.quat_to_rv))
    jac_ref = jax.jit(jax.jacfwd(_qrv_closed))
    f = jax.jit(A.quat_to_rv)
    for n in np.r_[1e-6 * (1 + np.linspace(-1e-3, 1e-3, 11)), 3e-7, 3e-6, 1e-4]:
        q = _q_of(n)
        np.testing.assert_allclose(f(q), _qrv_closed(q), rtol=0, atol=1e-15)
        np.testing.assert_allclose(jac(q), jac_ref(q), rtol=0, atol=1e-15)
    lo, hi = _q_of(1e-6 * (1 - 1e-10)), _q_of(1e-6 * (1 + 1e-10))
    np.testing.assert_allclose(f(hi), f(lo), rtol=0, atol=1e-15)
    np.testing.assert_allclose(jac(hi), jac(lo), rtol=0, atol=1e-15)
    # and the pair inverts each other through the switch region
    for t in (1e-7, 2e-6, 1e-4, 1e-3):
        np.testing.assert_allclose(_rv_quat_rv(jnp.array(t * U)), t * U, rtol=1e-15, atol=0)


def test_batched_jit_vmap(rand):
    """Leading batch dimensions = jit(vmap) = a loop of single jitted calls; and equal scipy."""
    att = jnp.array(rand[0][:16])
    f = lambda a: A.quat_to_rv(A.euler_to_quat(a))
    batched = np.array(jax.jit(f)(att))
    np.testing.assert_allclose(np.array(jax.jit(jax.vmap(f))(att)), batched, rtol=0, atol=1e-15)
    g = jax.jit(f)  # one compile for shape (3,), reused in the loop
    np.testing.assert_allclose(np.stack([np.array(g(a)) for a in att]), batched, rtol=0, atol=1e-15)
    ref = Rotation.from_euler("ZXY", np.array(att)[:, [2, 0, 1]]).as_rotvec()
    np.testing.assert_allclose(batched, ref, rtol=0, atol=1e-14)


def test_rv_to_quat_series_is_exact_up_to_two_pi():
    """The power series of the block mechanization equals scipy's rotation to rounding for |phi| <= 2 pi,
    and is smooth at zero (its Jacobian there is [0; I/2])."""
    rng = np.random.default_rng(7)
    u = rng.normal(size=(20000, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    for tmax in (1e-6, 1e-2, 1.0, np.pi, A.SERIES_MAX_ANGLE):
        phi = u * rng.uniform(0.0, tmax, (20000, 1))
        q = np.stack(jax.jit(A.rv_to_quat_series_c)(*jnp.asarray(phi.T)), axis=-1)
        ref = Rotation.from_rotvec(phi).as_quat()[:, [3, 0, 1, 2]]  # scipy: scalar last, w >= 0
        err = np.minimum(np.abs(q - ref).max(axis=1), np.abs(q + ref).max(axis=1))
        assert err.max() < 2e-15, (tmax, err.max())  # measured 9.0e-16 at 2 pi, 3.3e-16 at pi
        np.testing.assert_allclose(np.sum(q * q, axis=1), 1.0, rtol=0, atol=4e-15)
    J = jax.jacfwd(lambda p: jnp.stack(A.rv_to_quat_series_c(*p)))(jnp.zeros(3))
    np.testing.assert_array_equal(np.asarray(J), np.vstack([np.zeros(3), 0.5 * np.eye(3)]))
