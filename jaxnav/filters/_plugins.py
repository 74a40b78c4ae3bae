"""The plug-in interface of the shared filter step: what a prior-inflation rule or a noise
estimator sees, what it must provide (``typing.Protocol``), and the two defaults.

The adaptive filters of the source papers differ from the classic Kalman filter only in a
scalar factor on the predicted covariance (S0 eqs. (10), (12), (13): constant S, attenuated
S_k, fading lambda_k) or in the noise covariances used at an epoch (S1 eqs. (12)-(19): variance
compensation; Sage-Husa; robust IGG-III). :func:`jaxnav.filters.filter_step` calls, at every
epoch k, first the estimator's :meth:`NoiseEstimator.noise`, then the rule's
:meth:`InflationRule.factor`, predicts with the factor, updates with the chosen noise, and
finally calls :meth:`NoiseEstimator.after` with the update's results.

A new variant is a frozen dataclass registered as a pytree (tunable numbers as array leaves,
structural choices as static fields) that provides the attributes and methods of one protocol.
For example, an inflation that grows linearly with the epoch number up to a cap::

    import dataclasses, jax, jax.numpy as jnp
    from typing import Any, ClassVar, Optional

    @jax.tree_util.register_dataclass
    @dataclasses.dataclass(frozen=True)
    class Linear:
        rate: Any                       # array leaf: vmap/grad reach it
        cap: Any = 10.0
        states: Optional[tuple] = dataclasses.field(default=None, metadata=dict(static=True))
        data_independent: ClassVar[bool] = True   # the factor never looks at the data

        def init(self, n, m, p, dtype):
            return ()                   # no state carried between epochs

        def factor(self, state, ctx):
            return jnp.minimum(1.0 + self.rate * ctx.k, self.cap), state

    jf.kalman_filter(model, x0, P0, zs, inflation=Linear(rate=jnp.asarray(0.01)))
"""

from __future__ import annotations

import math
from typing import Any, ClassVar, NamedTuple, Optional, Protocol, runtime_checkable

import jax
import jax.numpy as jnp
import numpy as np

from jaxnav import _status


class StepContext(NamedTuple):
    """What a rule or estimator may look at when epoch k is predicted (all shapes per sequence).

    Attributes:
      k: scalar float, the epoch number being predicted (1 for the first measurement).
      v: (m,) innovation Z_k - H X_{k,k-1} (S0 eq. (17)); zero in invalid components.
      z: (m,) measurement Z_k (zero in invalid components).
      x_pred: (n,) predicted mean F X_{k-1}.
      valid: (m,) bool, which components of Z_k are used.
      observed: scalar bool, any component valid.
      F: (n, n) transition into epoch k.
      H: (m, n) measurement matrix with invalid rows zeroed.
      G: (n, p) noise input matrix (identity when the model has none).
      Q: (p, p) the model's process-noise covariance at this epoch.
      R: (m, m) the model's measurement-noise covariance at this epoch (not masked).
      FPF: (n, n) F P_{k-1} F^T.
      GQG: (n, n) process noise used in this prediction (after any noise estimator).
      R_used: (m, m) measurement noise used in this update (after any noise estimator).
    """

    k: Any
    v: Any
    z: Any
    x_pred: Any
    valid: Any
    observed: Any
    F: Any
    H: Any
    G: Any
    Q: Any
    R: Any
    FPF: Any
    GQG: Any
    R_used: Any


class PostUpdate(NamedTuple):
    """What the update produced at epoch k (for estimators that learn after it).

    Attributes:
      x: (n,) filtered mean.  P: (n, n) filtered covariance.
      K: (n, m) gain (zero columns for invalid components).
      eps: (m,) post-fit residual Z - H x (zero where invalid).  P_pred: (n, n) the prior covariance used.
    """

    x: Any
    P: Any
    K: Any
    eps: Any
    P_pred: Any


@runtime_checkable
class InflationRule(Protocol):
    """A prior-inflation rule: the factor f_k of P_{k,k-1} = f_k F P_{k-1} F^T + G Q G^T.

    Attributes:
      data_independent: True when the factor never depends on the measurements (then the
        covariance recursion is the same for every data set with the same mask, which
        :func:`jaxnav.filters.kalman_filter_batch` needs and ``vmap`` exploits).
      states: None (the factor scales all of F P F^T) or the static indices of the inflated
        states (then the block of those states is scaled by f_k, their cross terms by sqrt(f_k)).
    """

    data_independent: ClassVar[bool]
    states: Optional[tuple]

    def init(self, n: int, m: int, p: int, dtype) -> Any:
        """Initial rule state (a pytree) for n states, m measurements, p process noises."""

    def factor(self, state, ctx: StepContext) -> tuple[Any, ...]:
        """(scalar factor f_k, new state) for the epoch described by ``ctx``, optionally followed by
        int32 status flags (:mod:`jaxnav._status`, e.g. a parameter out of range or a capped factor)."""


