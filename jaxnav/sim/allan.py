"""The overlapping Allan variance, as used to check the simulators' noise: the estimator lives in
:mod:`jaxnav.ins.allan` (beside the noise identification from a static recording); re-exported here."""

from jaxnav.ins.allan import allan_deviation, allan_variance, octave_ms

__all__ = ["allan_deviation", "allan_variance", "octave_ms"]
