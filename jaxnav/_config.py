"""TOML configuration files (host side): the one place the package parses and checks TOML.

Every config loader (the ``jaxnav ins`` configs, scenarios, the S0 experiment, sweep/tune
configs, cadastral surveys) reads its file with :func:`load_toml` (or :func:`loads_toml` for
text) and its keys through one :class:`ConfigTable` reader: typed keys, bounds, plausible ranges,
unknown keys refused, and every message naming the file and the key.
"""

from __future__ import annotations

import math
import os
import pathlib
import re
import tomllib

import numpy as np


def loads_toml(text: str, source=None) -> dict:
    """Parse TOML text into a dict.

    Args:
      text: TOML document.  source: file name for messages (None: the message has no prefix).
    Raises:
      ValueError: "SOURCE: invalid TOML: ... (at line L, column C)".
    """
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        where = "" if source is None else f"{os.fspath(source)}: "
        raise ValueError(f"{where}invalid TOML: {exc}") from None


def load_toml(path) -> dict:
    """Read a TOML file (UTF-8) into a dict.

    Args:
      path: str or path-like.
    Raises:
      FileNotFoundError: no such file (the message names the path).
      ValueError: a syntax error or a byte that is not UTF-8, naming the file, line and column.
    """
    path = pathlib.Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: no such TOML file") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise ValueError(f"{path}:{line}: not UTF-8 text (byte 0x{data[exc.start]:02X})") from None
    return loads_toml(text, source=path)


class ConfigError(ValueError):
    """A configuration problem; the message names the file (when known) and the key (``FILE: section.key ...``)."""


#: the ``default`` of :meth:`ConfigTable.get` for a key that must be given
REQUIRED = ...

_VAR = re.compile(r"\$\{([A-Za-z_][A-Za-z0-9_]*)\}")


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _interval(lo, hi, lo_open=False, hi_open=False) -> str:
    return f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"


