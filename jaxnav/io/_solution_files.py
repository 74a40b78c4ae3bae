"""Writers of a navigation solution: trajectory CSV with a units header, RTKLIB-style ``.pos``, GeoJSON
and KML tracks (host side).

Times GPST (seconds since 1980-01-06 and calendar, no leap seconds); positions geodetic with
ellipsoidal heights in the solution's datum; attitude of the forward-right-down vehicle frame (roll,
pitch, heading clockwise from north). The record :class:`NavSolution` is SI (rad, m, m/s); the files
carry degrees where their formats do.
"""

from __future__ import annotations

import datetime as _dt
import math
import pathlib
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from jaxnav.io._rtklib import GPS_EPOCH

#: trajectory CSV columns with their units (the header says the same)
TRAJECTORY_COLUMNS = (
    ("gpst_s", "s"),
    ("gpst_iso", "GPST"),
    ("lat_deg", "deg"),
    ("lon_deg", "deg"),
    ("h_m", "m"),
    ("ve_m_s", "m/s"),
    ("vn_m_s", "m/s"),
    ("vu_m_s", "m/s"),
    ("roll_deg", "deg"),
    ("pitch_deg", "deg"),
    ("heading_deg", "deg"),
    ("sigma_e_m", "m"),
    ("sigma_n_m", "m"),
    ("sigma_u_m", "m"),
    ("sigma_ve_m_s", "m/s"),
    ("sigma_vn_m_s", "m/s"),
    ("sigma_vu_m_s", "m/s"),
    ("sigma_tilt_e_deg", "deg"),
    ("sigma_tilt_n_deg", "deg"),
    ("sigma_heading_deg", "deg"),
    ("gnss_used", "0/1"),
)


class NavSolution(NamedTuple):
    """A navigation solution at M epochs, SI.

    Attributes:
      t: (M,) GPST s since 1980-01-06.  pos: (M, 3) [lat rad, lon rad, h m].  v_enu: (M, 3) m/s.
      rpy: (M, 3) roll, pitch, heading (clockwise from north, in [0, 2 pi)) of the vehicle frame, rad.
      sig_pos_enu: (M, 3) east, north, up 1-sigma, m.  sig_vel: (M, 3) east, north, up 1-sigma, m/s.
      sig_att: (M, 3) 1-sigma misalignments about east, north and up, rad.
      gnss_used: (M,) bool, GNSS entered the solution at the epoch.
      quality: (M,) int, the GNSS quality used (``.pos`` Q: 1 fix, 2 float, ...; 0 inertial only).
    """

    t: np.ndarray
    pos: np.ndarray
    v_enu: np.ndarray
    rpy: np.ndarray
    sig_pos_enu: np.ndarray
    sig_vel: np.ndarray
    sig_att: np.ndarray
    gnss_used: np.ndarray
    quality: np.ndarray


def nav_solution(t, nav, covs, idx, *, gnss_used=None, quality=None) -> NavSolution:
    """A filter's or smoother's navigation states with their sigmas as a :class:`NavSolution` for the writers.

    Args:
      t: (M,) GPST s.  nav: :class:`jaxnav.ins.NavState` at ``t`` (body RFU, nav ENU).
      covs: (M, n, n) error covariances of the model with index ``idx`` (:class:`jaxnav.ins.error_model.ErrorStateIndex`).
      gnss_used: (M,) bool, GNSS entered the solution at the epoch (None: all False).
      quality: (M,) int GNSS quality used (None: 0, inertial only).
    """
    from jaxnav.ins import position_sigmas_enu
    from jaxnav.ins.attitude import quat_to_roll_pitch_heading

    pos = np.asarray(nav.pos, float)
    P = np.asarray(covs)
    sd = np.sqrt(np.clip(np.diagonal(P, axis1=-2, axis2=-1), 0.0, None))
    M = pos.shape[0]
    return NavSolution(
        t=np.asarray(t, float),
        pos=pos,
        v_enu=np.asarray(nav.v_n),
        rpy=np.asarray(quat_to_roll_pitch_heading(np.asarray(nav.q_bn))),
        sig_pos_enu=position_sigmas_enu(P, pos, idx),
        sig_vel=sd[:, idx.dv],
        sig_att=sd[:, idx.phi],
        gnss_used=np.zeros(M, bool) if gnss_used is None else np.asarray(gnss_used, bool),
        quality=np.zeros(M, int) if quality is None else np.asarray(quality),
    )


