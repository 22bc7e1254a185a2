"""Limits on untrusted input, and bounded parsing of JSON and TOML text.

Files come from other labs, old rigs and half-finished downloads, so every reader checks what it
is given against these limits *before* it allocates or recurses. They are far above anything a
real measurement needs and far below what would exhaust a workstation:

* :data:`MAX_BRDF` — no measured reflectance reaches 1e10 1/sr (a mirror tabulated on a
  0.01-degree cell peaks near 3e7 1/sr); larger values are corruption, not data.
* :data:`MAX_DECODED_BYTES` — the memory one file's decoded arrays may take together (1 GiB: a
  MERL-resolution table is 17 MB); a reader refuses a file whose declared shapes exceed it.
* :data:`MAX_COMPRESSION_RATIO` — each compressed chunk must store at least 1/1100 of its
  decoded size (deflate cannot exceed about 1032:1, so only a crafted filter pipeline can).
* :data:`MAX_NESTING`, :data:`MAX_JSON_BYTES`, :data:`MAX_TOML_BYTES` — JSON and TOML
  documents (fit results, rig and plan files) are at most 64 levels deep and 64 MiB / 1 MiB.
* :data:`MAX_CHANNELS` — a table holds at most 128 channels (wavelengths): the published
  spectral files hold a few dozen, and a fit's and a tabulation's memory grow with the count
  (a 2,000-wavelength Cornell file of 20 samples took 16 GiB in ``gonio fit``).
* :data:`MAX_TEXT_BYTES` — numeric text files (Cornell, ALTA) are at most 64 MiB (the largest
  published one is about 1 MB); binary files at most :data:`MAX_DECODED_BYTES` plus 1 MiB.

Writing is the other side: what gonio prints or writes as JSON is strict JSON through
:mod:`gonio.io.strict_json`.

This module imports nothing of gonio but :mod:`gonio.errors`, so every subpackage may use it.
"""

from __future__ import annotations

import json
import math
import os
import sys
import tomllib
from typing import Any

from gonio.errors import FormatError, GonioError

MAX_BRDF = 1e10
MAX_DECODED_BYTES = 1 << 30
MAX_COMPRESSION_RATIO = 1100
MAX_NESTING = 64
MAX_JSON_BYTES = 64 << 20
MAX_TOML_BYTES = 1 << 20
MAX_TEXT_BYTES = 64 << 20
MAX_CHANNELS = 128


def decode_utf8(data: bytes, source: str, error: type[GonioError] = FormatError) -> str:
    """``data`` as UTF-8 text; an undecodable byte is an error naming its offset."""
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise error(f"{source}: not UTF-8 text (byte offset {exc.start})") from None


def nesting_depth(text: str, toml: bool = False) -> int:
    """Deepest bracket nesting (``[`` and ``{``) outside strings (and, for TOML, comments).

    A linear scan that never recurses, so it can measure documents that would overflow a
    recursive parser. Strings follow JSON (``"..."`` with backslash escapes) and, with
    ``toml``, TOML (basic, literal and multi-line strings; ``#`` comments to the end of a line).
    """
    depth = top = 0
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if c in "[{":
            depth += 1
            top = max(top, depth)
        elif c in "]}":
            depth -= 1
        elif c == '"' or (toml and c == "'"):
            quote = text[i : i + 3] if toml and text[i : i + 3] in ('"""', "'''") else c
            i += len(quote)
            while i < n and not text.startswith(quote, i):
                i += 2 if text[i] == "\\" and c == '"' else 1
            i += len(quote)
            continue
        elif toml and c == "#":
            j = text.find("\n", i)
            i = n if j < 0 else j
            continue
        i += 1
    return top


def _finite_float(token: str) -> float:
    v = float(token)
    if not math.isfinite(v):
        raise ValueError(f"number {token[:30]} overflows a float")
    return v


def _no_constant(token: str) -> Any:
    raise ValueError(f"{token} is not a JSON number (non-finite values are written as null)")


