"""Reader for raw IMU logs recorded through RTKLIB streams (CSV + ``.tag`` time tags), host side (numpy).

The logs this reads (e.g. rtklibexplorer's consumer-IMU walk/drive sets) are text lines
``ax,ay,az,gx,gy,gz,counter`` -- specific force in g, angular rate in deg/s, and an integer
millisecond counter from the IMU's own clock -- captured from a serial port by an RTKLIB stream
(str2str / rtknavi) with time tags on. Units are converted to SI at this edge and times to GPST
seconds since the GPS epoch (:data:`jaxnav.io.GPS_EPOCH`).

RTKLIB time-tag file (``<file>.tag``), little-endian, as decoded from RTKLIB's stream writer and
checked against real files:

====== ======= ===============================================================================
offset size    content
====== ======= ===============================================================================
0      60      text header ``"TIMETAG RTKLIB <version>"``, NUL padded
60     4       uint32 ``tick_f``: the logging PC's millisecond tick when the file was opened
               (absolute; only used by RTKLIB to synchronise two replayed files -- not needed here)
64     4       uint32 ``time``: start time, whole seconds of GPST counted like Unix time
               (GPST 1980-01-06 00:00:00 = 315964800; no leap seconds applied)
68     8       float64 fraction of a second of the start time
76     8 or 12 records, one per write to the data file: uint32 ``tick`` (ms since the start time,
               already relative to ``tick_f``) and the data file's byte position *after* that
               write -- uint32 in the files seen here (a Windows build); RTKLIB also has an
               8-byte-position variant (uint64), which is detected
====== ======= ===============================================================================

So the bytes ``[fpos[k-1], fpos[k])`` reached the PC by ``tick[k]`` ms after the start time.
The byte positions count the file as logged; a file whose CRLF line ends were later turned into
LF (e.g. by git) is recognised by its size (last position = size + number of bare LFs) and the
positions are mapped back.
"""

from __future__ import annotations

import datetime as _dt
import math
import pathlib
import struct
from typing import NamedTuple

import numpy as np

from jaxnav.io._errors import ReaderError
from jaxnav.io._rtklib import GPS_EPOCH, GPST_RANGE_S

STANDARD_GRAVITY = 9.80665
"""m/s^2 per g (standard gravity, CGPM 1901), the unit of the logs' accelerometer columns."""
DEG = math.pi / 180.0
"""rad per degree; the logs' gyro columns are deg/s."""
GPS_EPOCH_UNIX = (GPS_EPOCH - _dt.datetime(1970, 1, 1)).total_seconds()
"""315964800.0: GPS-epoch offset of RTKLIB's Unix-style GPST seconds (``gtime_t.time`` in GPST)."""

TAG_HEADER_MAGIC = b"TIMETAG RTKLIB"
TAG_HEADER_LEN = 60  # text part; tick_f follows at 60, the start time at 64 and 68
TAG_DATA_START = 76
#: the largest |specific force| a record may give, m/s^2 (about 100 g: beyond any IMU's range)
ACCEL_MAX = 1000.0
#: the largest |angular rate| a record may give, rad/s (about 11 500 deg/s)
GYRO_MAX = 200.0
#: counters accepted (non-negative, well inside int64)
COUNTER_MAX = 2**62
_TIMINGS = ("counter", "arrival", "endpoints")


