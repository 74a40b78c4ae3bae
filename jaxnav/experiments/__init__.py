"""The seeds' reproductions and real-data pipelines, composed from the library layers below.

Each module runs one experiment end to end, scores it against the published numbers and writes
its outputs (``results.json``, figures); the ``jaxnav`` commands are thin wrappers over them.
Import from the module (``from jaxnav.experiments.s0 import run_s0``): the package re-exports
nothing, the public API is the library layers below.

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