class Track(NamedTuple):
    """A line for :func:`write_geojson` / :func:`write_kml`.

    Attributes:
      name: the line's name.  pos: (K, 3) [lat rad, lon rad, h m].  properties: extra GeoJSON properties.
      color: KML line colour 'aabbggrr' (hex) or None.  width: KML line width, px, or None.
      clamp_to_ground: KML altitude mode "clampToGround" (else the file's default).
    """

    name: str
    pos: np.ndarray
    properties: dict | None = None
    color: str | None = None
    width: float | None = None
    clamp_to_ground: bool = False


def gpst_iso(t, *, date_sep="-", sep="T") -> str:
    """GPST seconds since 1980-01-06 -> 'YYYY-MM-DDTHH:MM:SS.sss' (GPST calendar, no leap seconds; rounded to ms)."""
    d = GPS_EPOCH + _dt.timedelta(milliseconds=round(float(t) * 1000.0))
    return d.strftime(f"%Y{date_sep}%m{date_sep}%d{sep}%H:%M:%S.") + f"{d.microsecond // 1000:03d}"


def _check(sol: NavSolution) -> int:
    M = np.shape(sol.t)[0]
    for name in ("pos", "v_enu", "rpy", "sig_pos_enu", "sig_vel", "sig_att"):
        if np.shape(getattr(sol, name)) != (M, 3):
            raise ValueError(f"NavSolution.{name} has shape {np.shape(getattr(sol, name))}, expected ({M}, 3)")
    for name in ("gnss_used", "quality"):
        if np.shape(getattr(sol, name)) != (M,):
            raise ValueError(f"NavSolution.{name} has shape {np.shape(getattr(sol, name))}, expected ({M},)")
    return M


def write_trajectory_csv(path, sol: NavSolution, *, title: str) -> pathlib.Path:
    """Write ``sol`` as CSV (:data:`TRAJECTORY_COLUMNS`) under a comment header: ``title``, frames and units.

    Returns:
      the path written.
    Raises:
      ValueError: fields whose shapes do not match.
    """
    M = _check(sol)
    pos, v = np.asarray(sol.pos), np.asarray(sol.v_enu)
    rpy, sa = np.degrees(np.asarray(sol.rpy)), np.degrees(np.asarray(sol.sig_att))
    se, sv, used = np.asarray(sol.sig_pos_enu), np.asarray(sol.sig_vel), np.asarray(sol.gnss_used)
    t = np.asarray(sol.t, float)
    path = pathlib.Path(path)
    with path.open("w", encoding="utf-8") as f:
        f.write(
            f"# {title}; time GPST, WGS-84 geodetic, ellipsoidal height;\n"
            "# attitude of the forward-right-down vehicle frame (roll, pitch, heading clockwise from north);\n"
            "# sigma_tilt_e/n and sigma_heading are 1-sigma misalignments about east, north and up;\n"
            "# units: " + ", ".join(f"{n} [{u}]" for n, u in TRAJECTORY_COLUMNS) + "\n"
        )
        f.write(",".join(n for n, _ in TRAJECTORY_COLUMNS) + "\n")
        for k in range(M):
            row = [
                f"{t[k]:.3f}",
                gpst_iso(t[k]),
                f"{math.degrees(pos[k, 0]):.9f}",
                f"{math.degrees(pos[k, 1]):.9f}",
                f"{pos[k, 2]:.4f}",
                *(f"{x:.4f}" for x in v[k]),
                *(f"{x:.4f}" for x in rpy[k]),
                *(f"{x:.4f}" for x in se[k]),
                *(f"{x:.4f}" for x in sv[k]),
                *(f"{x:.4f}" for x in sa[k]),
                str(int(used[k])),
            ]
            f.write(",".join(row) + "\n")
    return path


