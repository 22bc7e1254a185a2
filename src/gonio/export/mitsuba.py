"""Mitsuba 3: a ``load_dict`` dictionary and the equivalent XML ``<bsdf>`` fragment.

Mapping (exact): Lambert -> ``diffuse`` (``reflectance`` = albedo); a Torrance-Sparrow lobe with
Beckmann or GGX and Smith shadowing -> ``roughconductor`` (``distribution`` unchanged,
``alpha`` = gonio's alpha unchanged, ``eta``/``k`` = the Conductor's complex index; a
Dielectric(eta) Fresnel term is the conductor formula with ``k = 0``); a lone GGX/Smith lobe
with Schlick Fresnel -> ``principled`` with ``metallic`` 1, ``base_color`` = f0 and
``roughness`` = sqrt(alpha) (Mitsuba squares it; with metallic 1 its diffuse, sheen and
dielectric parts are weighted 0 and its Fresnel is Schlick's from ``base_color``); a sum ->
``blendbsdf`` (``f = (1 - w) f_0 + w f_1``) with ``w = min(0.5, 1 - max albedo)``, the diffuse
reflectance divided by ``1 - w`` and the conductor's ``specular_reflectance`` = ``1 / w`` (a uniform
spectrum, which Mitsuba accepts above 1). Refitted: other lobes, V-cavity shadowing, Blinn,
Schlick Fresnel next to a diffuse term (``principled`` cannot be scaled inside a ``blendbsdf``
and its own diffuse is Disney's, not Lambert's) or no Fresnel: Lambert + TorranceSparrow(ggx or
beckmann as fitted, smith, Conductor(eta, k)). Not used: ``roughplastic`` (its diffuse part
scatters inside the coating, which no gonio model expresses).

Mitsuba's Smith term is the separable product ``G1(wi) G1(wo)``; gonio's is height-correlated.
They agree at normal incidence and differ toward grazing angles: over the appearance sphere's
pixels under lights at 0, 30 and 60 degrees (Mitsuba's ``BSDF.eval``), 1.1 % relative RMSE for
GGX at alpha 0.4 and 2.2 % at 0.5 (Beckmann 0.1 % at 0.55), so GGX lobes above
:data:`GGX_ALPHA_MAX` are refitted.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from typing import Any

import numpy as np

from gonio.export._common import Export, family_name, fmt, rgb, template, uniform
from gonio.export._lobes import Lobes
from gonio.io.strict_json import dumps_json

TARGET = "mitsuba"
TITLE = "Mitsuba 3"
SUFFIXES = (".xml", ".json")
#: Entry of ``gonio export --help``: what is written, [families expressed exactly], mapping.
HELP = """\
Mitsuba 3 XML <bsdf> fragment (.xml) and its load_dict dictionary (.json).
[Lambert + TorranceSparrow(beckmann|ggx, smith, Conductor|Dielectric), TS(ggx, smith, Schlick)]
diffuse: reflectance = albedo; roughconductor: distribution as fitted,
alpha = alpha (unchanged), eta/k = the conductor's index (k = 0 for Dielectric);
a lone TS(ggx, smith, Schlick): principled, metallic 1, base_color = f0, roughness = sqrt(alpha);
a sum is a blendbsdf of weight w = min(0.5, 1 - max albedo) with reflectance
albedo / (1 - w) and specular_reflectance 1 / w. Mitsuba's Smith term is separable,
gonio's height-correlated: GGX above alpha 0.45 (over 2 % relative RMSE) is refitted.
"""
FAMILY = "Lambert + TorranceSparrow(beckmann|ggx, smith, Conductor(eta, k))"
#: Largest GGX alpha exported as exact: Mitsuba's separable Smith term G1(wi) G1(wo) against
#: gonio's height-correlated one, over the appearance sphere's pixels at 0/30/60 degrees (Mitsuba's
#: BSDF.eval, tests/export/test_table.py): 1.1 % relative RMSE at alpha 0.4, 2.2 % at 0.5
#: (Beckmann: 0.1 % at 0.55).
GGX_ALPHA_MAX = 0.45
SEPARABLE_NOTE = (
    "Mitsuba's Smith shadowing is separable (G1(wi) G1(wo)), gonio's height-correlated: they "
    "differ toward grazing angles (up to 2 % relative RMSE on the sphere for GGX at alpha 0.45)"
)


def check(lobes: Lobes) -> str | None:
    """None when Mitsuba expresses ``lobes`` exactly, else the reason."""
    sp = lobes.specular
    if lobes.diffuse is not None and lobes.diffuse_scale is not None:
        if uniform(lobes.diffuse_scale) is None:
            return "a diffuse term with per-channel scale"
    if sp is None:
        return None
    if sp.distribution not in ("beckmann", "ggx"):
        return f"the {sp.distribution} distribution (Mitsuba has beckmann and ggx)"
    if sp.shadowing != "smith":
        return f"{sp.shadowing} shadowing (Mitsuba's microfacet lobes use Smith's)"
    if sp.distribution == "ggx" and sp.alpha > GGX_ALPHA_MAX:
        return (
            f"GGX alpha {sp.alpha:.3g} > {GGX_ALPHA_MAX}: Mitsuba's separable Smith term differs "
            "from gonio's height-correlated one by more than 2 % there"
        )
    if principled(lobes):
        return None
    if sp.fresnel == "schlick" and lobes.diffuse is not None:
        return (
            "Schlick Fresnel beside a diffuse term (principled's metal cannot be scaled in a "
            "blendbsdf; roughconductor takes a complex index eta, k)"
        )
    if sp.fresnel not in ("conductor", "dielectric"):
        return f"{sp.fresnel} Fresnel (Mitsuba's roughconductor takes a complex index eta, k)"
    if sp.scale is not None and uniform(sp.scale) is None:
        return "a per-channel lobe scale"
    return None


def principled(lobes: Lobes) -> bool:
    """Whether ``lobes`` is a lone GGX/Smith/Schlick lobe: Mitsuba's ``principled`` metal."""
    sp = lobes.specular
    return (
        sp is not None
        and lobes.diffuse is None
        and sp.scale is None
        and (sp.distribution, sp.shadowing, sp.fresnel) == ("ggx", "smith", "schlick")
    )


