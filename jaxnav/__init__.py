"""jaxnav: fast, batched and differentiable navigation and geodetic Kalman filtering in JAX.

Conventions (held to throughout the package):

* Navigation frame ENU (east, north, up), as in the source papers S0 and S3; the body frame
  is right-forward-up unless a module documents otherwise. Names carry frames (``v_n``,
  ``f_b``, ``C_bn`` = body -> nav).
* SI units and radians inside the library; degrees, deg/h, mg, arc-seconds only at the edges
  (configs, CLI, plots) through the named helpers of :mod:`jaxnav.units`.
* float64 for navigation states and absolute coordinates: call :func:`enable_x64` before
  creating arrays. float32 paths are opt-in (``allow_float32=True``) and tested.
* Every algorithm is a pure ``step(state, inputs, params) -> (state, info)`` over NamedTuple
  pytrees plus a ``lax.scan`` driver; what a user may sweep or differentiate is an array leaf.
"""

from __future__ import annotations

import jax

__version__ = "0.1.0"


def enable_x64(enable: bool = True) -> None:
    """Switch JAX to 64-bit floats (``jax_enable_x64``); call before creating arrays."""
    jax.config.update("jax_enable_x64", bool(enable))


def x64_enabled() -> bool:
    """Whether JAX currently creates float64 arrays by default."""
    return bool(jax.config.read("jax_enable_x64"))


from jaxnav import filters, units  # noqa: E402  (after enable_x64 is defined)
from jaxnav._status import (  # noqa: E402  (likewise)
    INFO_FLAGS,
    StatusError,
    raise_for_status,
    status_messages,
    status_words,
)

__all__ = [
    "enable_x64",
    "x64_enabled",
    "filters",
    "units",
    "raise_for_status",
    "status_messages",
    "status_words",
    "INFO_FLAGS",
    "StatusError",
    "__version__",
]
