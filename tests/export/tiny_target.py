"""A tiny export target defined outside gonio: one module, registered by one registry line.

It writes a Lambertian fit as one line of text, ``albedo R G B``; anything else is refitted to
a Lambert term. tests/export/test_registry.py shows the command line and the Python API pick it
up without any other file naming it."""

from __future__ import annotations

from typing import Any

from gonio.export import Export

TARGET = "tiny"
TITLE = "Tiny text"
SUFFIXES = (".tiny",)
HELP = """\
one line of text, albedo R G B (.tiny).
[Lambert]
albedo = albedo."""


def check(lobes: Any) -> str | None:
    """None for a Lambert term alone."""
    return "a microfacet lobe" if lobes.specular is not None else None


def refit_template(model: Any, lobes: Any) -> tuple[Any, dict[str, Any], str]:
    """A Lambert term."""
    from gonio.brdf import models

    return models.Lambert(albedo=0.5), {}, "Lambert"


def build(name: str, lobes: Any) -> Export:
    """``albedo R G B`` of a Lambert term."""
    albedo = [float(x) for x in lobes.diffuse]
    text = "albedo " + " ".join(f"{x:.6g}" for x in albedo) + "\n"
    return Export(TARGET, name, {".tiny": text}, "exact", "Lambert", {"albedo": albedo})
