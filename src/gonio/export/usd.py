"""USD: a ``.usda`` layer with a ``Material`` whose surface is a ``UsdPreviewSurface``.

Mapping (the UsdPreviewSurface specification's specular workflow: GGX with
``roughness`` = sqrt(alpha), Schlick Fresnel from ``specularColor`` at normal incidence to white
at grazing, and a Lambertian ``diffuseColor``): ``useSpecularWorkflow`` 1, ``diffuseColor`` =
albedo, ``specularColor`` = f0, ``roughness`` = sqrt(alpha), ``metallic`` 0, ``opacity`` 1,
``ior`` 1.5 (unused by an opaque surface). The specification does not say how a renderer
combines the two lobes; gonio writes the additive reading ``f = diffuseColor / pi + GGX``, and
a renderer that weights the diffuse by ``1 - F`` darkens it by at most ``F``. Its specular edge
colour is always white, so a Lambert-only fit has no exact preview surface. Refitted: every
other model to Lambert + TorranceSparrow(ggx, smith, Schlick(f0)).
"""

from __future__ import annotations

from typing import Any

from gonio.export._common import Export, family_name, fmt, rgb, template
from gonio.export._lobes import Lobes

TARGET = "usd"
TITLE = "USD"
SUFFIXES = (".usda",)
#: Entry of ``gonio export --help``: what is written, [families expressed exactly], mapping.
HELP = """\
USD layer with a UsdPreviewSurface material (.usda).
[Lambert + TorranceSparrow(ggx, smith, Schlick)]
useSpecularWorkflow 1, diffuseColor = albedo, specularColor = f0,
roughness = sqrt(alpha); read additively (the spec leaves the coupling open).
"""
FAMILY = "Lambert + TorranceSparrow(ggx, smith, Schlick)"
ADDITIVE_NOTE = (
    "UsdPreviewSurface does not define how diffuse and specular combine; these values read "
    "additively (diffuseColor / pi + GGX Schlick(specularColor)); a renderer weighting the "
    "diffuse by (1 - F) darkens it by at most F"
)


def check(lobes: Lobes) -> str | None:
    """None when the preview surface expresses ``lobes`` exactly, else the reason."""
    sp = lobes.specular
    if sp is None:
        return "no specular lobe (a preview surface always has a Schlick lobe, white at grazing)"
    if lobes.diffuse_scale is not None or sp.scale is not None:
        return "a scaled lobe"
    if sp.distribution != "ggx":
        return f"the {sp.distribution} distribution (UsdPreviewSurface is GGX)"
    if sp.shadowing != "smith":
        return f"{sp.shadowing} shadowing"
    if sp.fresnel != "schlick":
        return f"{sp.fresnel} Fresnel (UsdPreviewSurface's specular workflow is Schlick's)"
    return None


def refit_template(model: Any, lobes: Lobes | None) -> tuple[Any, dict[str, Any], str]:
    """Lambert + TS(ggx, smith, Schlick) started from ``model``."""
    from gonio.brdf import models  # JAX: imported when a refit is built

    tmpl, fixed = template(model, "ggx", models.Schlick(0.04))
    return tmpl, fixed, "Lambert + TorranceSparrow(ggx, smith, Schlick)"


def _c3(v: list[float]) -> str:
    return "(" + ", ".join(fmt(x) for x in v) + ")"


def build(name: str, lobes: Lobes) -> Export:
    """The ``.usda`` layer of representable ``lobes``."""
    sp = lobes.specular
    assert sp is not None
    params: dict[str, Any] = {
        "useSpecularWorkflow": 1,
        "diffuseColor": rgb(lobes.diffuse),
        "specularColor": rgb(sp.f0),
        "roughness": float(sp.alpha) ** 0.5,
        "metallic": 0.0,
        "opacity": 1.0,
        "ior": 1.5,
    }
    text = f"""#usda 1.0
(
    doc = "gonio export: {name} ({family_name(lobes)}); roughness = sqrt(alpha)"
    defaultPrim = "{name}"
)

def Material "{name}"
{{
    token outputs:surface.connect = </{name}/PreviewSurface.outputs:surface>

    def Shader "PreviewSurface"
    {{
        uniform token info:id = "UsdPreviewSurface"
        int inputs:useSpecularWorkflow = 1
        color3f inputs:diffuseColor = {_c3(params["diffuseColor"])}
        color3f inputs:specularColor = {_c3(params["specularColor"])}
        float inputs:roughness = {fmt(params["roughness"])}
        float inputs:metallic = 0
        float inputs:opacity = 1
        float inputs:ior = 1.5
        token outputs:surface
    }}
}}
"""
    return Export(TARGET, name, {".usda": text}, "exact", family_name(lobes), params,
                  notes=[ADDITIVE_NOTE])  # fmt: skip