def refit_template(model: Any, lobes: Lobes | None) -> tuple[Any, dict[str, Any], str]:
    """Lambert + TS(ggx, smith, Conductor) started from ``model``; Beckmann where ``lobes`` are
    Beckmann or GGX rougher than :data:`GGX_ALPHA_MAX` (a GGX refit that ended there is refitted
    as Beckmann, whose Mitsuba evaluation stays within 0.1 % of gonio's at alpha 0.55)."""
    from gonio.brdf import models  # JAX: imported when a refit is built

    sp = lobes.specular if lobes else None
    rough_ggx = sp is not None and sp.distribution == "ggx" and sp.alpha > GGX_ALPHA_MAX
    dist = "beckmann" if sp is not None and (sp.distribution == "beckmann" or rough_ggx) else "ggx"
    tmpl, fixed = template(model, dist, models.Conductor(eta=1.5, k=0.0))
    return tmpl, fixed, f"Lambert + TorranceSparrow({dist}, smith, Conductor)"


def _spectrum(v: list[float]) -> dict[str, Any]:
    return {"type": "rgb", "value": v}


def bsdf_dict(lobes: Lobes) -> tuple[dict[str, Any], dict[str, Any]]:
    """``(load_dict dictionary, target parameters)`` for representable ``lobes``."""
    d_scale = 1.0 if lobes.diffuse_scale is None else uniform(lobes.diffuse_scale) or 1.0
    rho = None if lobes.diffuse is None else np.asarray(rgb(lobes.diffuse)) * d_scale
    sp = lobes.specular
    cond = None
    params: dict[str, Any] = {}
    if principled(lobes):
        assert sp is not None
        f0, rough = rgb(sp.f0), float(sp.alpha) ** 0.5
        params.update(base_color=f0, metallic=1.0, roughness=rough)
        node = {"type": "principled", "base_color": _spectrum(f0), "metallic": 1.0,
                "roughness": rough}  # fmt: skip
        return node, params
    if sp is not None:
        eta = rgb(sp.eta)
        k = rgb(sp.k) if sp.fresnel == "conductor" else [0.0, 0.0, 0.0]
        cond = {
            "type": "roughconductor",
            "distribution": sp.distribution,
            "alpha": float(sp.alpha),
            "eta": _spectrum(eta),
            "k": _spectrum(k),
        }
        params.update(distribution=sp.distribution, alpha=float(sp.alpha), eta=eta, k=k)
        s_scale = 1.0 if sp.scale is None else uniform(sp.scale) or 1.0
    if cond is None:
        assert rho is not None
        params["reflectance"] = rho.tolist()
        return {"type": "diffuse", "reflectance": _spectrum(rho.tolist())}, params
    if rho is None:
        if s_scale != 1.0:
            cond["specular_reflectance"] = {"type": "uniform", "value": s_scale}
            params["specular_reflectance"] = s_scale
        return cond, params
    top = float(np.max(rho))
    w = min(0.5, 1.0 - top)
    if w <= 1e-6:
        from gonio.errors import ParameterError

        raise ParameterError(
            f"diffuse albedo {top:g} leaves no weight for the specular lobe in Mitsuba's blendbsdf"
        )
    refl = (rho / (1.0 - w)).tolist()
    cond["specular_reflectance"] = {"type": "uniform", "value": s_scale / w}
    params.update(
        weight=w, reflectance=refl, specular_reflectance=s_scale / w, diffuse_albedo=rho.tolist()
    )
    blend = {
        "type": "blendbsdf",
        "weight": w,
        "bsdf_0": {"type": "diffuse", "reflectance": _spectrum(refl)},
        "bsdf_1": cond,
    }
    return blend, params


