"""Per-point results CSV of the S2 pipeline (``jaxnav rtk``), host side (csv module).

One row a point, in the column order of :data:`RTK_RESULT_COLUMNS`: coordinates and heights in m
(4 decimals), precisions in mm (3 decimals), levelling differences in cm (3 decimals); an empty
field where a value is not finite.
"""

from __future__ import annotations

import csv
import math
import pathlib

from jaxnav.units import CM, MM

RTK_RESULT_COLUMNS = (
    "point", "n", "x", "y", "h", "H", "m_x_mm", "m_y_mm", "m_h_mm",
    "raw_x", "raw_y", "raw_h", "raw_m_x_mm", "raw_m_y_mm", "raw_m_h_mm",
    "formal_m_x_mm", "formal_m_y_mm", "formal_m_h_mm",
    "terminal_x", "terminal_y", "terminal_h", "h_level", "d_filtered_cm", "d_terminal_cm",
)


def _f(v, scale=1.0, fmt=".4f"):
    v = float(v)
    return "" if not math.isfinite(v) else format(v / scale, fmt)


def write_rtk_results(path, names, result, h_level) -> pathlib.Path:
    """Write the S2 per-point results (:class:`jaxnav.survey.RtkResult`, as numpy) as CSV.

    Args:
      path: output file.  names: (P,) point names.
      result: the P points' :class:`jaxnav.survey.RtkResult` (n, xyh, H, precision, raw_xyh,
        raw_precision, formal_precision, terminal_xyh are read; m).
      h_level: (P,) levelled heights, m (NaN where none).
    Returns:
      The path written.
    """
    res = result
    path = pathlib.Path(path)
    with path.open("w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(RTK_RESULT_COLUMNS)
        for i, name in enumerate(names):
            w.writerow([name, int(res.n[i]), *(_f(v) for v in res.xyh[i]), _f(res.H[i]),
                        *(_f(v, MM, ".3f") for v in res.precision[i]), *(_f(v) for v in res.raw_xyh[i]),
                        *(_f(v, MM, ".3f") for v in res.raw_precision[i]),
                        *(_f(v, MM, ".3f") for v in res.formal_precision[i]),
                        *(_f(v) for v in res.terminal_xyh[i]), _f(h_level[i]),
                        _f(res.xyh[i, 2] - h_level[i], CM, ".3f"), _f(res.terminal_xyh[i, 2] - h_level[i], CM, ".3f")])
    return path
