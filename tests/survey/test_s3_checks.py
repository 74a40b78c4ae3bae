"""S3 checks as library calls: horizontal speed of an RTK track, stop records."""

import jax.numpy as jnp
import numpy as np

from jaxnav import geodesy as g
from jaxnav import survey


def test_horizontal_speed_of_a_straight_track():
    t = np.arange(0.0, 20.0, 0.5)
    ref = np.array([0.6, 2.0, 50.0])
    enu = np.stack([1.5 * t, -2.0 * t, 0.3 * t], -1)  # 2.5 m/s horizontally, climbing
    pos = ref + np.asarray(g.enu_to_curvilinear(ref, jnp.asarray(enu)))
    np.testing.assert_allclose(survey.horizontal_speed(t, pos), 2.5, rtol=1e-5)


def test_stop_records():
    stops = survey.make_stop_list([1.0, 5.0], [3.0, 9.5], ["known_coordinate", "target"], name=["K1", "T1"])
    assert survey.stop_records(stops) == [
        {"name": "K1", "kind": "known_coordinate", "t_start": 1.0, "t_end": 3.0},
        {"name": "T1", "kind": "target", "t_start": 5.0, "t_end": 9.5},
    ]
