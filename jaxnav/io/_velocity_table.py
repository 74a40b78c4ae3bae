"""``velocities.csv`` of ``jaxnav monitor`` on several stations: one row per station."""

from __future__ import annotations

import pathlib

import numpy as np

from jaxnav.monitoring import COMPONENTS


def write_velocity_table(path, records: dict, *, command: str = "") -> pathlib.Path:
    """``velocities.csv``: one row per station (coordinates, model and MIDAS rates with sigmas, noise, span).

    Args:
      path: output file.
      records: {station: :func:`jaxnav.io.station_fit_record` dict with ``latitude_deg``, ``longitude_deg``
        (deg or None), ``first_day`` and ``last_day`` (ISO dates) added}.
      command: the command line, for the header.
    Returns:
      The path written.
    """
    cols = [
        "station",
        "latitude_deg",
        "longitude_deg",
        "ve_mm_per_yr",
        "vn_mm_per_yr",
        "vu_mm_per_yr",
        "se_mm_per_yr",
        "sn_mm_per_yr",
        "su_mm_per_yr",
        "corr_en",
        "midas_ve_mm_per_yr",
        "midas_vn_mm_per_yr",
        "midas_vu_mm_per_yr",
        "midas_se_mm_per_yr",
        "midas_sn_mm_per_yr",
        "midas_su_mm_per_yr",
        "first_day",
        "last_day",
        "span_yr",
        "steps",
        "noise_model",
        "file",
    ]

    def num(v, fmt=".3f"):
        return "" if v is None or not np.isfinite(v) else format(v, fmt)

    lines = [
        "# jaxnav station velocities" + (f": {command}" if command else ""),
        "# units: rates and sigmas mm/yr (1 sigma), latitude/longitude deg (geodetic, from the file; empty where "
        "the file has none), span yr, dates ISO 8601",
        "# reference frame: as in each input file (not transformed); east/north/up local to the station",
        "# ve..su: trajectory model (offset, rate, annual, semi-annual, steps) with the coloured noise named in "
        "noise_model; corr_en: east-north rate correlation (0: the components are fitted independently)",
        "# midas_*: MIDAS (Blewitt et al. 2016, with the same steps); steps: steps in the model (given + detected)",
    ]
    extra = sorted(
        {
            f"polynomial of degree {r['polynomial']['degree']} (rate at the reference epoch, mid-span)"
            for r in records.values()
            if r.get("polynomial", {}).get("degree", 1) > 1
        }
        | {
            f"post-seismic terms at {n} (its midas_* from the series less them)"
            for n, r in records.items()
            if r.get("postseismic")
        }
    )
    if extra:
        lines.append("# the model also has: " + "; ".join(extra))
    lines.append(",".join(cols))
    for name, r in records.items():
        v, sd = r["velocity_mm_per_yr"], r["velocity_sigma_mm_per_yr"]
        mv, ms = r["midas_velocity_mm_per_yr"], r["midas_velocity_sigma_mm_per_yr"]
        row = [
            name,
            num(r.get("latitude_deg"), ".7f"),
            num(r.get("longitude_deg"), ".7f"),
            *(num(v[c]) for c in COMPONENTS),
            *(num(sd[c]) for c in COMPONENTS),
            "0",
            *(num(mv[c]) for c in COMPONENTS),
            *(num(ms[c]) for c in COMPONENTS),
            r["first_day"],
            r["last_day"],
            num(r["span_years"], ".2f"),
            str(len(r["steps"])),
            '"' + r["model"].replace('"', "'") + '"',
            '"' + r["file"] + '"',
        ]
        lines.append(",".join(row))
    path = pathlib.Path(path)
    path.write_text("\n".join(lines) + "\n")
    return path
