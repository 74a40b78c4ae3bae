"""Strapdown mechanization against pyins (python-ins 1.0.1), an outside reference.

One hour of sine motion (speed, heading, pitch and roll oscillating) is simulated with pyins's own
trajectory-to-IMU generator (``pyins.sim.generate_imu``, increment-type sensor, 100 Hz). The same
raw increments are mechanized by pyins (``strapdown.compute_increments_from_imu`` for its two-sample
coning/sculling, then ``strapdown.Integrator``) and by :func:`jaxnav.ins.mechanize` (which applies
the identical two-sample corrections itself), both starting from the true state at t_0.

Conventions and their conversion
--------------------------------
pyins: navigation frame NED, body frame forward-right-down (FRD), ``mat_nb`` = body -> NED =
``Rotation.from_euler('xyz', [roll, pitch, heading])`` (extrinsic x, y, z: Rz(heading) Ry(pitch)
Rx(roll)), angles and lat/lon in degrees, velocity [VN, VE, VD], increments (rad, m/s) over
[t_{k-1}, t_k] indexed by t_k, first IMU row duplicated as the "before" sample.
jaxnav: ENU, right-forward-up (RFU), C_bn = Rz(yaw) Rx(pitch) Ry(roll), radians.

Both changes of axes are the same matrix ::

    P = [[0, 1, 0],      x_ENU = y_NED (east),  y_ENU = x_NED (north),  z_ENU = -z_NED
         [1, 0, 0],      x_RFU = y_FRD (right), y_RFU = x_FRD (fwd),    z_RFU = -z_FRD
         [0, 0, -1]]

P is symmetric, P = P^-1 and det P = +1 (a proper rotation, 180 deg about (1, 1, 0)/sqrt 2: both
triads are right-handed), so angular increments (axial vectors) convert exactly like velocity
increments: dtheta_RFU = P dtheta_FRD, dv_RFU = P dv_FRD, v_ENU = P v_NED, and
C_bn(jaxnav) = P mat_nb(pyins) P. In Euler angles this is [pitch, roll, yaw] = [pitch, roll,
-heading]: pitch (nose up, about the right axis) and roll (right wing down, about the forward axis)
mean the same in both, the rotation order (heading/yaw, then pitch, then roll) is the same, and
jaxnav's yaw is counter-clockwise about up. ``test_frame_conversion_*`` check this on random angles
and on the stationary sensor readings pyins generates (Earth rate and gravity in the body axes).
jaxnav's ``nav[i]`` is the state at t_{i+1}; pyins's trajectory row i + 1.

Agreement and where the difference comes from (measured on the 2-core development machine)
-----------------------------------------------------------------------------------------
Height held in both (pyins ``with_altitude=False`` zeroes VD each step and so keeps the altitude;
jaxnav ``hold_height=True`` sets V_U = 0 and keeps h: the same constraint, and the simulated
motion is level, VD = 0). Over 1 h at 100 Hz:

    jaxnav - pyins   horizontal position 6.3 mm, velocity 4.3e-6 m/s, attitude 2.0e-9 rad
    jaxnav - truth   8.6 mm, 7.1e-6 m/s, 1.4e-9 rad;   pyins - truth   9.1 mm, 9.0e-6 m/s, 2.3e-9 rad

for a vehicle that has travelled 29 km. Both are second-order algorithms with the *same* coning and
sculling, but pyins evaluates two terms at the start of the interval where jaxnav uses the
mid-interval value (checked step by step while writing this test: from the same state, jaxnav's
attitude update differs from pyins's by O(dt^3) per step, its velocity update by O(dt^2)):

* the Earth rate, radii and tan L at the start latitude L_k, not L_k + V_N dt / (2 R): an
  Earth-rate error of Omega V_N dt / (2 R) times sin L about north (2.3e-13 rad/s at 100 Hz) and
  cos L about down, which acts like a constant gyro drift and, through the Schuler loop, gives a
  position error growing as R eps_N t = Omega sin L V_N dt t / 2 (5 mm east after 1 h);
* the Coriolis and transport terms with V_k, not V_{k+1/2}: a velocity error
  (2 Omega + rho) x (v(t) - v(0)) dt / 2 (a few 1e-6 m/s).

Both are O(dt) *globally* (``test_discrepancy_is_first_order_in_dt``: the difference shrinks 10.0x
from 10 Hz to 100 Hz, while each one's error against the truth shrinks 75-115x). A transcription of
pyins's loop with just those two terms moved to mid-interval (``_pyins_loop_midpoint`` below,
numba) reproduces jaxnav to 1.9e-6 m, 1.5e-9 m/s and 5e-12 rad over the same hour, so nothing else
differs. The tolerances are 3x the first-order estimate of these two terms computed from the
trajectory (4.3 cm, 1.8e-5 m/s, 1.2e-8 rad at 100 Hz; ``first_order_estimate``); for scale, a
navigation-grade INS drifts ~1.8 km in this hour.

Earth and gravity model: pyins uses the WGS-84 constants jaxnav uses (a, e^2, omega, gamma_e,
gamma_p: Somigliana normal gravity on the ellipsoid agrees to 2e-11 m/s^2) but a linear height
correction gamma_0 (1 - 2 h / a) where jaxnav has (1 - 2 h/a (1 + f + m - 2 f sin^2 L) + 3 h^2/a^2)
(TR8350.2). At h = 200 m that is 3.1e-6 m/s^2. It does not enter the horizontal channels with the
height held; in the free vertical channel it drives the two heights apart as
-dgamma tau^2 (cosh(t / tau) - 1), tau = sqrt(a / 2 g) ~ 9.5 min: predicted / measured 0.615 /
0.605 m after 10 min, 3.21 / 3.21 m after 20 min, 278 / 301 m after 1 h (by then the unstable
channel has amplified everything else too). ``test_free_vertical_channel_gravity_model`` checks
the first 10 min (at 10 Hz). The truth itself is generated with pyins's gravity model, so with a
free vertical channel pyins tracks it better (the horizontal channels are then coupled to the
height difference through the Coriolis term: 1.3 cm, 8e-5 m/s after 10 min).

pyins (and numba, which it imports) runs in a subprocess (``tests/reference/pyins_run.py``): numba's
LLVM beside XLA's in one process crashed a test worker inside a later XLA compile.

Runtime: 20-35 s on the shared 2-core machine (~24 s of CPU: the 100 Hz pyins simulation ~5 s,
numba compiles ~3 s, three jaxnav compiles ~5 s; less with the persistent compilation cache).
"""