@runtime_checkable
class NoiseEstimator(Protocol):
    """A noise estimator: the G Q G^T and R used at epoch k, and what it learns from the update.

    Attributes:
      data_independent: True when the noise never depends on the measurements.
    """

    data_independent: ClassVar[bool]

    def init(self, n: int, m: int, p: int, dtype) -> Any:
        """Initial estimator state (a pytree)."""

    def noise(self, state, ctx: StepContext) -> tuple[Any, Any, Any, tuple[Any, Any]]:
        """(G Q G^T (n, n), R (m, m), new state, (per-epoch info pytree, int32 status flags))."""

    def after(self, state, ctx: StepContext, post: PostUpdate) -> Any:
        """The state after learning from the update of this epoch."""

    def screen(self, info, ctx: StepContext) -> Any:
        """(m,) bool: components that estimators after this one in a chain must not learn from."""


@jax.tree_util.register_pytree_node_class
class NoInflation:
    """The classic Kalman filter: factor 1 (S0 eq. (8))."""

    data_independent: ClassVar[bool] = True
    states: ClassVar[Optional[tuple]] = None

    def init(self, n, m, p, dtype):
        return ()

    def factor(self, state, ctx):
        return jnp.ones((), ctx.FPF.dtype), state

    def tree_flatten(self):
        return (), None

    @classmethod
    def tree_unflatten(cls, aux, children):
        return cls()


@jax.tree_util.register_pytree_node_class
class NoEstimator:
    """Keep the model's Q and R (the default)."""

    data_independent: ClassVar[bool] = True

    def init(self, n, m, p, dtype):
        return ()

    def noise(self, state, ctx):
        return ctx.GQG, ctx.R, state, ((), jnp.zeros((), jnp.int32))

    def after(self, state, ctx, post):
        return state

    def screen(self, info, ctx):
        return jnp.zeros_like(ctx.valid)

    def tree_flatten(self):
        return (), None

    @classmethod
    def tree_unflatten(cls, aux, children):
        return cls()


def data_independent(*plugins) -> bool:
    """Whether every plug-in (None = the default) leaves the covariance recursion independent of the data."""
    return all(p is None or p.data_independent for p in plugins)


# --------------------------------------------------------------------------------------------
# parameter ranges: checked by the constructors when concrete, flagged at run time when traced
# --------------------------------------------------------------------------------------------


class Range(NamedTuple):
    """The documented range of a plug-in parameter: lo <= x <= hi, with open ends where said."""

    lo: float = -math.inf
    hi: float = math.inf
    lo_open: bool = False
    hi_open: bool = True

    def text(self) -> str:
        """The interval in mathematical notation, e.g. ``[0, 1)``."""
        return f"{'(' if self.lo_open else '['}{self.lo:g}, {self.hi:g}{')' if self.hi_open else ']'}"

    def holds(self, x):
        """Elementwise bool: x in the range (NaN is outside); numpy for concrete values, jax for traced."""
        lo = (x > self.lo) if self.lo_open else (x >= self.lo)
        hi = (x < self.hi) if self.hi_open else (x <= self.hi)
        return lo & hi


def concrete_value(x):
    """A concrete parameter as a float64 numpy array, or None for a traced value (checked at run time)."""
    if x is None or isinstance(x, jax.core.Tracer):
        return None
    try:
        return np.asarray(x, dtype=np.float64)
    except (TypeError, jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError):
        return None


def check_ranges(where: str, ranges: dict, **values) -> None:
    """Raise ``ValueError`` naming the range if a concrete value lies outside it (traced values pass).

    Args:
      where: the constructor's name, for the message.  ranges: {name: :class:`Range`}.
      values: the parameters by name (None: not given).
    """
    for name, x in values.items():
        a = concrete_value(x)
        if a is not None and not bool(np.all(ranges[name].holds(a))):
            raise ValueError(f"{where}: {name} must be in {ranges[name].text()}, got {x!r}")


def range_flags(plugin, ranges: dict):
    """int32 PARAMETER_OUT_OF_RANGE when any of the plug-in's parameters (its attributes named in
    ``ranges``, None skipped) is outside its range at run time, else 0."""
    ok = jnp.ones((), bool)
    for name, rng in ranges.items():
        x = getattr(plugin, name)
        if x is not None:
            ok = ok & jnp.all(rng.holds(jnp.asarray(x)))
    return jnp.where(ok, 0, _status.PARAMETER_OUT_OF_RANGE).astype(jnp.int32)


def rule_factor(rule, state, ctx):
    """(factor, new state, int32 flags) of a rule, whether its ``factor`` returns flags or not."""
    out = rule.factor(state, ctx)
    if len(out) == 3:
        return out
    f, st = out
    return f, st, jnp.zeros((), jnp.int32)
