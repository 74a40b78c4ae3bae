"""Steps files of daily station series: known steps (equipment changes, earthquakes) with their kind.

jaxnav's format, one step a line, fields separated by blanks (or commas); ``#`` starts a comment::

    # station  date         kind        post-seismic terms (earthquakes only, optional)
    LHAS       1995-08-22   equipment
    ABCD       2011.1920    earthquake  log:30  exp:estimate
    ABCD       2014-06-01   unknown

* station: the four-character (or longer) name as in the series files (case-insensitive).
* date: ``YYYY-MM-DD`` (the step applies from the daily solution of that day on) or a decimal
  year (Julian years from 2000.0 at J2000, as the series' own decimal years).
* kind: ``equipment`` (antenna, radome or receiver change), ``earthquake`` or ``unknown``.
* post-seismic terms, only after ``earthquake``: ``log:TAU`` or ``exp:TAU`` with the time
  constant TAU in days, or ``log:estimate`` / ``exp:estimate`` to estimate it.

The Nevada Geodetic Laboratory's ``steps.txt`` lines are read too: ``SITE YYMMMDD 1 ...``
(type 1, an equipment change; the rest of the line is ignored) and ``SITE YYMMMDD 2 ...``
(type 2, an earthquake); the two-digit year is 19YY for YY >= 50, else 20YY.
"""

from __future__ import annotations

import datetime as _dt
import os
import re
from typing import NamedTuple

import numpy as np

from jaxnav.io._errors import ReaderError, text_lines
from jaxnav.monitoring._trajectory import POSTSEISMIC_FORMS  # the module, not the package
from jaxnav.units import DAY, YEAR

#: kinds of a known step
STEP_KINDS = ("equipment", "earthquake", "unknown")
_J2000_DATE = _dt.date(2000, 1, 1)
_MONTHS = ("JAN", "FEB", "MAR", "APR", "MAY", "JUN", "JUL", "AUG", "SEP", "OCT", "NOV", "DEC")
_NGL_DATE = re.compile(r"(\d{2})([A-Z]{3})(\d{2})")


class KnownStep(NamedTuple):
    """One known step.

    Attributes:
      station: upper-case station name.  epoch: s since J2000.  kind: one of :data:`STEP_KINDS`.
      postseismic: tuple of (form "log" | "exp", tau s or None to estimate).
      origin: where it was given ("FILE:LINE", or the option text).
    """

    station: str
    epoch: float
    kind: str
    postseismic: tuple
    origin: str


def date_to_epoch(text: str) -> float:
    """``YYYY-MM-DD`` (start of that day) or a decimal year in [1950, 2150] -> s since J2000.

    Raises:
      ValueError: text that is neither (the message names the expected forms).
    """
    text = text.strip()
    if re.fullmatch(r"\d{4}-\d{2}-\d{2}", text):
        try:
            d = _dt.date.fromisoformat(text)
        except ValueError:
            raise ValueError(f"{text!r} is not a calendar date") from None
        return (d - _J2000_DATE).days * DAY - 0.5 * DAY
    try:
        y = float(text)
    except ValueError:
        raise ValueError(f"cannot read the date {text[:40]!r} (YYYY-MM-DD or a decimal year)") from None
    if not 1950.0 <= y <= 2150.0:
        raise ValueError(f"decimal year {text[:40]!r} is outside 1950 .. 2150")
    return (y - 2000.0) * YEAR


def _ngl_epoch(text: str) -> float | None:
    m = _NGL_DATE.fullmatch(text.upper())
    if m is None or m.group(2) not in _MONTHS:
        return None
    yy = int(m.group(1))
    year = 1900 + yy if yy >= 50 else 2000 + yy
    try:
        d = _dt.date(year, _MONTHS.index(m.group(2)) + 1, int(m.group(3)))
    except ValueError:
        return None
    return (d - _J2000_DATE).days * DAY - 0.5 * DAY