def _xml(node: dict[str, Any], name: str | None = None, bsdf_id: str | None = None) -> ET.Element:
    el = ET.Element("bsdf", {"type": node["type"]})
    if name is not None:
        el.set("name", name)
    if bsdf_id is not None:
        el.set("id", bsdf_id)
    for key, value in node.items():
        if key == "type":
            continue
        if isinstance(value, dict) and value.get("type") == "rgb":
            ET.SubElement(
                el, "rgb", {"name": key, "value": ", ".join(fmt(x) for x in value["value"])}
            )
        elif isinstance(value, dict) and value.get("type") == "uniform":
            ET.SubElement(el, "float", {"name": key, "value": fmt(value["value"])})
        elif isinstance(value, dict):
            el.append(_xml(value, name=key))
        elif isinstance(value, str):
            ET.SubElement(el, "string", {"name": key, "value": value})
        else:
            ET.SubElement(el, "float", {"name": key, "value": fmt(value)})
    return el


def to_xml(bsdf: dict[str, Any], bsdf_id: str, header: str) -> str:
    """The ``<bsdf id=...>`` fragment for ``bsdf`` (include it in a ``<scene>`` and reference it
    with ``<ref id=.../>``)."""
    el = _xml(bsdf, bsdf_id=bsdf_id)
    ET.indent(el)
    return f"<!-- {header} -->\n" + ET.tostring(el, encoding="unicode") + "\n"


def build(name: str, lobes: Lobes) -> Export:
    """The Mitsuba export of representable ``lobes`` (mapping and refit filled in by the
    caller)."""
    bsdf, params = bsdf_dict(lobes)
    header = f"gonio export: {name} for Mitsuba 3 ({family_name(lobes)})"
    files = {
        ".xml": to_xml(bsdf, name, header),
        ".json": dumps_json(bsdf, indent=2, nonfinite="refuse", source=f"{name}.json") + "\n",
    }
    notes = [SEPARABLE_NOTE] if lobes.specular is not None else []
    return Export(TARGET, name, files, "exact", family_name(lobes), params, notes=notes, data=bsdf)
