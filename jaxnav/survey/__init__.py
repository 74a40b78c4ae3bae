"""Survey post-processing: S2 RTK point series (``rtk``) and S3 cadastral IMU survey (``cadastral``)."""

from jaxnav.survey import rtk  # noqa: E402
from jaxnav.survey.rtk import (  # noqa: E402
    ConnectionModels,
    InitialValues,
    LevellingComparison,
    MotionParams,
    MotionSegments,
    PointSigmas,
    RtkResult,
    SIGMA_METHOD,
    RtkSeries,
    compare_levelling,
    connection_models,
    initial_values,
    motion_segments,
    pack_points,
    point_sigmas,
    process_points,
    windows_from_pos,
)

# S3 cadastral survey
from jaxnav.survey import cadastral  # noqa: E402
from jaxnav.survey._ar import (  # noqa: E402
    ARFit,
    ARKalmanResult,
    OrderSelection,
    ar_kalman,
    ar_state_space,
    autocovariance,
    autocovariance_masked,
    mean_variance_from_acov,
    fit_ar,
    select_ar_order,
    simulate_ar,
    white_noise_variance,
)
from jaxnav.survey._preprocess import (  # noqa: E402
    OutlierResult,
    PreprocessParams,
    PreprocessResult,
    SeriesStats,
    butter2_lowpass,
    preprocess_imu,
    reject_outliers,
    running_median,
    series_stats,
    zero_phase_lowpass,
)
from jaxnav.survey._stops import (  # noqa: E402
    STOP_KINDS,
    DataClasses,
    DetectionResult,
    DetectorParams,
    MatchScore,
    StopList,
    classify,
    detect_stops,
    make_stop_list,
    match_stops,
    stance_statistic,
    static_spans,
    validate_stops,
)
from jaxnav.survey.cadastral import (  # noqa: E402
    STAGES,
    CadastralParams,
    SurveyOutput,
    SurveyPlan,
    cadastral_params,
    plan_survey,
    process_survey,
    strapdown_with_resets,
    summarize_errors,
    target_errors,
)
