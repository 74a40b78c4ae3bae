"""Prior-inflation rules that plug into the one shared predict step (protocol:
:class:`jaxnav.filters.InflationRule`).

Every rule returns a scalar factor f_k and the predict step forms
``P_{k,k-1} = f_k * F P_{k-1} F^T + G Q G^T`` (S0 eqs. (8), (10), (12), (13)). Rules are
:func:`~jaxnav.filters.pytree_dataclass` subclasses of :class:`~jaxnav.filters.InflationRule`:
the tunable numbers (S, b, rho, smoothing temperature) are array leaves, so ``jax.vmap`` and
``jax.grad`` reach them; structural choices (window length, absolute value or not) are static
fields. The constructors check their arguments (concrete values against the documented ranges;
traced values are flagged in ``status`` at run time); the lower-case functions are shorthands.
"""

from __future__ import annotations

from typing import ClassVar, NamedTuple

import jax
import jax.numpy as jnp

from jaxnav import _status
from jaxnav._numerics import smooth_max1
from jaxnav.filters._plugins import (
    InflationRule,
    NoInflation,
    Range,
    check_ranges,
    leaf,
    pytree_dataclass,
    range_flags,
    static_field,
)


def state_mask(n, states):
    """(n,) bool mask of the inflated states (all when ``states`` is None)."""
    if states is None:
        return jnp.ones((n,), bool)
    return jnp.zeros((n,), bool).at[jnp.asarray(states)].set(True)


def inflated_part(FPF, states):
    """The part of F P F^T that a rule restricted to ``states`` scales fully (both indices inside)."""
    if states is None:
        return FPF
    m = state_mask(FPF.shape[-1], states)
    return jnp.where(m[:, None] & m[None, :], FPF, 0.0)


def inflation_scale(factor, n, states):
    """Per-state square-root scale d with P_pred = (d d^T) o F P F^T + G Q G^T.

    d_i = sqrt(factor) for inflated states and 1 otherwise, so the inflated block is multiplied
    by the factor, cross terms by its square root, and the rest is untouched (a partial fading
    memory; with ``states=None`` it is the scalar inflation of S0 eqs. (12), (13)).
    """
    return jnp.where(state_mask(n, states), jnp.sqrt(factor), 1.0)


def _masked_trace(A, valid):
    return jnp.sum(jnp.where(valid, jnp.diagonal(A), 0.0))


@pytree_dataclass
class Constant(InflationRule):
    """Constant inflation S >= 1 (S0 eq. (10)); equals filterpy's fading ``alpha`` with S = alpha^2.

    Attributes:
      S: scalar array in [1, inf), the factor applied to F P F^T at every epoch (out of range at
        run time: PARAMETER_OUT_OF_RANGE in ``status``).
      states: static indices of the inflated states (None = all; a slice is accepted).

    Raises:
      ValueError: a concrete S outside [1, inf); bad ``states``.
    """

    ranges: ClassVar[dict] = {"S": Range(1.0)}

    S: jax.Array
    states: tuple | None = static_field(None)

    def __post_init__(self):
        check_ranges("Constant", self.ranges, S=self.S)
        object.__setattr__(self, "S", leaf(self.S))
        object.__setattr__(self, "states", _states(self.states))

    @property
    def data_independent(self) -> bool:
        return True

    def factor(self, state, ctx):
        return jnp.asarray(self.S, ctx.FPF.dtype), state, range_flags(self, self.ranges)


