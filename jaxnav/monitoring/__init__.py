"""S1 deformation monitoring: network constant-velocity model, adaptive forecasting, statistics."""

from jaxnav.monitoring._daily import PSD_GRID, StationVelocity, daily_forecasts, station_velocity, weighted_slope
from jaxnav.monitoring._experiment import (
    S1_PUBLISHED,
    S1Settings,
    format_s1_tables,
    run_s1_simulation,
    s1_tables,
)
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
    "Forecast", "InternalPrecision", "PSD_GRID", "PeriodStatistics", "S1Settings", "S1_PUBLISHED",
    "S1_THRESHOLDS_XYH", "StationVelocity", "daily_forecasts", "forecast", "format_s1_tables", "improvement",
    "initial_state", "internal_precision", "network_model", "network_model_irregular", "outlier_flags",
    "period_statistics", "rms", "run_s1_simulation", "s1_filters", "s1_tables", "station_velocity",
    "weighted_slope",
]
