"""A simulated car for the issue-18 input tests (alignment, time offset, standstill): static start,
drives with turns, a stop, drives again; 100 Hz ideal IMU from jaxnav.sim plus chosen sensor noise.

Built once per test session (lru_cache); ~10 000 samples."""

import functools
import math

import numpy as np

import jaxnav
from jaxnav import sim

LAT, LON, H = math.radians(45.0), math.radians(7.0), 300.0
RATE = 100.0
HEADING0 = math.radians(37.0)
D = math.radians


@functools.cache
def car():
    """Truth: t (N+1,), euler (N+1, 3) [pitch, roll, yaw], v_n, pos; ideal dtheta, dv (N, 3); rest spans."""
    jaxnav.enable_x64()
    S = sim.Segment
    segs = (
        S("rest", 20.0),
        S("accelerate", 4.0, dspeed=8.0),
        S("turn", 6.0, dheading=D(90)),
        S("cruise", 4.0),
        S("turn", 5.0, dheading=D(-60)),
        S("accelerate", 4.0, dspeed=-8.0),
        S("rest", 10.0),
        S("accelerate", 3.0, dspeed=6.0),
        S("turn", 4.0, dheading=D(45)),
        S("turn", 6.0, dheading=D(-110)),
        S("cruise", 3.0),
        S("turn", 4.0, dheading=D(70)),
        S("accelerate", 3.0, dspeed=-6.0),
        S("rest", 5.0),
    )
    spec = sim.TrajectorySpec(lat=LAT, lon=LON, h=H, heading=HEADING0, segments=segs)
    tr = sim.generate_trajectory(spec, imu_rate_hz=RATE)
    t = np.asarray(tr.t)
    speed = np.linalg.norm(np.asarray(tr.v_n), axis=1)
    return dict(
        t=t,
        euler=np.asarray(tr.euler),
        v_n=np.asarray(tr.v_n),
        pos=np.asarray(tr.pos),
        dtheta=np.asarray(tr.dtheta),
        dv=np.asarray(tr.dv),
        speed=speed,
        dt=1.0 / RATE,
    )


def measured(seed=0, *, arw=None, vrw=None, gyro_bias=(0.0, 0.0, 0.0), accel_bias=(0.0, 0.0, 0.0), vibration=True):
    """(t_imu (N,), w_b (N, 3) rad/s, f_b (N, 3) m/s^2) at the interval ends t[1:], body RFU.

    Consumer-class noise by default (ARW 0.5 deg/sqrt(h), VRW 0.1 m/s/sqrt(h)); ``vibration`` adds
    road/engine vibration while the car moves (white, 0.3 m/s^2 and 0.02 rad/s per sample), which
    is what makes a moving car at constant velocity distinguishable from a parked one.
    """
    c = car()
    rng = np.random.default_rng(seed)
    dt = c["dt"]
    n = c["dtheta"].shape[0]
    noise = jaxnav.ins.noise_preset("consumer")
    arw = noise.gyro_arw if arw is None else arw
    vrw = noise.accel_vrw if vrw is None else vrw
    w = c["dtheta"] / dt + np.asarray(gyro_bias) + rng.standard_normal((n, 3)) * arw / math.sqrt(dt)
    f = c["dv"] / dt + np.asarray(accel_bias) + rng.standard_normal((n, 3)) * vrw / math.sqrt(dt)
    if vibration:
        moving = (c["speed"][1:] > 0.05)[:, None]
        w = w + moving * rng.standard_normal((n, 3)) * 0.02
        f = f + moving * rng.standard_normal((n, 3)) * 0.3
    return c["t"][1:], w, f


def gnss(rate_hz=10.0, *, sigma_v=0.02, seed=1, t_shift=0.0):
    """GNSS epochs (every 1/rate_hz s) with true ENU velocity + white noise, positions exact.

    Returns (t (M,), v_enu (M, 3), llh (M, 3)); ``t_shift`` is added to the epochs' time tags.
    """
    c = car()
    step = int(round(RATE / rate_hz))
    k = np.arange(0, c["t"].size, step)
    rng = np.random.default_rng(seed)
    v = c["v_n"][k] + rng.standard_normal((k.size, 3)) * sigma_v
    return c["t"][k] + t_shift, v, c["pos"][k]


def rest_truth(t):
    """True standstill flag at the IMU sample times (interval (t-dt, t] at rest)."""
    c = car()
    s = c["speed"]
    still = (s[1:] < 1e-9) & (s[:-1] < 1e-9)
    return np.interp(t, c["t"][1:], still.astype(float)) > 0.5
