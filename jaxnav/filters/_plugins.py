"""The plug-in interface of the shared filter step: what a prior-inflation rule or a noise
estimator sees, what it provides (:class:`InflationRule`, :class:`NoiseEstimator`: protocols
whose default methods a plug-in inherits by subclassing), and the two defaults.

The adaptive filters of the source papers differ from the classic Kalman filter only in a
scalar factor on the predicted covariance (S0 eqs. (10), (12), (13): constant S, attenuated
S_k, fading lambda_k) or in the noise covariances used at an epoch (S1 eqs. (12)-(19): variance
compensation; Sage-Husa; robust IGG-III). :func:`jaxnav.filters.filter_step` calls, at every
epoch k, first the estimator's :meth:`NoiseEstimator.noise`, then the rule's
:meth:`InflationRule.factor`, predicts with the factor, updates with the chosen noise, and
finally calls :meth:`NoiseEstimator.after` with the update's results.

A new variant subclasses one protocol and is made a pytree by :func:`pytree_dataclass`
(tunable numbers as array leaves, structural choices as static fields); it overrides what
differs from the defaults. For example, an inflation that grows linearly with the epoch number
up to a cap::

    import dataclasses, jax, jax.numpy as jnp
    from jaxnav.filters import InflationRule, pytree_dataclass

    @pytree_dataclass
    class Linear(InflationRule):
        rate: jax.Array                 # array leaf: vmap/grad reach it
        cap: jax.Array = 10.0

        @property
        def data_independent(self):     # the factor never looks at the data
            return True

        def factor(self, state, ctx):
            f = jnp.minimum(1.0 + self.rate * ctx.k, self.cap)
            return f, state, jnp.zeros((), jnp.int32)   # (factor, new state, status flags)

    jf.kalman_filter(model, x0, P0, zs, inflation=Linear(rate=jnp.asarray(0.01)))
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, NamedTuple, Protocol, runtime_checkable

import jax
import jax.numpy as jnp
import numpy as np

from jaxnav import _status
from jaxnav._numerics import as_leaf


def pytree_dataclass(cls):
    """Make ``cls`` a frozen dataclass and a pytree: fields with ``metadata=dict(static=True)``
    are part of the tree structure, all other fields are leaves.

    JAX rebuilds a pytree from whatever its leaves became (tracers, shapes, ``in_axes``
    entries, sharding specs), so rebuilding bypasses ``__init__`` and ``__post_init__``:
    a constructor's validation applies to what a user builds, not to what JAX rebuilds.

    Args:
      cls: a class body with annotated fields (dataclass syntax).
    Returns:
      The same class, frozen dataclass and registered pytree (keys are the field names).
    """
    cls = dataclasses.dataclass(frozen=True)(cls)
    fields = dataclasses.fields(cls)
    data = tuple(f.name for f in fields if not f.metadata.get("static", False))
    meta = tuple(f.name for f in fields if f.metadata.get("static", False))
    keys = tuple(jax.tree_util.GetAttrKey(name) for name in data)

    def flatten_with_keys(obj):
        return [(key, getattr(obj, name)) for key, name in zip(keys, data)], tuple(getattr(obj, n) for n in meta)

    def flatten(obj):
        return [getattr(obj, name) for name in data], tuple(getattr(obj, n) for n in meta)

    def unflatten(aux, children):
        obj = object.__new__(cls)
        for name, value in zip(meta, aux):
            object.__setattr__(obj, name, value)
        for name, value in zip(data, children):
            object.__setattr__(obj, name, value)
        return obj

    jax.tree_util.register_pytree_with_keys(cls, flatten_with_keys, unflatten, flatten)
    return cls


def static_field(default=dataclasses.MISSING):
    """A dataclass field of :func:`pytree_dataclass` that is tree structure (a Python value), not a leaf."""
    return dataclasses.field(default=default, metadata=dict(static=True))


def leaf(x):
    """A plug-in's tunable number as a float array leaf (:func:`jaxnav._numerics.as_leaf`); None stays None."""
    return None if x is None else as_leaf(x)


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

    k: jax.Array
    v: jax.Array
    z: jax.Array
    x_pred: jax.Array
    valid: jax.Array
    observed: jax.Array
    F: jax.Array
    H: jax.Array
    G: jax.Array
    Q: jax.Array
    R: jax.Array
    FPF: jax.Array
    GQG: jax.Array
    R_used: jax.Array


