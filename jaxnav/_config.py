"""TOML configuration files (host side): the one place the package parses TOML.

Every config loader (scenarios, the S0 experiment, sweep/tune configs, cadastral surveys) reads
its file with :func:`load_toml` (or :func:`loads_toml` for text) and then checks its own keys.
"""

from __future__ import annotations

import os
import pathlib
import tomllib


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
