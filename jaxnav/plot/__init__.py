"""Figures (matplotlib, Agg backend); every function saves a file and returns the figure."""

from jaxnav.plot._filters import plot_filter_family

__all__ = ["plot_filter_family"]
