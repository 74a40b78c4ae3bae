"""Figures (matplotlib); every function saves a file and returns the figure.

The library does not choose a matplotlib backend: in a notebook the figures show inline, on a
headless machine matplotlib falls back to Agg; the ``jaxnav`` commands select Agg themselves.
"""

from jaxnav.plot._allan import plot_allan
from jaxnav.plot._cadastral import plot_cadastral_errors, plot_cadastral_route, plot_stop_detection
from jaxnav.plot._ins import (
    plot_ins_attitude,
    plot_ins_biases,
    plot_ins_differences,
    plot_outage_track,
    plot_shifted_outages,
    plot_standstill,
    plot_time_offset_likelihood,
    plot_truth_errors,
)
from jaxnav.plot._monitoring import (
    plot_daily_velocity,
    plot_s1_period,
    plot_s1_statistics,
    plot_station_fit,
    plot_velocity_map,
)
from jaxnav.plot._rtk import plot_rtk
from jaxnav.plot._save import FORMATS, figure_formats, save_figure
from jaxnav.plot._tune import plot_sweep, plot_tune

__all__ = [
    "plot_allan",
    "FORMATS",
    "figure_formats",
    "save_figure",
    "plot_sweep",
    "plot_tune",
    "plot_cadastral_errors",
    "plot_cadastral_route",
    "plot_stop_detection",
    "plot_ins_attitude",
    "plot_ins_biases",
    "plot_ins_differences",
    "plot_shifted_outages",
    "plot_standstill",
    "plot_time_offset_likelihood",
    "plot_truth_errors",
    "plot_outage_track",
    "plot_rtk",
    "plot_daily_velocity",
    "plot_s1_period",
    "plot_s1_statistics",
    "plot_station_fit",
    "plot_velocity_map",
]
