"""Run pyins (python-ins 1.0.1) for tests/ins/test_pyins.py in a process of its own.

pyins compiles its loops with numba, whose llvmlite carries its own copy of LLVM. Two LLVMs in one
process (numba's and XLA's) is a known source of crashes (numba/numba#7857): a test worker that had
run pyins in-process later segfaulted inside an XLA compile. So everything that imports pyins or
numba runs here, in a subprocess, and comes back as arrays; the test process holds only jaxnav.

Usage: ``python pyins_run.py OUT.npz``. ``sine_motion``, ``P`` and the constants are plain numpy and
are imported by the test module too, so both sides use the same motion.
"""

from __future__ import annotations

import sys

import numpy as np

#: NED <-> ENU and FRD <-> RFU (the same proper rotation; its own inverse).
P = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
DEG = np.pi / 180.0
LLA0 = (30.0, 114.0, 200.0)  # deg, deg, m
T_TOTAL = 3600.0
STATIONARY_RPH = ((0.0, 0.0, 0.0), (0.0, 0.0, 90.0), (20.0, -10.0, 135.0))


def sine_motion(dt, total=T_TOTAL):
    """Vehicle-like sine motion: speed and track oscillate, heading, pitch, roll oscillate; level (VD = 0)."""
    t = np.arange(0.0, total + 0.5 * dt, dt)
    w = 2.0 * np.pi * t
    v_ned = np.stack([8.0 + 4.0 * np.sin(w / 60.0), 6.0 * np.sin(w / 90.0 + 0.5), 0.0 * t], 1)
    rph = np.stack([10.0 * np.sin(w / 20.0), 5.0 * np.sin(w / 30.0 + 1.0), 40.0 + 60.0 * np.sin(w / 120.0)], 1)
    return t, v_ned, rph


def random_rph():
    """200 random [roll, pitch, heading] (deg) for the frame-conversion check."""
    rng = np.random.default_rng(0)
    return rng.uniform([-179.0, -89.0, -180.0], [179.0, 89.0, 360.0], (200, 3))


def _rotvec_to_mat(r0, r1, r2, M):  # pragma: no cover - numba
    """pyins's ``mat_from_rotvec`` (Rodrigues with the same series below |r|^2 = 1e-6)."""
    n2 = r0 * r0 + r1 * r1 + r2 * r2
    if n2 > 1e-6:
        n = np.sqrt(n2)
        cs, k1, k2 = np.cos(n), np.sin(n) / n, (1.0 - np.cos(n)) / n2
    else:
        cs, k1, k2 = 1 - n2 / 2 + n2 * n2 / 24, 1 - n2 / 6 + n2 * n2 / 120, 0.5 - n2 / 24 + n2 * n2 / 720
    M[0, 0], M[0, 1], M[0, 2] = k2 * r0 * r0 + cs, k2 * r0 * r1 - k1 * r2, k2 * r0 * r2 + k1 * r1
    M[1, 0], M[1, 1], M[1, 2] = k2 * r1 * r0 + k1 * r2, k2 * r1 * r1 + cs, k2 * r1 * r2 - k1 * r0
    M[2, 0], M[2, 1], M[2, 2] = k2 * r2 * r0 - k1 * r1, k2 * r2 * r1 + k1 * r0, k2 * r2 * r2 + cs


def _pyins_loop_midpoint(dt, lat, lon, alt, vel, C, theta, dv):  # pragma: no cover - numba
    """pyins's ``_numba_integrate.integrate`` (with_altitude=False) transcribed, NED/FRD, lat/lon in rad,
    with two changes: the latitude (Earth rate, radii, tan L) and the velocity of the Coriolis and
    transport terms are taken at mid-interval (the velocity extrapolated with the previous step's
    acceleration, as jaxnav does). Arrays (N+1,) / (N+1, 3) / (N+1, 3, 3) are filled from index 1."""
    E2, A, RATE = 6.6943799901413e-3, 6378137.0, 7.292115e-5
    a0 = a1 = 0.0
    dBn = np.empty((3, 3))
    dBb = np.empty((3, 3))
    M = np.empty((3, 3))
    for i in range(theta.shape[0]):
        V0, V1 = vel[i, 0] + 0.5 * a0 * dt, vel[i, 1] + 0.5 * a1 * dt  # VD = 0 (height held)
        x = 1 - E2 * np.sin(lat[i]) ** 2
        L = lat[i] + 0.5 * dt * V0 / (A * (1 - E2) / x**1.5 + alt)
        s, c = np.sin(L), np.cos(L)
        x = 1 - E2 * s * s
        re, rn = A / np.sqrt(x) + alt, A * (1 - E2) / x**1.5 + alt
        Om0, Om2 = RATE * c, -RATE * s
        chi0, chi1, chi2 = Om0 + V1 / re, -V0 / rn, Om2 - V1 / re * s / c
        d0 = C[i, 0, 0] * dv[i, 0] + C[i, 0, 1] * dv[i, 1] + C[i, 0, 2] * dv[i, 2]
        d1 = C[i, 1, 0] * dv[i, 0] + C[i, 1, 1] * dv[i, 1] + C[i, 1, 2] * dv[i, 2]
        d2 = C[i, 2, 0] * dv[i, 0] + C[i, 2, 1] * dv[i, 1] + C[i, 2, 2] * dv[i, 2]
        vel[i + 1, 0] = vel[i, 0] + d0 + ((chi2 + Om2) * V1 - 0.5 * (chi1 * d2 - chi2 * d1)) * dt
        vel[i + 1, 1] = vel[i, 1] + d1 + (-(chi2 + Om2) * V0 - 0.5 * (chi2 * d0 - chi0 * d2)) * dt
        vel[i + 1, 2] = 0.0
        a0, a1 = (vel[i + 1, 0] - vel[i, 0]) / dt, (vel[i + 1, 1] - vel[i, 1]) / dt
        Vm0, Vm1 = 0.5 * (vel[i, 0] + vel[i + 1, 0]), 0.5 * (vel[i, 1] + vel[i + 1, 1])
        lat[i + 1] = lat[i] + Vm0 / rn * dt
        lon[i + 1] = lon[i] + Vm1 / (re * c) * dt
        _rotvec_to_mat(-(Om0 + Vm1 / re) * dt, Vm0 / rn * dt, -(Om2 - Vm1 / re * s / c) * dt, dBn)
        _rotvec_to_mat(theta[i, 0], theta[i, 1], theta[i, 2], dBb)
        for r in range(3):
            for k in range(3):
                M[r, k] = C[i, r, 0] * dBb[0, k] + C[i, r, 1] * dBb[1, k] + C[i, r, 2] * dBb[2, k]
        for r in range(3):
            for k in range(3):
                C[i + 1, r, k] = dBn[r, 0] * M[0, k] + dBn[r, 1] * M[1, k] + dBn[r, 2] * M[2, k]


