"""Small bijectors from unconstrained reals to the parameter domains a filter needs.

Gradient tuning works on unconstrained values u; the filter sees p = forward(u). S0's
attenuation factor b lives in (0, 1) (sigmoid), variances and noise scales in (0, inf)
(softplus or exp), the fading rho in (0, inf).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import NamedTuple

import jax
import jax.numpy as jnp


class Bijector(NamedTuple):
    """A named pair of elementwise maps: ``forward`` (R -> domain) and ``inverse``.

    ``lo`` and ``hi`` are the open domain bounds (for messages and grid checks).
    """

    name: str
    forward: Callable
    inverse: Callable
    lo: float
    hi: float


def real() -> Bijector:
    """Identity on R."""
    return Bijector("real", lambda u: u, lambda p: p, -math.inf, math.inf)


def interval(lo: float, hi: float) -> Bijector:
    """(lo, hi) by a scaled sigmoid: p = lo + (hi - lo) / (1 + exp(-u))."""
    lo, hi = float(lo), float(hi)
    if not hi > lo:
        raise ValueError(f"interval needs lo < hi, got ({lo}, {hi})")
    w = hi - lo

    def inverse(p):
        s = (jnp.asarray(p) - lo) / w
        return jnp.log(s) - jnp.log1p(-s)

    return Bijector(f"interval({lo:g}, {hi:g})", lambda u: lo + w * jax.nn.sigmoid(u), inverse, lo, hi)


def unit() -> Bijector:
    """(0, 1) by the sigmoid (S0's attenuation factor b, forgetting factors)."""
    return interval(0.0, 1.0)


def positive() -> Bijector:
    """(0, inf) by softplus p = log(1 + e^u) (noise scales; linear for large u)."""
    return Bijector("softplus", jax.nn.softplus, lambda p: jnp.log(jnp.expm1(jnp.asarray(p))), 0.0, math.inf)


def log() -> Bijector:
    """(0, inf) by p = exp(u) (scale parameters whose relative change matters: ML noise tuning)."""
    return Bijector("log", jnp.exp, jnp.log, 0.0, math.inf)


BIJECTORS = {"real": real, "unit": unit, "positive": positive, "log": log}


def bijector(spec) -> Bijector:
    """A :class:`Bijector` from itself, a name in ``BIJECTORS`` or ``("interval", lo, hi)``."""
    if isinstance(spec, Bijector):
        return spec
    if isinstance(spec, str) and spec in BIJECTORS:
        return BIJECTORS[spec]()
    if isinstance(spec, (tuple, list)) and len(spec) == 3 and spec[0] == "interval":
        return interval(spec[1], spec[2])
    raise ValueError(f"unknown bijector {spec!r}; expected one of {sorted(BIJECTORS)} or ('interval', lo, hi)")


class Space:
    """Named parameters with their bijectors and which of them are trainable.

    Args:
      bijectors: mapping name -> bijector (or its name, see :func:`bijector`).
      trainable: names that the optimiser moves (default all); the others stay at their
        initial value (their gradient is zeroed).
    """

    def __init__(self, bijectors: Mapping, trainable: tuple | None = None):
        self.bijectors = {k: bijector(v) for k, v in bijectors.items()}
        names = tuple(self.bijectors)
        trainable = names if trainable is None else tuple(trainable)
        unknown = [t for t in trainable if t not in self.bijectors]
        if unknown:
            raise ValueError(f"trainable names {unknown} are not parameters; parameters are {list(names)}")
        self.trainable = trainable

    @property
    def names(self):
        return tuple(self.bijectors)

    def check(self, params: Mapping):
        """Raise ValueError if names differ or a value lies outside its open domain."""
        if set(params) != set(self.bijectors):
            raise ValueError(f"parameters {sorted(params)} do not match the space {sorted(self.bijectors)}")
        for k, b in self.bijectors.items():
            v = jnp.asarray(params[k])
            if not isinstance(v, jax.core.Tracer) and not bool(jnp.all((v > b.lo) & (v < b.hi))):
                raise ValueError(f"parameter {k} = {v} lies outside the open domain ({b.lo}, {b.hi}) of {b.name}")

    def unconstrain(self, params: Mapping) -> dict:
        """Constrained values -> unconstrained u (dict of arrays)."""
        self.check(params)
        return {k: self.bijectors[k].inverse(jnp.asarray(params[k], float)) for k in self.names}

    def constrain(self, u: Mapping) -> dict:
        """Unconstrained u -> constrained values."""
        return {k: self.bijectors[k].forward(u[k]) for k in self.names}

    def mask(self) -> dict:
        """{name: 1.0 if trainable else 0.0} (multiplies gradients)."""
        return {k: 1.0 if k in self.trainable else 0.0 for k in self.names}
