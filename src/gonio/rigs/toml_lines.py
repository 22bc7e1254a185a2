"""Where a key is in a TOML file, and numbers TOML allows that gonio does not.

:mod:`tomllib` reports no positions; :func:`key_line` finds the line of a key by scanning the
text, so that an error in a rig or plan file names ``file:LINE: dotted.key``.
"""

from __future__ import annotations

import math
import re
from typing import Any


def key_line(text: str, path: tuple) -> int | None:
    """Best-effort line number (1-based) of the key at ``path`` in TOML ``text``.

    tomllib reports no positions, so we scan: the line of the deepest key of ``path`` that
    appears after its enclosing table header (``[a.b]`` or the n-th ``[[a]]``).
    """
    lines = text.splitlines()
    keys = [k for k in path if isinstance(k, str)]
    if not keys:
        return None
    # locate the enclosing table header
    start, end = 0, len(lines)
    idx_in_array = None
    table_keys: list[str] = []
    for i, k in enumerate(path):
        if isinstance(k, int):
            idx_in_array = k
            table_keys = [x for x in path[:i] if isinstance(x, str)]
            break
    header_re = re.compile(r"^\s*\[\[?\s*([^\]]+?)\s*\]\]?")
    if idx_in_array is not None:
        name = ".".join(table_keys)
        count = -1
        for n, line in enumerate(lines):
            m = re.match(r"^\s*\[\[\s*" + re.escape(name) + r"\s*\]\]", line)
            if m:
                count += 1
                if count == idx_in_array:
                    start = n
                    break
        else:
            # no [[name]] tables: an inline array value, whose key line is the answer
            cut = path.index(idx_in_array)
            return key_line(text, path[:cut]) if cut else None
        # end at the next header
        for n in range(start + 1, len(lines)):
            if header_re.match(lines[n]):
                end = n
                break
        rest = [x for x in path[path.index(idx_in_array) + 1 :] if isinstance(x, str)]
        target = rest[-1] if rest else None
        if target is None:
            return start + 1
    else:
        target = keys[-1]
        parents = keys[:-1]
        for depth in range(len(parents), 0, -1):
            name = ".".join(parents[:depth])
            for n, line in enumerate(lines):
                if re.match(r"^\s*\[\s*" + re.escape(name) + r"\s*\]", line):
                    start = n
                    for m2 in range(n + 1, len(lines)):
                        if header_re.match(lines[m2]):
                            end = m2
                            break
                    break
            else:
                continue
            break
    pat = re.compile(r"^\s*(?:[A-Za-z0-9_.\"-]*\.)?\"?" + re.escape(str(target)) + r"\"?\s*=")
    for n in range(start, end):
        if pat.match(lines[n]) or re.search(
            r"[{,]\s*" + re.escape(str(target)) + r"\s*=", lines[n]
        ):
            return n + 1
    hdr = re.compile(r"^\s*\[\[?\s*" + re.escape(".".join(keys)) + r"\s*\]\]?")
    for n, line in enumerate(lines):
        if hdr.match(line):
            return n + 1
    return start + 1 if start else None


def where(source: str, text: str, path: tuple) -> str:
    """``source:LINE: dotted.key`` of the key at ``path`` in TOML ``text`` (for one-line errors)."""
    dotted = ".".join(f"[{k}]" if isinstance(k, int) else str(k) for k in path).replace(".[", "[")
    line = key_line(text, path)
    loc = f"{source}:{line}" if line else source
    return f"{loc}: {dotted or '(top level)'}"


def non_finite(data: Any, path: tuple = ()):
    """Yield ``(path, value)`` of every NaN or infinite float in parsed TOML ``data``."""
    if isinstance(data, float):
        if not math.isfinite(data):
            yield path, data
    elif isinstance(data, dict):
        for k, v in data.items():
            yield from non_finite(v, (*path, k))
    elif isinstance(data, list):
        for i, v in enumerate(data):
            yield from non_finite(v, (*path, i))
