"""Renderer-ready materials from fits: Mitsuba 3, pbrt-v4, Blender, OpenPBR/MaterialX, USD.

>>> from gonio import export
>>> e = export.to_mitsuba("fits/lambert-ts.json")
>>> e.mapping, e.params, e.write("material.xml")

Each target lives in its own module, listed once in :mod:`gonio.export.registry`
(:mod:`~gonio.export.mitsuba`, :mod:`~gonio.export.pbrt`, ...), whose docstring states its
parameter mapping and what it refits; ``to_<target>`` exists for every registered target. A fit
the target expresses exactly is written unchanged (``mapping == "exact"``); otherwise the
target's family is refitted to the fit's data with :func:`gonio.fit.fit` and the refit's loss is
reported next to the original's (``mapping == "refit"``, ``Export.refit``).
"""

from importlib import import_module
from typing import Any

_API = ("REFIT_FROM", "export")


def __getattr__(name: str) -> Any:
    # Lazy: ``gonio export --help`` (which imports gonio.export.cli) must not load JAX. The
    # submodules are imported by name: ``from gonio.export import x`` asks this function first.
    if name in _API:
        return getattr(import_module("gonio.export._api"), name)
    if name == "Export":
        return import_module("gonio.export._common").Export
    if name == "registry" or (name.startswith("_") and name != "__all__"):
        raise AttributeError(f"module 'gonio.export' has no attribute {name!r}")
    registry = import_module("gonio.export.registry")
    if name == "TARGETS":
        return registry.targets()
    if name.startswith("to_") and name[3:] in registry.names():
        return import_module("gonio.export._api").to_target(name[3:])
    if name == "__all__":
        return ["Export", "TARGETS", *_API, *(f"to_{n}" for n in registry.names())]
    raise AttributeError(f"module 'gonio.export' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), *__getattr__("__all__")})