class ConfigTable:
    """Typed, checked access to one table of a TOML document: the package's one config reader.

    Every loader of a TOML file (the ``jaxnav ins`` configs, the S0 experiment, sweep/tune
    configs, simulation scenarios, cadastral surveys) reads its keys through this class, so
    every config error has one shape: ``FILE: section.key message`` (the file left out when
    the table did not come from a file). A key read with :meth:`get` (or :meth:`table`,
    :meth:`tables`, :meth:`file`) is known; :meth:`done` refuses the others.

    Args:
      data: the table (a dict; anything else is refused, naming the table).
      name: dotted name of the table in its document ("gnss", "params.b", "segments[3]";
        "" for the document root).
      source: the file, for messages (None: no file prefix).
      error: the exception class raised (a ``ValueError`` subclass; default :class:`ConfigError`).
      plausible: optional {"section.key": (lo, hi)} ranges in the key's own unit; a number read
        with :meth:`get` outside its range is refused as a typing slip or a unit mix-up.
      variables: optional {NAME: value} for ``${NAME}`` in :meth:`file` paths, used before the
        environment.
    """

    def __init__(self, data, name: str = "", *, source=None, error=ConfigError, plausible=None, variables=None):
        self.name, self.source, self.error = name, source, error
        self.plausible, self.variables = dict(plausible or {}), dict(variables or {})
        if not isinstance(data, dict):
            self.fail(None, f"must be a table [{name}], got {data!r}")
        self.data, self.used = data, set()

    def key(self, key) -> str:
        """The dotted name of ``key`` in the document (the table's name for None)."""
        if key is None:
            return self.name
        return f"{self.name}.{key}" if self.name else str(key)

    def fail(self, key, msg: str):
        """Raise ``error`` with "FILE: section.key msg"."""
        where = "" if self.source is None else f"{os.fspath(self.source)}: "
        name = self.key(key)
        raise self.error(f"{where}{name} {msg}" if name else f"{where}{msg}")

    def has(self, key) -> bool:
        """Whether ``key`` is given."""
        return key in self.data

    def get(self, key, kind, default=REQUIRED, *, lo=None, hi=None, lo_open=False, hi_open=False, choices=None):
        """The value of ``key`` checked against ``kind``, its bounds and choices.

        Args:
          key: the key in this table.
          kind: float (an int is accepted and converted; finite), int, bool, str, list, dict,
            "vec3" (a list of 3 finite numbers, returned as a (3,) float array) or
            "numbers" (a list of finite numbers).
          default: the value when the key is absent; :data:`REQUIRED` refuses its absence.
          lo, hi: bounds of a number (ends included unless ``lo_open``/``hi_open``).
          choices: the allowed values.
        Returns:
          The value (``default`` when absent).
        """
        self.used.add(key)
        if key not in self.data:
            if default is REQUIRED:
                self.fail(key, "is required")
            return default
        v = self.data[key]
        if kind is float:
            if not _is_number(v):
                self.fail(key, f"must be a number, got {v!r}")
            v = float(v)
            if not math.isfinite(v):
                self.fail(key, f"must be finite, got {v!r}")
        elif kind is int:
            if isinstance(v, bool) or not isinstance(v, int):
                self.fail(key, f"must be an integer, got {v!r}")
        elif kind is bool:
            if not isinstance(v, bool):
                self.fail(key, f"must be true or false, got {v!r}")
        elif kind is str:
            if not isinstance(v, str):
                self.fail(key, f"must be a string, got {v!r}")
        elif kind is list:
            if not isinstance(v, list):
                self.fail(key, f"must be a list, got {v!r}")
        elif kind is dict:
            if not isinstance(v, dict):
                self.fail(key, f"must be a table, got {v!r}")
        elif kind == "vec3":
            if not isinstance(v, list) or len(v) != 3 or not all(_is_number(x) and math.isfinite(x) for x in v):
                self.fail(key, f"must be a list of 3 finite numbers, got {v!r}")
            return np.asarray(v, float)
        elif kind == "numbers":
            if not isinstance(v, list) or not all(_is_number(x) and math.isfinite(x) for x in v):
                self.fail(key, f"must be a list of finite numbers, got {v!r}")
        else:
            raise TypeError(f"ConfigTable.get: unknown kind {kind!r}")
        if choices is not None and v not in choices:
            self.fail(key, f"must be one of {list(choices)}, got {v!r}")
        if lo is not None or hi is not None:
            self.check_bounds(key, v, lo=lo, hi=hi, lo_open=lo_open, hi_open=hi_open)
        rng = self.plausible.get(self.key(key))
        if rng is not None and kind is float:
            self.check_plausible(key, v, rng)
        return v

    def check_bounds(self, key, v, *, lo=None, hi=None, lo_open=False, hi_open=False):
        """Refuse a number ``v`` (or each of a list) of ``key`` outside [lo, hi] (open ends as said)."""
        for x in v if isinstance(v, list) else [v]:
            if lo is not None and not (x > lo if lo_open else x >= lo):
                self.fail(key, f"= {x!r} must be {'>' if lo_open else '>='} {lo:g}")
            if hi is not None and not (x < hi if hi_open else x <= hi):
                self.fail(key, f"= {x!r} must be {'<' if hi_open else '<='} {hi:g}")

    def check_plausible(self, key, v, rng):
        """Refuse a number ``v`` (or each of a list) of ``key`` outside the plausible range (lo, hi), ends included."""
        for x in v if isinstance(v, list) else [v]:
            if not _is_number(x) or not math.isfinite(x):
                self.fail(key, f"must be a finite number, got {x!r}")
            if not rng[0] <= x <= rng[1]:
                self.fail(
                    key, f"= {x!r} is outside the plausible range {_interval(*rng)} (a typing slip or a unit mix-up?)"
                )

    def table(self, key, required: bool = False) -> ConfigTable | None:
        """The sub-table ``key`` as a :class:`ConfigTable` (None when absent and not required)."""
        self.used.add(key)
        if key not in self.data:
            if required:
                self.fail(key, "is required")
            return None
        return ConfigTable(
            self.data[key],
            self.key(key),
            source=self.source,
            error=self.error,
            plausible=self.plausible,
            variables=self.variables,
        )

    def tables(self, key) -> list:
        """The array of tables ``[[key]]`` as :class:`ConfigTable` s named ``key[i]`` (empty when absent)."""
        self.used.add(key)
        v = self.data.get(key, [])
        if not isinstance(v, list):
            self.fail(key, f"must be an array of tables ([[{self.key(key)}]]), got {v!r}")
        return [
            ConfigTable(
                t,
                f"{self.key(key)}[{i}]",
                source=self.source,
                error=self.error,
                plausible=self.plausible,
                variables=self.variables,
            )
            for i, t in enumerate(v)
        ]

    def file(self, key, required: bool = True) -> pathlib.Path | None:
        """A path ``key``: ``~`` and ``${NAME}`` expanded (``variables`` first, then the environment);
        a relative path is taken against the config file's folder, one that starts with a variable
        against the working directory."""
        v = self.get(key, str, REQUIRED if required else None)
        if v is None:
            return None

        def sub(m):
            name = m.group(1)
            if name in self.variables:
                return self.variables[name]
            if name not in os.environ:
                self.fail(key, f"uses ${{{name}}}, which is not set in the environment (set it, or pass --data)")
            return os.environ[name]

        p = pathlib.Path(os.path.expanduser(_VAR.sub(sub, v)))
        if p.is_absolute():
            return p
        if _VAR.match(v) or self.source is None:
            return pathlib.Path(os.path.abspath(p))
        return pathlib.Path(self.source).parent / p

    def expect(self, keys):
        """Declare ``keys`` as this table's keys and refuse any other now (a misspelt key is then
        named as unknown before its correct spelling is reported missing)."""
        self.used.update(keys)
        self.done()

    def done(self):
        """Refuse the keys not read, each by its dotted name ("unknown key gnss.rate; expected some
        of [...]"; "unknown section [x]" for the document root)."""
        unknown = sorted(set(self.data) - self.used)
        if not unknown:
            return
        where = "" if self.source is None else f"{os.fspath(self.source)}: "
        s = "s" if len(unknown) > 1 else ""
        if not self.name:
            names = ", ".join(f"[{k}]" for k in unknown)
            raise self.error(f"{where}unknown section{s} {names}; expected some of {sorted(self.used)}")
        names = ", ".join(self.key(k) for k in unknown)
        raise self.error(f"{where}unknown key{s} {names}; expected some of {sorted(self.used)}")
