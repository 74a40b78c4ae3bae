"""Gradient tuning: an optax loop inside ``lax.scan`` over constrained, named parameters."""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from typing import Any, NamedTuple

import jax
import jax.flatten_util
import jax.numpy as jnp
import optax

from jaxnav.tune._bijectors import Space


class TuneResult(NamedTuple):
    """Result of :func:`minimize`.

    Attributes:
      params: dict of the final constrained parameter values.
      loss: scalar loss at ``params``.
      losses: (steps,) loss at the parameters each step started from.
      path: dict name -> (steps,) + shape, constrained parameters each step started from.
      grad_norm: (steps,) norm of the (masked) gradient w.r.t. the unconstrained parameters.
      n_evals: total loss evaluations (counting a gradient as one; line searches add more).
      wall_time_s: host time of the whole call (compilation included).
      compile_time_s: of which compilation.
    """

    params: dict
    loss: jax.Array
    losses: jax.Array
    path: dict
    grad_norm: jax.Array
    n_evals: int
    wall_time_s: float = 0.0
    compile_time_s: float = 0.0


def _resolve_mode(mode, u):
    if mode not in ("auto", "forward", "reverse"):
        raise ValueError(f"mode must be 'auto', 'forward' or 'reverse', got {mode!r}")
    if mode != "auto":
        return mode
    d = sum(int(jnp.size(x)) for x in jax.tree_util.tree_leaves(u))
    return "forward" if d <= 4 else "reverse"


def _forward_value_and_grad(f, u):
    flat, unravel = jax.flatten_util.ravel_pytree(u)
    g_flat = lambda x: f(unravel(x))
    if flat.shape[0] == 1:  # one scalar: a plain jvp (a size-1 vmap costs ~1.5x more, measured on S0)
        val, d = jax.jvp(g_flat, (flat,), (jnp.ones_like(flat),))
        return val, unravel(jnp.reshape(d, (1,)))
    vals, dirs = jax.vmap(lambda t: jax.jvp(g_flat, (flat,), (t,)))(jnp.eye(flat.shape[0], dtype=flat.dtype))
    return vals[0], unravel(dirs)


def forward_gradient(f: Callable) -> Callable:
    """``f`` whose reverse-mode derivative is computed in forward mode (one tangent per scalar).

    ``jax.grad`` of the result runs the vmapped ``jax.jvp`` of :func:`value_and_grad` instead of
    building a tape, so code that insists on reverse mode (optax's zoom line search of
    ``optax.lbfgs``) gets forward-mode cost and memory for a few parameters.
    """

    @jax.custom_vjp
    def g(u):
        return f(u)

    def g_fwd(u):
        return _forward_value_and_grad(f, u)

    def g_bwd(grad, ct):
        return (jax.tree_util.tree_map(lambda x: ct * x, grad),)

    g.defvjp(g_fwd, g_bwd)
    return g


def value_and_grad(f: Callable, mode: str = "auto"):
    """``value_and_grad`` of a scalar function of a dict of arrays, in forward or reverse mode.

    Forward mode pushes one tangent per scalar parameter through the computation (vmapped
    ``jax.jvp``): no tape, memory of a forward run, cost about (1 + d/2) forward runs for d
    parameters; it is the better choice for the few scalars of a filter (b, rho, noise scales)
    through a long INS/GNSS run. Reverse mode costs a few forward runs for any d and needs the
    tape (bounded with ``jax.checkpoint``, see ``LCPropagation.remat`` of :func:`jaxnav.ins.loosely_coupled`).

    Args:
      f: u (dict of arrays) -> scalar.
      mode: "forward", "reverse" or "auto" (forward for up to 4 scalars).
    Returns:
      u -> (value, grad dict).
    """
    _resolve_mode(mode, {})  # validate early

    def vg(u):
        if _resolve_mode(mode, u) == "reverse":
            return jax.value_and_grad(f)(u)
        return _forward_value_and_grad(f, u)

    return vg


