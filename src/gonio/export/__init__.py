"""Renderer-ready materials from fits: Mitsuba 3, pbrt-v4, Blender, OpenPBR/MaterialX, USD.

>>> from gonio import export
>>> e = export.to_mitsuba("fits/lambert-ts.json")
>>> e.mapping, e.params, e.write("material.xml")

Each target lives in its own module (:mod:`~gonio.export.mitsuba`, :mod:`~gonio.export.pbrt`,
:mod:`~gonio.export.blender`, :mod:`~gonio.export.openpbr`, :mod:`~gonio.export.usd`), whose
docstring states its parameter mapping and what it refits. A fit the target expresses exactly is
written unchanged (``mapping == "exact"``); otherwise the target's family is refitted to the
fit's data with :func:`gonio.fit.fit` and the refit's loss is reported next to the original's
(``mapping == "refit"``, ``Export.refit``).
"""

from typing import Any

_API = ("REFIT_FROM", "TARGETS", "export", "to_blender", "to_mitsuba", "to_openpbr", "to_pbrt",
        "to_usd")  # fmt: skip

__all__ = ["Export", *_API]


def __getattr__(name: str) -> Any:
    # Lazy: ``gonio export --help`` (which imports gonio.export.cli) must not load JAX.
    if name in _API:
        from gonio.export import _api

        return getattr(_api, name)
    if name == "Export":
        from gonio.export._common import Export

        return Export
    raise AttributeError(f"module 'gonio.export' has no attribute {name!r}")
