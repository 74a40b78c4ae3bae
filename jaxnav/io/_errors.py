"""What every reader shares: :class:`ReaderError` (file and line of the fault), strict UTF-8 line
reading, and the checks of finite and physically possible values."""

from __future__ import annotations

import math
import os
from collections.abc import Iterator

#: the largest |latitude| a file may give, deg
LAT_MAX_DEG = 90.0
#: longitudes accepted, deg (some formats write 0..360, some -180..180)
LON_RANGE_DEG = (-360.0, 360.0)
#: heights (ellipsoidal, normal, up offsets) accepted, m: from below the deepest trench to above
#: any aircraft; a value outside is a corrupted number, not a position on Earth
HEIGHT_RANGE_M = (-1.2e4, 1.0e5)
#: plane coordinates (Gauss-Krüger x, y; daily east/north offsets) accepted, m (|.| <= 4e7: Earth's size)
PLANE_MAX_M = 4.0e7
#: standard deviations accepted, m (> 0; above this a solution carries no position information)
SIGMA_MAX_M = 1.0e4


class ReaderError(ValueError):
    """A file a reader cannot use; ``str()`` is ``"FILE:LINE: message"`` (``"FILE: message"`` for the
    file as a whole). Attributes: ``path`` (str), ``line`` (1-based int or None), ``reason`` (the message)."""

    def __init__(self, path, line: int | None, reason: str):
        self.path, self.line, self.reason = os.fspath(path), line, reason
        where = self.path if line is None else f"{self.path}:{line}"
        super().__init__(f"{where}: {reason}")


def text_lines(path) -> Iterator[tuple[int, str]]:
    """(line number, text without the line end) of a UTF-8 text file; a byte that is not UTF-8
    raises :class:`ReaderError` naming the line and column (a BOM at the start is dropped)."""
    p = os.fspath(path)
    with open(p, "rb") as fh:
        data = fh.read()
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    pieces = data.split(b"\n")
    if pieces[-1] == b"":
        pieces.pop()  # the file's final newline
    for i, raw in enumerate(pieces, start=1):
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise ReaderError(p, i, f"not UTF-8 text: byte 0x{raw[exc.start]:02X} at column {exc.start + 1}") from None
        if "\x00" in text:
            raise ReaderError(p, i, f"NUL byte at column {text.index(chr(0)) + 1} (a binary or corrupted file)")
        yield i, text.rstrip("\r")


def to_float(text: str, path, line: int, what: str) -> float:
    """``float(text)`` or :class:`ReaderError` naming ``what``; NaN and infinities are returned as such."""
    try:
        return float(text)
    except (ValueError, OverflowError):
        raise ReaderError(path, line, f"{what}: cannot read {text[:40]!r} as a number") from None


def check_finite(v: float, path, line: int, what: str) -> float:
    """``v`` if finite, else :class:`ReaderError` naming ``what``."""
    if not math.isfinite(v):
        raise ReaderError(path, line, f"{what} is {v} (not a finite number)")
    return v


def check_range(v: float, lo: float, hi: float, path, line: int, what: str, unit: str = "") -> float:
    """``v`` if finite and in [lo, hi], else :class:`ReaderError` naming ``what`` and the range."""
    check_finite(v, path, line, what)
    if not lo <= v <= hi:
        raise ReaderError(path, line, f"{what} = {v:g}{unit} is outside [{lo:g}, {hi:g}]{unit}")
    return v


def check_sigma(v: float, path, line: int, what: str, *, allow_nan: bool = False) -> float:
    """``v`` if 0 < v <= :data:`SIGMA_MAX_M` (or NaN when ``allow_nan``), else :class:`ReaderError`."""
    if allow_nan and math.isnan(v):
        return v
    if not (math.isfinite(v) and 0.0 < v <= SIGMA_MAX_M):
        raise ReaderError(path, line, f"{what} = {v:g} m must be positive, finite and <= {SIGMA_MAX_M:g} m")
    return v
