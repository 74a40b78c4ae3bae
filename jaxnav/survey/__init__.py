"""Survey post-processing: S2 RTK point series (``rtk``) and S3 cadastral IMU survey (``cadastral``)."""

from jaxnav.survey import rtk  # noqa: E402
from jaxnav.survey.rtk import (  # noqa: E402
    ConnectionModels,
    InitialValues,
    LevellingComparison,
    RtkResult,
    RtkSeries,
    compare_levelling,
    connection_models,
    initial_values,
    pack_points,
    process_points,
    windows_from_pos,
)
