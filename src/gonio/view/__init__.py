"""``gonio view``: look at measurements and fits in the browser (one self-contained page).

>>> import gonio.view
>>> gonio.view("material.binary", "fit.json")      # in Jupyter: the page inline
>>> gonio.view.build(t, "fit.json").save("view.html")

The package itself is callable (``gonio.view(obj, ...)`` is :func:`view`). Inputs are paths
(anything ``gonio view`` reads) or objects (anything :func:`gonio.io.load` returns, a model).
See docs/guide/viewing.md.
"""

from __future__ import annotations

import html
import os
import sys
import types
from pathlib import Path
from typing import Any

__all__ = ["ViewPage", "build", "view"]


class ViewPage:
    """A built page: ``save(path)`` writes it (atomically); in Jupyter it shows itself inline
    (an iframe holding the page, ``_repr_html_``)."""

    def __init__(self, text: str, height: int = 900) -> None:
        self.text = text
        self.height = height

    def save(self, path: str | os.PathLike[str]) -> Path:
        from gonio.io.atomic import atomic_output

        out = Path(path)
        with atomic_output(out, ".html") as tmp:
            tmp.write_text(self.text, encoding="utf-8")
        return out

    def _repr_html_(self) -> str:
        return (
            f'<iframe srcdoc="{html.escape(self.text, quote=True)}" style="width:100%;'
            f'height:{self.height}px;border:0" sandbox="allow-scripts"></iframe>'
        )


def build(*inputs: Any, labels: list[str] | None = None) -> ViewPage:
    """Build the page of ``inputs`` (paths or objects); ``labels`` name objects."""
    from gonio.view.page import build_page
    from gonio.view.sources import from_object, from_path, unique_labels

    sources = []
    for k, obj in enumerate(inputs):
        if isinstance(obj, str | os.PathLike):
            sources.append(from_path(obj))
        else:
            name = labels[k] if labels and k < len(labels) else type(obj).__name__
            sources.append(from_object(obj, name))
    unique_labels(sources)
    return ViewPage(build_page(sources))


def view(*inputs: Any, labels: list[str] | None = None) -> ViewPage:
    """The page of ``inputs``, shown inline when it is a notebook cell's value."""
    return build(*inputs, labels=labels)


class _CallableModule(types.ModuleType):
    def __call__(self, *inputs: Any, labels: list[str] | None = None) -> ViewPage:
        return view(*inputs, labels=labels)


sys.modules[__name__].__class__ = _CallableModule