def loads_json(data: bytes, source: str) -> Any:
    """Parse untrusted JSON bytes within the module's limits; FormatError naming ``source``.

    Refused: more than :data:`MAX_JSON_BYTES`, non-UTF-8 text, nesting deeper than
    :data:`MAX_NESTING`, ``NaN`` / ``Infinity`` tokens, numbers that overflow a float, integers
    with more digits than Python converts, duplicate keys in an object.
    """
    if len(data) > MAX_JSON_BYTES:
        raise FormatError(f"{source}: {len(data)} bytes of JSON, more than {MAX_JSON_BYTES}")
    text = decode_utf8(data, source)
    if nesting_depth(text) > MAX_NESTING:
        raise FormatError(f"{source}: JSON nested deeper than {MAX_NESTING} levels")

    def pairs(items: list[tuple[str, Any]]) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for k, v in items:
            if k in out:
                raise ValueError(f"duplicate key {k[:40]!r}")
            out[k] = v
        return out

    try:
        return json.loads(
            text, parse_float=_finite_float, parse_constant=_no_constant, object_pairs_hook=pairs
        )
    except json.JSONDecodeError as exc:
        raise FormatError(f"{source}: not JSON ({exc.msg} at line {exc.lineno})") from None
    except (ValueError, RecursionError) as exc:
        raise FormatError(f"{source}: not acceptable JSON ({exc})") from None


def read_json(path: str | os.PathLike[str]) -> Any:
    """Read and parse an untrusted JSON file with :func:`loads_json`."""
    source = os.fspath(path)
    try:
        with open(path, "rb") as fh:
            data = fh.read(MAX_JSON_BYTES + 1)
    except OSError as exc:
        raise FormatError(f"{source}: cannot read ({exc.strerror or exc})") from None
    return loads_json(data, source)


def loads_toml(
    data: bytes | str, source: str, error: type[GonioError] = FormatError
) -> dict[str, Any]:
    """Parse untrusted TOML within the module's limits; ``error`` (a GonioError) otherwise.

    Refused: more than :data:`MAX_TOML_BYTES`, non-UTF-8 text, nesting deeper than
    :data:`MAX_NESTING`, invalid TOML, integers with more digits than Python converts.
    ``nan`` and ``inf`` are valid TOML and are left to the caller's range checks, which must
    name the key.
    """
    raw = data.encode("utf-8", "surrogatepass") if isinstance(data, str) else data
    if len(raw) > MAX_TOML_BYTES:
        raise error(f"{source}: {len(raw)} bytes of TOML, more than {MAX_TOML_BYTES}")
    text = data if isinstance(data, str) else decode_utf8(data, source, error)
    if nesting_depth(text, toml=True) > MAX_NESTING:
        raise error(f"{source}: TOML nested deeper than {MAX_NESTING} levels")
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{source}: invalid TOML: {exc}") from None
    except RecursionError:
        raise error(f"{source}: TOML nested too deeply") from None
    except ValueError:
        # tomllib converts integers with int(), which refuses more than
        # sys.get_int_max_str_digits() digits (4300): no count or angle has that many
        limit = sys.get_int_max_str_digits()
        raise error(f"{source}: invalid TOML: an integer of more than {limit} digits") from None


def bad_number_path(
    tree: Any, prefix: str = "", limit: float = math.inf, tiny: float = 0.0
) -> str | None:
    """Dotted path of the first bad number in a parsed JSON/TOML tree, else None.

    Bad: a NaN or infinite float.

    With ``limit``, a number (float or integer) whose magnitude exceeds it counts as well; with
    ``tiny``, a non-zero float whose magnitude is below it.
    """
    stack: list[tuple[str, Any]] = [(prefix, tree)]
    while stack:
        where, node = stack.pop()
        if isinstance(node, float) and not math.isfinite(node):
            return where or "<root>"
        if isinstance(node, int | float) and not isinstance(node, bool) and abs(node) > limit:
            return where or "<root>"
        if isinstance(node, float) and 0.0 < abs(node) < tiny:
            return where or "<root>"
        if isinstance(node, dict):
            stack += [(f"{where}.{k}" if where else str(k), v) for k, v in node.items()]
        elif isinstance(node, list):
            stack += [(f"{where}[{i}]", v) for i, v in enumerate(node)]
    return None
