"""S1 deformation monitoring: network constant-velocity model, adaptive forecasting, statistics;
station velocities with coloured noise (trajectory model, white + power-law + random walk,
maximum likelihood through the Kalman filter, outlier screening).

The S1 experiment itself (simulation, Tables 1-6) is :mod:`jaxnav.experiments.s1`.
"""

from jaxnav.monitoring._daily import PSD_GRID, StationVelocity, daily_forecasts, station_velocity, weighted_slope
from jaxnav.monitoring._midas import MidasVelocity, midas_pairs, midas_velocity
from jaxnav.monitoring._network import (
    Forecast,
    forecast,
    initial_state,
    network_model,
    network_model_irregular,
    outlier_flags,
    s1_filters,
)
from jaxnav.monitoring._noise import GGM_ONE_MINUS_PHI, GaussMarkovSum, gauss_markov_sum, ggm_autocovariance
from jaxnav.monitoring._simulate import simulate_powerlaw_series
from jaxnav.monitoring._station import (
    DailyGrid,
    Screening,
    StationFit,
    daily_grid,
    detect_steps,
    fit_series_batch,
    PostseismicTerm,
    fit_station,
    period_amplitudes,
    polynomial_terms,
    profile_tau,
    residual_trend,
    screen_outliers,
    step_penalty,
)
from jaxnav.monitoring._trajectory import (
    COMPONENTS,
    Design,
    NoiseFit,
    NoiseSpec,
    component_loglik,
    design_matrix,
    fit_component,
    noise_spec,
    noise_state_space,
    POSTSEISMIC_FORMS,
    postseismic_column,
    robust_scale,
)
from jaxnav.monitoring._statistics import (
    S1_THRESHOLDS_XYH,
    InternalPrecision,
    PeriodStatistics,
    improvement,
    internal_precision,
    period_statistics,
    rms,
)

__all__ = [
    "Forecast", "InternalPrecision", "PSD_GRID", "PeriodStatistics", "S1_THRESHOLDS_XYH", "StationVelocity",
    "daily_forecasts", "forecast", "improvement", "initial_state", "internal_precision", "network_model",
    "network_model_irregular", "outlier_flags", "period_statistics", "rms", "s1_filters", "station_velocity",
    "weighted_slope", "MidasVelocity", "midas_pairs", "midas_velocity",
    "COMPONENTS", "DailyGrid", "Design", "GGM_ONE_MINUS_PHI", "GaussMarkovSum", "NoiseFit", "NoiseSpec", "Screening",
    "StationFit", "component_loglik", "daily_grid", "design_matrix", "detect_steps", "fit_component",
    "fit_series_batch", "fit_station", "gauss_markov_sum", "ggm_autocovariance", "noise_spec", "noise_state_space",
    "period_amplitudes", "residual_trend", "PostseismicTerm", "polynomial_terms", "profile_tau",
    "POSTSEISMIC_FORMS", "postseismic_column", "robust_scale", "screen_outliers", "step_penalty", "simulate_powerlaw_series",
]
