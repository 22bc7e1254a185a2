"""Validation of an untrusted ``model_spec`` (a model's ``to_dict()`` read from a fit result).

:meth:`Node.from_dict` trusts its input: a missing parameter silently takes the constructor's
default (a Lambert albedo of 0.5 that was never fitted), a ``params`` that is not a mapping raises
a bare ``TypeError``. :func:`check_model_spec` walks the description first and refuses, naming the
field: unknown model types, fields of the wrong type, missing or null parameters, unknown
parameters, and parameter values that are not finite numbers (or nested lists of them).
"""

from __future__ import annotations

import math
from typing import Any

from gonio.errors import FormatError

_MAX_LOBES = 64
_MAX_VALUE_RANK = 3


def _numbers(value: Any, rank: int = 0) -> bool:
    """True for a finite number or a (nested, rectangular or not) non-empty list of them."""
    if isinstance(value, bool):
        return False
    if isinstance(value, int | float):
        return math.isfinite(value)
    if isinstance(value, list) and value and rank < _MAX_VALUE_RANK:
        return all(_numbers(v, rank + 1) for v in value)
    return False


def check_model_spec(spec: Any, source: str, where: str = "model_spec") -> None:
    """Raise :class:`FormatError` ``"<source>: <where>...: <problem>"`` unless ``spec`` is a
    complete, well-typed model description (see the module docstring)."""
    from gonio.brdf.models._base import registry

    def bad(problem: str) -> FormatError:
        return FormatError(f"{source}: {where}: {problem}")

    if not isinstance(spec, dict):
        raise bad("not an object")
    kind = spec.get("type")
    classes = registry()
    if not isinstance(kind, str) or kind not in classes:
        raise bad(f"unknown model type {str(kind)[:40]!r}")
    if kind == "Sum":
        lobes = spec.get("lobes")
        if not isinstance(lobes, list) or not 1 <= len(lobes) <= _MAX_LOBES:
            raise bad(f"a Sum needs 1 to {_MAX_LOBES} lobes")
        for i, lobe in enumerate(lobes):
            check_model_spec(lobe, source, f"{where}.lobes[{i}]")
        return
    cls = classes[kind]
    parts = {}
    for key in ("params", "static", "children"):
        value = spec.get(key, {})
        if not isinstance(value, dict):
            raise bad(f"{key} is not an object")
        parts[key] = value
    params, static, children = parts["params"], parts["static"], parts["children"]
    names = [p.name for p in cls.PARAMS]
    for name in names:
        if params.get(name) is None:
            raise bad(f"parameter {name!r} of {kind} is missing or null")
        if not _numbers(params[name]):
            raise bad(f"parameter {name!r} of {kind} is not a finite number or list of numbers")
    for key, allowed in (("params", names), ("static", cls.STATIC), ("children", cls.CHILDREN)):
        unknown = sorted(set(parts[key]) - set(allowed))
        if unknown:
            raise bad(f"unknown {key} entry {unknown[0][:40]!r} for {kind}")
    for name, value in static.items():
        if value is not None and not isinstance(value, str | int | float | bool):
            raise bad(f"static option {name!r} of {kind} is not a string, number or boolean")
    for name, child in children.items():
        kids = child if isinstance(child, list) else [child]
        for i, c in enumerate(kids):
            if c is not None:
                check_model_spec(c, source, f"{where}.{name}" + (f"[{i}]" if kids is child else ""))