class ImuLog(NamedTuple):
    """A raw IMU log in SI units; per-sample arrays of length N (body axes as logged).

    Attributes:
      path: the CSV file read.
      t: (N,) GPS time, seconds since the GPS epoch 1980-01-06 (GPST, no leap seconds).
      f_b: (N, 3) specific force, m/s^2 (the logged g times :data:`STANDARD_GRAVITY` unless
        ``accel_scale`` says otherwise).
      w_b: (N, 3) angular rate, rad/s.
      counter: (N,) int64 raw 7th column (the IMU's millisecond counter), as logged.
      lineno: (N,) int 1-based line number of each sample in the CSV.
      n_skipped_lines: number of lines not turned into samples.
      skipped: tuple of ``(lineno, reason)`` for those lines.
      timing: how ``t`` was made: 'counter', 'arrival', 'endpoints' (see :func:`read_rtklib_imu`);
        'increments' (:func:`jaxnav.io.read_kfgins_imu`) or 'csv' (:func:`jaxnav.io.read_csv_imu`): the
        file's own time column (``counter`` is then the sample index).
      t_start: GPST (s since the GPS epoch) of the tag file's start time, or the given ``t_start``.
    """

    path: str
    t: np.ndarray
    f_b: np.ndarray
    w_b: np.ndarray
    counter: np.ndarray
    lineno: np.ndarray
    n_skipped_lines: int
    skipped: tuple
    timing: str
    t_start: float


class TimeTags(NamedTuple):
    """A decoded RTKLIB ``.tag`` file.

    Attributes:
      path: the tag file.
      version: the header text after ``"TIMETAG RTKLIB "``.
      tick_f: the logging PC's absolute ms tick at the start (informational).
      t_start: start time, GPST seconds since the GPS epoch.
      tick: (K,) int64 ms after ``t_start`` of each write (non-decreasing).
      fpos: (K,) int64 data-file byte position after each write (non-decreasing).
      fpos_bytes: 4 or 8, the width of the stored positions.
    """

    path: str
    version: str
    tick_f: int
    t_start: float
    tick: np.ndarray
    fpos: np.ndarray
    fpos_bytes: int


#: the longest pause accepted between two writes of a tag file, ms; a longer one is a wrapped or
#: corrupted uint32 tick (a jump to near 2^32 ms), not a logging pause
TAG_GAP_MAX_MS = 3_600_000


def _decode_tag_records(buf, path, fpos_bytes):
    rec = 4 + fpos_bytes
    n = (len(buf) - TAG_DATA_START) // rec
    if (len(buf) - TAG_DATA_START) % rec:
        raise ReaderError(
            path,
            None,
            f"{len(buf) - TAG_DATA_START} bytes of records is not a whole number of "
            f"{rec}-byte (uint32 tick, uint{8 * fpos_bytes} position) records",
        )
    dt = np.dtype([("tick", "<u4"), ("fpos", "<u4" if fpos_bytes == 4 else "<u8")])
    r = np.frombuffer(buf, dtype=dt, count=n, offset=TAG_DATA_START)
    tick, fpos = r["tick"].astype(np.int64), r["fpos"].astype(np.int64)
    for name, a in (("tick", tick), ("byte position", fpos)):
        bad = np.flatnonzero(np.diff(a) < 0)
        if bad.size:
            k = int(bad[0]) + 1
            raise ReaderError(
                path,
                None,
                f"record {k} (file offset {TAG_DATA_START + k * rec}): {name} {a[k]} is "
                f"smaller than the previous {a[k - 1]}; not a {rec}-byte-record RTKLIB "
                "tag file",
            )
    gap = np.diff(tick)
    bad = np.flatnonzero(gap > TAG_GAP_MAX_MS)
    if bad.size:
        k = int(bad[0]) + 1
        raise ReaderError(
            path,
            None,
            f"record {k} (file offset {TAG_DATA_START + k * rec}): tick {tick[k]} ms is "
            f"{gap[k - 1] / 1e3:g} s after the previous {tick[k - 1]} ms, more than "
            f"{TAG_GAP_MAX_MS / 1e3:g} s (a wrapped or corrupted tick)",
        )
    return tick, fpos


