"""OpenPBR Surface in MaterialX: an ``.mtlx`` document with ``open_pbr_surface`` shaders.

Mapping (exact under the OpenPBR specification's definitions): a Lambert term -> an
``open_pbr_surface`` with ``base_color`` = albedo, ``base_weight`` 1, ``base_metalness`` 0,
``base_diffuse_roughness`` 0 (Lambert) and ``specular_weight`` 0 (no dielectric layer above it);
a Torrance-Sparrow lobe with GGX, Smith shadowing and Schlick Fresnel -> ``base_metalness`` 1
with ``base_color`` = f0 and the F82 tint ``specular_color`` white (which reduces OpenPBR's
F82-tint metal Fresnel to Schlick's), ``specular_weight`` 1, ``specular_roughness`` =
sqrt(alpha) (OpenPBR squares it); a sum of both -> a MaterialX ``mix`` of the two shaders,
``mix * fg + (1 - mix) * bg``, which is exact only in the form ``(1 - m) Lambert + m TS``:
OpenPBR's own dielectric base layers the diffuse under the specular with energy conservation,
which gonio's sum does not do, so it is not used. Refitted: every other model, including an
unscaled sum, to ``0.5 Lambert + 0.5 TorranceSparrow(ggx, smith, Schlick(f0))``.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from typing import Any

from gonio.export._common import Export, family_name, fmt, mix_amount, rgb, template
from gonio.export._lobes import Lobes

TARGET = "openpbr"
TITLE = "OpenPBR/MaterialX"
SUFFIXES = (".mtlx",)
#: Entry of ``gonio export --help``: what is written, [families expressed exactly], mapping.
HELP = """\
MaterialX document with open_pbr_surface shaders (.mtlx).
[Lambert, TorranceSparrow(ggx, smith, Schlick), (1-m) Lambert + m TS]
diffuse: base_color = albedo, specular_weight 0; metal: base_metalness 1,
base_color = f0, specular_color (F82 tint) white, specular_roughness = sqrt(alpha);
a sum is a MaterialX mix of the two with mix = m.
"""
FAMILY = "Lambert, TorranceSparrow(ggx, smith, Schlick), or (1 - m) Lambert + m TS"
MIX = 0.5
MTLX_VERSION = "1.39"


def check(lobes: Lobes) -> str | None:
    """None when the OpenPBR document expresses ``lobes`` exactly, else the reason."""
    sp = lobes.specular
    if lobes.diffuse is not None and (lobes.diffuse > 1).any():
        return "a diffuse albedo above 1"
    if sp is None:
        return None if lobes.diffuse_scale is None else "a scaled diffuse term"
    if sp.distribution != "ggx":
        return f"the {sp.distribution} distribution (OpenPBR is GGX)"
    if sp.shadowing != "smith":
        return f"{sp.shadowing} shadowing (OpenPBR's GGX uses Smith's)"
    if sp.fresnel != "schlick":
        return f"{sp.fresnel} Fresnel (an OpenPBR metal is F82-tint Schlick)"
    if lobes.diffuse is None:
        return None if sp.scale is None else "a scaled microfacet lobe"
    if mix_amount(lobes) is None:
        return "a diffuse + specular sum not of the form (1 - m) Lambert + m TS"
    return None


def refit_template(model: Any, lobes: Lobes | None) -> tuple[Any, dict[str, Any], str]:
    """0.5 Lambert + 0.5 TS(ggx, smith, Schlick) started from ``model``."""
    from gonio.brdf import models  # JAX: imported when a refit is built

    tmpl, fixed = template(model, "ggx", models.Schlick(0.04), scales=(1 - MIX, MIX))
    return tmpl, fixed, f"{1 - MIX:g} Lambert + {MIX:g} TorranceSparrow(ggx, smith, Schlick)"


def _input(el: ET.Element, name: str, kind: str, value: Any) -> None:
    text = ", ".join(fmt(x) for x in value) if isinstance(value, list) else fmt(value)
    ET.SubElement(el, "input", {"name": name, "type": kind, "value": text})


def _shader(doc: ET.Element, name: str, inputs: dict[str, Any]) -> None:
    el = ET.SubElement(doc, "open_pbr_surface", {"name": name, "type": "surfaceshader"})
    for key, value in inputs.items():
        _input(el, key, "color3" if isinstance(value, list) else "float", value)


def build(name: str, lobes: Lobes) -> Export:
    """The ``.mtlx`` document of representable ``lobes``."""
    doc = ET.Element("materialx", {"version": MTLX_VERSION, "colorspace": "lin_rec709"})
    doc.append(ET.Comment(f" gonio export: {name} for OpenPBR ({family_name(lobes)}) "))
    params: dict[str, Any] = {}
    shaders = []
    if lobes.diffuse is not None:
        p = {
            "base_weight": 1.0,
            "base_color": rgb(lobes.diffuse),
            "base_metalness": 0.0,
            "base_diffuse_roughness": 0.0,
            "specular_weight": 0.0,
        }
        shaders.append((f"{name}_diffuse", p))
    sp = lobes.specular
    if sp is not None:
        p = {
            "base_weight": 1.0,
            "base_color": rgb(sp.f0),
            "base_metalness": 1.0,
            "specular_weight": 1.0,
            "specular_color": [1.0, 1.0, 1.0],
            "specular_roughness": float(sp.alpha) ** 0.5,
        }
        shaders.append((f"{name}_metal", p))
    for sname, p in shaders:
        _shader(doc, sname, p)
        params[sname] = p
    top = shaders[0][0]
    if len(shaders) == 2:
        m = mix_amount(lobes)
        assert m is not None
        mix = ET.SubElement(doc, "mix", {"name": f"{name}_mix", "type": "surfaceshader"})
        ET.SubElement(
            mix, "input", {"name": "fg", "type": "surfaceshader", "nodename": shaders[1][0]}
        )
        ET.SubElement(
            mix, "input", {"name": "bg", "type": "surfaceshader", "nodename": shaders[0][0]}
        )
        _input(mix, "mix", "float", m)
        params[f"{name}_mix"] = {"mix": m}
        top = f"{name}_mix"
    mat = ET.SubElement(doc, "surfacematerial", {"name": name, "type": "material"})
    ET.SubElement(mat, "input", {"name": "surfaceshader", "type": "surfaceshader", "nodename": top})
    ET.indent(doc)
    text = '<?xml version="1.0"?>\n' + ET.tostring(doc, encoding="unicode") + "\n"
    notes = ["specular_roughness = sqrt(alpha); OpenPBR leaves the exact Smith form to the "
             "renderer (gonio's is height-correlated)"]  # fmt: skip
    return Export(TARGET, name, {".mtlx": text}, "exact", family_name(lobes), params, notes=notes)
