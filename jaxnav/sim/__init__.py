"""Simulators: INS/GNSS scenarios (trajectory, ideal and corrupted IMU, GNSS fixes), linear
Gaussian series and the constant-velocity deformation scenario.

Frames and units: ENU navigation frame, right-forward-up body frame, SI inside; scenario files
(TOML) carry edge units in their field names. PRNG keys are explicit first arguments of the
random generators (:func:`simulate` takes ``(config, key)``); everything vmaps over keys.

Typical use::

    cfg = jaxnav.sim.s0_scenario()
    truth = jaxnav.sim.make_trajectory(cfg)             # deterministic, once
    run = jaxnav.sim.simulate(cfg, key, trajectory=truth)
    dv = jax.jit(jax.vmap(lambda k: jaxnav.sim.simulate(cfg, k, trajectory=truth).imu.dv))(keys)
    ie = cfg.initial_errors
    params = jaxnav.ins.lc_params(jaxnav.ins.ERROR_MODEL_18, jaxnav.sim.imu_noise(cfg), cfg.origin,
                                  att=ie.attitude, vel=ie.velocity, pos_enu=ie.position)
    res = jaxnav.ins.loosely_coupled(*jaxnav.sim.lc_inputs(cfg, run), params, dt_imu=cfg.dt)
"""

from jaxnav.sim import allan
from jaxnav.sim._cadastral import (
    CadastralRun,
    CadastralScenario,
    CalibrationRecord,
    ImuGrade,
    Leg,
    SurveyTruth,
    cadastral_from_dict,
    cadastral_scenarios,
    calibration_record,
    load_cadastral,
    short_survey,
    simulate_cadastral,
    survey_truth,
)
from jaxnav.sim._filter_inputs import LCInputs, imu_noise, lc_inputs
from jaxnav.sim._gnss import GnssConfig, GnssData, GnssEpochs, gnss_epochs, simulate_gnss
from jaxnav.sim._imu import (
    SensorDraw,
    SensorLimits,
    allan_variance_theory,
    apply_sensor_errors,
    corrupt_increments,
    draw_sensor_errors,
    lowpass,
    markov_ar1,
    simulator_noise,
)
from jaxnav.sim._linear import CVScenario, simulate_cv_scenario, simulate_linear
from jaxnav.sim._rtk_points import RtkPointsConfig, RtkPointsSim, simulate_rtk_points, true_height_anomaly
from jaxnav.sim._scenario import (
    ImuData,
    InitialErrorConfig,
    InitialErrorDraw,
    ScenarioConfig,
    SensorErrors,
    SimResult,
    cut_timeline,
    dumps_scenario,
    load_scenario,
    loads_scenario,
    make_trajectory,
    perturb_nav,
    s0_scenario,
    scenario_from_dict,
    scenario_to_dict,
    simulate,
)
from jaxnav.sim._subsidence import (
    SubsidenceConfig,
    SubsidenceSim,
    knothe,
    simulate_subsidence,
    subsidence_config,
)
from jaxnav.sim._trajectory import (
    SEGMENT_KINDS,
    Kinematics,
    ScenarioError,
    Segment,
    SegmentTable,
    Trajectory,
    TrajectorySpec,
    generate_trajectory,
    kinematics,
    segment_table,
)
from jaxnav.sim.allan import allan_deviation, allan_variance

__all__ = [
    "LCInputs",
    "imu_noise",
    "lc_inputs",
    "RtkPointsConfig",
    "RtkPointsSim",
    "simulate_rtk_points",
    "true_height_anomaly",
    "CVScenario",
    "GnssConfig",
    "GnssData",
    "GnssEpochs",
    "ImuData",
    "InitialErrorConfig",
    "InitialErrorDraw",
    "Kinematics",
    "SEGMENT_KINDS",
    "ScenarioConfig",
    "ScenarioError",
    "Segment",
    "SegmentTable",
    "SensorDraw",
    "SensorLimits",
    "SensorErrors",
    "SimResult",
    "Trajectory",
    "TrajectorySpec",
    "allan",
    "allan_deviation",
    "allan_variance",
    "allan_variance_theory",
    "apply_sensor_errors",
    "corrupt_increments",
    "cut_timeline",
    "draw_sensor_errors",
    "dumps_scenario",
    "generate_trajectory",
    "gnss_epochs",
    "kinematics",
    "load_scenario",
    "loads_scenario",
    "lowpass",
    "make_trajectory",
    "markov_ar1",
    "simulator_noise",
    "perturb_nav",
    "s0_scenario",
    "scenario_from_dict",
    "scenario_to_dict",
    "segment_table",
    "simulate",
    "simulate_cv_scenario",
    "simulate_gnss",
    "simulate_linear",
    "SubsidenceConfig",
    "SubsidenceSim",
    "knothe",
    "simulate_subsidence",
    "subsidence_config",
    # S3 cadastral survey
    "CadastralRun",
    "CadastralScenario",
    "CalibrationRecord",
    "ImuGrade",
    "Leg",
    "SurveyTruth",
    "cadastral_from_dict",
    "cadastral_scenarios",
    "calibration_record",
    "load_cadastral",
    "short_survey",
    "simulate_cadastral",
    "survey_truth",
]