def read_rtklib_tag(path, *, fpos_bytes=None) -> TimeTags:
    """Read an RTKLIB stream time-tag file (``<data file>.tag``).

    Args:
      path: tag file path.
      fpos_bytes: 4 or 8, the width of the stored byte positions; None (default) tries 4 then 8
        and keeps the one whose ticks and positions are non-decreasing (4 if both are).
    Returns:
      :class:`TimeTags`.
    Raises:
      ReaderError: (a ValueError) naming the file, for a wrong header, a short file, a header
        without records, a start time before 1980 or after 2100, a partial record, decreasing
        ticks/positions, or two writes more than :data:`TAG_GAP_MAX_MS` apart (a wrapped tick).
      FileNotFoundError: if the file does not exist.
    """
    path = pathlib.Path(path)
    buf = path.read_bytes()
    if not buf.startswith(TAG_HEADER_MAGIC):
        raise ReaderError(
            path,
            None,
            f"not an RTKLIB time-tag file (header {buf[:20]!r} does not start with {TAG_HEADER_MAGIC.decode()!r})",
        )
    if len(buf) < TAG_DATA_START:
        raise ReaderError(path, None, f"{len(buf)} bytes is shorter than the {TAG_DATA_START}-byte tag header")
    if len(buf) == TAG_DATA_START:
        raise ReaderError(path, None, "no time-tag records after the header (an empty log)")
    version = buf[len(TAG_HEADER_MAGIC) : TAG_HEADER_LEN].split(b"\0", 1)[0].decode("ascii", "replace").strip()
    tick_f, time_s = struct.unpack_from("<II", buf, TAG_HEADER_LEN)
    (frac,) = struct.unpack_from("<d", buf, TAG_HEADER_LEN + 8)
    if not (0.0 <= frac < 1.0):
        raise ReaderError(path, None, f"start-time fraction {frac!r} at offset 68 is not in [0, 1)")
    t_start = time_s - GPS_EPOCH_UNIX + frac
    if not GPST_RANGE_S[0] <= t_start <= GPST_RANGE_S[1]:
        raise ReaderError(
            path,
            None,
            f"start time {time_s} (offset 64, GPST counted like Unix time) is before 1980-01-06 or after 2100",
        )
    if fpos_bytes is not None:
        if fpos_bytes not in (4, 8):
            raise ValueError(f"fpos_bytes must be 4 or 8, not {fpos_bytes!r}")
        tick, fpos = _decode_tag_records(buf, path, fpos_bytes)
    else:
        errors = []
        for fpos_bytes in (4, 8):
            try:
                tick, fpos = _decode_tag_records(buf, path, fpos_bytes)
                break
            except ReaderError as exc:
                errors.append(exc.reason)
        else:
            raise ReaderError(path, None, " / ".join(errors))
    return TimeTags(
        path=str(path),
        version=version,
        tick_f=int(tick_f),
        t_start=float(t_start),
        tick=tick,
        fpos=fpos,
        fpos_bytes=fpos_bytes,
    )


def _parse_line(s, accel_scale=STANDARD_GRAVITY, gyro_scale=DEG):
    """(ax, ay, az, gx, gy, gz, counter) from one stripped CSV line, or a reason string."""
    try:
        s.decode("utf-8")
    except UnicodeDecodeError as exc:
        return f"not UTF-8 text: byte 0x{s[exc.start]:02X} at column {exc.start + 1}"
    words = s.split(b",")
    if len(words) != 7:
        return f"{len(words)} comma-separated fields, expected 7"
    try:
        vals = [float(w) for w in words[:6]]
        counter = int(words[6])
    except ValueError as exc:
        return str(exc)[:120]
    if not all(math.isfinite(v) for v in vals):
        return "non-finite value"
    for i, v in enumerate(vals):
        acc = i < 3
        lim, scale = (ACCEL_MAX, accel_scale) if acc else (GYRO_MAX, gyro_scale)
        if abs(v * scale) > lim:
            what = "specific force" if acc else "angular rate"
            return (
                f"{what} {'ax ay az gx gy gz'.split()[i]} = {v:g} ({v * scale:g} {'m/s^2' if acc else 'rad/s'}) "
                f"exceeds {lim:g} {'m/s^2' if acc else 'rad/s'}: not a measurement"
            )
    if not 0 <= counter < COUNTER_MAX:
        return f"counter {words[6][:30].decode('ascii', 'replace')} outside [0, 2^62)"
    return vals, counter