def parse_postseismic(text: str) -> tuple:
    """``log:TAU`` / ``exp:TAU`` (TAU days > 0) or ``log:estimate`` -> (form, tau s or None).

    Raises:
      ValueError: naming the expected form.
    """
    form, _, tau = text.strip().partition(":")
    form = form.lower()
    if form not in POSTSEISMIC_FORMS or not tau:
        raise ValueError(
            f"post-seismic term {text[:40]!r}: expected log:TAU_DAYS, exp:TAU_DAYS, log:estimate or exp:estimate"
        )
    if tau.strip().lower() in ("estimate", "est", "free"):
        return form, None
    try:
        v = float(tau)
    except ValueError:
        raise ValueError(
            f"post-seismic term {text[:40]!r}: time constant {tau[:40]!r} is not a number of days (or 'estimate')"
        ) from None
    if not 0.0 < v <= 1e5:
        raise ValueError(f"post-seismic term {text[:40]!r}: time constant must be in (0, 1e5] days")
    return form, v * DAY


def read_steps_file(path) -> list:
    """Read a steps file (format in :mod:`jaxnav.io._steps_file`: jaxnav's or NGL's ``steps.txt``).

    Returns:
      list of :class:`KnownStep` in file order.
    Raises:
      ReaderError: (a ValueError) naming the file and line: too few fields, an unreadable date,
        an unknown kind, a post-seismic term on a step that is not an earthquake or one that
        cannot be read; or a file with no step at all.
    """
    p = os.fspath(path)
    out = []
    for lineno, line in text_lines(p):
        s = line.split("#", 1)[0].replace(",", " ").strip()
        if not s:
            continue
        w = s.split()
        if len(w) < 3:
            raise ReaderError(p, lineno, f"expected 'station date kind [post-seismic terms]', got {len(w)} field(s)")
        station = w[0].upper()
        ngl = _ngl_epoch(w[1]) if w[2] in ("1", "2") else None
        if ngl is not None:
            out.append(KnownStep(station, ngl, "equipment" if w[2] == "1" else "earthquake", (), f"{p}:{lineno}"))
            continue
        try:
            epoch = date_to_epoch(w[1])
        except ValueError as exc:
            raise ReaderError(p, lineno, str(exc)) from None
        kind = w[2].lower()
        if kind not in STEP_KINDS:
            raise ReaderError(p, lineno, f"unknown step kind {w[2][:40]!r} (expected one of {', '.join(STEP_KINDS)})")
        terms = []
        for extra in w[3:]:
            if kind != "earthquake":
                raise ReaderError(
                    p,
                    lineno,
                    f"post-seismic term {extra[:40]!r} on a step of kind {kind!r}: only "
                    "earthquake steps take post-seismic terms",
                )
            try:
                terms.append(parse_postseismic(extra))
            except ValueError as exc:
                raise ReaderError(p, lineno, str(exc)) from None
        out.append(KnownStep(station, epoch, kind, tuple(terms), f"{p}:{lineno}"))
    if not out:
        raise ReaderError(p, None, "no step in the file (only comments or blank lines)")
    return out


def explicit_step(k: KnownStep) -> bool:
    """A step given on the command line (an option, not a file): its mistakes are errors, not warnings."""
    return k.origin.startswith("--")


_KIND_RANK = {"unknown": 0, "equipment": 1, "earthquake": 2}


def merge_known_steps(items) -> list[KnownStep]:
    """Known steps of one station merged by calendar day, in time order.

    Steps on the same day (a steps file and ``--step``, or two files) become one: the earliest
    epoch, the most specific kind (earthquake > equipment > unknown), the post-seismic terms of
    all with one per form (a command-line option's before a file's), the origins joined by "; "
    (options first).

    Args:
      items: :class:`jaxnav.io.KnownStep` of one station.
    Returns:
      list of :class:`jaxnav.io.KnownStep`.
    """
    groups = {}
    for k in items:
        groups.setdefault(int(np.floor(k.epoch / DAY + 0.5)), []).append(k)  # a date's epoch: its start, -0.5 d
    out = []
    for day in sorted(groups):
        g = sorted(groups[day], key=lambda k: (not explicit_step(k), k.epoch))
        terms = {}
        for k in g:
            for form, tau in k.postseismic:
                terms.setdefault(form, tau)
        out.append(
            KnownStep(
                g[0].station,
                min(k.epoch for k in g),
                max((k.kind for k in g), key=_KIND_RANK.get),
                tuple(terms.items()),
                "; ".join(k.origin for k in g),
            )
        )
    return out
