"""Blender: a Python script that builds the material's node tree through ``bpy``.

Run it with ``blender --python FILE.py`` (or ``exec`` it where ``import bpy`` works, e.g. the
``bpy`` module); it creates (or rebuilds) the material named in ``MATERIAL`` and returns it from
``build()``. Nothing else in the scene is touched.

Mapping (exact, for Cycles and EEVEE's Principled BSDF with the single-scattering ``GGX``
distribution): the specular lobe -> Principled BSDF with Roughness = sqrt(alpha) (Blender
squares it); a Schlick Fresnel term -> Metallic 1, Base Color = f0, Specular Tint white (the
F82-tint model with a white tint is Schlick's formula); a Dielectric(eta) term with one eta for
every channel -> Metallic 0, Base Color black, IOR = eta, Specular IOR Level 0.5 (no
adjustment); a Conductor(eta, k) term, or a Beckmann lobe with Schlick Fresnel -> a Metallic BSDF
node (Blender 4.3 or later: the script refuses to run on older ones) with the fitted
distribution, Roughness = sqrt(alpha) and Fresnel type Physical Conductor (IOR = eta,
Extinction = k) or F82 (Base Color = f0, Edge Tint white: Schlick's formula); the diffuse term ->
a Diffuse BSDF (Roughness 0: Lambert) with Color = albedo,
added to the Principled BSDF by an Add Shader (the Principled BSDF's own base layer would
darken the diffuse by the specular albedo, which gonio's sum does not). Refitted: every other
model to Lambert + TorranceSparrow(ggx, smith, Schlick(f0)). Cycles' microfacet lobes use the
height-correlated Smith term, as gonio's.
"""

from __future__ import annotations

from typing import Any

from gonio.export._common import Export, family_name, fmt, rgb, template, uniform
from gonio.export._lobes import Lobes

TARGET = "blender"
TITLE = "Blender"
SUFFIXES = (".py",)
#: Entry of ``gonio export --help``: what is written, [families expressed exactly], mapping.
HELP = """\
Python script building the node tree with bpy (.py): blender --python FILE.py.
[Lambert + TorranceSparrow(ggx, smith, Schlick|Dielectric|Conductor), TS(beckmann, smith,
Schlick|Conductor)]
Diffuse BSDF (Color = albedo, Roughness 0) + Principled BSDF (distribution GGX,
Roughness = sqrt(alpha); Schlick: Metallic 1, Base Color = f0, Specular Tint white;
Dielectric: Metallic 0, Base Color black, IOR = eta) joined by an Add Shader;
Conductor or Beckmann: Metallic BSDF node (Blender >= 4.3), Physical Conductor
(IOR = eta, Extinction = k) or F82 (Base Color = f0, Edge Tint white).
"""
FAMILY = "Lambert + TorranceSparrow(ggx|beckmann, smith, Schlick | Dielectric | Conductor)"
#: Blender version that added the Metallic BSDF node.
METALLIC_NODE = (4, 3)


def check(lobes: Lobes) -> str | None:
    """None when the Blender node tree expresses ``lobes`` exactly, else the reason."""
    if lobes.diffuse_scale is not None:
        return "a scaled diffuse term"
    sp = lobes.specular
    if sp is None:
        return None
    if sp.distribution not in ("ggx", "beckmann"):
        return f"the {sp.distribution} distribution (Cycles has GGX and Beckmann)"
    if sp.distribution == "beckmann" and sp.fresnel == "dielectric":
        return "Beckmann with dielectric Fresnel (the Principled BSDF is GGX)"
    if sp.shadowing != "smith":
        return f"{sp.shadowing} shadowing (Cycles' microfacet lobes use Smith's)"
    if sp.scale is not None:
        return "a scaled microfacet lobe"
    if sp.fresnel == "dielectric" and uniform(sp.eta) is None:
        return "a per-channel index of refraction (the Principled IOR is one number)"
    if sp.fresnel not in ("schlick", "dielectric", "conductor"):
        return f"{sp.fresnel} Fresnel (Cycles has Schlick/F82, dielectric and conductor)"
    return None


def _metallic_node(lobes: Lobes) -> bool:
    """Whether the lobe needs the Metallic BSDF node (a conductor, or Beckmann)."""
    sp = lobes.specular
    return sp is not None and (sp.fresnel == "conductor" or sp.distribution == "beckmann")


def refit_template(model: Any, lobes: Lobes | None) -> tuple[Any, dict[str, Any], str]:
    """Lambert + TS(ggx, smith, Schlick) started from ``model``."""
    from gonio.brdf import models  # JAX: imported when a refit is built

    tmpl, fixed = template(model, "ggx", models.Schlick(0.04))
    return tmpl, fixed, "Lambert + TorranceSparrow(ggx, smith, Schlick)"


def _color(v: list[float]) -> str:
    return "(" + ", ".join(fmt(x) for x in v) + ", 1.0)"


def _vec3(v: list[float]) -> str:
    return "(" + ", ".join(fmt(x) for x in v) + ")"


