"""The model-agnostic Kalman filter family of the source papers (S0 eqs. (1)-(17), S1 eqs. (7)-(19)).

* :class:`LinearGaussian` model with static or time-varying leaves, :func:`validate_model`.
* :func:`kalman_filter`: classic KF with Cholesky solves and Joseph update, plus plug-ins:
  prior-inflation rules :func:`constant`, :func:`attenuated`, :func:`fading` (and
  :func:`switch` to pick one by an array index in one compiled program) and noise
  estimators :func:`variance_compensation`, :func:`sage_husa`, :func:`igg3`, :func:`chain`.
  New plug-ins subclass the protocols :class:`InflationRule` and :class:`NoiseEstimator`
  (which hold the default methods) and are made pytrees by :func:`pytree_dataclass`.
* :func:`rts_smoother`: fixed-interval smoothing over the saved filter moments.
* :func:`kalman_filter_batch`, :func:`rts_smoother_batch`: B sequences sharing one covariance
  recursion (Monte Carlo studies), the means in blocks of epochs as dense products.
  ``jax.vmap(kalman_filter)`` shares the recursion for clean batches (checked at run time).
* :func:`log_likelihood`: the classic filter's innovation log-likelihood with exact gradients
  from one backward smoothing pass (no tape through the filter).
* :func:`parallel_filter`, :func:`parallel_smoother`: associative-scan forms.
* :class:`NonlinearGaussian` models: :func:`extended_kalman_filter` (and iterated),
  :func:`unscented_kalman_filter`, :func:`cubature_kalman_filter`, :func:`extended_rts_smoother`,
  :func:`unscented_rts_smoother`, on the same step and plug-ins.
* :func:`predict`, :func:`update`, :func:`filter_step`, :func:`init_state`: the pure pieces,
  for custom scans.

Module layout (imports point down): ``_plugins`` (protocols, contexts, defaults) <- ``_rules``,
``_estimators``, ``_robust`` <- ``_step`` (records, predict, update, filter_step) <- ``_kalman``
(the driver) <- ``_smoother`` <- ``_batch``, ``_loglik``, ``_parallel``, ``_nonlinear``.
"""

from jaxnav.filters._batch import kalman_filter_batch, rts_smoother_batch
from jaxnav.filters._estimators import (
    SageHusa,
    SageHusaInfo,
    VarianceCompensation,
    VCInfo,
    sage_husa,
    variance_compensation,
)
from jaxnav.filters._kalman import KalmanResult, kalman_filter
from jaxnav.filters._loglik import LoglikGradients, log_likelihood, loglik_and_gradients
from jaxnav.filters._model import LinearGaussian, check_shapes, validate_model
from jaxnav.filters._models import constant_velocity, coordinated_turn
from jaxnav.filters._nonlinear import (
    NonlinearGaussian,
    cubature_kalman_filter,
    extended_kalman_filter,
    extended_rts_smoother,
    unscented_kalman_filter,
    unscented_rts_smoother,
)
from jaxnav.filters._parallel import parallel_filter, parallel_smoother
from jaxnav.filters._plugins import (
    InflationRule,
    NoEstimator,
    NoInflation,
    NoiseEstimator,
    PostUpdate,
    StepContext,
    no_flags,
    pytree_dataclass,
    static_field,
)
from jaxnav.filters._robust import (
    IGG3,
    Chain,
    ChainInfo,
    IGG3State,
    RobustInfo,
    YangFactor,
    chain,
    igg3,
    igg3_weight,
    yang_alpha,
    yang_factor,
)
from jaxnav.filters._rts import rts_smoother
from jaxnav.filters._rules import (
    Attenuated,
    Constant,
    Fading,
    Switch,
    attenuated,
    constant,
    fading,
    switch,
)
from jaxnav.filters._smoother import SmootherResult
from jaxnav.filters._step import (
    ALL_OUTPUTS,
    FilterParams,
    FilterState,
    StepInfo,
    StepInput,
    UpdateResult,
    filter_step,
    init_state,
    predict,
    update,
)

__all__ = [
    "ALL_OUTPUTS",
    "Attenuated",
    "Constant",
    "Fading",
    "FilterParams",
    "FilterState",
    "KalmanResult",
    "LinearGaussian",
    "SageHusa",
    "SageHusaInfo",
    "SmootherResult",
    "StepContext",
    "StepInfo",
    "StepInput",
    "UpdateResult",
    "VCInfo",
    "VarianceCompensation",
    "attenuated",
    "check_shapes",
    "constant",
    "constant_velocity",
    "coordinated_turn",
    "fading",
    "filter_step",
    "init_state",
    "kalman_filter",
    "predict",
    "rts_smoother",
    "sage_husa",
    "update",
    "validate_model",
    "variance_compensation",
    "IGG3",
    "IGG3State",
    "Chain",
    "ChainInfo",
    "RobustInfo",
    "YangFactor",
    "chain",
    "igg3",
    "igg3_weight",
    "yang_alpha",
    "yang_factor",
    "parallel_filter",
    "parallel_smoother",
    "Switch",
    "switch",
    "LoglikGradients",
    "log_likelihood",
    "loglik_and_gradients",
    "kalman_filter_batch",
    "rts_smoother_batch",
    "InflationRule",
    "NoiseEstimator",
    "NoInflation",
    "NoEstimator",
    "PostUpdate",
    "no_flags",
    "pytree_dataclass",
    "static_field",
    "NonlinearGaussian",
    "extended_kalman_filter",
    "unscented_kalman_filter",
    "cubature_kalman_filter",
    "extended_rts_smoother",
    "unscented_rts_smoother",
]
