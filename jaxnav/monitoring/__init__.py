"""S1 deformation monitoring: network constant-velocity model, adaptive forecasting, statistics.

The S1 experiment itself (simulation, Tables 1-6) is :mod:`jaxnav.experiments.s1`.
"""

from jaxnav.monitoring._daily import PSD_GRID, StationVelocity, daily_forecasts, station_velocity, weighted_slope
from jaxnav.monitoring._network import (
    Forecast,
    forecast,
    initial_state,
    network_model,
    network_model_irregular,
    outlier_flags,
    s1_filters,
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
    "weighted_slope",
]