@pytree_dataclass
class Attenuated(InflationRule):
    """Attenuated memory S_k = (1 - b^k) / (1 - b), 0 <= b < 1, k counting filter updates (S0 eqs. (11)-(12)).

    S_1 = 1 and S_k rises monotonically towards 1 / (1 - b); b = 0 is the classic filter.

    Notes:
      k is the number of filter *updates*, not of predictions: it advances only at epochs with at
      least one valid measurement component, and an epoch without any applies the factor 1
      (the classic prediction, as the fading rule's lambda_k = 1 there). S0 derives eq. (12) for a
      filter that updates at every epoch, where the two counts agree; the attenuated memory
      weights old *measurements* down, so with no measurement there is nothing to forget. Counting
      predictions instead would multiply P by up to 1/(1 - b) per empty epoch: a 60-epoch gap
      with b = 0.254 inflates the variance by 1.34^60 = 4e7 (sigma 185 m against 4.5 mm for the
      classic filter on the 3 mm constant-velocity model; in a 60 s INS/GNSS outage with the
      navigation states inflated, sigma 1e5 m and a smoothed RMS of 189 m, against 17 m and 0.7 m
      when counting updates).
      After a gap the sequence continues S_{k+1}, S_{k+2}, ... where it stopped.

    Attributes:
      b: scalar array in [0, 1), the attenuation factor (S0 used 0.254 chosen by trial and error);
        out of range at run time: PARAMETER_OUT_OF_RANGE in ``status``.
      states: static indices of the inflated states (None = all; a slice is accepted).

    Raises:
      ValueError: a concrete b outside [0, 1); bad ``states``.
    """

    ranges: ClassVar[dict] = {"b": Range(0.0, 1.0)}

    b: jax.Array
    states: tuple | None = static_field(None)

    def __post_init__(self):
        check_ranges("Attenuated", self.ranges, b=self.b)
        object.__setattr__(self, "b", leaf(self.b))
        object.__setattr__(self, "states", _states(self.states))

    @property
    def data_independent(self) -> bool:
        return True  # the factor depends on the mask only, not on the values

    def init(self, n, m, p, dtype):
        return AttenuatedState(updates=jnp.zeros((), dtype))

    def factor(self, state, ctx):
        dt = ctx.FPF.dtype
        b = jnp.asarray(self.b, dt)
        k = state.updates + ctx.observed.astype(dt)
        S_k = (1.0 - b ** jnp.maximum(k, 1.0)) / (1.0 - b)  # k >= 1 keeps d/db finite at b = 0
        return jnp.where(ctx.observed, S_k, 1.0), AttenuatedState(updates=k), range_flags(self, self.ranges)


class AttenuatedState(NamedTuple):
    """Filter updates counted by the attenuated-memory rule (the k of S_k).

    Attributes:
      updates: scalar float, epochs with at least one valid measurement so far.
    """

    updates: jax.Array


class FadingState(NamedTuple):
    """Running innovation statistics of the fading-memory rule.

    Attributes:
      buf: (window,) v^T v of the last observed epochs (window estimator), else (0,).
      filled: (window,) bool, slots of ``buf`` holding a value.
      pos: int32 ring position in ``buf``.
      C: scalar, recursive estimate of tr E(v v^T).
      started: scalar bool, C holds a value.
    """

    buf: jax.Array
    filled: jax.Array
    pos: jax.Array
    C: jax.Array
    started: jax.Array


