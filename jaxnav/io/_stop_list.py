"""Stop-list CSV files of a cadastral survey (S3 step 2), host side.

One stop a line: ``name, kind, t_start_s, t_end_s [, lat_deg, lon_deg, h_m [, sigma_e_m, sigma_n_m,
sigma_u_m]]``; ``kind`` is one of :data:`jaxnav.survey.STOP_KINDS`; degrees at this edge, radians
in the returned :class:`jaxnav.survey.StopList`.
"""

from __future__ import annotations

import math
import os

import numpy as np

from jaxnav import units
from jaxnav.io._errors import HEIGHT_RANGE_M, SIGMA_MAX_M, ReaderError, text_lines
from jaxnav.survey._stops import STOP_KINDS, StopList, make_stop_list  # the module, not the package: no cycle

_HEADER = "# name, kind, t_start_s, t_end_s, lat_deg, lon_deg, h_m, sigma_e_m, sigma_n_m, sigma_u_m"


def write_stop_list(path, stops: StopList) -> None:
    """Write a stop list as CSV (degrees at the edge; ``nan`` for unknown coordinates)."""
    lines = [_HEADER, f"# kinds: {', '.join(STOP_KINDS)}"]
    for i in range(len(stops.t_start)):
        lat, lon, h = stops.pos[i]
        s = stops.sigma[i]
        lines.append(
            f"{stops.name[i]}, {STOP_KINDS[stops.kind[i]]}, {stops.t_start[i]:.4f}, {stops.t_end[i]:.4f}, "
            f"{units.rad_to_deg(lat):.11f}, {units.rad_to_deg(lon):.11f}, {h:.4f}, "
            f"{s[0]:.4f}, {s[1]:.4f}, {s[2]:.4f}"
        )
    with open(path, "w", encoding="utf-8") as f:
        f.write("\n".join(lines) + "\n")


def read_stop_list(path) -> StopList:
    """Read a stop-list CSV (see :func:`write_stop_list`); ``#`` starts a comment.

    Columns: name, kind, t_start_s, t_end_s [, lat_deg, lon_deg, h_m [, sigma_e_m, sigma_n_m, sigma_u_m]].
    Known-coordinate points need lat, lon and h; known-position points lat and lon; levelling
    points h.

    Raises:
      ReaderError: (a ValueError) naming the file and line for an unreadable line (bytes that are
        not UTF-8 included), an unknown kind, a missing coordinate, an infinite or impossible
        number (|lat| > 90 deg, a non-positive sigma), or t_end <= t_start. Unknown coordinates
        of stops that do not need them may be ``nan``.
    """
    rows = []
    p = os.fspath(path)
    for lineno, line in text_lines(p):
        s = line.split("#", 1)[0].strip()
        if not s:
            continue
        cols = [c.strip() for c in s.split(",")]
        if len(cols) not in (4, 7, 10):
            raise ReaderError(p, lineno, f"expected 4, 7 or 10 comma-separated columns, got {len(cols)}")
        name, kind = cols[0], cols[1].lower()
        if kind not in STOP_KINDS:
            raise ReaderError(p, lineno, f"unknown stop kind {cols[1][:40]!r} (expected one of {STOP_KINDS})")
        try:
            nums = [float(c) for c in cols[2:]]
        except ValueError:
            raise ReaderError(p, lineno, f"non-numeric value in {cols[2:]}"[:200]) from None
        t0, t1 = nums[0], nums[1]
        if not (math.isfinite(t0) and math.isfinite(t1) and t1 > t0 and max(abs(t0), abs(t1)) <= 1e10):
            raise ReaderError(p, lineno, f"stop {name!r} needs finite t_end > t_start (|t| <= 1e10 s), got {t0}, {t1}")
        lat, lon, h = nums[2:5] if len(nums) >= 5 else [math.nan] * 3
        sig = nums[5:8] if len(nums) == 8 else [0.01, 0.01, 0.01]
        for v, what, lo, hi in (
            (lat, "lat_deg", -90.0, 90.0),
            (lon, "lon_deg", -360.0, 360.0),
            (h, "h_m", *HEIGHT_RANGE_M),
        ):
            if not math.isnan(v) and not lo <= v <= hi:
                raise ReaderError(p, lineno, f"{what} = {v:g} is not finite or outside [{lo:g}, {hi:g}]")
        for v, what in zip(sig, ("sigma_e_m", "sigma_n_m", "sigma_u_m")):
            if not 0.0 < v <= SIGMA_MAX_M:
                raise ReaderError(p, lineno, f"{what} = {v:g} must be positive, finite and <= {SIGMA_MAX_M:g} m")
        need = {"known_coordinate": (lat, lon, h), "known_position": (lat, lon), "levelling": (h,)}.get(kind, ())
        if any(not math.isfinite(v) for v in need):
            raise ReaderError(
                p,
                lineno,
                f"a {kind} stop needs its known coordinates "
                f"(lat_deg, lon_deg, h_m), got {cols[4:7] if len(cols) > 4 else 'none'}",
            )
        rows.append((name, STOP_KINDS.index(kind), t0, t1, units.deg_to_rad(lat), units.deg_to_rad(lon), h, *sig))
    if not rows:
        raise ReaderError(p, None, "no stops in the file")
    name = tuple(r[0] for r in rows)
    a = np.array([r[1:] for r in rows], float)
    return make_stop_list(a[:, 1], a[:, 2], a[:, 0].astype(int), a[:, 3:6], a[:, 6:9], name)