def write_pos(path, sol: NavSolution, *, comments: Sequence[tuple[str, str]] = ()) -> pathlib.Path:
    """Write ``sol`` as an RTKLIB-style ``.pos`` (readable by :func:`jaxnav.io.read_pos` and RTKLIB tools).

    ``comments``: (key, value) header lines written as ``% key       : value`` before the fixed ones.
    Q is ``sol.quality``; ns is 0; sdne/sdeu/sdun, age and ratio are 0 (no ENU cross terms are written).
    """
    M = _check(sol)
    pos, v = np.asarray(sol.pos), np.asarray(sol.v_enu)
    se, sv, q, t = np.asarray(sol.sig_pos_enu), np.asarray(sol.sig_vel), np.asarray(sol.quality), np.asarray(sol.t)
    path = pathlib.Path(path)
    with path.open("w", encoding="utf-8") as f:
        for key, value in comments:
            f.write(f"% {key:<10}: {value}\n")
        f.write("% Q         : GNSS quality used at the epoch (0: inertial only)\n")
        f.write(
            "%  GPST                  latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m)   sde(m)   sdu(m)"
            "  sdne(m)  sdeu(m)  sdun(m) age(s)  ratio    vn(m/s)    ve(m/s)    vu(m/s)      sdvn     sdve     sdvu"
            "    sdvne    sdveu    sdvun\n"
        )
        for k in range(M):
            tt = gpst_iso(t[k], date_sep="/", sep=" ")
            e, n, u = se[k]
            ve, vn, vu = v[k]
            sve, svn, svu = sv[k]
            f.write(
                f"{tt} {math.degrees(pos[k, 0]):14.9f} {math.degrees(pos[k, 1]):14.9f} "
                f"{pos[k, 2]:10.4f} {int(q[k]):3d} {0:3d} {n:8.4f} {e:8.4f} {u:8.4f} {0:8.4f} {0:8.4f} "
                f"{0:8.4f} {0:6.2f} {0:6.1f} {vn:10.5f} {ve:10.5f} {vu:10.5f} {svn:9.5f} {sve:9.5f} {svu:9.5f} "
                f"{0:8.5f} {0:8.5f} {0:8.5f}\n"
            )
    return path


def _lonlath(pos):
    return [(math.degrees(p[1]), math.degrees(p[0]), float(p[2])) for p in np.asarray(pos)]


def write_geojson(path, tracks: Sequence[Track]) -> pathlib.Path:
    """Write ``tracks`` as a GeoJSON FeatureCollection of LineStrings (lon deg, lat deg, h m), properties
    ``name`` and the track's own; strict JSON (a NaN raises ValueError)."""
    import geojson

    feats = [
        geojson.Feature(
            geometry=geojson.LineString(_lonlath(tr.pos)), properties={"name": tr.name, **(tr.properties or {})}
        )
        for tr in tracks
    ]
    path = pathlib.Path(path)
    path.write_text(geojson.dumps(geojson.FeatureCollection(feats), allow_nan=False) + "\n", encoding="utf-8")
    return path


def write_kml(path, tracks: Sequence[Track], *, name: str) -> pathlib.Path:
    """Write ``tracks`` as KML LineStrings (Google Earth) in a document called ``name``."""
    import simplekml

    kml = simplekml.Kml(name=name)
    for tr in tracks:
        ls = kml.newlinestring(name=tr.name, coords=_lonlath(tr.pos))
        if tr.clamp_to_ground:
            ls.altitudemode = simplekml.AltitudeMode.clamptoground
        if tr.color is not None:
            ls.style.linestyle.color = tr.color
        if tr.width is not None:
            ls.style.linestyle.width = tr.width
    path = pathlib.Path(path)
    kml.save(str(path))
    return path
