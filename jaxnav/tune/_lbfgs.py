"""L-BFGS with a strong-Wolfe line search in which every loss evaluation is one scan step.

``optax.lbfgs`` with its zoom line search evaluates the loss at three places of the program (the
initial gradient and the two branches of the zoom), so an expensive loss (a 2000 s INS/GNSS
run under ``jax.jvp``) is compiled three times. Here the optimiser is a state machine advanced
once per evaluation inside one ``lax.scan``: the loss and its gradient appear once in the
program, the step direction comes from ``optax.scale_by_lbfgs`` and the step length from the
bracketing / cubic-interpolation search of Nocedal & Wright (Numerical Optimization, 2nd ed.,
Algorithms 3.5-3.6, eq. (3.59)), written without branches.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from typing import Any, NamedTuple

import jax
import jax.flatten_util
import jax.numpy as jnp
import optax

from jaxnav.tune._bijectors import Space
from jaxnav.tune._optimize import TuneResult, value_and_grad


class _LS(NamedTuple):
    """Line-search state along u = u_acc + alpha d."""

    alpha: jax.Array  # the trial step of the next evaluation
    lo: jax.Array  # bracket end with the lowest Armijo-satisfying value: (step, value, slope)
    f_lo: jax.Array
    g_lo: jax.Array
    hi: jax.Array
    f_hi: jax.Array
    g_hi: jax.Array
    bracketed: jax.Array


class _State(NamedTuple):
    u: jax.Array  # flat accepted point
    f: jax.Array  # its loss (inf before the first evaluation)
    g: jax.Array  # its gradient
    d: jax.Array  # search direction
    slope: jax.Array  # g . d at the accepted point
    ls: _LS
    lbfgs: Any
    steps: jax.Array  # accepted steps so far
    done: jax.Array


def _cubic_min(a, fa, ga, b, fb, gb):
    """Minimiser of the cubic through (a, fa, ga), (b, fb, gb) (Nocedal & Wright eq. (3.59)), else the midpoint."""
    d1 = ga + gb - 3.0 * (fa - fb) / (a - b)
    disc = d1 * d1 - ga * gb
    d2 = jnp.sign(b - a) * jnp.sqrt(jnp.maximum(disc, 0.0))
    x = b - (b - a) * (gb + d2 - d1) / (gb - ga + 2.0 * d2)
    lo, hi = jnp.minimum(a, b), jnp.maximum(a, b)
    w = hi - lo
    ok = jnp.isfinite(x) & (disc >= 0.0)
    return jnp.where(ok, jnp.clip(x, lo + 0.1 * w, hi - 0.1 * w), 0.5 * (a + b))


def minimize_lbfgs(
    loss: Callable,
    params0: Mapping,
    space: Space,
    *,
    max_evals: int = 20,
    memory_size: int = 10,
    c1: float = 1e-4,
    c2: float = 0.9,
    ftol: float = 1e-4,
    gtol: float = 1e-10,
    mode: str = "auto",
) -> TuneResult:
    """Minimise ``loss(params)`` by L-BFGS with a strong-Wolfe line search, one loss evaluation per scan step.

    Each step of the ``lax.scan`` evaluates the loss and its gradient (forward or reverse mode, see
    :func:`jaxnav.tune.value_and_grad`) at one trial point and updates the line search: Armijo
    f(u + a d) <= f(u) + c1 a g.d and strong curvature |g(u + a d).d| <= c2 |g.d| accept the
    trial (the L-BFGS memory of ``optax.scale_by_lbfgs`` is updated there and the next direction
    tried with a = 1); otherwise the bracket [lo, hi] is extended (doubling) or shrunk (safeguarded
    cubic interpolation). The run stops (later scan steps skip the evaluation) when an accepted
    step lowers the loss by less than ``ftol`` relative, or the L-BFGS model predicts less than
    that for the next step (-g.d / 2, from the second accepted point on), or the gradient's
    max-norm is below ``gtol``, or after ``max_evals`` evaluations.

    Args:
      loss: dict of constrained parameters -> scalar.
      params0: dict of initial constrained values.  space: :class:`jaxnav.tune.Space`.
      max_evals: static number of evaluations at most (scan length).
      memory_size: L-BFGS memory.  c1, c2: Wolfe constants (0 < c1 < c2 < 1).
      ftol, gtol: stopping tolerances.  mode: "auto", "forward" or "reverse" gradients.
    Returns:
      :class:`TuneResult` whose per-step arrays are per *evaluation*: ``losses`` the trial losses,
      ``path`` the trial parameters, ``grad_norm`` their gradient norms (inf / NaN after the stop);
      ``n_evals`` the evaluations done; ``params``/``loss`` the last accepted point.
    """
    if max_evals < 2:
        raise ValueError(f"max_evals must be >= 2, got {max_evals}")
    if not 0.0 < c1 < c2 < 1.0:
        raise ValueError(f"need 0 < c1 < c2 < 1, got c1={c1}, c2={c2}")
    t0 = time.perf_counter()
    u0 = space.unconstrain(params0)
    flat0, unravel = jax.flatten_util.ravel_pytree(u0)
    m = space.mask()  # one factor per parameter, broadcast over a vector parameter's elements
    mask = jax.flatten_util.ravel_pytree({k: jnp.full(jnp.shape(v), m[k]) for k, v in u0.items()})[0].astype(
        flat0.dtype
    )
    vg_tree = value_and_grad(lambda u: loss(space.constrain(u)), mode=mode)

    def vg(x):
        val, g = vg_tree(unravel(x))
        return val, jax.flatten_util.ravel_pytree(g)[0] * mask

    lb = optax.scale_by_lbfgs(memory_size=memory_size)
    dtype = flat0.dtype
    inf = jnp.asarray(jnp.inf, dtype)

    def accept(s, x, f, g):
        p, lbs = lb.update(g, s.lbfgs, x)
        d = -p * mask
        slope = jnp.dot(g, d)
        bad = ~(slope < 0.0)  # not a descent direction: steepest descent
        d = jnp.where(bad, -g, d)
        slope = jnp.where(bad, -jnp.dot(g, g), slope)
        tol = ftol * jnp.maximum(jnp.abs(f), 1.0)
        # converged: the step just taken gained less than ftol, or (once the memory holds curvature)
        # the quadratic model's decrease for the next unit step, -g.d / 2, is below ftol
        conv = ((s.f - f) <= tol) | ((s.steps > 0) & (-0.5 * slope <= tol)) | (jnp.max(jnp.abs(g)) <= gtol)
        # first direction (empty memory: -g): a step of unit length in the unconstrained space, so
        # the search does not depend on the loss's units (Nocedal & Wright Sec. 3.5); then 1
        norm = jnp.sqrt(jnp.dot(d, d))
        alpha0 = jnp.where((s.steps == 0) & (norm > 0.0), 1.0 / jnp.where(norm > 0.0, norm, 1.0), 1.0)
        ls = _LS(
            alpha=alpha0.astype(dtype),
            lo=jnp.zeros((), dtype),
            f_lo=f,
            g_lo=slope,
            hi=inf,
            f_hi=inf,
            g_hi=inf,
            bracketed=jnp.zeros((), bool),
        )
        return _State(u=x, f=f, g=g, d=d, slope=slope, ls=ls, lbfgs=lbs, steps=s.steps + 1, done=s.done | conv)

    def trial(s, f, dg, armijo):
        ls = s.ls
        a = ls.alpha
        high = ~armijo | (f >= ls.f_lo)
        # high: [lo, a] brackets a minimum.  else: a is the new lo; if the slope turned
        # non-negative the old lo (or, bracketed, the end on the slope's side) becomes hi
        swap = ~high & jnp.where(ls.bracketed, dg * (ls.hi - ls.lo) >= 0.0, dg >= 0.0)
        hi, f_hi, g_hi = (
            jnp.where(high, a, jnp.where(swap, ls.lo, ls.hi)),
            jnp.where(high, f, jnp.where(swap, ls.f_lo, ls.f_hi)),
            jnp.where(high, dg, jnp.where(swap, ls.g_lo, ls.g_hi)),
        )
        lo, f_lo, g_lo = (jnp.where(high, ls.lo, a), jnp.where(high, ls.f_lo, f), jnp.where(high, ls.g_lo, dg))
        bracketed = ls.bracketed | high | swap
        nxt = jnp.where(bracketed, _cubic_min(lo, f_lo, g_lo, hi, f_hi, g_hi), 2.0 * a)
        tiny = bracketed & (jnp.abs(hi - lo) * jnp.max(jnp.abs(s.d)) <= 1e-12 * (1.0 + jnp.max(jnp.abs(s.u))))
        return s._replace(
            ls=_LS(alpha=nxt, lo=lo, f_lo=f_lo, g_lo=g_lo, hi=hi, f_hi=f_hi, g_hi=g_hi, bracketed=bracketed),
            done=s.done | tiny,
        )

    def step(s, _):
        x = s.u + s.ls.alpha * s.d
        f, g = jax.lax.cond(s.done, lambda x: (inf, jnp.full_like(x, jnp.nan)), vg, x)
        dg = jnp.dot(g, s.d)
        armijo = jnp.isfinite(f) & (f <= s.f + c1 * s.ls.alpha * s.slope)
        ok = ~jnp.isfinite(s.f) | (armijo & (jnp.abs(dg) <= c2 * jnp.abs(s.slope)))  # first point, or strong Wolfe
        new = jax.tree_util.tree_map(lambda a, b: jnp.where(ok, a, b), accept(s, x, f, g), trial(s, f, dg, armijo))
        new = jax.tree_util.tree_map(lambda a, b: jnp.where(s.done, a, b), s, new)
        return new, (f, jnp.where(s.done, jnp.nan, x), jnp.sqrt(jnp.dot(g, g)), ~s.done)

    @jax.jit
    def run(flat0):
        s0 = _State(
            u=flat0,
            f=inf,
            g=jnp.zeros_like(flat0),
            d=jnp.zeros_like(flat0),
            slope=jnp.zeros((), dtype),
            ls=_LS(jnp.zeros((), dtype), *(jnp.zeros((), dtype),) * 3, inf, inf, inf, jnp.zeros((), bool)),
            lbfgs=lb.init(flat0),
            steps=jnp.zeros((), jnp.int32),
            done=jnp.zeros((), bool),
        )
        s, (fs, xs, gn, did) = jax.lax.scan(step, s0, None, length=max_evals)
        return s.u, s.f, fs, xs, gn, jnp.sum(did)

    compiled = run.lower(flat0).compile()
    t_compile = time.perf_counter() - t0
    u, f, fs, xs, gn, n = jax.block_until_ready(compiled(flat0))
    path = jax.vmap(lambda x: space.constrain(unravel(x)))(xs)
    return TuneResult(
        params=space.constrain(unravel(u)),
        loss=f,
        losses=fs,
        path=path,
        grad_norm=gn,
        n_evals=int(n),
        wall_time_s=time.perf_counter() - t0,
        compile_time_s=t_compile,
    )