class PostUpdate(NamedTuple):
    """What the update produced at epoch k (for estimators that learn after it).

    Attributes:
      x: (n,) filtered mean.  P: (n, n) filtered covariance.
      K: (n, m) gain (zero columns for invalid components).
      eps: (m,) post-fit residual Z - H x (zero where invalid).  P_pred: (n, n) the prior covariance used.
    """

    x: jax.Array
    P: jax.Array
    K: jax.Array
    eps: jax.Array
    P_pred: jax.Array


def no_flags() -> jax.Array:
    """int32 status flags with no bit set (:mod:`jaxnav._status`)."""
    return jnp.zeros((), jnp.int32)


@runtime_checkable
class InflationRule(Protocol):
    """A prior-inflation rule: the factor f_k of P_{k,k-1} = f_k F P_{k-1} F^T + G Q G^T.

    Subclass it to inherit the defaults below (no state, no restriction to states, data
    dependent); a class that provides every member without subclassing is accepted too.

    Attributes:
      data_independent: True when the factor never depends on the measurements (then the
        covariance recursion is the same for every data set with the same mask, which
        :func:`jaxnav.filters.kalman_filter_batch` needs and ``vmap`` exploits). A read-only
        property; default False.
      states: None (the factor scales all of F P F^T) or the static indices of the inflated
        states (then the block of those states is scaled by f_k, their cross terms by sqrt(f_k)).
    """

    states: tuple | None = None

    @property
    def data_independent(self) -> bool:
        return False

    def init(self, n: int, m: int, p: int, dtype) -> Any:
        """Initial rule state (a pytree) for n states, m measurements, p process noises; default ()."""
        return ()

    def factor(self, state, ctx: StepContext) -> tuple[jax.Array, Any, jax.Array]:
        """(scalar factor f_k, new state, int32 status flags) for the epoch described by ``ctx``.

        The flags are :mod:`jaxnav._status` bits (e.g. a parameter out of range or a capped
        factor); :func:`no_flags` when there is nothing to say.
        """
        raise NotImplementedError


@runtime_checkable
class NoiseEstimator(Protocol):
    """A noise estimator: the G Q G^T and R used at epoch k, and what it learns from the update.

    Subclass it to inherit the defaults below (no state, learns nothing after the update,
    screens nothing, data dependent); a class that provides every member without subclassing
    is accepted too.

    Attributes:
      data_independent: True when the noise never depends on the measurements. A read-only
        property; default False.
    """

    @property
    def data_independent(self) -> bool:
        return False

    def init(self, n: int, m: int, p: int, dtype) -> Any:
        """Initial estimator state (a pytree); default ()."""
        return ()

    def noise(self, state, ctx: StepContext) -> tuple[jax.Array, jax.Array, Any, tuple[Any, jax.Array]]:
        """(G Q G^T (n, n), R (m, m), new state, (per-epoch info pytree, int32 status flags))."""
        raise NotImplementedError

    def after(self, state, ctx: StepContext, post: PostUpdate) -> Any:
        """The state after learning from the update of this epoch; default: unchanged."""
        return state

    def screen(self, info, ctx: StepContext) -> jax.Array:
        """(m,) bool: components that estimators after this one in a chain must not learn from; default none."""
        return jnp.zeros_like(ctx.valid)


@pytree_dataclass
class NoInflation(InflationRule):
    """The classic Kalman filter: factor 1 (S0 eq. (8))."""

    @property
    def data_independent(self) -> bool:
        return True

    def factor(self, state, ctx):
        return jnp.ones((), ctx.FPF.dtype), state, no_flags()


@pytree_dataclass
class NoEstimator(NoiseEstimator):
    """Keep the model's Q and R (the default)."""

    @property
    def data_independent(self) -> bool:
        return True

    def noise(self, state, ctx):
        return ctx.GQG, ctx.R, state, ((), no_flags())


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