def _logged_offsets(raw, line_ends, tags, csv_path):
    """Map the CSV's line-end byte offsets to the positions the tag file counts."""
    size, last = len(raw), int(tags.fpos[-1])
    if last == size:
        return line_ends
    # LF without a preceding CR: those were CRLF when logged if the sizes differ by exactly their count
    lf = np.frombuffer(raw, dtype=np.uint8) == 0x0A
    bare = lf.copy()
    bare[1:] &= np.frombuffer(raw, dtype=np.uint8)[:-1] != 0x0D
    n_bare = int(bare.sum())
    if n_bare and last == size + n_bare:
        cum = np.concatenate([[0], np.cumsum(bare)])  # bare LFs before each byte position
        return line_ends + cum[line_ends]
    msg = f"the tag file ends at byte {last} but {csv_path} has {size} bytes"
    if n_bare:
        msg += f" ({size + n_bare} if logged with CRLF line ends)"
    raise ReaderError(tags.path, None, msg + "; the tag file does not belong to this CSV (or one of them is truncated)")


def _envelope_clock(cs, arr, bin_s=1.0):
    """Offset a and rate b of t = a + b*cs: b fitted to the earliest read per bin, a so that t <= arr everywhere."""
    lat = arr - cs
    edges = np.floor((cs - cs[0]) / bin_s).astype(np.int64)
    _, first = np.unique(edges, return_index=True)
    idx = np.array([i0 + int(np.argmin(lat[i0:i1])) for i0, i1 in zip(first, list(first[1:]) + [len(cs)])])
    b = float(np.polyfit(cs[idx], arr[idx], 1)[0]) if len(idx) >= 2 else 1.0
    a = float(np.min(arr - b * cs))
    return a, b