@pytree_dataclass
class Fading(InflationRule):
    """Fading memory lambda_k = max{1, |tr N_k / tr M_k|} (S0 eqs. (13)-(17)).

    N_k = P_vk - H G Q G^T H^T - R_k, M_k = H F P_{k-1} F^T H^T. Only traces enter, so the
    innovation statistic kept is tr(P_vk) = E(v^T v), estimated in one of three ways:

    * window n (``window=n``): the sample mean of v_i^T v_i over the last n observed epochs,
      the current one included (the 1/n of eq. (14) read as the mean of eq. (16));
    * recursive (``rho=``): C_k = (rho C_{k-1} + v_k^T v_k) / (1 + rho), C at the first
      observed epoch = v^T v;
    * single epoch (neither given, or ``window=1``): v_k^T v_k.

    Notes:
      Epochs with no valid measurement get lambda_k = 1 and leave the statistics unchanged; with
      partially valid measurements the traces run over the valid components. ``absolute=True``
      follows the printed eq. (14) (|tr N / tr M|); ``absolute=False`` is the Yang & Gao form
      max{1, tr N / tr M}, which does not inflate when the innovations are *smaller* than
      expected. ``smooth`` replaces max(1, .) by 1 + tau softplus((x - 1)/tau) so that gradients
      are continuous; the hard max has gradient 0 where lambda_k = 1.

      lambda_k is capped at ``max_factor`` (default 1e6, as Yang's factor; a factor of 1000 on
      the standard deviations in one epoch) and the epoch is flagged INFLATION_CAPPED: eq. (14)
      itself is unbounded (1.8e14 was reported for a diverging run). Large single-epoch values
      can be legitimate: the first GNSS fix after a 60 s outage of the S0-type INS/GNSS filter
      gives 4.7e5 with all 18 states inflated (22 with the navigation states only), which is
      why the default cap is not lower.

    Attributes:
      rho: None or scalar array > 0, the recursive estimator's weight.
      smooth: None or scalar array tau > 0, temperature of the smooth surrogate.
      max_factor: scalar array >= 1, cap of lambda_k.
      window: static int or None, the window length n.
      absolute: static bool, take |tr N / tr M| as printed in S0 eq. (14).
      states: static indices of the inflated states (None = all; a slice is accepted); M_k is
        then taken over the inflated block of F P F^T.

    Raises:
      ValueError: both window and rho given, window < 1, or concrete rho, smooth outside
        (0, inf), max_factor outside [1, inf) (traced values are flagged in ``status`` instead).
    """

    ranges: ClassVar[dict] = {
        "rho": Range(0.0, lo_open=True),
        "smooth": Range(0.0, lo_open=True),
        "max_factor": Range(1.0),
    }

    rho: jax.Array | None = None
    smooth: jax.Array | None = None
    max_factor: jax.Array = 1e6
    window: int | None = static_field(None)
    absolute: bool = static_field(True)
    states: tuple | None = static_field(None)

    def __post_init__(self):
        if self.window is not None and self.rho is not None:
            raise ValueError("Fading: give either window=n or rho=..., not both")
        if self.window is not None and (int(self.window) != self.window or self.window < 1):
            raise ValueError(f"Fading: window must be a positive integer, got {self.window!r}")
        check_ranges("Fading", self.ranges, rho=self.rho, smooth=self.smooth, max_factor=self.max_factor)
        object.__setattr__(self, "rho", leaf(self.rho))
        object.__setattr__(self, "smooth", leaf(self.smooth))
        object.__setattr__(self, "max_factor", leaf(self.max_factor))
        object.__setattr__(self, "window", None if self.window is None else int(self.window))
        object.__setattr__(self, "absolute", bool(self.absolute))
        object.__setattr__(self, "states", _states(self.states))

    def _n(self):
        return 1 if self.window is None else int(self.window)

    def init(self, n, m, p, dtype):
        w = self._n() if self.rho is None else 0
        return FadingState(
            buf=jnp.zeros((w,), dtype),
            filled=jnp.zeros((w,), bool),
            pos=jnp.zeros((), jnp.int32),
            C=jnp.zeros((), dtype),
            started=jnp.zeros((), bool),
        )

    def factor(self, state, ctx):
        vv = jnp.sum(jnp.where(ctx.valid, ctx.v * ctx.v, 0.0))
        obs = ctx.observed
        if self.rho is None:
            w = self._n()
            buf = jnp.where(obs, state.buf.at[state.pos].set(vv), state.buf)
            filled = jnp.where(obs, state.filled.at[state.pos].set(True), state.filled)
            pos = jnp.where(obs, (state.pos + 1) % w, state.pos)
            cnt = jnp.maximum(jnp.sum(filled), 1)
            trPv = jnp.sum(jnp.where(filled, buf, 0.0)) / cnt
            new = state._replace(buf=buf, filled=filled, pos=pos)
        else:
            rho = jnp.asarray(self.rho, ctx.FPF.dtype)
            C = jnp.where(state.started, (rho * state.C + vv) / (1.0 + rho), vv)
            C = jnp.where(obs, C, state.C)
            trPv = C
            new = state._replace(C=C, started=state.started | obs)
        trN = trPv - _masked_trace(ctx.H @ ctx.GQG @ ctx.H.T, ctx.valid) - _masked_trace(ctx.R_used, ctx.valid)
        trM = _masked_trace(ctx.H @ inflated_part(ctx.FPF, self.states) @ ctx.H.T, ctx.valid)
        pos_M = trM > 0
        ratio = trN / jnp.where(pos_M, trM, 1.0)  # double-where: finite gradient when trM = 0
        ratio = jnp.abs(ratio) if self.absolute else ratio
        ratio = jnp.where(pos_M, ratio, 1.0)
        if self.smooth is None:
            lam = jnp.maximum(1.0, ratio)
        else:
            lam = smooth_max1(ratio, jnp.asarray(self.smooth, ctx.FPF.dtype))
        cap = jnp.asarray(self.max_factor, ctx.FPF.dtype)
        capped = obs & ~(lam <= cap)  # NaN counts as capped
        lam = jnp.where(obs, jnp.minimum(lam, cap), 1.0)
        flags = range_flags(self, self.ranges) | jnp.where(capped, _status.INFLATION_CAPPED, 0).astype(jnp.int32)
        return lam, new, flags