def main(out):  # pragma: no cover - runs in its own process
    import warnings

    import numba
    from pyins import earth as pe
    from pyins import sim, strapdown, transform

    # pyins 1.0.1's Integrator passes pandas' deprecated copy= keyword (a pandas 3 warning, not ours)
    warnings.filterwarnings("ignore", message="The copy keyword is deprecated")
    rotvec = numba.njit(cache=False)(_rotvec_to_mat)
    loop_globals = _pyins_loop_midpoint.__globals__
    loop_globals["_rotvec_to_mat"] = rotvec
    loop = numba.njit(cache=False)(_pyins_loop_midpoint)

    def to_nav(df):
        pos = np.stack([df.lat.to_numpy() * DEG, df.lon.to_numpy() * DEG, df.alt.to_numpy()], 1)
        v = df[["VN", "VE", "VD"]].to_numpy() @ P.T
        C = P @ transform.mat_from_rph(df[["roll", "pitch", "heading"]].to_numpy()) @ P
        return pos, v, C

    res = {}
    for tag, dt in (("c100", 0.01), ("c10", 0.1)):
        t, v_ned, rph = sine_motion(dt)
        traj, imu = sim.generate_imu(t, np.array(LLA0), rph, v_ned, sensor_type="increment")
        inc = strapdown.compute_increments_from_imu(imu, "increment")
        outn = strapdown.Integrator(traj.iloc[0], with_altitude=False).integrate(inc)
        for name, nav in (
            ("truth", to_nav(traj.iloc[1:])),
            ("pyins", to_nav(outn.iloc[1:])),
            ("init", to_nav(traj.iloc[:1])),
        ):
            for k, a in zip(("pos", "v", "C"), nav):
                res[f"{tag}_{name}_{k}"] = a
        res[f"{tag}_dth"] = imu[["gyro_x", "gyro_y", "gyro_z"]].to_numpy()[1:] @ P.T
        res[f"{tag}_dv"] = imu[["accel_x", "accel_y", "accel_z"]].to_numpy()[1:] @ P.T
        res[f"{tag}_n_inc"] = np.array(inc.shape[0])
        if tag == "c100":
            N = inc.shape[0]
            pos0, v0, C0 = to_nav(traj.iloc[:1])
            lat, lon = np.empty(N + 1), np.empty(N + 1)
            vel, C = np.empty((N + 1, 3)), np.empty((N + 1, 3, 3))
            lat[0], lon[0] = pos0[0, 0], pos0[0, 1]
            vel[0] = P @ v0[0]
            C[0] = P @ C0[0] @ P
            loop(
                dt,
                lat,
                lon,
                LLA0[2],
                vel,
                C,
                np.ascontiguousarray(inc[["theta_x", "theta_y", "theta_z"]].to_numpy()),
                np.ascontiguousarray(inc[["dv_x", "dv_y", "dv_z"]].to_numpy()),
            )
            res["mid_pos"] = np.stack([lat[1:], lon[1:], np.full(N, LLA0[2])], 1)
            res["mid_v"] = vel[1:] @ P.T
            res["mid_C"] = P @ C[1:] @ P
        else:
            free = strapdown.Integrator(traj.iloc[0], with_altitude=True).integrate(inc)
            for k, a in zip(("pos", "v", "C"), to_nav(free.iloc[1:])):
                res[f"free_{k}"] = a

    res["rand_C"] = P @ transform.mat_from_rph(random_rph()) @ P
    res["east_C"] = P @ transform.mat_from_rph([0.0, 0.0, 90.0]) @ P
    tt = np.arange(0.0, 10.0, 0.1)
    lla = np.tile([LLA0[0], LLA0[1], 0.0], (len(tt), 1))
    gy, ac = [], []
    for rph in STATIONARY_RPH:
        _, imu = sim.generate_imu(tt, lla, np.tile(rph, (len(tt), 1)), np.zeros((len(tt), 3)), sensor_type="rate")
        gy.append(imu[["gyro_x", "gyro_y", "gyro_z"]].to_numpy()[len(tt) // 2] @ P.T)
        ac.append(imu[["accel_x", "accel_y", "accel_z"]].to_numpy()[len(tt) // 2] @ P.T)
    res["stat_gyro"], res["stat_acc"] = np.array(gy), np.array(ac)
    res["gravity_0"] = np.array(pe.gravity(LLA0[0], 0.0))
    res["gravity_h0"] = np.array(pe.gravity(LLA0[0], LLA0[2]))
    res["rate"], res["a"] = np.array(pe.RATE), np.array(pe.A)
    np.savez(out, **res)


if __name__ == "__main__":  # pragma: no cover
    main(sys.argv[1])
