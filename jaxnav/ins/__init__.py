"""Strapdown INS: Earth model, attitude, forward and reverse mechanization (S0, S3).

Navigation frame ENU; body frame right-forward-up; quaternions scalar first; see
:mod:`jaxnav.ins.attitude` for the Euler-angle convention.
"""

from jaxnav.ins import attitude, earth
from jaxnav.ins.earth import EarthParams, earth_params, normal_gravity, position_rate
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
    "EarthParams", "ImuSample", "MechParams", "MechResult", "MechState", "NavState", "attitude",
    "check_imu", "earth", "earth_params", "mech_step", "mechanize", "mechanize_backward",
    "normal_gravity", "position_rate",
]
