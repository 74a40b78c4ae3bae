"""File readers (host side): RTKLIB solutions, raw IMU logs with RTKLIB time tags, daily station
series (NGL tenv3, SIO .neu, .col tables, EarthScope/PBO .pos), TOML configuration files (among
them the ``jaxnav ins`` config, :func:`load_ins_config`); IMU and GNSS files by format name
(:func:`read_imu`, :func:`read_gnss`);
S3 stop lists and S2 result tables (readers and writers); KF-GINS IMU/GNSS text files and generic
CSV tables with a column map and units; reference (truth) trajectories: KF-GINS ``truth.nav`` and CSV;
writers of a navigation solution (trajectory CSV, ``.pos``, GeoJSON, KML).

Errors are :class:`ReaderError` (a ValueError) naming the file and line; units are converted to SI
here, at the edge. :func:`write_json` is the one strict JSON writer (non-finite numbers as null
with a reason); :func:`provenance` is the block every command's ``results.json`` carries.
"""

from jaxnav._config import (  # the one TOML parser sits below every layer (sim reads scenarios)
    ConfigError,
    ConfigTable,
    load_toml,
    loads_toml,
)
from jaxnav.io._csv import read_csv_gnss, read_csv_imu, read_csv_series
from jaxnav.io._daily import DailySeries, read_col, read_daily, read_neu, read_pbo_pos, read_tenv3, year_to_seconds
from jaxnav.io._errors import ReaderError
from jaxnav.io._formats import GNSS_FORMATS, IMU_FORMATS, TRUTH_FORMATS, read_gnss, read_imu, read_truth
from jaxnav.io._imu import STANDARD_GRAVITY, ImuLog, TimeTags, imu_increments, read_rtklib_imu, read_rtklib_tag
from jaxnav.io._ins_config import (
    INS_CONFIG_DIR,
    INS_CONFIG_RANGES,
    INS_NOISE_KEYS,
    NOISE_TOML_SHORT_S,
    InsConfig,
    find_ins_config,
    load_ins_config,
    noise_in_config_units,
    noise_toml,
)
from jaxnav.io._ins_files import read_ins_heading, read_ins_inputs, read_ins_odometer, read_ins_truth
from jaxnav.io._json import json_ready, write_json
from jaxnav.io._kfgins import read_kfgins_gnss, read_kfgins_imu, read_kfgins_odometer
from jaxnav.io._provenance import files_snapshot, files_written, git_commit, provenance, utc_now
from jaxnav.io._rtk_epochs import read_rtk_epochs
from jaxnav.io._rtk_results import RTK_RESULT_COLUMNS, write_rtk_results
from jaxnav.io._rtklib import GPS_EPOCH, PosSolution, read_pos
from jaxnav.io._solution_files import (
    TRAJECTORY_COLUMNS,
    NavSolution,
    Track,
    gpst_iso,
    nav_solution,
    write_geojson,
    write_kml,
    write_pos,
    write_trajectory_csv,
)
from jaxnav.io._station_record import station_fit_record
from jaxnav.io._steps_file import (
    STEP_KINDS,
    KnownStep,
    date_to_epoch,
    explicit_step,
    merge_known_steps,
    parse_postseismic,
    read_steps_file,
)
from jaxnav.io._stop_list import read_stop_list, write_stop_list
from jaxnav.io._survey_files import (
    ControlPoints,
    EpochLog,
    Levelling,
    read_control_points,
    read_epoch_log,
    read_levelling,
    write_control_points,
    write_epoch_log,
    write_levelling,
)
from jaxnav.io._truth import TruthTrajectory, read_csv_truth, read_kfgins_truth
from jaxnav.io._velocity_table import write_velocity_table

__all__ = [
    "GPS_EPOCH",
    "ImuLog",
    "PosSolution",
    "STANDARD_GRAVITY",
    "TimeTags",
    "read_pos",
    "read_rtklib_imu",
    "read_rtklib_tag",
    "ControlPoints",
    "EpochLog",
    "Levelling",
    "read_control_points",
    "read_epoch_log",
    "read_levelling",
    "write_control_points",
    "write_epoch_log",
    "write_levelling",
    "load_toml",
    "loads_toml",
    "imu_increments",
    "RTK_RESULT_COLUMNS",
    "write_rtk_results",
    "read_stop_list",
    "write_stop_list",
    "ReaderError",
    "json_ready",
    "write_json",
    "provenance",
    "git_commit",
    "utc_now",
    "files_snapshot",
    "files_written",
    "read_kfgins_imu",
    "read_kfgins_gnss",
    "read_kfgins_odometer",
    "read_csv_imu",
    "read_csv_gnss",
    "read_csv_series",
    "TruthTrajectory",
    "read_kfgins_truth",
    "read_csv_truth",
    "STEP_KINDS",
    "KnownStep",
    "date_to_epoch",
    "parse_postseismic",
    "read_steps_file",
    "explicit_step",
    "merge_known_steps",
    "write_velocity_table",
    "station_fit_record",
    "read_rtk_epochs",
]
__all__ += [
    "TRAJECTORY_COLUMNS",
    "NavSolution",
    "Track",
    "gpst_iso",
    "nav_solution",
    "write_geojson",
    "write_kml",
    "write_pos",
    "write_trajectory_csv",
]
__all__ += ["DailySeries", "read_col", "read_daily", "read_neu", "read_pbo_pos", "read_tenv3", "year_to_seconds"]
__all__ += ["GNSS_FORMATS", "IMU_FORMATS", "TRUTH_FORMATS", "read_gnss", "read_imu", "read_truth"]
__all__ += [
    "INS_CONFIG_DIR",
    "INS_CONFIG_RANGES",
    "INS_NOISE_KEYS",
    "InsConfig",
    "find_ins_config",
    "load_ins_config",
    "noise_in_config_units",
    "noise_toml",
    "NOISE_TOML_SHORT_S",
    "read_ins_heading",
    "read_ins_inputs",
    "read_ins_odometer",
    "read_ins_truth",
]
__all__ += ["ConfigError", "ConfigTable"]
