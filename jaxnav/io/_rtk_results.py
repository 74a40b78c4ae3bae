"""Per-point results CSV of the S2 pipeline (``jaxnav rtk``), host side (csv module).

Comment lines starting with ``#`` come first: what the file is, the coordinate reference system
(with its PROJ definition where there is no EPSG code), the zone (central meridian), the height
system (ellipsoidal, or normal via which height-anomaly fit), the time system, the precision
method and the units; then the column names and one row a point, in the column order of
:data:`RTK_RESULT_COLUMNS`. Every column name carries its unit: ``_m`` coordinates and heights
(4 decimals), ``_mm`` precisions (3 decimals), ``_cm`` levelling differences (3 decimals),
``n_epochs`` a count; an empty field where a value is not finite. Read with e.g.
``numpy.genfromtxt(path, delimiter=",", names=True, dtype=None, skip_header=<number of # lines>)``
or ``pandas.read_csv(path, comment="#")``.
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
    "point",
    "n_epochs",
    "x_m",
    "y_m",
    "h_m",
    "H_ellipsoidal_m",
    "m_x_mm",
    "m_y_mm",
    "m_h_mm",
    "raw_x_m",
    "raw_y_m",
    "raw_h_m",
    "raw_m_x_mm",
    "raw_m_y_mm",
    "raw_m_h_mm",
    "formal_m_x_mm",
    "formal_m_y_mm",
    "formal_m_h_mm",
    "terminal_x_m",
    "terminal_y_m",
    "terminal_h_m",
    "h_level_m",
    "d_filtered_cm",
    "d_terminal_cm",
    "sigma_x_mm",
    "sigma_y_mm",
    "sigma_h_mm",
)

#: what each column is (the ``# columns:`` comment lines say the same)
RTK_RESULT_MEANING = (
    "x_m y_m h_m: filtered point (x north, y east in the CRS; h in the height system)",
    "H_ellipsoidal_m: filtered WGS-84 ellipsoidal height",
    "m_*_mm: internal precision of the filtered mean, S2 eq. (19) (epochs taken as independent)",
    "raw_*: conventional averaging of the epochs; raw_m_*_mm its S2 eq. (19) precision",
    "formal_m_*_mm: precision from the receiver's reported sigmas",
    "terminal_*_m: the controller's own (terminal) coordinates, where the epoch log has them",
    "h_level_m: levelled height; d_filtered_cm, d_terminal_cm: h minus h_level",
    "sigma_*_mm: precision of the point's mean with time-correlated epochs (see sigma method)",
)


def _f(v, scale=1.0, fmt=".4f"):
    v = float(v)
    return "" if not math.isfinite(v) else format(v / scale, fmt)


def write_rtk_results(
    path, names, result, h_level, *, sigma=None, sigma_method="", crs="", zone="", height_system=""
) -> pathlib.Path:
    """Write the S2 per-point results (:class:`jaxnav.survey.RtkResult`, as numpy) as CSV.

    Args:
      path: output file.  names: (P,) point names.
      result: the P points' :class:`jaxnav.survey.RtkResult` (n, xyh, H, precision, raw_xyh,
        raw_precision, formal_precision, terminal_xyh are read; m).
      h_level: (P,) levelled heights, m (NaN where none).
      sigma: optional (P, 3) precision of the means with correlated epochs, m (empty fields if None).
      sigma_method, crs, zone, height_system: text for the ``#`` header lines.
    Returns:
      The path written.
    """
    res = result
    path = pathlib.Path(path)
    head = [
        f"jaxnav rtk: per-point results of the S2 pipeline, one row a point ({len(names)} points)",
        f"crs: {crs or 'not given'}",
        f"zone: {zone or 'not given'}",
        f"height system: {height_system or 'not given'}",
        "time system: GPST",
        f"sigma method: {sigma_method or 'not computed'}",
        "units: suffix _m metres, _mm millimetres, _cm centimetres; n_epochs a count; an empty field is "
        "not finite or not available",
        *(f"columns: {m}" for m in RTK_RESULT_MEANING),
    ]
    with path.open("w", newline="") as fh:
        for line in head:
            fh.write("# " + " ".join(str(line).split()) + "\n")
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(RTK_RESULT_COLUMNS)
        for i, name in enumerate(names):
            w.writerow(
                [
                    name,
                    int(res.n[i]),
                    *(_f(v) for v in res.xyh[i]),
                    _f(res.H[i]),
                    *(_f(v, MM, ".3f") for v in res.precision[i]),
                    *(_f(v) for v in res.raw_xyh[i]),
                    *(_f(v, MM, ".3f") for v in res.raw_precision[i]),
                    *(_f(v, MM, ".3f") for v in res.formal_precision[i]),
                    *(_f(v) for v in res.terminal_xyh[i]),
                    _f(h_level[i]),
                    _f(res.xyh[i, 2] - h_level[i], CM, ".3f"),
                    _f(res.terminal_xyh[i, 2] - h_level[i], CM, ".3f"),
                    *((_f(v, MM, ".3f") for v in sigma[i]) if sigma is not None else ("", "", "")),
                ]
            )
    return path
