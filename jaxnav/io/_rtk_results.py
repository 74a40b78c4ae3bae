"""Per-point results CSV of the S2 pipeline (``jaxnav rtk``), host side (csv module).

A first line starting with ``#`` states the units, the coordinate reference system, the zone, the
height system and the precision method; then the column names and one row a point, in the column
order of :data:`RTK_RESULT_COLUMNS`: coordinates and heights in m (4 decimals), precisions in mm
(3 decimals), levelling differences in cm (3 decimals); an empty field where a value is not finite.
``sigma_*_mm`` is the precision of the point's mean with time-correlated epochs
(:func:`jaxnav.survey.point_sigmas`); ``m_*_mm`` and ``raw_m_*_mm`` are S2 eq. (19), which takes the
epochs as independent.
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
    "sigma_x_mm", "sigma_y_mm", "sigma_h_mm",
)


def _f(v, scale=1.0, fmt=".4f"):
    v = float(v)
    return "" if not math.isfinite(v) else format(v / scale, fmt)


def write_rtk_results(path, names, result, h_level, *, sigma=None, sigma_method="", crs="", zone="",
                      height_system="") -> pathlib.Path:
    """Write the S2 per-point results (:class:`jaxnav.survey.RtkResult`, as numpy) as CSV.

    Args:
      path: output file.  names: (P,) point names.
      result: the P points' :class:`jaxnav.survey.RtkResult` (n, xyh, H, precision, raw_xyh,
        raw_precision, formal_precision, terminal_xyh are read; m).
      h_level: (P,) levelled heights, m (NaN where none).
      sigma: optional (P, 3) precision of the means with correlated epochs, m (empty fields if None).
      sigma_method, crs, zone, height_system: text for the ``#`` header line.
    Returns:
      The path written.
    """
    res = result
    path = pathlib.Path(path)
    with path.open("w", newline="") as fh:
        fh.write(f"# units: x y h H m; m_* raw_m_* formal_m_* sigma_* mm; d_* cm | crs: {crs or 'not given'} | "
                 f"zone: {zone or 'not given'} | height system: {height_system or 'not given'} | "
                 f"sigma_*: {sigma_method or 'not computed'} | time: GPST\n")
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(RTK_RESULT_COLUMNS)
        for i, name in enumerate(names):
            w.writerow([name, int(res.n[i]), *(_f(v) for v in res.xyh[i]), _f(res.H[i]),
                        *(_f(v, MM, ".3f") for v in res.precision[i]), *(_f(v) for v in res.raw_xyh[i]),
                        *(_f(v, MM, ".3f") for v in res.raw_precision[i]),
                        *(_f(v, MM, ".3f") for v in res.formal_precision[i]),
                        *(_f(v) for v in res.terminal_xyh[i]), _f(h_level[i]),
                        _f(res.xyh[i, 2] - h_level[i], CM, ".3f"), _f(res.terminal_xyh[i, 2] - h_level[i], CM, ".3f"),
                        *((_f(v, MM, ".3f") for v in sigma[i]) if sigma is not None else ("", "", ""))])
    return path
