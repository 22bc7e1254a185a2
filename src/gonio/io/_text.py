"""Shared parsing of whitespace-separated numeric text (Cornell, ALTA), in bounded memory.

A text file of at most :data:`gonio._bounded.MAX_TEXT_BYTES` can still hold tens of millions
of numbers; as Python lists of strings and floats they took 40 times their text. Two bounds,
checked before the numbers are stored:

* :data:`MAX_TEXT_ROWS` lines (counted before parsing, :func:`check_line_count`) and, in a
  Cornell file, sample records: 2,097,152, above MERL's 1.46 M cells written one per line
  (the published files hold 7,400 and 1,440);
* :data:`MAX_TEXT_NUMBERS` numbers in all (16,777,216: 128 MiB as float64), and
  :data:`MAX_LINE_CHARS` characters on one line (65,536; the published lines are under 400).

Lines are read lazily (:func:`numbered_lines`) and numbers converted :data:`BLOCK_LINES` lines
at a time into float64 arrays (:class:`NumberBlocks`).
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from gonio.io._common import PathLike, fail

MAX_TEXT_ROWS = 1 << 21
MAX_TEXT_NUMBERS = 1 << 24
MAX_LINE_CHARS = 1 << 16
#: Lines, or characters, converted at once (a block's Python objects stay a few MB).
BLOCK_LINES = 1 << 14
_BLOCK_CHARS = 1 << 20
_SLICE_CHARS = 1 << 20


def check_line_count(path: PathLike, text: str) -> None:
    """Refuse a text of more than :data:`MAX_TEXT_ROWS` lines (a count, nothing stored)."""
    n = text.count("\n") + 1
    if n > MAX_TEXT_ROWS:
        raise fail(path, f"{n} lines of text, more than {MAX_TEXT_ROWS}")


def numbered_lines(text: str) -> Iterator[tuple[int, str]]:
    """``(line number from 1, line)`` of ``text`` as ``str.splitlines`` splits it, produced
    from 1 MiB slices cut after a newline (never the whole list of lines at once)."""
    lineno, pos, n = 0, 0, len(text)
    while pos < n:
        end = text.find("\n", min(pos + _SLICE_CHARS, n))
        end = n if end < 0 else end + 1
        for line in text[pos:end].splitlines():
            lineno += 1
            yield lineno, line
        pos = end


def parse_row(path: PathLike, lineno: int, line: str) -> list[float]:
    """Parse one line of numbers; a bad token is a :class:`FormatError` naming the line."""
    out = []
    for tok in line.split():
        try:
            out.append(float(tok))
        except ValueError:
            raise fail(path, f"line {lineno}: not a number: {tok[:40]!r}") from None
    return out


class NumberBlocks:
    """Numbers of many lines, converted a block at a time; per line, how many it held.

    Parameters
    ----------
    path : the file (named in errors).
    what : what a line is, in errors ("data row", "sample record").
    """

    def __init__(self, path: PathLike, what: str) -> None:
        self.path = path
        self.what = what
        self._lines: list[tuple[int, str]] = []
        self._values: list[np.ndarray] = []
        self._counts: list[np.ndarray] = []
        self.n_numbers = 0
        self._chars = 0

    def add(self, lineno: int, line: str) -> None:
        """Queue one line of numbers (line number ``lineno``, for errors)."""
        if len(line) > MAX_LINE_CHARS:
            raise fail(self.path, f"line {lineno}: more than {MAX_LINE_CHARS} characters")
        self._lines.append((lineno, line))
        self._chars += len(line)
        if len(self._lines) >= BLOCK_LINES or self._chars >= _BLOCK_CHARS:
            self._flush()

    def _flush(self) -> None:
        if not self._lines:
            return
        split = [line.split() for _, line in self._lines]
        counts = np.fromiter((len(t) for t in split), dtype=np.int64, count=len(split))
        self.n_numbers += int(counts.sum())
        if self.n_numbers > MAX_TEXT_NUMBERS:
            raise fail(self.path, f"more than {MAX_TEXT_NUMBERS} numbers in {self.what}s")
        try:
            values = np.fromiter(
                (float(t) for toks in split for t in toks), dtype=np.float64, count=-1
            )
        except ValueError:
            for lineno, line in self._lines:  # the first bad token, named with its line
                parse_row(self.path, lineno, line)
            raise
        self._values.append(values)
        self._counts.append(counts)
        self._lines = []
        self._chars = 0

    def numbers(self) -> np.ndarray:
        """All numbers, in order, float64 ``(n_numbers,)``."""
        self._flush()
        return np.concatenate(self._values) if self._values else np.zeros(0)

    def counts(self) -> np.ndarray:
        """Numbers per line, int64 ``(n_lines,)``."""
        self._flush()
        return np.concatenate(self._counts) if self._counts else np.zeros(0, np.int64)


def rows_to_array(path: PathLike, rows: NumberBlocks, width: int, what: str) -> np.ndarray:
    """The rows of equal ``width`` as ``(N, width)``; a row of another width or a NaN/Inf is
    refused, naming the first such row."""
    counts = rows.counts()
    if not counts.size:
        raise fail(path, f"no {what} records")
    bad = np.flatnonzero(counts != width)
    if bad.size:
        i = int(bad[0])
        raise fail(
            path,
            f"{what} row {i + 1} has {int(counts[i])} numbers, expected {width} "
            "(truncated or malformed)",
        )
    arr = rows.numbers().reshape(-1, width)
    if not np.all(np.isfinite(arr)):
        n_bad = int(np.count_nonzero(~np.all(np.isfinite(arr), axis=1)))
        raise fail(path, f"{n_bad} {what} record(s) contain NaN or Inf")
    return arr
