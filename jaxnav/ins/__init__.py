"""Strapdown INS: Earth model, attitude, forward and reverse mechanization (S0, S3).

Navigation frame ENU; body frame right-forward-up; quaternions scalar first; see
:mod:`jaxnav.ins.attitude` for the Euler-angle convention.
"""

from jaxnav.ins import attitude, earth, error_model, integration, measurements
from jaxnav.ins.allan import (  # Allan variance and noise identification from a static recording
    AllanFit,
    allan_deviation,
    allan_model,
    allan_noise_fit,
    allan_variance,
    allan_variance_sigma,
    imu_noise_from_allan,
    uniform_rates,
)
from jaxnav.ins.evaluation import TrajectoryErrors, error_statistics, trajectory_errors, wrap_angle
from jaxnav.ins.evaluation import (  # GNSS outage protocol and sigmas of error covariances
    OutageScores,
    attitude_sigmas,
    horizontal_sigma,
    in_windows,
    outage_windows,
    position_cov_enu,
    position_sigmas_enu,
    score_outages,
    training_windows,
)
from jaxnav.ins.likelihood import horizontal_fix_nll
from jaxnav.ins.resample import interpolate_on_samples, nearest_samples
from jaxnav.ins.alignment import HEADING_METHODS, Alignment, coarse_alignment
from jaxnav.ins.mounting import (  # IMU mounting (sensor -> FRD vehicle -> RFU body)
    C_RFU_FRD,
    mounting_from_dcm,
    mounting_from_groves,
    mounting_from_groves_deg,
    mounting_from_rpy,
    mounting_from_rpy_deg,
    mounting_to_rpy,
    sensor_to_body,
)
from jaxnav.ins.noise import NOISE_GRADES, ImuNoise, imu_noise_from_datasheet, imu_noise_to_datasheet, noise_preset
from jaxnav.ins.standstill import (
    PLATFORMS,
    CheckedStandstill,
    gnss_checked_standstill,
    DetectionScores,
    StandstillParams,
    detect_standstill,
    detection_scores,
    gnss_motion_labels,
    gnss_speed_test,
    keep_runs,
    quiet_threshold,
    runs_touching,
    shoe_statistic,
    standstill_intervals,
    threshold_standstill,
)
from jaxnav.ins.timing import TimeOffset, estimate_time_offset
from jaxnav.ins.timing import (  # refinement by the filter's innovation likelihood
    LikelihoodOffset,
    clock_drift,
    likelihood_time_offset,
    offset_search_epochs,
    parabola_peak,
)
from jaxnav.ins.earth import EarthParams, earth_params, gravity_minus_coriolis, normal_gravity, position_rate
from jaxnav.ins.error_model import (
    ERROR_MODEL_15,
    ERROR_MODEL_15GM,
    ERROR_MODEL_18,
    ERROR_MODEL_21,
    IDX15,
    IDX18,
    IDX21,
    STATE_NAMES15,
    STATE_NAMES18,
    STATE_NAMES21,
    ErrorModel,
    discretize_series,
    discretize_taylor,
    discretize_van_loan,
    error_model_for,
    markov_psd,
    nav_error_F,
)
from jaxnav.ins.integration import (
    LC_OUTPUTS,
    LCDiscretization,
    LCEpochs,
    LCGate,
    LCParams,
    LCPropagation,
    LCResult,
    LCSave,
    PVMeasurements,
    SensorBiases,
    chi2_quantile,
    gnss_measurements,
    lc_params,
    loosely_coupled,
    predict_gnss_pv,
    segment_imu,
    smooth,
)
from jaxnav.ins.measurements import (
    Aid,
    MeasContext,
    MeasRows,
    MeasurementModel,
    heading,
    nhc,
    odometer,
    zaru,
    zupt,
)
from jaxnav.ins.mechanization import (
    ImuSample,
    MechParams,
    MechResult,
    MechState,
    NavState,
    check_imu,
    mech_step,
    mechanize,
    mechanize_backward,
)

__all__ = [
    "IDX15", "IDX18", "STATE_NAMES15", "STATE_NAMES18", "discretize_series", "discretize_taylor", "discretize_van_loan",
    "error_model", "markov_psd", "nav_error_F",
    "ERROR_MODEL_15", "ERROR_MODEL_18", "ErrorModel", "error_model_for", "gravity_minus_coriolis",
    "LC_OUTPUTS", "LCDiscretization", "LCEpochs", "LCGate", "LCParams", "LCPropagation", "LCResult", "LCSave",
    "PVMeasurements", "SensorBiases", "integration", "gnss_measurements", "lc_params", "loosely_coupled", "predict_gnss_pv", "segment_imu", "smooth",
    "EarthParams", "ImuSample", "MechParams", "MechResult", "MechState", "NavState", "attitude",
    "check_imu", "earth", "earth_params", "mech_step", "mechanize", "mechanize_backward",
    "normal_gravity", "position_rate", "Alignment", "coarse_alignment",
    # inputs: mounting, alignment, time offset, standstill, noise grades
    "HEADING_METHODS", "C_RFU_FRD", "mounting_from_dcm", "mounting_from_groves", "mounting_from_groves_deg",
    "mounting_from_rpy", "mounting_from_rpy_deg", "mounting_to_rpy", "sensor_to_body",
    "NOISE_GRADES", "ImuNoise", "AllanFit", "allan_deviation", "allan_model", "allan_noise_fit", "allan_variance",
    "allan_variance_sigma", "imu_noise_from_allan", "uniform_rates",
    "TrajectoryErrors", "error_statistics", "trajectory_errors", "wrap_angle", "imu_noise_from_datasheet", "imu_noise_to_datasheet", "noise_preset",
    "DetectionScores", "StandstillParams", "detect_standstill", "detection_scores", "shoe_statistic",
    "standstill_intervals", "threshold_standstill", "PLATFORMS", "gnss_motion_labels", "gnss_speed_test", "keep_runs",
    "quiet_threshold", "runs_touching", "TimeOffset", "estimate_time_offset",
    "ERROR_MODEL_15GM", "ERROR_MODEL_21", "IDX21", "STATE_NAMES21", "chi2_quantile", "measurements", "Aid", "MeasContext", "MeasRows",
    "MeasurementModel", "heading", "nhc", "odometer", "zaru", "zupt",
]
__all__ += [
    "OutageScores", "attitude_sigmas", "horizontal_sigma", "in_windows", "outage_windows", "position_cov_enu",
    "position_sigmas_enu", "score_outages", "training_windows", "horizontal_fix_nll",
    "LikelihoodOffset", "clock_drift", "likelihood_time_offset", "offset_search_epochs", "parabola_peak",
    "CheckedStandstill", "gnss_checked_standstill", "interpolate_on_samples", "nearest_samples",
]
