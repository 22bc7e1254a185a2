"""Shared parsing of whitespace-separated numeric text (Cornell, ALTA)."""

from __future__ import annotations

import numpy as np

from gonio.io._common import PathLike, fail


def parse_row(path: PathLike, lineno: int, line: str) -> list[float]:
    """Parse one line of numbers; a bad token is a :class:`FormatError` naming the line."""
    out = []
    for tok in line.split():
        try:
            out.append(float(tok))
        except ValueError:
            raise fail(path, f"line {lineno}: not a number: {tok[:40]!r}") from None
    return out


def rows_to_array(path: PathLike, rows: list[list[float]], width: int, what: str) -> np.ndarray:
    """Stack rows of equal ``width`` into ``(N, width)`` and reject NaN/Inf."""
    if not rows:
        raise fail(path, f"no {what} records")
    arr = np.asarray(rows, dtype=np.float64).reshape(-1, width)
    if not np.all(np.isfinite(arr)):
        bad = int(np.count_nonzero(~np.all(np.isfinite(arr), axis=1)))
        raise fail(path, f"{bad} {what} record(s) contain NaN or Inf")
    return arr
