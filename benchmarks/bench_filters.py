"""Benchmark jaxnav's Kalman filter and RTS smoother against peer libraries.

A script, not a test. Run it from the repository root in the bench environment:

    make bench                                   # full run, rewrites benchmarks/RESULTS.md
    .venv-bench/bin/python benchmarks/bench_filters.py --quick          # smoke run, writes nothing
    .venv-bench/bin/python benchmarks/bench_filters.py --T 3600 --batch 256 --repeats 7

Problem (identical for every implementation): 3-D constant velocity, dt = 1 s, continuous
white-noise acceleration PSD q = 1e-6 m^2/s^3, position measurements with sigma = 3 mm,
T epochs simulated from the model with a fixed NumPy seed; float64 throughout.

Cases: (a) one sequence, filter only; (b) one sequence, filter + RTS smoother; (c) a batch of
B sequences, filter only (vmap for the JAX implementations, native batching for simdkalman,
a few sequences timed and extrapolated linearly for the loop-based NumPy peers); (d)-(h): per-sequence
covariances, gradients and batch filter + RTS, as the section titles of the report say.

See benchmarks/README.md for what every column means.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import os
import platform
import re
import statistics
import sys
import time
import warnings
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from _harness import cpu_model, git_revision, loadavg, write_section
from _harness import package_version as _version

import jaxnav

jaxnav.enable_x64()
# Honest compile times: never read compiled executables from a persistent cache.
jax.config.update("jax_enable_compilation_cache", False)

from jaxnav import filters as jf
from jaxnav import tune as jtune

HERE = Path(__file__).resolve().parent
BEGIN = "<!-- BEGIN bench_filters results (generated; rerun the script to refresh) -->"
END = "<!-- END bench_filters results -->"

DT, SIGMA, Q_PSD = 1.0, 0.003, 1e-6
N_STATE, N_OBS = 6, 3


# --------------------------------------------------------------------------------------
# the problem
# --------------------------------------------------------------------------------------


def model_matrices(dt=DT, sigma=SIGMA, q=Q_PSD):
    """F, H, Q, R of the 3-D constant-velocity model, written out independently of jaxnav."""
    I3, Z3 = np.eye(3), np.zeros((3, 3))
    F = np.block([[I3, dt * I3], [Z3, I3]])
    H = np.hstack([I3, Z3])
    Q = q * np.kron(np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]]), I3)
    R = sigma**2 * np.eye(3)
    return F, H, Q, R


def initial_moments():
    """Prior at k = 0: mean zero, 1 m position and 0.1 m/s velocity standard deviations."""
    x0 = np.zeros(N_STATE)
    P0 = np.diag([1.0] * 3 + [0.01] * 3)
    return x0, P0


def simulate(T, B, seed=20240611):
    """B sequences of T position measurements, drawn from the model (state and noise)."""
    F, H, Q, R = model_matrices()
    x0, P0 = initial_moments()
    rng = np.random.default_rng(seed)
    LQ, LR, LP = np.linalg.cholesky(Q), np.linalg.cholesky(R), np.linalg.cholesky(P0)
    x = x0 + rng.standard_normal((B, N_STATE)) @ LP.T
    zs = np.empty((B, T, N_OBS))
    for t in range(T):
        x = x @ F.T + rng.standard_normal((B, N_STATE)) @ LQ.T
        zs[:, t] = x @ H.T + rng.standard_normal((B, N_OBS)) @ LR.T
    return zs


def first_prior(F, Q, x0, P0):
    """The prior of epoch 1, for peers whose initial moments are the first *predicted* ones.

    jaxnav and filterpy's batch_filter predict before the first update (x0, P0 live at k = 0);
    dynamax, pykalman and simdkalman update first, so they get (F x0, F P0 F^T + Q).
    """
    return F @ x0, F @ P0 @ F.T + Q


def flops_per_step(n=N_STATE, m=N_OBS):
    """Nominal dense floating-point operations of one textbook Joseph-form KF step (multiply+add = 2).

    A fixed yardstick for the rates (jaxnav's per-sequence step executes about this; its
    shared-recursion batch far fewer).

    predict: F x (2n^2), F P F^T (4n^3), + Q (n^2);
    update:  H x (2mn), P H^T (2n^2 m), H (P H^T) + R (2m^2 n + m^2), Cholesky (m^3/3),
             K by two triangular solves with n right-hand sides (2 m^2 n), x + K v (2nm),
             I - K H (2n^2 m), (I-KH) P (I-KH)^T (4n^3), K R K^T (2nm^2 + 2n^2 m).
    Masks, symmetrisation, status and log-likelihood bookkeeping are not counted.
    """
    return (
        2 * n * n
        + 4 * n**3
        + n * n
        + 2 * m * n
        + 2 * n * n * m
        + 2 * m * m * n
        + m * m
        + m**3 / 3
        + 2 * m * m * n
        + 2 * n * m
        + 2 * n * n * m
        + 4 * n**3
        + 2 * n * m * m
        + 2 * n * n * m
    )


# --------------------------------------------------------------------------------------
# timing helpers
# --------------------------------------------------------------------------------------


def _block(out):
    return jax.block_until_ready(out)


class _Scheduler:
    """Runs the timed repeats of every registered call round-robin.

    The machine is shared, so its load drifts during a run; interleaving the repeats gives every
    implementation the same conditions, which keeps the ratios honest. The order is shuffled
    every round (fixed seed), and a short call (< 0.2 s) gets one untimed call right before its
    timed one, so that it is not measured cold after a large NumPy job has churned memory.
    """

    def __init__(self):
        self.jobs = []  # [fn, repeats, runs list to fill, short]

    def add(self, fn, repeats, first_s):
        runs = []
        self.jobs.append((fn, repeats, runs, first_s < 0.2))
        return runs

    def run(self, log=None):
        rounds = max((job[1] for job in self.jobs), default=0)
        rng = np.random.default_rng(0)
        for k in range(rounds):
            if log:
                log(f"timing round {k + 1}/{rounds}")
            for i in rng.permutation(len(self.jobs)):
                fn, repeats, runs, short = self.jobs[i]
                if len(runs) < repeats:
                    if short:
                        _block(fn())
                    t0 = time.perf_counter()
                    _block(fn())
                    runs.append(time.perf_counter() - t0)
        self.jobs = []


SCHED = _Scheduler()


def time_call(fn, repeats, *, compile=None):
    """Compile and call ``fn`` once now; queue ``repeats`` timed calls on :data:`SCHED`.

    Returns (overhead_s, runs, output of the first call); ``runs`` is filled by ``SCHED.run()``.
    With ``compile`` (a callable doing ``jitted.lower(...).compile()`` for every jitted function
    ``fn`` calls), overhead_s is the time of that ahead-of-time trace + lower + compile, measured
    on its own; JAX caches the executable, so the calls that follow do not compile again (checked
    by :func:`check_cache_hits`). Without it, overhead_s is the wall time of the first call.
    """
    if compile is not None:
        t0 = time.perf_counter()
        compile()
        comp = time.perf_counter() - t0
    t0 = time.perf_counter()
    out = _block(fn())
    first = time.perf_counter() - t0
    runs = SCHED.add(fn, repeats, first)
    if compile is not None:
        _FIRST_AFTER_AOT.append((first, runs))
        first = comp
    return first, runs, out


_FIRST_AFTER_AOT = []


def check_cache_hits():
    """Warn where the first call after the AOT compile was much slower than the later calls."""
    for first, runs in _FIRST_AFTER_AOT:
        if runs and first > 0.25 + 3 * min(runs):
            print(
                f"warning: first call after the AOT compile took {first:.2f} s, later calls "
                f"{min(runs):.3f} s (compile cache missed?)",
                file=sys.stderr,
            )
    _FIRST_AFTER_AOT.clear()


def jit_time(jitted, args, repeats):
    """time_call for a jitted function of positional array arguments."""
    return time_call(lambda: jitted(*args), repeats, compile=lambda: jitted.lower(*args).compile())


class Row:
    """One measured (implementation, case) pair."""

    def __init__(self, case, name, first, runs, *, scale=1.0, note="", means=None, smoothed=None, jax_impl=False):
        self.case, self.name, self.note = case, name, note
        self.scale = scale  # multiply measured times by this to get the full-size estimate
        self.first = first
        self.runs = runs
        self.jax_impl = jax_impl
        self.means = means
        self.smoothed = smoothed

    @property
    def tmin(self):
        return min(self.runs) * self.scale

    @property
    def tmed(self):
        return statistics.median(self.runs) * self.scale

    @property
    def compile_s(self):
        """Ahead-of-time trace + lower + compile time (JAX rows)."""
        return self.first


# --------------------------------------------------------------------------------------
# implementations
# --------------------------------------------------------------------------------------


def plain_filter(F, H, Q, R, x0, P0, zs, keep_all=False, joseph=False):
    """A plain textbook KF in lax.scan (jnp.linalg.solve, no masks, no log-lik; Joseph form on request)."""

    def step(carry, z):
        x, P = carry
        xp, Pp = F @ x, F @ P @ F.T + Q
        PHt = Pp @ H.T
        S = H @ PHt + R
        K = jnp.linalg.solve(S, PHt.T).T
        x = xp + K @ (z - H @ xp)
        if joseph:
            IKH = jnp.eye(F.shape[0]) - K @ H
            P = IKH @ Pp @ IKH.T + K @ R @ K.T
        else:
            P = Pp - K @ S @ K.T
        P = 0.5 * (P + P.T)
        out = (x, P, xp, Pp) if keep_all else x
        return (x, P), out

    _, out = jax.lax.scan(step, (x0, P0), zs)
    return out


def plain_rts(F, xs, Ps, xps, Pps):
    """A plain RTS smoother in lax.scan over the saved filter moments."""

    def step(carry, inp):
        xs_next, Ps_next = carry
        x, P, xp_next, Pp_next = inp
        C = jnp.linalg.solve(Pp_next, F @ P).T  # P F^T Pp^-1 (Pp symmetric)
        x_s = x + C @ (xs_next - xp_next)
        P_s = P + C @ (Ps_next - Pp_next) @ C.T
        return (x_s, P_s), x_s

    _, m = jax.lax.scan(step, (xs[-1], Ps[-1]), (xs[:-1], Ps[:-1], xps[1:], Pps[1:]), reverse=True)
    return jnp.concatenate([m, xs[-1:]], axis=0)


def run_benchmarks(args, zs_batch, log):
    """Measure every implementation on the three cases; return the list of Rows."""
    T, B, reps = args.T, args.batch, args.repeats
    F, H, Q, R = model_matrices()
    x0, P0 = initial_moments()
    m1, P1 = first_prior(F, Q, x0, P0)
    z1 = zs_batch[0]
    rows = []
    jF, jH, jQ, jR = (jnp.asarray(a) for a in (F, H, Q, R))
    jx0, jP0, jz1, jzB = jnp.asarray(x0), jnp.asarray(P0), jnp.asarray(z1), jnp.asarray(zs_batch)
    jm1, jP1 = jnp.asarray(m1), jnp.asarray(P1)

    # ---------------- jaxnav (public API, called as a user would) ----------------
    model = jf.constant_velocity(DT, sigma=SIGMA, q=Q_PSD)
    err = max(
        float(np.max(np.abs(np.asarray(getattr(model, k)) - v))) for k, v in (("F", F), ("H", H), ("Q", Q), ("R", R))
    )
    if err > 1e-15:
        raise SystemExit(f"jaxnav constant_velocity differs from the benchmark model by {err:g}")
    save_rts = ("means", "covs", "pred_means", "pred_covs")

    log("jaxnav (a) filter")
    f1 = jax.jit(lambda z: jf.kalman_filter(model, jx0, jP0, z, save=("means",)))
    first, runs, out = jit_time(f1, (jz1,), reps)
    rows.append(
        Row(
            "a",
            "jaxnav",
            first,
            runs,
            means=np.asarray(out.means),
            jax_impl=True,
            note="means saved; log-lik, status always computed",
        )
    )
    f1 = jax.jit(lambda z: jf.kalman_filter(model, jx0, jP0, z, save=("means", "covs")))
    first, runs, out = jit_time(f1, (jz1,), reps)
    rows.append(
        Row(
            "a",
            "jaxnav (means+covs)",
            first,
            runs,
            means=np.asarray(out.means),
            jax_impl=True,
            note="also saves the (T, 6, 6) covariances",
        )
    )

    log("jaxnav (b) filter+RTS")
    kf = jax.jit(lambda z: jf.kalman_filter(model, jx0, jP0, z, save=save_rts))
    rts = jax.jit(lambda r: jf.rts_smoother(model, r))

    def f():
        res = kf(jz1)
        return res.means, rts(res)

    def c():
        kf.lower(jz1).compile()
        rts.lower(jax.eval_shape(kf, jz1)).compile()

    first, runs, out = time_call(f, reps, compile=c)
    rows.append(
        Row(
            "b",
            "jaxnav",
            first,
            runs,
            means=np.asarray(out[0]),
            smoothed=np.asarray(out[1].means),
            jax_impl=True,
            note="kalman_filter + rts_smoother, two calls",
        )
    )
    fj = jax.jit(
        lambda z: (lambda r: (r.means, jf.rts_smoother(model, r, save=("means",)).means))(
            jf.kalman_filter(model, jx0, jP0, z, save=save_rts)
        )
    )
    first, runs, out = jit_time(fj, (jz1,), reps)
    rows.append(
        Row(
            "b",
            "jaxnav (one jit, means only)",
            first,
            runs,
            means=np.asarray(out[0]),
            smoothed=np.asarray(out[1]),
            jax_impl=True,
            note="both in one jit returning filtered + smoothed means, like the peers",
        )
    )

    log("jaxnav (c) batch")
    fb = jax.jit(lambda z: jf.kalman_filter_batch(model, jx0, jP0, z, save=("means",)))
    first, runs, out = jit_time(fb, (jzB,), max(3, reps // 2))
    rows.append(
        Row(
            "c",
            "jaxnav",
            first,
            runs,
            means=np.asarray(out.means),
            jax_impl=True,
            note=f"kalman_filter_batch over B={B}: one covariance recursion (NaN masking on), the means "
            "in blocks of 4 epochs",
        )
    )
    jzG = jzB.at[:, T // 3 : T // 3 + 60, :].set(jnp.nan)
    first, runs, out = jit_time(fb, (jzG,), max(3, reps // 2))
    rows.append(
        Row(
            "c",
            "jaxnav (common gap)",
            first,
            runs,
            jax_impl=True,
            note="the same call; a 60 s outage in every sequence: masked for all",
        )
    )
    fv = jax.jit(jax.vmap(lambda z: jf.kalman_filter(model, jx0, jP0, z, save=("means",), check_finite=False)))
    first, runs, out = jit_time(fv, (jzB,), max(3, reps // 2))
    rows.append(
        Row(
            "c",
            "jaxnav vmap(kalman_filter, check_finite=False)",
            first,
            runs,
            means=np.asarray(out.means),
            jax_impl=True,
            note="plain vmap, data trusted: nothing in P depends on the batched data, so vmap runs one P recursion",
        )
    )
    fv = jax.jit(jax.vmap(lambda z: jf.kalman_filter(model, jx0, jP0, z, save=("means",))))
    first, runs, out = jit_time(fv, (jzB,), max(3, reps // 2))
    rows.append(
        Row(
            "c",
            "jaxnav vmap(kalman_filter)",
            first,
            runs,
            means=np.asarray(out.means),
            jax_impl=True,
            note="plain vmap with NaN masking: the masks make P per sequence (as in (d))",
        )
    )

    floor = jax.jit(lambda z: jnp.concatenate([z, z], axis=-1) * 2.0)
    first, runs, out = jit_time(floor, (jzB,), max(3, reps // 2))
    rows.append(
        Row(
            "c",
            "memory floor (no filtering)",
            first,
            runs,
            jax_impl=True,
            note="reads the (B, T, 3) data and writes a fresh (B, T, 6) array: what any filter "
            "returning the means pays",
        )
    )

    # (d): the same batch with P0 given per sequence (B identical copies), so that no
    # implementation can share one covariance recursion between the sequences.
    jP0B = jnp.broadcast_to(jP0, (B,) + jP0.shape)
    jP1B = jnp.broadcast_to(jP1, (B,) + jP1.shape)
    fd = jax.jit(jax.vmap(lambda z, P: jf.kalman_filter(model, jx0, P, z, save=("means",))))
    first, runs, out = jit_time(fd, (jzB, jP0B), max(3, reps // 2))
    rows.append(
        Row(
            "d",
            "jaxnav",
            first,
            runs,
            means=np.asarray(out.means),
            jax_impl=True,
            note=f"jit(vmap) over (zs, P0), B={B}",
        )
    )
    fd = jax.jit(jax.vmap(lambda z, P: jf.kalman_filter(model, jx0, P, z, save=("means",), joseph=False)))
    first, runs, out = jit_time(fd, (jzB, jP0B), max(3, reps // 2))
    rows.append(
        Row(
            "d",
            "jaxnav (joseph=False)",
            first,
            runs,
            means=np.asarray(out.means),
            jax_impl=True,
            note="textbook covariance update P - K H P, like the plain scan below",
        )
    )
    jzN = jzB.at[jnp.arange(B), (jnp.arange(B) * 37) % T, jnp.arange(B) % N_OBS].set(jnp.nan)
    fv = jax.jit(jax.vmap(lambda z: jf.kalman_filter(model, jx0, jP0, z, save=("means",))))
    first, runs, out = jit_time(fv, (jzN,), max(3, reps // 2))
    rows.append(
        Row(
            "d",
            "jaxnav (one NaN per sequence, shared P0)",
            first,
            runs,
            jax_impl=True,
            note="jit(vmap(kalman_filter)): every sequence masks its own NaN, so each has its own P",
        )
    )

    # (g): filter + RTS means under vmap, written as a user writes it, and by the batch entry points
    log("jaxnav (g) filter + RTS, batch")
    fg = jax.jit(
        lambda z: (
            jf.rts_smoother_batch(
                model, jf.kalman_filter_batch(model, jx0, jP0, z, save=("means", "covs", "pred_covs"))
            ).means
        )
    )
    first, runs, out = jit_time(fg, (jzB,), max(3, reps // 2))
    rows.append(
        Row(
            "g",
            "jaxnav",
            first,
            runs,
            smoothed=np.asarray(out),
            jax_impl=True,
            note='rts_smoother_batch(m, kalman_filter_batch(m, x0, P0, zs, save=("means", "covs", '
            '"pred_covs"))).means: one P recursion, the means of filter and smoother in blocks',
        )
    )
    fg = jax.jit(lambda z: jf.rts_smoother_batch(model, jf.kalman_filter_batch(model, jx0, jP0, z)).means)
    first, runs, out = jit_time(fg, (jzB,), max(3, reps // 2))
    rows.append(
        Row(
            "g",
            "jaxnav (default outputs)",
            first,
            runs,
            smoothed=np.asarray(out),
            jax_impl=True,
            note="the same with the filter's default save (every output)",
        )
    )
    fg = jax.jit(
        jax.vmap(lambda z: jf.rts_smoother(model, jf.kalman_filter(model, jx0, jP0, z, check_finite=False)).means)
    )
    first, runs, out = jit_time(fg, (jzB,), max(3, reps // 2))
    rows.append(
        Row(
            "g",
            "jaxnav vmap(filter(check_finite=False) + RTS)",
            first,
            runs,
            smoothed=np.asarray(out),
            jax_impl=True,
            note="plain vmap, data trusted: vmap shares P and the smoother gains",
        )
    )
    fg = jax.jit(jax.vmap(lambda z: jf.rts_smoother(model, jf.kalman_filter(model, jx0, jP0, z)).means))
    first, runs, out = jit_time(fg, (jzB,), max(3, reps // 2))
    rows.append(
        Row(
            "g",
            "jaxnav vmap(filter + RTS)",
            first,
            runs,
            smoothed=np.asarray(out),
            jax_impl=True,
            note="jit(vmap(lambda z: rts_smoother(m, kalman_filter(m, x0, P0, z)).means)), as a user writes "
            "it: NaN masking on; a clean batch runs one P recursion (run-time choice)",
        )
    )

    # (h): filter + RTS with a covariance per sequence, written as a user writes it
    log("jaxnav (h) filter + RTS, a covariance per sequence")
    fh = jax.jit(jax.vmap(lambda z, P: jf.rts_smoother(model, jf.kalman_filter(model, jx0, P, z)).means))
    first, runs, out = jit_time(fh, (jzB, jP0B), max(3, reps // 2))
    rows.append(
        Row(
            "h",
            "jaxnav",
            first,
            runs,
            smoothed=np.asarray(out),
            jax_impl=True,
            note=f"jit(vmap) over (zs, P0), B={B}: rts_smoother(m, kalman_filter(m, x0, P0, z)).means, Joseph update",
        )
    )
    fh = jax.jit(jax.vmap(lambda z: jf.rts_smoother(model, jf.kalman_filter(model, jx0, jP0, z)).means))
    first, runs, out = jit_time(fh, (jzN,), max(3, reps // 2))
    rows.append(
        Row(
            "h",
            "jaxnav (one NaN per sequence, shared P0)",
            first,
            runs,
            jax_impl=True,
            note="jit(vmap) over zs: every sequence masks its own NaN, so each has its own P",
        )
    )

    # ---------------- plain lax.scan ----------------
    log("plain lax.scan")
    pf = jax.jit(lambda z: plain_filter(jF, jH, jQ, jR, jx0, jP0, z))
    first, runs, out = jit_time(pf, (jz1,), reps)
    rows.append(
        Row(
            "a",
            "plain lax.scan",
            first,
            runs,
            means=np.asarray(out),
            jax_impl=True,
            note="textbook KF, no Joseph/masks/log-lik",
        )
    )

    @jax.jit
    def pfs(z):
        xs, Ps, xps, Pps = plain_filter(jF, jH, jQ, jR, jx0, jP0, z, keep_all=True)
        return xs, plain_rts(jF, xs, Ps, xps, Pps)

    first, runs, out = jit_time(pfs, (jz1,), reps)
    rows.append(
        Row(
            "b",
            "plain lax.scan",
            first,
            runs,
            means=np.asarray(out[0]),
            smoothed=np.asarray(out[1]),
            jax_impl=True,
            note="one jit",
        )
    )
    pfb = jax.jit(jax.vmap(lambda z: plain_filter(jF, jH, jQ, jR, jx0, jP0, z)))
    first, runs, out = jit_time(pfb, (jzB,), max(3, reps // 2))
    rows.append(
        Row("c", "plain lax.scan", first, runs, means=np.asarray(out), jax_impl=True, note=f"jit(vmap) over B={B}")
    )
    pfd = jax.jit(jax.vmap(lambda z, P: plain_filter(jF, jH, jQ, jR, jx0, P, z)))
    first, runs, out = jit_time(pfd, (jzB, jP0B), max(3, reps // 2))
    rows.append(
        Row(
            "d",
            "plain lax.scan",
            first,
            runs,
            means=np.asarray(out),
            jax_impl=True,
            note=f"jit(vmap) over (zs, P0), B={B}",
        )
    )
    pfj = jax.jit(jax.vmap(lambda z, P: plain_filter(jF, jH, jQ, jR, jx0, P, z, joseph=True)))
    first, runs, out = jit_time(pfj, (jzB, jP0B), max(3, reps // 2))
    rows.append(
        Row(
            "d",
            "plain lax.scan, Joseph form",
            first,
            runs,
            means=np.asarray(out),
            jax_impl=True,
            note="the same with jaxnav's default covariance update (I-KH) P (I-KH)^T + K R K^T",
        )
    )
    pfg = jax.jit(
        jax.vmap(lambda z: (lambda o: plain_rts(jF, *o))(plain_filter(jF, jH, jQ, jR, jx0, jP0, z, keep_all=True)))
    )
    first, runs, out = jit_time(pfg, (jzB,), max(3, reps // 2))
    rows.append(
        Row(
            "g",
            "plain lax.scan",
            first,
            runs,
            smoothed=np.asarray(out),
            jax_impl=True,
            note=f"jit(vmap) of the plain filter + RTS over B={B} (no NaN handling: vmap shares P)",
        )
    )
    for label, joseph in (("", False), (", Joseph form", True)):
        pfh = jax.jit(
            jax.vmap(
                lambda z, P, joseph=joseph: (lambda o: plain_rts(jF, *o))(
                    plain_filter(jF, jH, jQ, jR, jx0, P, z, keep_all=True, joseph=joseph)
                )
            )
        )
        first, runs, out = jit_time(pfh, (jzB, jP0B), max(3, reps // 2))
        rows.append(
            Row(
                "h",
                "plain lax.scan" + label,
                first,
                runs,
                smoothed=np.asarray(out),
                jax_impl=True,
                note=f"jit(vmap) of the plain filter + RTS over (zs, P0), B={B}",
            )
        )

    # ---------------- dynamax ----------------
    try:
        from dynamax.linear_gaussian_ssm import lgssm_filter, lgssm_smoother
        from dynamax.linear_gaussian_ssm.inference import make_lgssm_params
    except Exception as e:  # pragma: no cover - depends on the environment
        log(f"dynamax unavailable: {e!r}")
        rows.append(Row("a", "dynamax", float("nan"), [float("nan")], note=f"not installed: {e!r}"))
    else:
        log("dynamax")
        params = make_lgssm_params(jm1, jP1, jF, jQ, jH, jR)
        df = jax.jit(lambda z: (lambda p: (p.filtered_means, p.marginal_loglik))(lgssm_filter(params, z)))
        first, runs, out = jit_time(df, (jz1,), reps)
        rows.append(
            Row(
                "a",
                "dynamax",
                first,
                runs,
                means=np.asarray(out[0]),
                jax_impl=True,
                note="jit(lgssm_filter); means + log-lik kept",
            )
        )
        ds = jax.jit(lambda z: (lambda p: (p.filtered_means, p.smoothed_means))(lgssm_smoother(params, z)))
        first, runs, out = jit_time(ds, (jz1,), reps)
        rows.append(
            Row(
                "b",
                "dynamax",
                first,
                runs,
                means=np.asarray(out[0]),
                smoothed=np.asarray(out[1]),
                jax_impl=True,
                note="jit(lgssm_smoother)",
            )
        )
        dfb = jax.jit(jax.vmap(lambda z: (lambda p: (p.filtered_means, p.marginal_loglik))(lgssm_filter(params, z))))
        first, runs, out = jit_time(dfb, (jzB,), max(3, reps // 2))
        rows.append(
            Row("c", "dynamax", first, runs, means=np.asarray(out[0]), jax_impl=True, note=f"jit(vmap) over B={B}")
        )
        dfd = jax.jit(
            jax.vmap(
                lambda z, P: (lambda p: (p.filtered_means, p.marginal_loglik))(
                    lgssm_filter(make_lgssm_params(jm1, P, jF, jQ, jH, jR), z)
                )
            )
        )
        first, runs, out = jit_time(dfd, (jzB, jP1B), max(3, reps // 2))
        rows.append(
            Row(
                "d",
                "dynamax",
                first,
                runs,
                means=np.asarray(out[0]),
                jax_impl=True,
                note=f"jit(vmap) over (zs, initial cov), B={B}",
            )
        )
        dsg = jax.jit(jax.vmap(lambda z: lgssm_smoother(params, z).smoothed_means))
        first, runs, out = jit_time(dsg, (jzB,), max(3, reps // 2))
        rows.append(
            Row(
                "g",
                "dynamax",
                first,
                runs,
                smoothed=np.asarray(out),
                jax_impl=True,
                note=f"jit(vmap(lgssm_smoother)) over B={B}",
            )
        )
        dsh = jax.jit(
            jax.vmap(lambda z, P: lgssm_smoother(make_lgssm_params(jm1, P, jF, jQ, jH, jR), z).smoothed_means)
        )
        first, runs, out = jit_time(dsh, (jzB, jP1B), max(3, reps // 2))
        rows.append(
            Row(
                "h",
                "dynamax",
                first,
                runs,
                smoothed=np.asarray(out),
                jax_impl=True,
                note=f"jit(vmap(lgssm_smoother)) over (zs, initial cov), B={B}",
            )
        )

    # ---------------- (e), (f): value_and_grad of the innovation log-likelihood ----------------
    # theta = (log q, log sigma); the forward pass (log-likelihood only) is the reference row
    # "jaxnav", so the ratio column of value_and_grad reads "times the forward pass".
    log("gradients (e) single, (f) batch")
    Qunit = jnp.asarray(model_matrices(q=1.0)[2])
    theta0 = jnp.array([np.log(Q_PSD), np.log(SIGMA)])

    def jx_nll(theta, z, check_finite=True):
        mod = jf.constant_velocity(DT, sigma=jnp.exp(theta[1]), q=jnp.exp(theta[0]))
        return -jf.kalman_filter(mod, jx0, jP0, z, save=(), check_finite=check_finite).loglik

    def jx_ll(theta, z):
        mod = jf.constant_velocity(DT, sigma=jnp.exp(theta[1]), q=jnp.exp(theta[0]))
        return -jf.log_likelihood(mod, jx0, jP0, z)

    def batch(fn, **kw):
        return lambda theta, zB: jnp.sum(jax.vmap(lambda z: fn(theta, z, **kw))(zB))

    grad_cases = [
        ("e", jz1, lambda f, **kw: f, reps, ""),
        ("f", jzB, batch, max(3, reps // 2), f" over B={B} (sum of log-likelihoods)"),
    ]
    for case, data, wrap, rr, sfx in grad_cases:
        for label, kw in (("", {}), (" (check_finite=False)", dict(check_finite=False))):
            if case == "e" and kw:
                continue
            fwd = jax.jit(wrap(jx_nll, **kw))
            first, runs, _ = jit_time(fwd, (theta0, data), rr)
            rows.append(
                Row(
                    case,
                    "jaxnav" + label,
                    first,
                    runs,
                    jax_impl=True,
                    note="forward: negative log-likelihood only" + sfx,
                )
            )
            vg = jax.jit(jax.value_and_grad(wrap(jx_nll, **kw)))
            first, runs, _ = jit_time(vg, (theta0, data), rr)
            rows.append(
                Row(
                    case,
                    "jaxnav value_and_grad" + label,
                    first,
                    runs,
                    jax_impl=True,
                    note="d(-loglik)/d(log q, log sigma)" + sfx,
                )
            )
            if not kw:
                g_auto = np.asarray(vg(theta0, data)[1])
                # two parameters: forward mode (one tangent each, no tape) is the cheaper gradient
                vg = jax.jit(lambda th, d: jtune.value_and_grad(lambda t: wrap(jx_nll)(t, d), mode="forward")(th))
                first, runs, _ = jit_time(vg, (theta0, data), rr)
                rows.append(
                    Row(
                        case,
                        "jaxnav value_and_grad, forward mode",
                        first,
                        runs,
                        jax_impl=True,
                        note="the same gradient by jaxnav.tune.value_and_grad(mode='forward')" + sfx,
                    )
                )
                # the gradient from one backward smoothing pass (jaxnav.filters.log_likelihood), no tape
                vg = jax.jit(jax.value_and_grad(wrap(jx_ll)))
                first, runs, out = jit_time(vg, (theta0, data), rr)
                rel = float(np.max(np.abs(np.asarray(out[1]) - g_auto) / np.abs(g_auto)))
                rows.append(
                    Row(
                        case,
                        "jaxnav log_likelihood value_and_grad",
                        first,
                        runs,
                        jax_impl=True,
                        note="the same gradient from one backward smoothing pass (`jf.log_likelihood`); max rel. "
                        f"difference to autodiff {rel:.1e}" + sfx,
                    )
                )

    def jx_nll_batch(theta, zB):
        mod = jf.constant_velocity(DT, sigma=jnp.exp(theta[1]), q=jnp.exp(theta[0]))
        return -jnp.sum(jf.kalman_filter_batch(mod, jx0, jP0, zB, save=()).loglik)

    rr = max(3, reps // 2)
    fwd = jax.jit(jx_nll_batch)
    first, runs, _ = jit_time(fwd, (theta0, jzB), rr)
    rows.append(
        Row(
            "f",
            "jaxnav kalman_filter_batch",
            first,
            runs,
            jax_impl=True,
            note=f"forward: the batch entry point (one covariance recursion) over B={B}",
        )
    )
    vg = jax.jit(jax.value_and_grad(jx_nll_batch))
    first, runs, _ = jit_time(vg, (theta0, jzB), rr)
    rows.append(
        Row(
            "f",
            "jaxnav kalman_filter_batch value_and_grad",
            first,
            runs,
            jax_impl=True,
            note=f"reverse mode through the batch entry point over B={B}",
        )
    )
    vg = jax.jit(lambda th, d: jtune.value_and_grad(lambda t: jx_nll_batch(t, d), mode="forward")(th))
    first, runs, _ = jit_time(vg, (theta0, jzB), rr)
    rows.append(
        Row(
            "f",
            "jaxnav kalman_filter_batch value_and_grad, forward mode",
            first,
            runs,
            jax_impl=True,
            note=f"forward mode through the batch entry point over B={B}",
        )
    )
    try:
        from dynamax.linear_gaussian_ssm import lgssm_filter as _dlf
        from dynamax.linear_gaussian_ssm.inference import make_lgssm_params as _dmp
    except Exception as e:  # pragma: no cover
        log(f"dynamax unavailable for gradients: {e!r}")
    else:

        def dx_nll(theta, z):
            Qt, Rt = jnp.exp(theta[0]) * Qunit, jnp.exp(2 * theta[1]) * jnp.eye(N_OBS)
            prm = _dmp(jF @ jx0, jF @ jP0 @ jF.T + Qt, jF, Qt, jH, Rt)
            return -_dlf(prm, z).marginal_loglik

        for case, data, wrap, rr, sfx in grad_cases:
            fwd = jax.jit(wrap(dx_nll))
            first, runs, _ = jit_time(fwd, (theta0, data), rr)
            rows.append(Row(case, "dynamax", first, runs, jax_impl=True, note="forward" + sfx))
            vg = jax.jit(jax.value_and_grad(wrap(dx_nll)))
            first, runs, _ = jit_time(vg, (theta0, data), rr)
            rows.append(
                Row(
                    case,
                    "dynamax value_and_grad",
                    first,
                    runs,
                    jax_impl=True,
                    note="d(-loglik)/d(log q, log sigma)" + sfx,
                )
            )

    # ---------------- filterpy ----------------
    try:
        from filterpy.kalman import KalmanFilter as FPKalman
    except Exception as e:  # pragma: no cover
        log(f"filterpy unavailable: {e!r}")
        rows.append(Row("a", "filterpy", float("nan"), [float("nan")], note=f"not installed: {e!r}"))
    else:
        log("filterpy")

        def fp_make():
            kf = FPKalman(dim_x=N_STATE, dim_z=N_OBS)
            kf.F, kf.H, kf.Q, kf.R = F.copy(), H.copy(), Q.copy(), R.copy()
            kf.x, kf.P = x0.copy(), P0.copy()
            return kf

        def fp_filter(z):
            return fp_make().batch_filter(z)[0]

        def fp_smooth(z):
            kf = fp_make()
            mu, cov, _, _ = kf.batch_filter(z)
            return mu, kf.rts_smoother(mu, cov)[0]

        fr = max(2, reps // 3)
        first, runs, out = time_call(lambda: fp_filter(z1), fr)
        rows.append(Row("a", "filterpy", first, runs, means=out, note="batch_filter (Joseph update)"))
        first, runs, out = time_call(lambda: fp_smooth(z1), fr)
        rows.append(
            Row("b", "filterpy", first, runs, means=out[0], smoothed=out[1], note="batch_filter + rts_smoother")
        )
        nb = min(B, args.extrapolate)
        first, runs, out = time_call(lambda: [fp_filter(z) for z in zs_batch[:nb]], fr)
        rows.append(
            Row(
                "c",
                "filterpy",
                first,
                runs,
                scale=B / nb,
                means=np.stack(out),
                note=f"loop; {nb} of {B} sequences timed, x{B / nb:g} extrapolated",
            )
        )

    # ---------------- pykalman ----------------
    try:
        from pykalman import KalmanFilter as PKKalman
    except Exception as e:  # pragma: no cover
        log(f"pykalman unavailable: {e!r}")
        rows.append(Row("a", "pykalman", float("nan"), [float("nan")], note=f"not installed: {e!r}"))
    else:
        log("pykalman")
        pk = PKKalman(
            transition_matrices=F,
            observation_matrices=H,
            transition_covariance=Q,
            observation_covariance=R,
            initial_state_mean=m1,
            initial_state_covariance=P1,
        )
        Tp = min(T, args.pykalman_T)
        sc = T / Tp
        sfx = "" if Tp == T else f"; timed at T={Tp}, x{sc:g} extrapolated"
        fr = max(2, reps // 3)
        first, runs, _ = time_call(lambda: pk.filter(z1[:Tp]), fr)
        means_full = pk.filter(z1)[0]
        rows.append(Row("a", "pykalman", first, runs, scale=sc, means=means_full, note="filter" + sfx))
        first, runs, _ = time_call(lambda: pk.smooth(z1[:Tp]), fr)
        sm = pk.smooth(z1)[0]
        rows.append(
            Row(
                "b",
                "pykalman",
                first,
                runs,
                scale=sc,
                means=means_full,
                smoothed=sm,
                note="smooth (filter + RTS inside)" + sfx,
            )
        )
        nb = min(B, args.extrapolate)
        first, runs, out = time_call(lambda: [pk.filter(z[:Tp])[0] for z in zs_batch[:nb]], fr)
        rows.append(
            Row(
                "c",
                "pykalman",
                first,
                runs,
                scale=sc * B / nb,
                means=np.stack(out) if Tp == T else None,
                note=f"loop; {nb} of {B} sequences timed, x{B / nb:g} extrapolated" + sfx,
            )
        )

    # ---------------- simdkalman ----------------
    try:
        import simdkalman
    except Exception as e:  # pragma: no cover
        log(f"simdkalman unavailable: {e!r}")
        rows.append(Row("a", "simdkalman", float("nan"), [float("nan")], note=f"not installed: {e!r}"))
    else:
        log("simdkalman")
        sk = simdkalman.KalmanFilter(state_transition=F, process_noise=Q, observation_model=H, observation_noise=R)

        def sk_run(data, smoothed):
            r = sk.compute(
                data, 0, initial_value=m1, initial_covariance=P1, smoothed=smoothed, filtered=True, observations=False
            )
            out = (r.filtered.states.mean,)
            return out + ((r.smoothed.states.mean,) if smoothed else ())

        fr = max(2, reps // 3)
        first, runs, out = time_call(lambda: sk_run(z1[None], False), fr)
        rows.append(Row("a", "simdkalman", first, runs, means=out[0][0], note="compute(filtered)"))
        first, runs, out = time_call(lambda: sk_run(z1[None], True), fr)
        rows.append(
            Row("b", "simdkalman", first, runs, means=out[0][0], smoothed=out[1][0], note="compute(filtered, smoothed)")
        )
        first, runs, out = time_call(lambda: sk_run(zs_batch, False), fr)
        rows.append(Row("c", "simdkalman", first, runs, means=out[0], note=f"native batch, B={B}"))
    # filterpy, pykalman and simdkalman carry one covariance per sequence anyway (simdkalman
    # stacks a 2-D initial covariance to (B, n, n)): (d) is the same computation as (c) for them.
    for r in [r for r in rows if r.case == "c" and r.name in ("filterpy", "pykalman", "simdkalman")]:
        rows.append(
            Row(
                "d",
                r.name,
                r.first,
                r.runs,
                scale=r.scale,
                means=r.means,
                note="the (c) measurement: it carries one covariance per sequence anyway",
            )
        )
    return rows


# --------------------------------------------------------------------------------------
# machine, versions, matmul rate
# --------------------------------------------------------------------------------------


def machine_info():
    cpu = cpu_model()
    rev = git_revision()
    return {
        "jaxnav commit": rev,
        "date": _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "host": f"{platform.system()} {platform.release()} {platform.machine()}",
        "cpu": cpu,
        "cores": os.cpu_count(),
        "python": platform.python_version(),
        "jax devices": ", ".join(str(d) for d in jax.devices()),
        "versions": {
            d: _version(d)
            for d in (
                "jax",
                "jaxlib",
                "numpy",
                "scipy",
                "jaxnav",
                "filterpy",
                "pykalman",
                "simdkalman",
                "dynamax",
                "tfp-nightly",
            )
        },
    }


def matmul_rates(n=1024, repeats=10):
    """Dense float64 n x n matmul rate (GFLOP/s, best of repeats) for NumPy and jnp."""
    rng = np.random.default_rng(0)
    a, b = rng.standard_normal((n, n)), rng.standard_normal((n, n))
    flops = 2.0 * n**3
    best = float("inf")
    a @ b
    for _ in range(repeats):
        t0 = time.perf_counter()
        a @ b
        best = min(best, time.perf_counter() - t0)
    np_rate = flops / best / 1e9
    ja, jb = jnp.asarray(a), jnp.asarray(b)
    mm = jax.jit(jnp.matmul)
    _block(mm(ja, jb))
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        _block(mm(ja, jb))
        best = min(best, time.perf_counter() - t0)
    return np_rate, flops / best / 1e9


def loop_body_profile(fn, *args, batch=None, split=False):
    """Count the ops XLA runs per scan iteration: (fusions, custom-calls, all instructions).

    Reads the optimized HLO of the compiled function and counts instructions inside the
    while-loop body computations; a crude but stable proxy for per-step dispatch overhead.
    """
    text = jax.jit(fn).lower(*args).compile().as_text()
    bodies = set(re.findall(r"body=(%?[\w.\-]+)", text))
    trips = dict(re.findall(r'body=(%?[\w.\-]+)[^\n]*?"known_trip_count":\{"n":"(\d+)"', text))
    comps, cur, name = {}, None, None
    for line in text.splitlines():
        m = re.match(r"^(?:ENTRY )?(%?[\w.\-]+) .*\{\s*$", line)
        if m:
            name, cur = m.group(1), []
            comps[name] = cur
            continue
        if line.startswith("}"):
            name, cur = None, None
            continue
        if cur is not None and "=" in line:
            cur.append(line)

    def stats(lines):
        ops = [ln for ln in lines if not re.search(r"= \S+ (parameter|get-tuple-element|tuple|constant)\(", ln)]
        factor = []
        for ln in ops:
            m = re.search(r'= \(?(f64\[[\d,]*\]).*custom_call_target="lapack_d(\w+?)_ffi"', ln)
            if m and m.group(2) in ("potrf", "getrf", "geqrf", "syevd"):
                factor.append(f"{m.group(2)} {m.group(1)}")
        pat = f"f64[{batch},{N_STATE},{N_STATE}]"
        return {
            "fusions": sum(1 for ln in ops if " fusion(" in ln),
            "custom_calls": sum(1 for ln in ops if "custom-call(" in ln),
            "calls": sum(1 for ln in ops if re.search(r" (call|while|conditional)\(", ln)),
            "ops": len(ops),
            "factor": ", ".join(factor) or "none (closed form)",
            "per_seq": "—" if batch is None else ("yes" if any(pat in ln for ln in lines) else "no (shared)"),
        }

    # split=True: a program with alternative time loops (jaxnav's batch-level switch compiles a
    # shared-covariance loop and a per-sequence one) reports each, joined by " / ", shared first
    names = sorted(bodies)
    groups = [comps.get(b, comps.get(b.lstrip("%"), [])) for b in names]
    if not split:
        groups = [[ln for g in groups for ln in g]]
    per_loop = [stats(g) for g in groups]
    if split:  # each loop's fusion count with its trip count, e.g. "17 x15"
        for st, b in zip(per_loop, names):
            st["trips"] = trips.get(b, "?")
    per_loop = [st for st in per_loop if st["fusions"] > 2] or per_loop
    per_loop.sort(key=lambda st: st["per_seq"] == "yes")
    for st in per_loop:
        st["other"] = st["ops"] - st["fusions"] - st["custom_calls"]
        if "trips" in st:
            st["fusions"] = f"{st['fusions']} x{st.pop('trips')}"
    return {
        k: " / ".join(dict.fromkeys(str(st[k]) for st in per_loop))
        if k == "factor"
        else " / ".join(str(st[k]) for st in per_loop)
        for k in per_loop[0]
    }


# --------------------------------------------------------------------------------------
# report
# --------------------------------------------------------------------------------------


def _fmt_t(s):
    if s != s:  # NaN
        return "n/a"
    if s >= 1.0:
        return f"{s:.2f} s"
    if s >= 1e-3:
        return f"{s * 1e3:.1f} ms"
    return f"{s * 1e6:.0f} µs"


def _fmt_d(d):
    return "—" if d is None else f"{d:.1e}"


def agreement(row, ref, attr):
    a, b = getattr(row, attr), getattr(ref, attr) if ref is not None else None
    if a is None or b is None or a is b:
        return None
    a, b = np.asarray(a), np.asarray(b)
    if a.ndim == 3 and b.ndim == 3:  # batch: compare the sequences both have
        k = min(len(a), len(b))
        a, b = a[:k], b[:k]
    if a.shape != b.shape:
        return None
    return float(np.max(np.abs(a - b)))


def build_report(args, rows, info, rates, load0, load1, profile, wall):
    T, B = args.T, args.batch
    by = {(r.case, r.name): r for r in rows}
    titles = {
        "a": f"(a) single sequence, filter only, T = {T}",
        "b": f"(b) single sequence, filter + RTS smoother, T = {T}",
        "c": f"(c) batch of B = {B} sequences, filter only, T = {T}",
        "d": f"(d) batch of B = {B} sequences with per-sequence P0, filter only, T = {T}",
        "e": f"(e) value_and_grad of the innovation log-likelihood, single sequence, T = {T} "
        "(ratio column: times jaxnav's forward pass)",
        "f": f"(f) value_and_grad of the innovation log-likelihood, batch of B = {B}, T = {T} "
        "(ratio column: times jaxnav's default forward pass)",
        "g": f"(g) batch of B = {B} sequences, filter + RTS smoother (smoothed means returned), T = {T}",
        "h": f"(h) batch of B = {B} sequences with a covariance per sequence (P0 per sequence, or one NaN "
        f"per sequence), filter + RTS smoother (smoothed means returned), T = {T}",
    }
    out = []
    v = info["versions"]
    cmd = " ".join(["benchmarks/bench_filters.py"] + sys.argv[1:])
    out.append(f"Generated by `{cmd}` on {info['date']}.")
    out.append("")
    out.append("| | |\n|---|---|")
    out.append(f"| machine | {info['cpu']}, {info['cores']} logical cores, {info['host']} |")
    out.append(
        f"| load average (1/5/15 min) | start {load0[0]:.2f} / {load0[1]:.2f} / {load0[2]:.2f}, "
        f"end {load1[0]:.2f} / {load1[1]:.2f} / {load1[2]:.2f} |"
    )
    out.append(f"| JAX devices | {info['jax devices']} (x64 enabled, persistent compile cache off) |")
    out.append(f"| python | {info['python']} |")
    out.append(f"| jaxnav source | git {info['jaxnav commit']} |")
    out.append("| versions | " + ", ".join(f"{k} {val}" for k, val in v.items()) + " |")
    out.append(
        f"| dense float64 matmul 1024² | NumPy {rates[0]:.1f} GFLOP/s, jnp (XLA) {rates[1]:.1f} GFLOP/s "
        "(best of 10 at the start and 10 at the end of the run) |"
    )
    out.append(
        f"| repeats | {args.repeats} (single sequence), {max(3, args.repeats // 2)} (JAX batch), "
        f"{max(2, args.repeats // 3)} (NumPy peers, their batch loops included); repeats run round-robin in shuffled order |"
    )
    out.append(f"| total wall time | {wall:.0f} s |")
    out.append("")
    for case in "abcdghef":
        crow = [r for r in rows if r.case == case]
        if not crow:
            continue
        ref = by.get((case, "jaxnav"))
        fpy = by.get((case, "filterpy"))
        out.append(f"### {titles[case]}")
        out.append("")
        out.append(
            "| implementation | compile (AOT) | run min | run median | "
            "per step | peer / jaxnav (min) | max abs Δ filtered vs jaxnav | vs filterpy | "
            "max abs Δ smoothed vs jaxnav | vs filterpy | notes |"
        )
        out.append("|---|---|---|---|---|---|---|---|---|---|---|")
        for r in crow:
            steps = T * (B if case in "cdfgh" else 1)
            ratio = "1.00" if r is ref else (f"{r.tmin / ref.tmin:.2f}" if ref and r.tmin == r.tmin else "n/a")
            per = (
                "n/a"
                if r.tmin != r.tmin
                else (f"{r.tmin / steps * 1e9:.0f} ns" if r.tmin / steps < 1e-6 else f"{r.tmin / steps * 1e6:.2f} µs")
            )
            comp = _fmt_t(r.compile_s) if r.jax_impl else "— (no JIT)"
            out.append(
                f"| {r.name} | {comp} | {_fmt_t(r.tmin)} | {_fmt_t(r.tmed)} | {per} | {ratio} | "
                f"{_fmt_d(agreement(r, ref, 'means'))} | {_fmt_d(agreement(r, fpy, 'means'))} | "
                f"{_fmt_d(agreement(r, ref, 'smoothed'))} | {_fmt_d(agreement(r, fpy, 'smoothed'))} | {r.note} |"
            )
        out.append("")
    fl = flops_per_step()
    best = max(rates)
    thr = [r for r in rows if r.case in "cd" and r.tmin == r.tmin and r.name != "pykalman" and r.name != "filterpy"]
    if thr:
        out.append("### Batch throughput")
        out.append("")
        out.append(
            f"Nominal operation count: {fl:.0f} flop per filter step (n = {N_STATE}, m = {N_OBS}, "
            "the textbook dense Joseph-form step, see `flops_per_step`; masks, "
            "symmetrisation and log-likelihood not counted), i.e. "
            f"{fl * T * B / 1e9:.2f} GFLOP per batch of B = {B}, T = {T}. "
            f"Rates are relative to the best measured float64 matmul rate, {best:.1f} GFLOP/s. "
            "For implementations that share one covariance recursion across the batch "
            "(see the HLO table below) the rate is *effective*: they execute far fewer flops."
        )
        out.append("")
        out.append("| case | implementation | ns per sequence-step | nominal GFLOP/s | % of matmul rate |")
        out.append("|---|---|---|---|---|")
        for r in thr:
            g = fl * T * B / r.tmin / 1e9
            out.append(f"| ({r.case}) | {r.name} | {r.tmin / (T * B) * 1e9:.0f} | {g:.2f} | {100 * g / best:.1f} % |")
        out.append("")
    if profile:
        out.append("### Per-iteration work in the compiled scan (optimized HLO of the while-loop body)")
        out.append("")
        out.append(
            "Counted in the XLA-optimized HLO (small T and B, same code): fusions and LAPACK "
            "custom-calls executed per scan step, and the shape of the factorisation each step "
            "runs, and whether a (B, 6, 6) covariance lives in the vmapped loop: if it does, the "
            "covariance recursion is repeated for every sequence; if not, `vmap` left it "
            "unbatched and one recursion serves the whole batch."
        )
        out.append("")
        out.append(
            "| implementation / case | fusions | custom-calls | other ops | factorisations per step "
            "| (B, 6, 6) covariance in the loop |"
        )
        out.append("|---|---|---|---|---|---|")
        for k, p in profile.items():
            out.append(
                f"| {k} | {p['fusions']} | {p['custom_calls']} | {p['other']} | {p['factor']} | {p['per_seq']} |"
            )
        out.append("")
    return "\n".join(out)


def write_results(path, report):
    write_section(path, report, BEGIN, END)


# --------------------------------------------------------------------------------------
# main
# --------------------------------------------------------------------------------------


def main(argv=None):
    p = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--T", type=int, default=3600, help="epochs per sequence (default 3600)")
    p.add_argument("--batch", type=int, default=256, help="sequences in case (c) (default 256)")
    p.add_argument("--repeats", type=int, default=15, help="timed repeats after the first call (default 15)")
    p.add_argument(
        "--quick",
        action="store_true",
        help="smoke run: T=300, batch=16, repeats=3, writes no results unless --results is given",
    )
    p.add_argument(
        "--extrapolate",
        type=int,
        default=4,
        help="sequences timed for the loop-based NumPy peers in case (c) (default 4)",
    )
    p.add_argument(
        "--pykalman-T",
        type=int,
        default=3600,
        help="time pykalman at this T (<= --T) and scale linearly (default 3600)",
    )
    p.add_argument("--no-profile", action="store_true", help="skip the HLO op count of the loop bodies")
    p.add_argument(
        "--results",
        default=None,
        help="markdown file whose generated section is rewritten (default benchmarks/RESULTS.md "
        "for full runs, none for --quick)",
    )
    p.add_argument("--no-write", action="store_true", help="print only, write no results file")
    p.add_argument("--seed", type=int, default=20240611)
    args = p.parse_args(argv)
    if args.quick:
        args.T, args.batch, args.repeats = min(args.T, 300), min(args.batch, 16), min(args.repeats, 3)
    if args.T < 10 or args.batch < 1 or args.repeats < 1:
        p.error("need --T >= 10, --batch >= 1, --repeats >= 1")
    results = args.results or (None if args.quick else str(HERE / "RESULTS.md"))
    if args.no_write:
        results = None

    t_start = time.perf_counter()
    log = lambda s: print(f"[{time.perf_counter() - t_start:6.1f} s] {s}", file=sys.stderr, flush=True)
    load0 = loadavg()
    info = machine_info()
    print(f"# bench_filters  {info['date']}")
    print(f"# {info['cpu']} ({info['cores']} cores), {info['host']}, python {info['python']}")
    print(f"# JAX devices: {info['jax devices']}; jaxnav git {info['jaxnav commit']}")
    print("# " + ", ".join(f"{k} {val}" for k, val in info["versions"].items()))
    print(f"# load average at start: {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}")
    rates = matmul_rates()
    print(f"# float64 1024^2 matmul: NumPy {rates[0]:.1f} GFLOP/s, jnp {rates[1]:.1f} GFLOP/s", flush=True)

    log(f"simulating B={args.batch} sequences of T={args.T}")
    zs = simulate(args.T, args.batch, args.seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", category=DeprecationWarning)
        rows = run_benchmarks(args, zs, log)
        SCHED.run(log)
        check_cache_hits()

    profile = {}
    if not args.no_profile:
        log("HLO op counts")
        F, H, Q, R = (jnp.asarray(a) for a in model_matrices())
        x0, P0 = (jnp.asarray(a) for a in initial_moments())
        model = jf.constant_velocity(DT, sigma=SIGMA, q=Q_PSD)
        zB = jnp.asarray(zs[:8, :100])
        z1 = zB[0]
        impls = {
            "jaxnav": lambda z: (lambda r: (r.means, r.loglik))(jf.kalman_filter(model, x0, P0, z, save=("means",))),
            "plain lax.scan": lambda z: plain_filter(F, H, Q, R, x0, P0, z),
        }
        try:
            from dynamax.linear_gaussian_ssm import lgssm_filter
            from dynamax.linear_gaussian_ssm.inference import make_lgssm_params
        except Exception:
            pass
        else:
            m1, P1 = first_prior(F, Q, x0, P0)
            params = make_lgssm_params(m1, P1, F, Q, H, R)
            impls["dynamax"] = lambda z: (lambda r: (r.filtered_means, r.marginal_loglik))(lgssm_filter(params, z))
        try:
            key = (
                f"jaxnav kalman_filter_batch (c), B={len(zB)} (every loop, fusions x trips: the covariance pass "
                "x T, the block maps x 4 (and a tail's), the blocks x T/4)"
            )
            profile[key] = loop_body_profile(
                lambda z: (lambda r: (r.means, r.loglik))(
                    jf.kalman_filter_batch(model, x0, P0, z, save=("means",), block=4)
                ),
                zB,
                batch=len(zB),
                split=True,
            )
        except Exception as e:
            log(f"profile of the batch filter skipped: {e!r}")
        for batched in (False, True):
            for name, fn in impls.items():
                key = f"{name} (c) vmap, B={len(zB)}" if batched else f"{name} (a) single"
                try:  # profiling is best effort
                    profile[key] = (
                        loop_body_profile(jax.vmap(fn), zB, batch=len(zB)) if batched else loop_body_profile(fn, z1)
                    )
                except Exception as e:
                    log(f"profile of {key} skipped: {e!r}")
        try:
            res = jf.kalman_filter(model, x0, P0, z1, save=("means", "covs", "pred_means", "pred_covs"))
            moments = (res.means, res.covs, res.pred_means, res.pred_covs)
            profile["jaxnav (b) rts_smoother, full result"] = loop_body_profile(
                lambda r: jf.rts_smoother(model, r), res
            )
            profile["jaxnav (b) rts_smoother, means only"] = loop_body_profile(
                lambda r: jf.rts_smoother(model, r, save=("means",)).means, res
            )
            profile["plain lax.scan (b) RTS, means only"] = loop_body_profile(lambda *mo: plain_rts(F, *mo), *moments)
        except Exception as e:
            log(f"smoother profile skipped: {e!r}")
    end_rates = matmul_rates()  # again at the end: the best of both is the machine's rate
    print(f"# float64 1024^2 matmul at the end: NumPy {end_rates[0]:.1f} GFLOP/s, jnp {end_rates[1]:.1f} GFLOP/s")
    rates = (max(rates[0], end_rates[0]), max(rates[1], end_rates[1]))
    load1 = loadavg()
    wall = time.perf_counter() - t_start
    report = build_report(args, rows, info, rates, load0, load1, profile, wall)
    print()
    print(report)
    if results:
        write_results(results, report)
        log(f"wrote {results}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
