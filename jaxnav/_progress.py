"""Progress of long host-side loops: a tqdm bar on a terminal, plain lines otherwise (the one helper).

Rule (used by every command and by :func:`jaxnav.tune.run_chunked` / :func:`jaxnav.tune.map_chunked`):

* stderr is a terminal (``sys.stderr.isatty()``): a ``tqdm`` bar on stderr;
* otherwise (a log file, a pipe, a notebook, CI): plain lines on stderr, no carriage returns,
  ``"<desc>: <done>/<total> <unit>s (<pct> %, <elapsed> s, about <left> s left)"``, one after the
  first update (its estimate from the first chunk's rate, and says so: a first call that compiles
  makes it too long), one when a further 10 % is done or 10 s have passed since the last line,
  and one at the end; later estimates use the rate after the first update (compiling excluded);
* nothing at all when ``enabled`` is False or the ``"jaxnav"`` logger has been set above INFO
  (``jaxnav -q`` does that; so can a library user with
  ``logging.getLogger("jaxnav").setLevel(logging.WARNING)``). An unset logger (level NOTSET, the
  library default) counts as INFO: progress shows.
"""

from __future__ import annotations

import logging
import sys
import time

#: the package logger; ``jaxnav -q`` sets it to WARNING, ``-v`` to DEBUG
LOGGER_NAME = "jaxnav"
#: a plain progress line at least every this many seconds (besides every 10 %)
LINE_EVERY_S = 10.0
#: and every this share of the total
LINE_EVERY_SHARE = 0.1


def progress_allowed() -> bool:
    """False when the ``"jaxnav"`` logger is set above INFO (``jaxnav -q``), else True."""
    level = logging.getLogger(LOGGER_NAME).level
    return level == logging.NOTSET or level <= logging.INFO


class Progress:
    """Progress of ``total`` items: ``with Progress(n, "sweep") as p: ... p.update(k)``.

    Args:
      total: number of items (>= 0).  desc: label.  unit: item name (singular).
      enabled: show anything at all (also needs :func:`progress_allowed`).
      stream: where to write (default ``sys.stderr`` at the time of the call).
      tty: force the terminal (True) or plain-line (False) form; default ``stream.isatty()``.
    """

    def __init__(self, total: int, desc: str = "", *, unit: str = "item", enabled: bool = True, stream=None, tty=None):
        self.total, self.desc, self.unit = max(0, int(total)), desc, unit
        self.stream = sys.stderr if stream is None else stream
        self.enabled = bool(enabled) and progress_allowed()
        if tty is None:
            try:
                tty = bool(self.stream.isatty())
            except (AttributeError, ValueError):
                tty = False
        self.tty = tty
        self.done = 0
        self._bar = None
        self._t0 = self._last_t = time.monotonic()
        self._last_share = 0.0
        self._written = 0
        self._first = None  # (time, done) at the first update: the rate after it excludes compiling

    def __enter__(self):
        if self.enabled and self.tty:
            from tqdm import tqdm

            self._bar = tqdm(total=self.total, desc=self.desc, unit=self.unit, file=self.stream)
        return self

    def update(self, n: int = 1) -> None:
        """``n`` more items done."""
        self.done += int(n)
        if not self.enabled:
            return
        if self._bar is not None:
            self._bar.update(int(n))
            return
        now = time.monotonic()
        share = self.done / self.total if self.total else 1.0
        first = self._first is None
        if first:
            self._first = (now, self.done)
        if (
            first
            or self.done >= self.total
            or share - self._last_share >= LINE_EVERY_SHARE - 1e-12
            or now - self._last_t >= LINE_EVERY_S
        ):
            self._line(now, share)

    def remaining_s(self, now=None):
        """Estimated seconds left (None before the first update or when done), and whether it comes
        from the first update alone (whose time includes compiling when the first call compiles)."""
        if self._first is None or self.done >= self.total or self.done <= 0:
            return None, False
        now = time.monotonic() if now is None else now
        t1, d1 = self._first
        if self.done > d1 and now > t1:
            return (now - t1) / (self.done - d1) * (self.total - self.done), False
        return (now - self._t0) / self.done * (self.total - self.done), True

    def _line(self, now, share):
        if self.done == self._written:
            return
        self._last_t, self._last_share, self._written = now, share, self.done
        left, upper = self.remaining_s(now)
        eta = (
            ""
            if left is None
            else (f", about {left:.0f} s left at the first chunk's rate" if upper else f", about {left:.0f} s left")
        )
        self.stream.write(
            f"{self.desc}: {self.done}/{self.total} {self.unit}s ({100.0 * share:.0f} %, {now - self._t0:.0f} s{eta})\n"
        )
        self.stream.flush()

    def __exit__(self, *exc):
        if self._bar is not None:
            self._bar.close()
        return False


def stage(message: str, *args) -> None:
    """An INFO line of the ``"jaxnav"`` logger (shown by the command line unless ``-q``)."""
    logging.getLogger(LOGGER_NAME).info(message, *args)
