"""The epochs of ``jaxnav rtk``'s input files (RTKLIB ``.pos`` and CSV epoch logs) as flat arrays."""

from __future__ import annotations

import pathlib

import numpy as np

from jaxnav.io._rtklib import read_pos
from jaxnav.io._survey_files import read_epoch_log
from jaxnav.survey.rtk import MotionParams, windows_from_pos


def read_rtk_epochs(files, *, step=2.0, window=60, min_epochs=30, fixed_only=True, motion=MotionParams()):
    """Flat epoch arrays (S2 input) from .pos files (cut into static occupations) and/or CSV epoch logs.

    Args:
      files: RTKLIB ``.pos`` files (:func:`jaxnav.survey.windows_from_pos` with ``step``, ``window``,
        ``min_epochs``, ``fixed_only`` and ``motion``) and/or CSV epoch logs (:func:`read_epoch_log`).
    Returns:
      (dict of N epochs: point (N,) names, t (N,) s, lat, lon (N,) rad, H (N,) m, sigma (N, 3) m,
      mask (N,) bool, h_terminal (N,) m and xy_terminal (N, 2) m (NaN for .pos files), segment (N,)
      static-segment labels, grid (N,) sampling-grid indices (-1: to be derived per point);
      list of per-file motion counts).
    Raises:
      ValueError: a point name in two files.
    """
    parts, motion_counts = [], []
    for f in files:
        f = pathlib.Path(f)
        if f.suffix.lower() == ".pos":
            w = windows_from_pos(
                read_pos(f), step=step, window=window, min_epochs=min_epochs, fixed_only=fixed_only, motion=motion
            )
            motion_counts.append(
                dict(
                    file=str(f),
                    n_epochs=w.pop("n_epochs"),
                    n_moving=w.pop("n_moving"),
                    n_short_static=w.pop("n_short_static"),
                    n_segments=w.pop("n_segments"),
                )
            )
            n = len(w["t"])
            w["h_terminal"] = np.full(n, np.nan)
            w["xy_terminal"] = np.full((n, 2), np.nan)
            parts.append(w)
        else:
            log = read_epoch_log(f)
            parts.append(
                dict(
                    point=log.point,
                    t=log.t,
                    lat=log.lat,
                    lon=log.lon,
                    H=log.H,
                    sigma=log.sigma,
                    mask=np.ones(len(log.t), bool),
                    h_terminal=log.h,
                    xy_terminal=np.stack([log.x, log.y], -1),
                    segment=np.array([f"{f.stem}/{p}" for p in log.point]),
                    grid=np.full(len(log.t), -1, np.int64),
                )
            )
    names_seen = {}
    for f, p in zip(files, parts):
        for name in dict.fromkeys(p["point"]):
            if name in names_seen:
                raise ValueError(f"{f}: point {str(name)!r} also appears in {names_seen[name]}")
            names_seen[name] = f
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}, motion_counts