def minimize(
    loss: Callable, params0: Mapping, space: Space, *, optimizer: Any | None = None, steps: int = 50, mode: str = "auto"
) -> TuneResult:
    """Minimise ``loss(params)`` with an optax optimiser, all steps in one jitted ``lax.scan``.

    The optimiser works on the unconstrained values u = space.inverse(params); parameters not
    in ``space.trainable`` keep their initial value (their gradient is zeroed). Optimisers that
    need the loss value or a line search (``optax.lbfgs``, ``optax.polyak_sgd``) receive
    ``value``, ``grad`` and ``value_fn`` as extra arguments.

    Args:
      loss: dict of constrained parameters -> scalar (close over data, PRNG keys, seeds).
      params0: dict of initial constrained values (inside each bijector's domain).
      space: :class:`jaxnav.tune.Space`.
      optimizer: an optax ``GradientTransformation`` (default ``optax.adam(0.1)``).
      steps: number of optimiser steps (static).
      mode: gradient mode, see :func:`value_and_grad`.
    Returns:
      :class:`TuneResult`.
    """
    if steps < 1:
        raise ValueError(f"steps must be >= 1, got {steps}")
    t0 = time.perf_counter()
    opt = optax.adam(0.1) if optimizer is None else optimizer
    u0 = space.unconstrain(params0)
    mask = space.mask()

    def f0(u):
        return loss(space.constrain(u))

    # in forward mode every gradient, the line searches' included, is taken by jvp
    f = forward_gradient(f0) if _resolve_mode(mode, u0) == "forward" else f0
    vg = jax.value_and_grad(f)
    extra = isinstance(opt, optax.GradientTransformationExtraArgs)
    stored = _stores_value_and_grad(opt.init(u0))

    def masked(g):
        return jax.tree_util.tree_map(lambda gi, m: gi * m, g, mask)

    @jax.jit
    def run(u0):
        def step(carry, _):
            u, s, val, g = carry
            if extra:
                upd, s = opt.update(g, s, u, value=val, grad=g, value_fn=f)
            else:
                upd, s = opt.update(g, s, u)
            upd = jax.tree_util.tree_map(lambda x, m: x * m, upd, mask)
            new = optax.apply_updates(u, upd)
            if stored:  # a line search evaluated value and gradient at the accepted point: reuse them
                new_val, new_g = optax.tree.get(s, "value"), optax.tree.get(s, "grad")
            else:
                new_val, new_g = vg(new)
            gn = jnp.sqrt(sum(jnp.sum(x**2) for x in jax.tree_util.tree_leaves(g)))
            return (new, s, new_val, masked(new_g)), (val, space.constrain(u), gn, _linesearch_evals(s))

        val0, g0 = vg(u0)
        (u, s, val, _), (losses, path, gn, n_ls) = jax.lax.scan(
            step, (u0, opt.init(u0), val0, masked(g0)), None, length=steps
        )
        return space.constrain(u), val, losses, path, gn, jnp.sum(n_ls)

    compiled = run.lower(u0).compile()
    t_compile = time.perf_counter() - t0
    params, final, losses, path, gn, n_ls = jax.block_until_ready(compiled(u0))
    n_evals = 1 + int(n_ls) + (0 if stored else steps)
    return TuneResult(
        params=params,
        loss=final,
        losses=losses,
        path=path,
        grad_norm=gn,
        n_evals=n_evals,
        wall_time_s=time.perf_counter() - t0,
        compile_time_s=t_compile,
    )


def _stores_value_and_grad(state) -> bool:
    """Whether an optax state keeps the value and gradient of its last accepted point (line searches)."""
    try:
        return optax.tree.get(state, "value") is not None and optax.tree.get(state, "grad") is not None
    except (KeyError, ValueError):
        return False


def _linesearch_evals(state):
    """Loss evaluations spent in the last step's optax line search (0 for plain optimisers)."""
    n = jnp.zeros((), jnp.int32)
    for leaf_state in jax.tree_util.tree_leaves(state, is_leaf=lambda x: hasattr(x, "info")):
        info = getattr(leaf_state, "info", None)
        if info is not None and hasattr(info, "num_linesearch_steps"):
            n = n + jnp.asarray(info.num_linesearch_steps, jnp.int32)
    return n