def build(name: str, lobes: Lobes) -> Export:
    """The Blender script of representable ``lobes``."""
    sp = lobes.specular
    params: dict[str, Any] = {}
    body = [
        "    nodes = mat.node_tree.nodes",
        "    links = mat.node_tree.links",
        "    nodes.clear()",
        '    out = nodes.new("ShaderNodeOutputMaterial")',
        "    out.location = (400, 0)",
        "    shaders = []",
    ]
    if lobes.diffuse is not None:
        col = rgb(lobes.diffuse)
        params["Diffuse BSDF"] = {"Color": col, "Roughness": 0.0}
        body += [
            '    diffuse = nodes.new("ShaderNodeBsdfDiffuse")',
            "    diffuse.location = (-300, 200)",
            f'    diffuse.inputs["Color"].default_value = {_color(col)}',
            '    diffuse.inputs["Roughness"].default_value = 0.0  # Lambert',
            "    shaders.append(diffuse)",
        ]
    if sp is not None and _metallic_node(lobes):
        rough = float(sp.alpha) ** 0.5
        dist = sp.distribution.upper()
        m: dict[str, Any] = {"distribution": dist, "Roughness": rough}
        body += [
            f"    if bpy.app.version < {METALLIC_NODE}:",
            "        raise RuntimeError('this material needs Blender 4.3 or later (Metallic BSDF')",
            '    metal = nodes.new("ShaderNodeBsdfMetallic")',
            "    metal.location = (-300, -200)",
            f'    metal.distribution = "{dist}"  # single scattering, as the fitted lobe',
            f'    metal.inputs["Roughness"].default_value = {fmt(rough)}  # sqrt(alpha)',
        ]
        if sp.fresnel == "conductor":
            eta, k = rgb(sp.eta), rgb(sp.k)
            m.update({"fresnel_type": "PHYSICAL_CONDUCTOR", "IOR": eta, "Extinction": k})
            body += [
                '    metal.fresnel_type = "PHYSICAL_CONDUCTOR"',
                f'    metal.inputs["IOR"].default_value = {_vec3(eta)}',
                f'    metal.inputs["Extinction"].default_value = {_vec3(k)}',
            ]
        else:
            f0 = rgb(sp.f0)
            m.update({"fresnel_type": "F82", "Base Color": f0, "Edge Tint": [1.0, 1.0, 1.0]})
            body += [
                '    metal.fresnel_type = "F82"',
                f'    metal.inputs["Base Color"].default_value = {_color(f0)}  # Schlick f0',
                '    metal.inputs["Edge Tint"].default_value = (1.0, 1.0, 1.0, 1.0)',
            ]
        body.append("    shaders.append(metal)")
        params["Metallic BSDF"] = m
    elif sp is not None:
        rough = float(sp.alpha) ** 0.5
        p: dict[str, Any] = {"distribution": "GGX", "Roughness": rough}
        body += [
            '    bsdf = nodes.new("ShaderNodeBsdfPrincipled")',
            "    bsdf.location = (-300, -200)",
            '    bsdf.distribution = "GGX"  # single scattering, as the fitted lobe',
            f'    bsdf.inputs["Roughness"].default_value = {fmt(rough)}  # sqrt(alpha)',
        ]
        if sp.fresnel == "schlick":
            f0 = rgb(sp.f0)
            p.update({"Metallic": 1.0, "Base Color": f0, "Specular Tint": [1.0, 1.0, 1.0]})
            body += [
                '    bsdf.inputs["Metallic"].default_value = 1.0',
                f'    bsdf.inputs["Base Color"].default_value = {_color(f0)}  # Schlick f0',
                '    bsdf.inputs["Specular Tint"].default_value = (1.0, 1.0, 1.0, 1.0)',
            ]
        else:
            eta = uniform(sp.eta)
            assert eta is not None
            p.update({"Metallic": 0.0, "Base Color": [0.0, 0.0, 0.0], "IOR": eta,
                      "Specular IOR Level": 0.5})  # fmt: skip
            body += [
                '    bsdf.inputs["Metallic"].default_value = 0.0',
                '    bsdf.inputs["Base Color"].default_value = (0.0, 0.0, 0.0, 1.0)',
                f'    bsdf.inputs["IOR"].default_value = {fmt(eta)}',
                '    bsdf.inputs["Specular IOR Level"].default_value = 0.5',
            ]
        body += [
            '    for key in ("Coat Weight", "Sheen Weight", "Transmission Weight",',
            '                "Subsurface Weight", "Emission Strength", "Thin Film Thickness"):',
            "        if key in bsdf.inputs:",
            "            bsdf.inputs[key].default_value = 0.0",
            "    shaders.append(bsdf)",
        ]
        params["Principled BSDF"] = p
    body += [
        "    if len(shaders) == 2:",
        '        add = nodes.new("ShaderNodeAddShader")',
        "        links.new(shaders[0].outputs[0], add.inputs[0])",
        "        links.new(shaders[1].outputs[0], add.inputs[1])",
        "        shaders = [add]",
        '    links.new(shaders[0].outputs[0], out.inputs["Surface"])',
        "    return mat",
    ]
    text = "\n".join(
        [
            f'"""gonio export: material {name!r} for Blender ({family_name(lobes)}).',
            "",
            "Run with `blender --python THIS_FILE` or exec it where `import bpy` works; build()",
            "creates or rebuilds the material and returns it. Roughness = sqrt(gonio alpha).",
            '"""',
            "",
            "import bpy",
            "",
            f"MATERIAL = {name!r}",
            "",
            "",
            "def build(name=MATERIAL):",
            "    mat = bpy.data.materials.get(name) or bpy.data.materials.new(name)",
            "    mat.use_nodes = True",
            *body,
            "",
            "",
            "material = build()",
            "",
        ]
    )
    notes = ["Roughness = sqrt(alpha); keep the Principled distribution GGX (Multiscatter GGX "
             "adds energy the fit does not have)"]  # fmt: skip
    return Export(TARGET, name, {".py": text}, "exact", family_name(lobes), params, notes=notes)