@pytree_dataclass
class Switch(InflationRule):
    """One of several prior-inflation rules, chosen by an array index at run time.

    Every rule's factor is computed and ``factors[index]`` is used, so the classic, attenuated
    and fading filters of S0 run in one compiled program (``vmap``/``tune.sweep`` over the
    index) instead of one program per rule: the S0 study compiles once (about half the
    compilation time of two programs). The extra cost per epoch is the unused rules' factors
    (a few traces of small products).

    Attributes:
      index: integer-valued scalar array (float accepted, rounded), clipped to the rules. The
        status flags are those of the chosen rule.
      rules: tuple of rules (:class:`NoInflation`, :class:`Constant`, :class:`Attenuated`,
        :class:`Fading`, ...) inflating the same states; None stands for the classic filter.

    Raises:
      ValueError: no rules, or rules that inflate different states.
    """

    index: jax.Array
    rules: tuple

    def __post_init__(self):
        rules = tuple(NoInflation() if r is None else r for r in self.rules)
        if not rules:
            raise ValueError("Switch: give at least one rule")
        states = {r.states for r in rules if not isinstance(r, NoInflation)}  # factor 1: its states do not matter
        if len(states) > 1:
            raise ValueError(
                f"Switch: the rules inflate different states {sorted(map(str, states))}; one filter step needs one set"
            )
        object.__setattr__(self, "rules", rules)
        object.__setattr__(self, "index", jnp.asarray(self.index))

    @property
    def states(self):
        """The inflated states, common to the rules (the classic rule has none of its own)."""
        return next((r.states for r in self.rules if not isinstance(r, NoInflation)), None)

    @property
    def data_independent(self) -> bool:
        return all(r.data_independent for r in self.rules)

    def init(self, n, m, p, dtype):
        return tuple(r.init(n, m, p, dtype) for r in self.rules)

    def factor(self, state, ctx):
        out = [r.factor(s, ctx) for r, s in zip(self.rules, state)]
        factors = jnp.stack([jnp.asarray(f, ctx.FPF.dtype) for f, _, _ in out])
        flags = jnp.stack([jnp.asarray(g, jnp.int32) for _, _, g in out])
        i = jnp.clip(jnp.round(jnp.asarray(self.index)).astype(jnp.int32), 0, len(self.rules) - 1)
        return factors[i], tuple(s for _, s, _ in out), flags[i]


def _states(states):
    """Static inflated-state indices from None, a sequence or a slice with a stop (None: all states)."""
    if states is None:
        return None
    if isinstance(states, slice):
        if states.stop is None:
            raise ValueError("states=slice(...) needs an explicit stop")
        states = range(*states.indices(states.stop))
    out = tuple(int(i) for i in states)
    if not out or min(out) < 0:
        raise ValueError(f"states must be non-empty non-negative indices, got {states!r}")
    return out


def constant(S, *, states=None) -> Constant:
    """Constant prior inflation S (S0 eq. (10)); filterpy's ``alpha`` is sqrt(S).

    ``states``: optional indices (or a slice) of the states to inflate (default all).

    Raises:
      ValueError: a concrete S outside [1, inf) (a traced S is flagged in ``status`` instead).
    """
    return Constant(S=S, states=states)


def attenuated(b, *, states=None) -> Attenuated:
    """Attenuated-memory rule S_k = (1 - b^k) / (1 - b), k = filter updates (S0 eqs. (11)-(12)); b an array leaf.

    Epochs without a valid measurement get the factor 1 and do not advance k (see :class:`Attenuated`).
    ``states``: optional indices (or a slice) of the states to inflate (default all). Inflating
    states that have no process noise and are weakly observable (sensor random constants in
    INS/GNSS) makes their variance grow like S^k: restrict the rule to the navigation states there.

    Raises:
      ValueError: a concrete b outside [0, 1) (a traced b is flagged in ``status`` instead).
    """
    return Attenuated(b=b, states=states)


def fading(
    window: int | None = None, rho=None, *, smooth=None, absolute: bool = True, max_factor=1e6, states=None
) -> Fading:
    """Fading-memory rule lambda_k (S0 eqs. (13)-(17)); see :class:`Fading`.

    Args:
      window: static int n >= 1 for the windowed sample mean of the innovations.
      rho: scalar > 0 for the recursive estimator C_k = (rho C_{k-1} + v v^T)/(1 + rho).
      smooth: optional temperature tau > 0 of a smooth surrogate of max(1, .).
      absolute: use |tr N / tr M| as printed (True) or tr N / tr M (False).
      max_factor: scalar >= 1, cap of lambda_k (default 1e6; reaching it sets INFLATION_CAPPED).
      states: optional indices (or a slice) of the states to inflate (default all); M_k is then
        taken over the inflated block of F P F^T.
    With neither ``window`` nor ``rho`` the single-epoch estimator (n = 1) is used.

    Raises:
      ValueError: both window and rho given, window < 1, or concrete rho, smooth outside
        (0, inf), max_factor outside [1, inf) (traced values are flagged in ``status`` instead).
    """
    return Fading(rho=rho, smooth=smooth, max_factor=max_factor, window=window, absolute=absolute, states=states)


def switch(index, rules) -> Switch:
    """Select one of ``rules`` by the array ``index`` (see :class:`Switch`); None stands for the classic filter.

    Raises:
      ValueError: no rules, or rules that inflate different states.
    """
    return Switch(index=index, rules=tuple(rules))
