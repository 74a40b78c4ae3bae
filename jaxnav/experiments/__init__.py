"""The seeds' reproductions and real-data pipelines, composed from the library layers below.

Each module runs one experiment end to end, scores it against the published numbers and writes
its outputs (``results.json``, figures); the ``jaxnav`` commands are thin wrappers over them.

* :mod:`~jaxnav.experiments.s0`: S0 INS/GPS with classic, attenuated and fading filters
  (``jaxnav demo``): :class:`S0Setup`, :func:`run_s0`, and :func:`s0_metrics` for tuning.
* :mod:`~jaxnav.experiments.filter_family`: the filter family on a constant-velocity series with
  an unmodelled burst (``jaxnav demo-filters``): :func:`run_filter_family`.
* :mod:`~jaxnav.experiments.s1`: S1 deformation monitoring on simulated stations or daily files
  (``jaxnav monitor``): :func:`run_s1_simulation`, :func:`s1_tables`, :func:`run_monitor_files`.
* :mod:`~jaxnav.experiments.velocities`: station velocities with coloured noise on daily files
  (``jaxnav monitor FILES``): :func:`run_monitor_velocities`.
* :mod:`~jaxnav.experiments.tuning`: sweeps and gradient tuning from a config
  (``jaxnav sweep`` / ``jaxnav tune``): :func:`load_config`, :func:`run_sweep`, :func:`run_tune`.
* :mod:`~jaxnav.experiments.s2`: S2 RTK point series from files or the simulated survey
  (``jaxnav rtk``): :func:`run_rtk`, :func:`write_simulated_survey`.
* :mod:`~jaxnav.experiments.s3`: S3 cadastral survey over Monte Carlo seeds (``jaxnav cadastral``):
  :func:`run_cadastral`, :func:`grade_params`, :func:`walk_detection`.
* :mod:`~jaxnav.experiments.ins_run`,
  :mod:`~jaxnav.experiments.ins_output`: INS/GNSS post-processing of a recording from a config
  (``jaxnav ins``): :func:`prepare`, :func:`run_ins`, :func:`tune_noise`, :func:`process`.
* :mod:`~jaxnav.experiments.ct_drive`: a coordinated-turn model on the real 1 Hz RTK car drive,
  EKF/UKF x classic/fading/IGG-III against the reference: :func:`run_ct_drive`.
* :mod:`~jaxnav.experiments.walk`: the walk set as the shipped ``walk_0827`` config (``jaxnav walk``):
  :func:`frame_check`, the set's reader :func:`load_walk`.
* :mod:`~jaxnav.experiments.figures`: figures of single experiments (``plot_s0``,
  ``plot_filter_family``, ``plot_ct_drive``).
"""

from jaxnav.experiments.filter_family import format_filter_family, run_filter_family
from jaxnav.experiments.ins_output import format_ins, process
from jaxnav.experiments.ins_run import InsRun, prepare, run_ins, tune_noise
from jaxnav.experiments.s0 import (
    EXPERIMENT,
    FILTERS,
    S0_FILTERS,
    S0_LOSSES,
    S0_PARAMS,
    S0Setup,
    filter_params,
    format_s0,
    inflated_states,
    load_experiment,
    rules,
    run_s0,
    s0_measurements,
    s0_metrics,
    s0_rule,
    scenario,
)
from jaxnav.experiments.s1 import (
    S1_PUBLISHED,
    S1Settings,
    format_s1_tables,
    run_monitor_files,
    run_monitor_simulation,
    run_s1_simulation,
    s1_tables,
)
from jaxnav.experiments.s2 import format_rtk, run_rtk, write_simulated_survey
from jaxnav.experiments.s3 import (
    ar_identification,
    detector_params_for,
    format_cadastral,
    grade_params,
    preprocessing_check,
    run_cadastral,
    survey_monte_carlo,
    walk_detection,
)
from jaxnav.experiments.tuning import CONFIGS, Problem, format_sweep, format_tune, load_config, run_sweep, run_tune
from jaxnav.experiments.velocities import run_monitor_velocities
from jaxnav.experiments.walk import (
    WALK_LEVER_RFU,
    WALK_SENSOR_TO_BODY,
    frame_check,
    load_walk,
    walk_config,
)

__all__ = [
    "CONFIGS",
    "EXPERIMENT",
    "FILTERS",
    "Problem",
    "S0Setup",
    "S0_FILTERS",
    "S0_LOSSES",
    "S0_PARAMS",
    "S1Settings",
    "S1_PUBLISHED",
    "filter_params",
    "format_filter_family",
    "format_s0",
    "format_s1_tables",
    "format_sweep",
    "format_tune",
    "inflated_states",
    "load_config",
    "load_experiment",
    "rules",
    "run_filter_family",
    "run_monitor_files",
    "run_monitor_simulation",
    "run_monitor_velocities",
    "run_s0",
    "run_s1_simulation",
    "run_sweep",
    "run_tune",
    "s0_measurements",
    "s0_metrics",
    "s0_rule",
    "s1_tables",
    "scenario",
]
__all__ += [
    "format_rtk",
    "run_rtk",
    "write_simulated_survey",
    "ar_identification",
    "detector_params_for",
    "format_cadastral",
    "grade_params",
    "preprocessing_check",
    "run_cadastral",
    "survey_monte_carlo",
    "walk_detection",
    "WALK_LEVER_RFU",
    "WALK_SENSOR_TO_BODY",
    "frame_check",
    "load_walk",
    "walk_config",
    "InsRun",
    "format_ins",
    "prepare",
    "process",
    "run_ins",
    "tune_noise",
]
