"""Simulators: linear Gaussian series and the constant-velocity deformation scenario.

PRNG keys are explicit first arguments; everything vmaps over keys.
"""

from jaxnav.sim._linear import CVScenario, simulate_cv_scenario, simulate_linear

__all__ = ["CVScenario", "simulate_cv_scenario", "simulate_linear"]