from __future__ import annotations

import importlib.util
import pathlib
import subprocess
import sys

import numpy as np
import pytest
from reference.pyins_run import DEG, LLA0, STATIONARY_RPH, P, random_rph, sine_motion

if importlib.util.find_spec("pyins") is None or importlib.util.find_spec("numba") is None:
    pytest.skip("python-ins / numba not installed (pip install -e '.[test]')", allow_module_level=True)

import jax.numpy as jnp
from scipy.spatial.transform import Rotation

from jaxnav.geodesy import meridian_radius, prime_vertical_radius
from jaxnav.ins import NavState, mechanize, normal_gravity
from jaxnav.ins import attitude as att
from jaxnav.ins.earth import earth_rate_n

T_FREE = 600.0  # s of free vertical channel compared


# ----------------------------------------------------------------------------- conversions
def pyins_rph_to_euler(rph_deg):
    """pyins [roll, pitch, heading] (deg) -> jaxnav [pitch, roll, yaw] (rad)."""
    rph = np.deg2rad(np.asarray(rph_deg, float))
    return np.stack([rph[..., 1], rph[..., 0], -rph[..., 2]], axis=-1)


def nav_diff(a, b):
    """Max over time of |E, N, U position diff| (m), |velocity diff| (m/s), attitude angle (rad)."""
    (pa, va, Ca), (pb, vb, Cb) = a, b
    RM = np.asarray(meridian_radius(pb[:, 0])) + pb[:, 2]
    RN = np.asarray(prime_vertical_radius(pb[:, 0])) + pb[:, 2]
    dp = np.stack([(pa[:, 1] - pb[:, 1]) * RN * np.cos(pb[:, 0]), (pa[:, 0] - pb[:, 0]) * RM, pa[:, 2] - pb[:, 2]], 1)
    ang = Rotation.from_matrix(np.einsum("nij,nkj->nik", Ca, Cb)).magnitude()
    return dict(pos=np.abs(dp).max(0), vel=np.abs(va - vb).max(0), att=ang.max(), dpos=dp)


