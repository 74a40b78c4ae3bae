"""The ``[noise]`` key table: config values read into SI and written back by ``noise_in_config_units``
(also per axis), unknown keys refused."""

import numpy as np
import pytest

from jaxnav import ins
from jaxnav.io import INS_NOISE_KEYS, noise_in_config_units


def test_config_units_round_trip():
    given = {k: 1.5 + i for i, k in enumerate(INS_NOISE_KEYS)}  # a distinct number per key, config units
    si = {INS_NOISE_KEYS[k][1]: v * INS_NOISE_KEYS[k][2] for k, v in given.items()}
    noise = ins.ImuNoise(**si)
    back = noise_in_config_units(noise)
    assert list(back) == list(INS_NOISE_KEYS)
    np.testing.assert_allclose([back[k] for k in given], list(given.values()), rtol=1e-14)
    # per-axis densities come back per axis; a key outside the table is refused
    per_axis = noise._replace(gyro_arw=np.array([1.0, 2.0, 3.0]) * INS_NOISE_KEYS["arw_deg_per_sqrt_h"][2])
    np.testing.assert_allclose(
        noise_in_config_units(per_axis, ("arw_deg_per_sqrt_h",))["arw_deg_per_sqrt_h"], [1, 2, 3]
    )
    with pytest.raises(ValueError, match="not \\[noise\\] keys"):
        noise_in_config_units(noise, ("arw",))
