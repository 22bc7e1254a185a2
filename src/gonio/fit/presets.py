"""Model names accepted by ``gonio fit --model`` and ``gonio.fit.fit(model="...")``.

A name is one lobe or several joined by ``+`` (``"lambert+ward"``, ``"lambert+ts+ts"``). Each
lobe name maps to a constructor of :mod:`gonio.brdf.models`; names whose model is not part of
this installation are not offered. When a sum contains a ``lambert`` lobe, the other lobes'
own diffuse term (a parameter named ``rho_d``) is fixed at 0, because two diffuse terms would
be the same parameter twice (not identifiable).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from gonio.brdf import models
from gonio.brdf.models import BRDFModel
from gonio.errors import FitError


def _make(cls_name: str, **kw: Any) -> Callable[[], BRDFModel] | None:
    cls = getattr(models, cls_name, None)
    if cls is None:
        return None

    def build() -> BRDFModel:
        return cls(**kw)

    return build


def _ts(distribution: str, shadowing: str) -> Callable[[], BRDFModel] | None:
    cls = getattr(models, "TorranceSparrow", None)
    if cls is None:
        return None

    def build() -> BRDFModel:
        kw: dict[str, Any] = {"distribution": distribution, "shadowing": shadowing}
        schlick = getattr(models, "Schlick", None)
        if schlick is not None:
            kw["fresnel"] = schlick()
        return cls(**kw)

    return build


def _lobes() -> dict[str, Callable[[], BRDFModel] | None]:
    return {
        "lambert": _make("Lambert"),
        "oren-nayar": _make("OrenNayar"),
        "phong": _make("Phong"),
        "blinn-phong": _make("BlinnPhong"),
        "ward": _make("Ward", variant="original"),
        "ward-duer": _make("Ward", variant="duer"),
        "ward-balanced": _make("Ward", variant="balanced"),
        "torrance-sparrow": _ts("beckmann", "vcavity"),
        "ts": _ts("beckmann", "vcavity"),
        "ts-ggx-smith": _ts("ggx", "smith"),
        "lafortune": _make("Lafortune", cx=[-1.0], cy=[-1.0], cz=[1.0], n=[20.0], rho_s=[0.5]),
        # A forward-scattering specular lobe and a broad retro/off-specular one.
        "lafortune-2": _make(
            "Lafortune",
            cx=[-1.0, -0.5],
            cy=[-1.0, -0.5],
            cz=[1.0, 0.7],
            n=[30.0, 3.0],
            rho_s=[0.5, 0.1],
        ),
        "ashikhmin-shirley": _make("AshikhminShirley"),
        # the literature's families as published (see FAMILIES)
        "cook-torrance": _make("CookTorrance"),
        "ngan-blinn-phong": _make("NganBlinnPhong"),
        "low": _make("LowMicrofacet"),
        # long-tailed microfacet lobe (free tail exponent) and a retro-reflective lobe
        "gtr": _make("GTR"),
        "retro": _make("Retroreflection"),
    }


_COMBOS = (
    "lambert+ward",
    "lambert+ts",
    "lambert+ts+ts",
    "lambert+ts-ggx-smith",
    "lambert+cook-torrance",
    "lambert+cook-torrance+cook-torrance",
    "lambert+ngan-blinn-phong",
    "lambert+ward+ward",
    "lambert+low",
    "lambert+low+low",
    "lambert+gtr",
    "lambert+gtr+gtr",
    "lambert+retro",
    "lambert+retro+gtr",
)

#: The literature's model families, parameterized as published, by preset name. Each lobe's
#: docstring (gonio.brdf.models) gives its formula and citation; per-channel parameters follow
#: the source (albedos per channel, lobe shapes and the Fresnel term shared).
FAMILIES: dict[str, str] = {
    "lambert+cook-torrance": "Cook & Torrance 1982 as fitted by Ngan et al. 2005: Lambert + "
    "rho_s D_Beckmann G_vcavity F_Schlick(f0) / (pi cos_i cos_o), rho_s per channel, one f0",
    "lambert+ward": "Ward 1992 (isotropic, original normalization) as fitted by Ngan et al. "
    "2005: Lambert + rho_s exp(-tan^2 theta_h / a^2) / (4 pi a^2 sqrt(cos_i cos_o))",
    "lambert+ngan-blinn-phong": "Blinn 1977 with the half vector as fitted by Ngan et al. 2005: "
    "Lambert + rho_s (n + 2) / (2 pi) cos^n theta_h",
    "ashikhmin-shirley": "Ashikhmin & Shirley 2000 (isotropic): coupled diffuse + Schlick-"
    "Fresnel Phong lobe of the half vector",
    "lambert+low": "Low et al. 2012 microfacet model: Lambert + A F_dielectric(eta) G / "
    "(pi (1 + B (1 - cos theta_h))^C cos_i cos_o)",
    "lambert+cook-torrance+cook-torrance": "two Cook-Torrance lobes (Ngan et al. 2005, section 6)",
    "lambert+ward+ward": "two Ward lobes",
    "lambert+low+low": "two Low et al. 2012 lobes",
}


def available() -> list[str]:
    """Every valid model name of this installation (single lobes, then the usual sums)."""
    lobes = {k: v for k, v in _lobes().items() if v is not None}
    names = [k for k in lobes if k != "ts"]
    names += [c for c in _COMBOS if all(p in lobes for p in c.split("+"))]
    return names


def build(name: str) -> tuple[BRDFModel, dict[str, Any], dict[str, str]]:
    """Template model, fixed parameters and tied parameters for a model name.

    Ward and Ashikhmin-Shirley lobes are fitted isotropic (``alpha_y`` tied to ``alpha_x``,
    ``nv`` to ``nu``): measurements of isotropic materials (every table in the half-diff-iso
    parameterization) cannot tell the two apart.

    Raises
    ------
    FitError
        For an unknown name (the message lists the valid ones).
    """
    lobes = {k: v for k, v in _lobes().items() if v is not None}
    parts = [p.strip().lower() for p in str(name).split("+")]
    if not parts or any(p not in lobes for p in parts):
        raise FitError(f"unknown model {name!r}; valid: {', '.join(available())}")
    built = [lobes[p]() for p in parts]
    model = built[0]
    for b in built[1:]:
        model = model + b
    fixed: dict[str, Any] = {}
    tied: dict[str, str] = {}
    for key in model.param_specs():
        head, _, pname = key.rpartition(".")
        prefix = f"{head}." if head else ""
        for y, x in (("alpha_y", "alpha_x"), ("nv", "nu")):
            if pname == y and f"{prefix}{x}" in model.param_specs():
                tied[key] = f"{prefix}{x}"
        if len(built) > 1 and "lambert" in parts and pname == "rho_d":
            if not head.startswith("lambert"):
                fixed[key] = 0.0
    if fixed:
        model = model.replace(**fixed)
    return model, fixed, tied
