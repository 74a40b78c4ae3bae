"""Strict JSON output (host side): the one writer of every ``results.json`` / ``monitor.json`` /
``rtk_results.json``.

JSON has no NaN or infinity. :func:`json_ready` turns arrays and numpy/JAX scalars into lists and
numbers and every non-finite number into ``null``; beside each key whose value holds such nulls
it adds ``"<key>_null_reason"`` (the producer's own reason where it gives one, such as "no fixed
epoch in the window"; else e.g. "not computed (nan): ..." or "2 of 45 values not finite (nan 2)"),
so a reader of the file sees why a value is missing. :func:`write_json` writes with ``allow_nan=False``.
"""

from __future__ import annotations

import json
import math
import pathlib

import numpy as np

#: suffix of the key that explains the nulls of its sibling
NULL_REASON = "_null_reason"


def _kind(v: float) -> str:
    return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf")


#: the reason written for a single non-finite number when its producer gives none
SCALAR_REASONS = {
    "nan": "not computed (nan): the data held nothing to compute it from",
    "inf": "infinite (inf): no finite value exists for these data",
    "-inf": "infinite (-inf): no finite value exists for these data",
}


def _convert(obj, counts):
    """JSON-ready copy of ``obj``; adds the non-finite numbers it replaced to ``counts`` (kind -> n).
    A ``"<key>_null_reason"`` the producer put beside a key is kept (it knows why better)."""
    if isinstance(obj, dict):
        out = {}
        for k, v in obj.items():
            c = {}
            out[str(k)] = _convert(v, c)
            if c and f"{k}{NULL_REASON}" in obj:
                for kind, m in c.items():
                    counts[kind] = counts.get(kind, 0) + m
            elif c:
                n = sum(c.values())
                kinds = ", ".join(f"{kind} {m}" for kind, m in sorted(c.items()))
                size = _size(v)
                if size == 1 and not isinstance(v, (list, tuple, dict)) and np.ndim(v) == 0:
                    reason = SCALAR_REASONS[next(iter(c))]
                elif isinstance(v, dict):
                    reason = f"{n} value(s) inside not finite ({kinds}); see the inner *{NULL_REASON} keys"
                else:
                    reason = f"{n} of {size} values not finite ({kinds})"
                out[f"{k}{NULL_REASON}"] = reason
                for kind, m in c.items():
                    counts[kind] = counts.get(kind, 0) + m
        return out
    if isinstance(obj, (list, tuple)):
        return [_convert(v, counts) for v in obj]
    if isinstance(obj, (str, bool)) or obj is None:
        return obj
    if isinstance(obj, int):
        return obj
    if isinstance(obj, float):
        if math.isfinite(obj):
            return obj
        counts[_kind(obj)] = counts.get(_kind(obj), 0) + 1
        return None
    if isinstance(obj, pathlib.PurePath):
        return str(obj)
    if hasattr(obj, "_asdict"):  # a NamedTuple record
        return _convert(obj._asdict(), counts)
    try:
        a = np.asarray(obj)
    except Exception:  # anything else is written as its text
        return str(obj)
    if a.dtype == object:
        return [_convert(v, counts) for v in a.tolist()] if a.ndim else str(obj)
    if a.dtype.kind in "fc":
        a = a.real.astype(np.float64) if a.dtype.kind == "c" else a.astype(np.float64)
        bad = ~np.isfinite(a)
        if bad.any():
            for kind, m in (("nan", np.isnan(a)), ("inf", np.isposinf(a)), ("-inf", np.isneginf(a))):
                if m.any():
                    counts[kind] = counts.get(kind, 0) + int(m.sum())
            obj_a = a.astype(object)
            obj_a[bad] = None
            return obj_a.tolist()
        return a.tolist()
    if a.dtype.kind in "iub":
        return a.tolist()
    return a.astype(str).tolist()


def _size(v) -> int:
    if isinstance(v, dict):
        return sum(_size(x) for x in v.values())
    if isinstance(v, (list, tuple)):
        return sum(_size(x) for x in v)
    try:
        return int(np.size(v))
    except Exception:
        return 1


def json_ready(obj):
    """A copy of ``obj`` that ``json.dumps(..., allow_nan=False)`` accepts: arrays as lists, non-finite
    numbers as null with a ``"<key>_null_reason"`` sibling; returns (copy, {kind: count of nulls})."""
    counts = {}
    return _convert(obj, counts), counts


def write_json(path, obj, *, indent=1) -> pathlib.Path:
    """Write ``obj`` as strict JSON (no NaN/Infinity tokens; see :func:`json_ready`); returns the path."""
    path = pathlib.Path(path)
    data, _ = json_ready(obj)
    text = json.dumps(data, indent=indent, allow_nan=False)
    path.write_text(text + "\n", encoding="utf-8")
    return path
