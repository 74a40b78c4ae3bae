"""Ready-made tuning targets: the S0 INS/GNSS experiment and a constant-velocity ML problem."""

from __future__ import annotations

from typing import Mapping

import jax
import jax.numpy as jnp

from jaxnav import filters as jf
from jaxnav.sim import simulate_linear
from jaxnav.tune._losses import innovation_nll, nis_consistency, rms
from jaxnav.tune._s0 import S0Setup, inflated_states

S0_FILTERS = ("classic", "constant", "attenuated", "fading")
S0_LOSSES = ("rms", "nll", "nis")
S0_PARAMS = {"classic": (), "constant": ("S",), "attenuated": ("b",), "fading": ("rho",)}


def s0_rule(setup: S0Setup, filter, params: Mapping):
    """The inflation rule of ``filter`` with its parameter taken from ``params``.

    classic: none.  constant: ``S`` (S0 eq. (10)).  attenuated: ``b`` (eqs. (11)-(12)).
    fading: ``rho`` (recursive innovation estimator) if given, else the experiment's window;
    ``tau`` (optional) is the temperature of the smooth max(1, .) (finite-difference-friendly).
    All rules inflate the experiment's ``inflate_states``. A tuple of names gives
    ``jf.switch(params["filter_index"], rules)``: several filters in one compiled program.
    """
    if isinstance(filter, tuple):
        return jf.switch(params.get("filter_index", 0), [s0_rule(setup, f, params) for f in filter])
    st = inflated_states(setup.exp)
    if filter == "classic":
        return None
    if filter == "constant":
        return jf.constant(params["S"], states=st)
    if filter == "attenuated":
        return jf.attenuated(params["b"], states=st)
    if filter == "fading":
        tau = params.get("tau")
        if "rho" in params:
            return jf.fading(rho=params["rho"], smooth=tau, states=st)
        return jf.fading(window=setup.exp["filter"]["fading_window"], smooth=tau, states=st)
    raise ValueError(f"unknown S0 filter {filter!r}; expected one of {S0_FILTERS}")


def s0_metrics(setup: S0Setup, params: Mapping, key, *, filter="attenuated", loss: str = "rms",
               remat: bool = False) -> dict:
    """One Monte Carlo run of the S0 experiment scored for tuning (pure in params and key).

    Args:
      setup: :class:`S0Setup`.
      params: dict of scalars: the rule's parameter (see :func:`s0_rule`) and optionally
        ``q_scale`` / ``r_scale`` (factors on the assumed Qc and R).
      key: PRNG key of the run.
      filter: "classic", "constant", "attenuated" or "fading" (static); or a tuple of them, with
        ``params["filter_index"]`` choosing one at run time (one program for all, ``vmap`` over
        the index; see :func:`jaxnav.filters.switch`).
      loss: which metric is ``loss``: "rms" (mean 3-D position RMS against the truth, m — the
        criterion of S0's Table 1), "nll" (innovation negative log-likelihood per component,
        no truth needed) or "nis" (NIS consistency).
      remat: checkpoint each GNSS epoch (for reverse-mode gradients).
    Returns:
      dict: ``loss`` (scalar), ``rms`` (9,) position E N U (m), velocity (m/s), attitude (rad),
      ``nll``, ``nis`` (scalars).
    """
    if loss not in S0_LOSSES:
        raise ValueError(f"unknown loss {loss!r}; expected one of {S0_LOSSES}")
    rule = s0_rule(setup, filter, params)
    res = setup.run(key, rule, save=("nav", "nis", "valid"), q_scale=params.get("q_scale", 1.0),
                    r_scale=params.get("r_scale", 1.0), remat=remat)
    pe, ve = setup.errors(res)
    r = jnp.concatenate([rms(pe), rms(ve), rms(setup.attitude_errors(res))])
    out = dict(rms=r, nll=innovation_nll(res), nis=nis_consistency(res))
    out["loss"] = {"rms": jnp.mean(r[:3]), "nll": out["nll"], "nis": out["nis"]}[loss]
    return out


def simulate_cv_batch(key, n_series: int, T: int, *, dt=1.0, sigma=0.003, q=1e-8, ndim: int = 3):
    """Measurement series of a constant-velocity model with continuous white-noise acceleration.

    Args:
      key: PRNG key.  n_series, T: static batch size and epochs.
      dt: s.  sigma: measurement standard deviation, m.  q: acceleration PSD, m^2/s^3.
    Returns:
      (n_series, T, ndim) measured positions, m.
    """
    model = jf.constant_velocity(dt, sigma=sigma, q=q, ndim=ndim)
    x0 = jnp.zeros(2 * ndim)
    return jax.vmap(lambda k: simulate_linear(k, model, x0, T)[1])(jax.random.split(key, n_series))


def cv_nll(params: Mapping, zs, *, dt=1.0, sigma=0.003, q=1e-8, P0_scale=1.0):
    """Mean innovation negative log-likelihood of a batch of series under scaled CV noise.

    The model is ``constant_velocity(dt, sigma=sqrt(r_scale) sigma, q=q_scale q)``: the scales
    multiply the nominal measurement variance and acceleration PSD, so the truth is 1 when the
    data came from the nominal values (maximum-likelihood noise identification).

    Args:
      params: dict with ``q_scale`` and ``r_scale`` (scalars > 0).
      zs: (B, T, ndim) measured positions, m.
      dt, sigma, q: nominal values.  P0_scale: initial position std, m (velocity: P0_scale / dt).
    Returns:
      scalar mean over series of the per-component NLL.
    """
    zs = jnp.asarray(zs)
    if zs.ndim != 3:
        raise ValueError(f"cv_nll(): zs must be (B, T, ndim), got shape {zs.shape}")
    ndim = zs.shape[-1]
    model = jf.constant_velocity(dt, sigma=jnp.sqrt(params["r_scale"]) * sigma, q=params["q_scale"] * q,
                                 ndim=ndim)
    P0 = jnp.diag(jnp.concatenate([jnp.full(ndim, P0_scale**2), jnp.full(ndim, (P0_scale / dt) ** 2)]))

    def one(z):
        x0 = jnp.concatenate([z[0], jnp.zeros(ndim)])
        res = jf.kalman_filter(model, x0, P0, z, save=("valid",))
        return innovation_nll(res)

    return jnp.mean(jax.vmap(one)(zs))