def read_rtklib_imu(
    csv_path,
    tag_path=None,
    *,
    timing=None,
    t_start=None,
    accel_scale=STANDARD_GRAVITY,
    gyro_scale=DEG,
    counter_unit=1e-3,
    bad_lines="raise",
    tag_fpos_bytes=None,
) -> ImuLog:
    """Read a raw ``ax,ay,az,gx,gy,gz,counter`` IMU log and its RTKLIB time tags.

    Lines: ``b"\\r"`` is stripped; blank lines are skipped. A malformed *first* or *last* line is
    skipped (logging starts and stops mid-line on a serial stream: the walk_0827 file begins
    with a 6-field tail of a line and ends with a cut-off line without newline). A truncation
    that happens to leave 7 parseable fields cannot be detected. Any other malformed line
    raises ``ValueError("<file>:<line>: ...")``, or with ``bad_lines="skip"`` is skipped. All
    skipped lines are listed in ``skipped`` with the reason.

    Timing (``t``, GPST s since the GPS epoch):

    * ``"counter"`` (default with a tag file): the IMU's own counter is the sample clock (1 ms
      resolution, no transport jitter); its rate and offset come from the tag file: each line's
      read time is the tick of the first tag record whose position covers the line's last byte
      (a strict bound: a sample cannot be read before it is taken), the counter-to-read-time
      line is fitted through the earliest read (least latency) in every 1 s of counter time
      (rate), then lowered until no sample is dated after its read (offset). So ``t`` is the
      sample time plus the log's smallest latency (which the tags cannot reveal), it runs at the
      logging PC's clock rate (walk_0827's IMU counter runs 9.5 ppm slow against it), and its
      steps are the counter's (6-9 ms on walk_0827). Requires a counter that increases line by
      line (a 32-bit wrap-around is unwrapped).
    * ``"arrival"``: the arrival time of each line's last byte, interpolated linearly in byte
      position between tag records (the serial stream delivers bytes at a nearly constant rate,
      and the tag counts bytes, not lines; interpolating by line would need the line lengths
      anyway and puts a write's lines at equal spacing whatever their lengths); lines within
      the first write get its tick (on walk_0827 a 113 ms backlog burst of 17 lines). It carries
      the USB/serial latency and its ~16 ms polling jitter, and is only non-decreasing: lines
      between two records with the same tick get equal times (15 pairs on walk_0827). For logs
      without a usable counter.
    * ``"endpoints"``: what rtklibexplorer's converter does: the counter scaled so the first kept
      line is at the start time and the last at the last tag tick (reproduces its ``t`` column).
    * Without a tag file (default then ``"counter"``): ``t = t_start + (counter - counter[0]) *
      counter_unit``; ``t_start`` (GPST s since the GPS epoch of the first kept sample) is required.

    Args:
      csv_path: the IMU CSV.
      tag_path: its RTKLIB time-tag file (usually ``csv_path + ".tag"``), or None.
      timing: "counter", "arrival" or "endpoints" (the last two need ``tag_path``).
      t_start: GPST of the first kept sample, only (and then required) without ``tag_path``.
      accel_scale: m/s^2 per logged accelerometer unit (default g = 9.80665; the data sets do
        not state another value, and their converter keeps g).
      gyro_scale: rad/s per logged gyro unit (default deg/s).
      counter_unit: seconds per counter count (default 1 ms).
      bad_lines: "raise" (default) or "skip" for malformed lines other than the first and last.
      tag_fpos_bytes: 4, 8 or None (detect), see :func:`read_rtklib_tag`.
    Returns:
      :class:`ImuLog`.
    Raises:
      ReaderError: (a ValueError) naming the file (and line) for malformed lines (bytes that are
        not UTF-8, non-finite values, |specific force| > :data:`ACCEL_MAX` m/s^2, |rate| >
        :data:`GYRO_MAX` rad/s, a negative or huge counter), a bad or mismatched tag file, a
        counter that does not increase (counter/endpoints timing), or a counter whose rate is
        more than 1 % off ``counter_unit`` against the tags.
      ValueError: missing or contradictory timing inputs.
      FileNotFoundError: if a file does not exist.
    """
    csv_path = pathlib.Path(csv_path)
    if bad_lines not in ("raise", "skip"):
        raise ValueError(f"bad_lines must be 'raise' or 'skip', not {bad_lines!r}")
    if timing is None:
        timing = "counter"
    if timing not in _TIMINGS:
        raise ValueError(f"timing must be one of {_TIMINGS}, not {timing!r}")
    if tag_path is None and timing != "counter":
        raise ValueError(f"timing={timing!r} needs the tag file (tag_path)")
    if tag_path is None and t_start is None:
        raise ValueError(f"{csv_path}: without a tag file give t_start (GPST of the first sample)")
    if tag_path is not None and t_start is not None:
        raise ValueError("give either tag_path or t_start, not both (the tag file holds the start time)")
    if t_start is not None and not GPST_RANGE_S[0] <= float(t_start) <= GPST_RANGE_S[1]:
        raise ValueError(f"t_start = {t_start!r} s is not a GPST time between 1980 and 2100")

    raw = csv_path.read_bytes()
    tags = read_rtklib_tag(tag_path, fpos_bytes=tag_fpos_bytes) if tag_path is not None else None

    pieces = raw.split(b"\n")
    if pieces and pieces[-1] == b"":
        pieces.pop()  # the file ends with a newline
    n_lines = len(pieces)
    ends = np.cumsum([len(p) + 1 for p in pieces], dtype=np.int64)  # after each line's LF
    if n_lines:
        ends[-1] = min(int(ends[-1]), len(raw))  # a last line without LF ends at the file's end

    rows, counters, linenos, keep_idx, skipped = [], [], [], [], []
    for i, p in enumerate(pieces):
        lineno = i + 1
        s = p.strip()
        if not s:
            skipped.append((lineno, "blank line"))
            continue
        got = _parse_line(s, accel_scale, gyro_scale)
        if isinstance(got, str):
            if i == 0 or i == n_lines - 1:
                where = "first" if i == 0 else "last"
                skipped.append((lineno, f"partial {where} line ({got})"))
                continue
            if bad_lines == "skip":
                skipped.append((lineno, got))
                continue
            raise ReaderError(csv_path, lineno, f"malformed IMU line {s[:80]!r}: {got}")
        rows.append(got[0])
        counters.append(got[1])
        linenos.append(lineno)
        keep_idx.append(i)
    if not rows:
        raise ReaderError(csv_path, None, "no IMU records")

    a = np.asarray(rows, dtype=np.float64)
    counter = np.asarray(counters, dtype=np.int64)
    lineno = np.asarray(linenos, dtype=np.int64)

    if timing in ("counter", "endpoints"):
        dc = np.diff(counter)
        dc = np.where(dc < -(2**31), dc + 2**32, dc)  # uint32 millisecond counter wrapping around
        bad = np.flatnonzero(dc <= 0)
        if bad.size:
            k = int(bad[0]) + 1
            raise ReaderError(
                csv_path,
                int(lineno[k]),
                f"counter {counter[k]} does not increase (previous "
                f"{counter[k - 1]} on line {lineno[k - 1]}); use "
                "timing='arrival' with a tag file",
            )
        cs = np.concatenate([[0], np.cumsum(dc)]) * counter_unit  # counter seconds since the first sample

    if tags is None:
        t = float(t_start) + cs
        t0 = float(t_start)
    else:
        t0 = tags.t_start
        logged_ends = _logged_offsets(raw, ends[np.asarray(keep_idx)], tags, csv_path)
        if timing == "arrival":
            t = t0 + np.interp(logged_ends, tags.fpos, tags.tick) * 1e-3
        elif timing == "endpoints":
            t = t0 + cs * (tags.tick[-1] * 1e-3 / cs[-1]) if cs[-1] > 0 else np.full(len(cs), t0)
        else:
            # the read (tag record) by which each line was complete: a strict bound, sample time <= read time
            read = tags.tick[np.searchsorted(tags.fpos, logged_ends)] * 1e-3
            off, rate = _envelope_clock(cs, read)
            if abs(rate - 1.0) > 0.01:
                raise ReaderError(
                    csv_path,
                    None,
                    f"the counter runs at {rate:.6g} x counter_unit={counter_unit} s "
                    f"against the tag file {tags.path}; wrong counter_unit or not a "
                    "counter",
                )
            t = t0 + off + rate * cs

    return ImuLog(
        path=str(csv_path),
        t=t,
        f_b=a[:, :3] * accel_scale,
        w_b=a[:, 3:6] * gyro_scale,
        counter=counter,
        lineno=lineno,
        n_skipped_lines=len(skipped),
        skipped=tuple(skipped),
        timing=timing,
        t_start=float(t0),
    )


def imu_increments(imu: ImuLog, C_bs):
    """Body-frame angle and velocity increments from a rate log (rectangular integration).

    Sample i is taken to cover (t[i-1], t[i]] (the logged rate times the interval); the first
    interval copies the second.

    Args:
      imu: :class:`ImuLog` (or any record with ``t`` (N,) s, ``w_b`` (N, 3) rad/s and ``f_b``
        (N, 3) m/s^2 in the sensor axes).
      C_bs: (3, 3) sensor -> body rotation (e.g. from :func:`jaxnav.ins.sensor_to_body`).
    Returns:
      (t (N,) s, dtheta (N, 3) rad, dv (N, 3) m/s, dt (N,) s), increments in the body frame.
    """
    t = np.asarray(imu.t, float)
    dt = np.diff(t)
    dt = np.concatenate([dt[:1], dt])
    C = np.asarray(C_bs, float)
    w_b = np.asarray(imu.w_b, float) @ C.T
    f_b = np.asarray(imu.f_b, float) @ C.T
    return t, w_b * dt[:, None], f_b * dt[:, None], dt
