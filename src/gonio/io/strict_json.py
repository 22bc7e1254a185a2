"""Strict JSON output: the one place gonio turns an object into JSON text or a JSON file.

JSON has no NaN or Infinity (RFC 8259); Python's :mod:`json` writes them anyway, and strict
parsers (``jq``, browsers, :func:`gonio._bounded.loads_json`) refuse the result. Every JSON
gonio prints (``--json`` reports) or writes (fit results, Mitsuba's ``load_dict`` files, a run's
log and internal stores, metadata inside native and EXR files) goes through this module, in one
of two ways:

* ``nonfinite="null"`` (reports, logs, metadata): a NaN or infinite number is written as
  ``null``; when the top level is an object, the dotted paths of those numbers and their values
  (``"NaN"``, ``"Infinity"``, ``"-Infinity"``) are listed under :data:`NONFINITE_KEY`, which is
  the reason a reader finds ``null`` there. In a bare numeric array ``null`` stands for a
  missing (NaN) number, and gonio's readers of such arrays read it back as NaN.
* ``nonfinite="refuse"`` (files whose readers need numbers: fit results, scene descriptions):
  a non-finite number is a :class:`~gonio.errors.FormatError` naming the file and the field, and
  nothing is written.

NumPy scalars and arrays are converted to plain numbers and lists first.

This module imports only :mod:`gonio.errors` and :mod:`gonio.io.atomic`, so every package
may use it.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from gonio.errors import FormatError
from gonio.io.atomic import atomic_output

#: Key under which :func:`dumps_json` lists the non-finite numbers it wrote as null.
NONFINITE_KEY = "nonfinite_as_null"
NONFINITE_POLICIES = ("null", "refuse")


def plain(obj: Any) -> Any:
    """``obj`` with NumPy scalars and arrays as Python numbers and lists (dicts, lists and
    tuples walked); everything else unchanged."""
    if isinstance(obj, dict):
        return {k: plain(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [plain(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return plain(obj.tolist())
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def finite_json(obj: Any, where: str = "") -> tuple[Any, dict[str, str]]:
    """A copy of ``obj`` (dicts, lists and tuples of JSON values, NumPy values converted) whose
    NaN and infinite floats are None, and ``{dotted path: "NaN" | "Infinity" | "-Infinity"}``
    of those replaced."""
    replaced: dict[str, str] = {}

    def walk(node: Any, at: str) -> Any:
        if isinstance(node, np.ndarray | np.generic):
            node = plain(node)
        if isinstance(node, float) and not math.isfinite(node):
            replaced[at or "<root>"] = json.dumps(float(node))
            return None
        if isinstance(node, dict):
            return {k: walk(v, f"{at}.{k}" if at else str(k)) for k, v in node.items()}
        if isinstance(node, list | tuple):
            return [walk(v, f"{at}[{i}]") for i, v in enumerate(node)]
        return node

    return walk(obj, where), replaced


def dumps_json(obj: Any, *, nonfinite: str = "null", source: str = "JSON", **kwargs: Any) -> str:
    """``json.dumps(obj, **kwargs)`` as strict JSON (module docstring); ``allow_nan`` is always
    False.

    Parameters
    ----------
    nonfinite : {"null", "refuse"}
        ``"null"``: non-finite numbers become null, listed under :data:`NONFINITE_KEY` when
        ``obj`` is an object. ``"refuse"``: FormatError ``"<source>: <path> is NaN ..."``.
    source : what the text is for (a file name), named by a refusal.
    """
    if nonfinite not in NONFINITE_POLICIES:
        raise ValueError(f"nonfinite must be one of {NONFINITE_POLICIES}, not {nonfinite!r}")
    kwargs.pop("allow_nan", None)
    clean, replaced = finite_json(obj)
    if replaced:
        if nonfinite == "refuse":
            at, value = next(iter(replaced.items()))
            raise FormatError(
                f"{source}: {at} is {value}; JSON has no NaN or Infinity (nothing written)"
            )
        if isinstance(clean, dict):
            clean = {**clean, NONFINITE_KEY: replaced}
    return json.dumps(clean, allow_nan=False, **kwargs)


def write_json(
    obj: Any, path: str | os.PathLike[str], *, nonfinite: str = "refuse", indent: int | None = 2,
    **kwargs: Any,
) -> Path:  # fmt: skip
    """Write ``obj`` as strict JSON (:func:`dumps_json`) atomically, with a final newline.

    The default ``nonfinite="refuse"`` suits files read as data (a fit result): a NaN or
    infinite number is a FormatError naming the file and the field, and nothing is written.
    """
    path = Path(path)
    text = dumps_json(obj, nonfinite=nonfinite, source=str(path), indent=indent, **kwargs)
    with atomic_output(path, make_parents=True) as tmp:
        tmp.write_text(text + "\n", encoding="utf-8")
    return path
