"""The Monte Carlo cases written the way a user writes them: ``jax.vmap`` of jaxnav's filter and smoother.

A script, not a test; a focused subset of ``bench_filters.py`` (same problem, same timing
harness: interleaved rounds, minimum after compilation), against dynamax and a plain vmapped
``lax.scan`` in the same process:

    .venv-bench/bin/python benchmarks/bench_user_vmap.py --T 3600 --batch 256 --repeats 7

Rows: (c) ``jit(vmap(kalman_filter))`` (means saved), (g) ``jit(vmap(lambda z:
rts_smoother(m, kalman_filter(m, x0, P0, z)).means))``, (f) ``jit(vmap(value_and_grad))`` of the
log-likelihood; each on clean data and with one NaN in one sequence (the per-sequence path).
Prints a markdown table; ``--results FILE`` replaces its generated section.
"""

from __future__ import annotations

import argparse
import sys
import warnings

import bench_filters as bf
import jax
import jax.numpy as jnp
import numpy as np
from _harness import git_revision, loadavg, write_section
from bench_filters import DT, N_OBS, Q_PSD, SCHED, SIGMA, jf, jit_time

BEGIN = "<!-- BEGIN bench_user_vmap results (generated; rerun the script to refresh) -->"
END = "<!-- END bench_user_vmap results -->"


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--T", type=int, default=3600)
    p.add_argument("--batch", type=int, default=256)
    p.add_argument("--repeats", type=int, default=7)
    p.add_argument("--cases", default="cgf", help="subset of the cases c, g, f to run (default all)")
    p.add_argument("--results", default=None, help="markdown file whose generated section is replaced")
    args = p.parse_args(argv)
    T, B, reps = args.T, args.batch, args.repeats
    load0 = loadavg()
    F, H, Q, R = (jnp.asarray(a) for a in bf.model_matrices())
    x0, P0 = (jnp.asarray(a) for a in bf.initial_moments())
    m1, P1 = (jnp.asarray(a) for a in bf.first_prior(*bf.model_matrices()[::2], *bf.initial_moments()))
    zB = jnp.asarray(bf.simulate(T, B))
    zN = zB.at[B // 2, T // 2, 0].set(jnp.nan)
    model = jf.constant_velocity(DT, sigma=SIGMA, q=Q_PSD)
    Qunit = jnp.asarray(bf.model_matrices(q=1.0)[2])
    theta0 = jnp.array([np.log(Q_PSD), np.log(SIGMA)])
    from dynamax.linear_gaussian_ssm import lgssm_filter, lgssm_smoother
    from dynamax.linear_gaussian_ssm.inference import make_lgssm_params

    params = make_lgssm_params(m1, P1, F, Q, H, R)

    def jx_nll(theta, z):
        mod = jf.constant_velocity(DT, sigma=jnp.exp(theta[1]), q=jnp.exp(theta[0]))
        return -jf.kalman_filter(mod, x0, P0, z, save=()).loglik

    def jx_ll(theta, z):
        mod = jf.constant_velocity(DT, sigma=jnp.exp(theta[1]), q=jnp.exp(theta[0]))
        return -jf.log_likelihood(mod, x0, P0, z)

    def dx_nll(theta, z):
        Qt, Rt = jnp.exp(theta[0]) * Qunit, jnp.exp(2 * theta[1]) * jnp.eye(N_OBS)
        return -lgssm_filter(make_lgssm_params(F @ x0, F @ P0 @ F.T + Qt, F, Qt, H, Rt), z).marginal_loglik

    vg = lambda f: jax.jit(jax.vmap(jax.value_and_grad(f), in_axes=(None, 0)))
    cases = {
        "c": [
            (
                "jaxnav vmap(kalman_filter)",
                jax.jit(jax.vmap(lambda z: jf.kalman_filter(model, x0, P0, z, save=("means",)).means)),
                True,
            ),
            ("plain lax.scan", jax.jit(jax.vmap(lambda z: bf.plain_filter(F, H, Q, R, x0, P0, z))), False),
            ("dynamax", jax.jit(jax.vmap(lambda z: lgssm_filter(params, z).filtered_means)), False),
        ],
        "g": [
            (
                "jaxnav vmap(filter + RTS)",
                jax.jit(jax.vmap(lambda z: jf.rts_smoother(model, jf.kalman_filter(model, x0, P0, z)).means)),
                True,
            ),
            (
                "plain lax.scan",
                jax.jit(
                    jax.vmap(
                        lambda z: (lambda o: bf.plain_rts(F, *o))(bf.plain_filter(F, H, Q, R, x0, P0, z, keep_all=True))
                    )
                ),
                False,
            ),
            ("dynamax", jax.jit(jax.vmap(lambda z: lgssm_smoother(params, z).smoothed_means)), False),
        ],
        "f": [
            ("jaxnav vmap(value_and_grad(log_likelihood))", vg(jx_ll), True),
            ("jaxnav vmap(value_and_grad(kalman_filter(...).loglik))", vg(jx_nll), True),
            ("dynamax", vg(dx_nll), False),
        ],
    }
    rows = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", category=DeprecationWarning)
        for case, impls in ((c, i) for c, i in cases.items() if c in args.cases):
            for name, fn, nan_too in impls:
                for label, data in (("clean", zB), ("one NaN", zN)) if nan_too else (("clean", zB),):
                    a = (theta0, data) if case == "f" else (data,)
                    first, runs, _ = jit_time(fn, a, reps)
                    rows.append((case, name, label, first, runs))
                    print(f"compiled ({case}) {name} {label}: {first:.1f} s", file=sys.stderr, flush=True)
        SCHED.run()
    load1 = loadavg()
    best = {(c, n, lab): min(r) for c, n, lab, _, r in rows}
    out = [
        f"jaxnav {git_revision()}, T = {T}, B = {B}, minimum of {reps} interleaved rounds; load average "
        f"(1/5/15 min) start {load0[0]:.2f} / {load0[1]:.2f} / {load0[2]:.2f}, end "
        f"{load1[0]:.2f} / {load1[1]:.2f} / {load1[2]:.2f}. Speed-up columns: the reference's time / jaxnav's "
        "(>= 1: jaxnav faster).",
        "",
        "| case | implementation | data | min | vs plain lax.scan | vs dynamax |",
        "|---|---|---|---|---|---|",
    ]
    for c, n, lab, _, r in rows:
        t = min(r)
        ps = best.get((c, "plain lax.scan", "clean"))
        dx = best.get((c, "dynamax", "clean"))
        ref_row = n in ("plain lax.scan", "dynamax")
        fmt = lambda ref: "—" if ref is None or ref_row else f"{ref / t:.2f}x"
        out.append(f"| ({c}) | {n} | {lab} | {bf._fmt_t(t)} | {fmt(ps)} | {fmt(dx)} |")
    report = "\n".join(out)
    print(report)
    if args.results:
        write_section(args.results, report, BEGIN, END)
    return 0


if __name__ == "__main__":
    sys.exit(main())
