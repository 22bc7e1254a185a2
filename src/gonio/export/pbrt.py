"""pbrt-v4: a scene-file block of ``MakeNamedMaterial`` statements and the ``NamedMaterial`` that
binds it.

Mapping (exact, up to pbrt's spectral rendering of RGB parameters, which it upsamples to smooth
spectra: ``RGBAlbedoSpectrum`` for reflectances, ``RGBUnboundedSpectrum`` for ``eta`` and ``k``):
Lambert -> ``"diffuse"`` (``"rgb reflectance"`` = albedo); a Torrance-Sparrow lobe with GGX and
Smith shadowing (pbrt's Trowbridge-Reitz with its height-correlated Smith term) ->
``"conductor"`` with ``"rgb eta"``, ``"rgb k"`` (``k = 0`` for a Dielectric Fresnel term),
``"float roughness"`` = gonio's alpha and ``"bool remaproughness" false`` (pbrt's default remap
would take ``roughness = alpha^2``); a sum -> ``"mix"`` of the two with ``"float amount"`` a,
which pbrt evaluates as ``(1 - a) f_diffuse + a f_conductor``; pbrt's conductor has no scale
factor, so a sum is exact only in the form ``(1 - a) Lambert(R) + a TS``. Refitted: every
other model, including an unscaled Lambert + GGX sum, to ``0.5 Lambert(R) + 0.5
TorranceSparrow(ggx, smith, Conductor(eta, k))`` (``R`` <= 1, as pbrt clamps reflectances).
pbrt's ``coateddiffuse`` is not used: it is a layered model evaluated by random walks, with no
closed form that a gonio model (and so a refit) could express.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from gonio.export._common import Export, family_name, fmt, mix_amount, rgb, template
from gonio.export._lobes import Lobes

TARGET = "pbrt"
TITLE = "pbrt-v4"
SUFFIXES = (".pbrt",)
#: Entry of ``gonio export --help``: what is written, [families expressed exactly], mapping.
HELP = """\
pbrt-v4 MakeNamedMaterial block + NamedMaterial (.pbrt).
[Lambert, TorranceSparrow(ggx, smith, Conductor|Dielectric), (1-a) Lambert + a TS]
diffuse: reflectance = albedo; conductor: eta, k, roughness = alpha with
"bool remaproughness" false; a sum is "mix" with amount a.
"""
FAMILY = "Lambert, TorranceSparrow(ggx, smith, Conductor), or (1 - a) Lambert + a TS of them"
MIX_AMOUNT = 0.5


def check(lobes: Lobes) -> str | None:
    """None when pbrt-v4 expresses ``lobes`` exactly, else the reason."""
    sp = lobes.specular
    if sp is None:
        if lobes.diffuse_scale is not None:
            return "a scaled diffuse term"
        if lobes.diffuse is not None and np.any(lobes.diffuse > 1):
            return "a diffuse albedo above 1 (pbrt clamps reflectances)"
        return None
    if sp.distribution != "ggx":
        return f"the {sp.distribution} distribution (pbrt-v4 has Trowbridge-Reitz, GGX, only)"
    if sp.shadowing != "smith":
        return f"{sp.shadowing} shadowing (pbrt's Trowbridge-Reitz uses Smith's)"
    if sp.fresnel not in ("conductor", "dielectric"):
        return f"{sp.fresnel} Fresnel (pbrt's conductor takes a complex index eta, k)"
    if lobes.diffuse is None:
        return None if sp.scale is None else "a scaled conductor lobe (pbrt has no factor)"
    a = mix_amount(lobes)
    if a is None:
        return "a sum of diffuse and conductor lobes not of the form (1 - a) Lambert + a TS"
    if np.any(lobes.diffuse > 1):
        return "a diffuse reflectance above 1 (pbrt clamps reflectances)"
    return None


def refit_template(model: Any, lobes: Lobes | None) -> tuple[Any, dict[str, Any], str]:
    """0.5 Lambert + 0.5 TS(ggx, smith, Conductor) started from ``model``."""
    from gonio.brdf import models  # JAX: imported when a refit is built

    tmpl, fixed = template(
        model, "ggx", models.Conductor(eta=1.5, k=0.0), scales=(1 - MIX_AMOUNT, MIX_AMOUNT)
    )
    return (
        tmpl,
        fixed,
        f"{1 - MIX_AMOUNT:g} Lambert + {MIX_AMOUNT:g} TorranceSparrow(ggx, smith, Conductor)",
    )


def _vals(v: list[float]) -> str:
    return "[ " + " ".join(fmt(x) for x in v) + " ]"


def build(name: str, lobes: Lobes) -> Export:
    """The pbrt-v4 block of representable ``lobes``."""
    lines = [
        f"# gonio export: {name} for pbrt-v4 ({family_name(lobes)})",
        "# roughness is gonio's alpha, used unchanged: remaproughness false",
    ]
    params: dict[str, Any] = {}
    sp = lobes.specular
    diff_name = cond_name = None
    if lobes.diffuse is not None:
        refl = rgb(lobes.diffuse)
        diff_name = name if sp is None else f"{name}_diffuse"
        lines.append(
            f'MakeNamedMaterial "{diff_name}"\n    "string type" "diffuse"\n'
            f'    "rgb reflectance" {_vals(refl)}'
        )
        params["reflectance"] = refl
    if sp is not None:
        eta = rgb(sp.eta)
        k = rgb(sp.k) if sp.fresnel == "conductor" else [0.0, 0.0, 0.0]
        cond_name = name if lobes.diffuse is None else f"{name}_conductor"
        lines.append(
            f'MakeNamedMaterial "{cond_name}"\n    "string type" "conductor"\n'
            f'    "rgb eta" {_vals(eta)}\n    "rgb k" {_vals(k)}\n'
            f'    "float roughness" [ {fmt(sp.alpha)} ]\n    "bool remaproughness" false'
        )
        params.update(eta=eta, k=k, roughness=float(sp.alpha), remaproughness=False)
    if diff_name and cond_name:
        a = mix_amount(lobes)
        assert a is not None
        lines.append(
            f'MakeNamedMaterial "{name}"\n    "string type" "mix"\n'
            f'    "string materials" [ "{diff_name}" "{cond_name}" ]\n'
            f'    "float amount" [ {fmt(a)} ]'
        )
        params["amount"] = a
    lines.append(f'NamedMaterial "{name}"')
    notes = [
        "pbrt-v4 renders spectrally: RGB parameters are upsampled to smooth spectra "
        "(RGBAlbedoSpectrum, RGBUnboundedSpectrum), so an RGB renderer's image differs slightly",
    ]
    if diff_name and cond_name:
        notes.append(
            "pbrt's mix picks one material per hit with probability amount: the same "
            "BRDF in expectation"
        )
    return Export(
        TARGET,
        name,
        {".pbrt": "\n".join(lines) + "\n"},
        "exact",
        family_name(lobes),
        params,
        notes=notes,
    )