# ----------------------------------------------------------------------------- the reference run
@pytest.fixture(scope="module")
def ref(tmp_path_factory):
    """Everything pyins computes, from its own process (see tests/reference/pyins_run.py)."""
    out = tmp_path_factory.mktemp("pyins") / "pyins.npz"
    script = pathlib.Path(__file__).resolve().parents[1] / "reference" / "pyins_run.py"
    proc = subprocess.run([sys.executable, str(script), str(out)], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    with np.load(out) as f:
        return {k: f[k] for k in f.files}


def _nav(ref, key):
    return tuple(ref[f"{key}_{k}"] for k in ("pos", "v", "C"))


def run_case(ref, tag, dt):
    t, v_ned, _ = sine_motion(dt)
    pos0, v0, C0 = _nav(ref, f"{tag}_init")
    dth, dv = ref[f"{tag}_dth"], ref[f"{tag}_dv"]
    nav0 = NavState(q_bn=att.dcm_to_quat(jnp.asarray(C0[0])), v_n=jnp.asarray(v0[0]), pos=jnp.asarray(pos0[0]))
    res = mechanize(nav0, dth, dv, dt, t=t[1:], hold_height=True)
    assert int(res.status) == 0
    jx = (np.asarray(res.nav.pos), np.asarray(res.nav.v_n), np.asarray(att.quat_to_dcm(res.nav.q_bn)))
    return dict(
        dt=dt,
        t=t,
        v_ned=v_ned,
        n_inc=int(ref[f"{tag}_n_inc"]),
        nav0=nav0,
        dth=dth,
        dv=dv,
        truth=_nav(ref, f"{tag}_truth"),
        pyins=_nav(ref, f"{tag}_pyins"),
        jax=jx,
    )


@pytest.fixture(scope="module")
def case100(ref):
    return run_case(ref, "c100", 0.01)


@pytest.fixture(scope="module")
def case10(ref):
    return run_case(ref, "c10", 0.1)


def first_order_estimate(case, ref):
    """O(dt) discrepancy of pyins's start-of-interval terms (see the module docstring), from the truth."""
    dt, t, v = case["dt"], case["t"], case["v_ned"]
    L = LLA0[0] * DEG
    Om, R = float(ref["rate"]), float(ref["a"])
    vn_mean = abs(v[:, 0].mean())
    # Earth rate at L_k: drift eps = Omega V_N dt / (2 R) about north and down -> R eps t of position.
    eps = Om * vn_mean * dt / (2.0 * R)
    pos_lat, vel_lat, att_lat = R * eps * t[-1], R * eps, eps * t[-1]
    # Coriolis with V_k: velocity error (2 Omega sin L) |v(t) - v(0)| dt / 2, its integral for position.
    dvh = np.hypot(*(v[:, :2] - v[0, :2]).T)
    disp = np.hypot(*np.cumsum((v[:, :2] - v[0, :2]) * dt, axis=0).T)
    k = 2.0 * Om * np.sin(L) * dt / 2.0
    pos_cor, vel_cor = k * disp.max(), k * dvh.max()
    pos, vel = pos_lat + pos_cor, vel_lat + vel_cor
    return dict(pos=pos, vel=vel, att=att_lat + pos / R)


# ----------------------------------------------------------------------------- tests
def test_frame_conversion_euler(ref):
    """P mat_nb(roll, pitch, heading) P == jaxnav euler_to_dcm([pitch, roll, -heading]) for any angles."""
    C_jax = np.asarray(att.euler_to_dcm(jnp.asarray(pyins_rph_to_euler(random_rph()))))
    np.testing.assert_allclose(C_jax, ref["rand_C"], atol=2e-15)
    assert np.isclose(np.linalg.det(P), 1.0) and np.allclose(P @ P, np.eye(3))
    # heading 90 deg (facing east): RFU forward maps to ENU east; jaxnav yaw = -90 deg.
    np.testing.assert_allclose(ref["east_C"] @ [0.0, 1.0, 0.0], [1.0, 0.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(np.asarray(att.heading_to_yaw(jnp.pi / 2)), -np.pi / 2, atol=1e-15)


@pytest.mark.parametrize("i", range(len(STATIONARY_RPH)), ids=[str(r) for r in STATIONARY_RPH])
def test_frame_conversion_stationary_readings(ref, i):
    """pyins's stationary gyro/accel readings, converted to RFU, equal jaxnav's C_bn^T w_ie^n and -C_bn^T g^n."""
    gyro, acc = ref["stat_gyro"][i], ref["stat_acc"][i]
    C_bn = np.asarray(att.euler_to_dcm(jnp.asarray(pyins_rph_to_euler(STATIONARY_RPH[i]))))
    lat = LLA0[0] * DEG
    np.testing.assert_allclose(gyro, C_bn.T @ np.asarray(earth_rate_n(jnp.asarray(lat))), atol=1e-14)
    g = float(normal_gravity(jnp.asarray(lat), 0.0))
    assert abs(g - float(ref["gravity_0"])) < 1e-10  # same normal gravity on the ellipsoid
    # specific force = -g^n, i.e. +g up (the simulator's cubic splines of the rotating-Earth ECI
    # trajectory leave ~1e-6 m/s^2; any axis or sign slip would be ~10 m/s^2)
    np.testing.assert_allclose(acc, C_bn.T @ np.array([0.0, 0.0, g]), atol=1e-5)


def test_agreement_with_pyins_1h_100hz(case100, ref):
    """1 h, 100 Hz, height held: jaxnav and pyins agree within 3x the first-order estimate of their difference."""
    d_jp = nav_diff(case100["jax"], case100["pyins"])
    d_jt = nav_diff(case100["jax"], case100["truth"])
    d_pt = nav_diff(case100["pyins"], case100["truth"])
    est = first_order_estimate(case100, ref)
    print(
        f"\n100 Hz, 1 h, {case100['n_inc']} samples; first-order estimate pos {est['pos']:.2e} m, "
        f"vel {est['vel']:.2e} m/s, att {est['att']:.2e} rad"
    )
    for name, d in (("jaxnav-pyins", d_jp), ("jaxnav-truth", d_jt), ("pyins-truth", d_pt)):
        print(f"  {name}: pos ENU {d['pos']} m, vel {d['vel']} m/s, att {d['att']:.2e} rad")
    assert d_jp["pos"][2] == 0.0 and d_jp["vel"][2] == 0.0  # both hold the height exactly
    assert d_jp["pos"][:2].max() < 3 * est["pos"]
    assert d_jp["vel"].max() < 3 * est["vel"]
    assert d_jp["att"] < 3 * est["att"]
    # Each agrees with the truth at the same level (the common part is the shared two-sample
    # coning/sculling and the simulator); jaxnav is no worse than pyins.
    assert d_jt["pos"].max() < 2e-2 and d_jt["vel"].max() < 2e-5 and d_jt["att"] < 1e-8
    assert d_jt["pos"].max() < 1.5 * d_pt["pos"].max()
    assert d_jt["vel"].max() < 1.5 * d_pt["vel"].max()
    assert d_jt["att"] < 1.5 * d_pt["att"]


def test_pyins_loop_with_midpoint_terms_reproduces_jaxnav(case100, ref):
    """pyins's loop with its two start-of-interval terms moved to mid-interval equals jaxnav to ~1e-5 m."""
    d = nav_diff(case100["jax"], _nav(ref, "mid"))
    print(f"\njaxnav - pyins(midpoint terms): pos {d['pos']} m, vel {d['vel']} m/s, att {d['att']:.2e} rad")
    assert d["pos"].max() < 2e-5 and d["vel"].max() < 2e-8 and d["att"] < 2e-11


def test_discrepancy_is_first_order_in_dt(case10, case100):
    """jaxnav - pyins shrinks ~10x from 10 to 100 Hz (pyins's O(dt) terms); each - truth ~100x (2nd order)."""
    r = {}
    for name, (a, b) in {"jp": ("jax", "pyins"), "jt": ("jax", "truth"), "pt": ("pyins", "truth")}.items():
        d10, d100 = nav_diff(case10[a], case10[b]), nav_diff(case100[a], case100[b])
        r[name] = {k: d10[k].max() / d100[k].max() for k in ("pos", "vel", "att")}
    print(f"\n10 Hz / 100 Hz ratios of the max differences: {r}")
    for k in ("pos", "vel", "att"):
        assert 7.0 < r["jp"][k] < 14.0, (k, r["jp"][k])
    for k in ("pos", "vel"):
        assert r["jt"][k] > 50.0 and r["pt"][k] > 50.0, (k, r["jt"][k], r["pt"][k])
    # 10 Hz: the jaxnav-pyins difference is still small next to their common error against the truth
    d = nav_diff(case10["jax"], case10["pyins"])
    dt_ = nav_diff(case10["jax"], case10["truth"])
    assert d["pos"].max() < 0.2 * dt_["pos"].max()


def test_free_vertical_channel_gravity_model(case10, ref):
    """Free vertical channel (10 Hz, 1 h run, first 10 min compared): the height difference is the
    gravity-model one, -dgamma tau^2 (cosh(t / tau) - 1)."""
    c = case10
    n = int(round(T_FREE / c["dt"]))
    pyi = _nav(ref, "free")
    res = mechanize(c["nav0"], c["dth"], c["dv"], c["dt"], hold_height=False)
    jx = (np.asarray(res.nav.pos), np.asarray(res.nav.v_n), np.asarray(att.quat_to_dcm(res.nav.q_bn)))
    lat, h0 = LLA0[0] * DEG, LLA0[2]
    g_pyins = float(ref["gravity_h0"])
    dgamma = float(normal_gravity(jnp.asarray(lat), h0)) - g_pyins  # jaxnav - pyins, m/s^2
    tau = np.sqrt(float(ref["a"]) / (2.0 * g_pyins))
    tt = c["t"][1:]
    pred = -dgamma * tau**2 * (np.cosh(tt / tau) - 1.0)  # jaxnav h - pyins h (weaker gravity -> higher)
    dh = jx[0][:, 2] - pyi[0][:, 2]
    cut = lambda x, m: tuple(a[:m] for a in x)
    d_jp, d_jt, d_pt = (nav_diff(cut(a, n), cut(b, n)) for a, b in ((jx, pyi), (jx, c["truth"]), (pyi, c["truth"])))
    print(
        f"\nfree vertical, 10 Hz: dgamma = {dgamma:.3e} m/s^2; jaxnav h - pyins h predicted / measured: "
        + ", ".join(f"{tt[i]:.0f} s {pred[i]:.3f} / {dh[i]:.3f} m" for i in (n - 1, 2 * n - 1, 3 * n - 1, len(tt) - 1))
    )
    print(f"  first {T_FREE:.0f} s:")
    for name, d in (("jaxnav-pyins", d_jp), ("jaxnav-truth", d_jt), ("pyins-truth", d_pt)):
        print(f"  {name}: pos ENU {d['pos']} m, vel {d['vel']} m/s, att {d['att']:.2e} rad")
    assert abs(dgamma) > 1e-6  # the models do differ at 200 m
    np.testing.assert_allclose(dh[:n], pred[:n], atol=0.02 + 0.05 * abs(pred[n - 1]))
    assert d_jp["pos"][:2].max() < 0.1 and d_jp["vel"][:2].max() < 5e-4
