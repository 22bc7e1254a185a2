"""Every published fit of the MERL materials in the BSDF benchmark library's files, as a gonio
model.

The files (``../shared/data/fits/*.fit``, from the bbm repository) hold one material per line,
``name = Aggregate(Lambertian(albedo = [r, g, b]), Model(key = value, ...))``, parsed by
:func:`gonio.brdf.ngan.parse_ngan_fits` (never evaluated). Parameter meanings follow bbm's model
definitions (``include/bsdfmodel/``); the values are in the MERL tables' standard units (sr^-1
after MERL's per-channel scales 1/1500, 1.15/1500, 1.66/1500), as bbm's MERL reader gives them.
Every model is ``Lambert(albedo) + lobe``; ``cos_i``, ``cos_o`` are the cosines of ``wi``,
``wo``, ``h`` the unit half vector:

* ``NganWard``, ``NganCookTorrance``, ``NganBlinnPhong``: as
  :func:`gonio.brdf.ngan.to_family` (the presets' lobes; the Blinn-Phong sharpness is read as a
  half-vector exponent, see there).
* ``NganWardDuer``: ``Ward(rho_s=albedo, alpha=roughness, variant="duer")``.
* ``NganLafortune``: ``Lafortune(cx=cy=Cxy, cz=Cz, n=sharpness, rho_s=albedo)`` with Ngan's
  normalization ``(n + 2) / (2 pi max(|Cxy|, |Cz|)^n)``.
* ``NganAshikhminShirley``: ``AshikhminShirleyLobe(albedo, sharpness,
  Schlick(fresnelReflectance))``.
* ``LowAshikhminShirley``: ``AshikhminShirleyLobe(albedo, sharpness,
  Dielectric(fresnelReflectance))`` (Löw's variant: the parameter is an index of refraction).
* ``LowCookTorrance``: bbm's ``albedo D G F / (pi cos_i cos_o)`` with the *unnormalized*
  Beckmann ``D = exp(-tan^2 theta_h / m^2) / (m^2 cos^4 theta_h)``, the V-groove ``G`` and the
  dielectric Fresnel term of index ``eta``, i.e. ``Scaled(TorranceSparrow(alpha=m, beckmann,
  vcavity, Dielectric(eta)), 4 albedo)``; the three published fits with ``m > 1`` (up to
  2.09: the Beckmann distribution is normalized for any ``m``) are within TorranceSparrow's
  range, above the box its fits search.
* ``LowMicrofacetFit``: ``LowMicrofacet(A, B, C, eta)`` (the fits' ``1 / pi`` normalization).
* ``LowSmooth``: ``LowSmooth(A, B, C, eta)``.
* ``Bagher``: ``BagherSGD(rho_s=albedo, alpha, p, f0=eta[0], f1=eta[1], K, Lambda, c, k,
  theta0)``.

``NganHe`` (bbm's He et al. variant after Westin's code, with its own wavelength convention and
series cut-offs) is not converted: :func:`to_model` raises FormatError for it.
"""

from __future__ import annotations

import math
from typing import Any

from gonio.brdf.ngan import NganFit, parse_ngan_fits, to_family
from gonio.errors import FormatError, ParameterError

#: Parameters of each bbm model that :func:`to_model` converts.
PARAMETERS: dict[str, tuple[str, ...]] = {
    "NganWard": ("albedo", "roughness"),
    "NganBlinnPhong": ("albedo", "sharpness"),
    "NganCookTorrance": ("albedo", "eta", "roughness"),
    "NganWardDuer": ("albedo", "roughness"),
    "NganLafortune": ("albedo", "Cxy", "Cz", "sharpness"),
    "NganAshikhminShirley": ("albedo", "fresnelReflectance", "sharpness"),
    "LowAshikhminShirley": ("albedo", "sharpness", "fresnelReflectance"),
    "LowCookTorrance": ("albedo", "roughness", "eta"),
    "LowMicrofacetFit": ("A", "B", "C", "eta"),
    "LowSmooth": ("A", "B", "C", "eta"),
    "Bagher": ("albedo", "alpha", "p", "eta", "K", "Lambda", "c", "k", "theta0"),
}

__all__ = ["PARAMETERS", "NganFit", "parse_ngan_fits", "to_model"]


def _check(fit: NganFit) -> None:
    if fit.model not in PARAMETERS:
        raise FormatError(
            f"{fit.material}: unsupported model {fit.model!r} (gonio converts "
            f"{', '.join(PARAMETERS)})"
        )
    need = PARAMETERS[fit.model]
    if sorted(need) != sorted(fit.params):
        raise FormatError(
            f"{fit.material}: {fit.model} needs parameters {need}, got {tuple(fit.params)}"
        )


def _flat(v: Any) -> list[float]:
    if isinstance(v, tuple):
        if any(isinstance(x, tuple) for x in v):
            raise FormatError(f"expected a number or a list of numbers, got {v!r}")
        return [float(x) for x in v]
    return [float(v)]


def _lobe(fit: NganFit) -> Any:
    from gonio.brdf import models

    p = fit.params
    m = fit.model
    if m == "NganWardDuer":
        a = float(p["roughness"])
        return models.Ward(rho_d=0.0, rho_s=_flat(p["albedo"]), alpha_x=a, alpha_y=a,
                           variant="duer")  # fmt: skip
    if m == "NganAshikhminShirley":
        fres = models.Schlick(f0=_flat(p["fresnelReflectance"]))
        return models.AshikhminShirleyLobe(_flat(p["albedo"]), float(p["sharpness"]), fres)
    if m == "LowAshikhminShirley":
        fres = models.Dielectric(eta=_flat(p["fresnelReflectance"]))
        return models.AshikhminShirleyLobe(_flat(p["albedo"]), float(p["sharpness"]), fres)
    if m == "LowCookTorrance":
        ts = models.TorranceSparrow(
            alpha=float(p["roughness"]),
            distribution="beckmann",
            shadowing="vcavity",
            fresnel=models.Dielectric(eta=_flat(p["eta"])),
        )
        return models.Scaled(ts, scale=[4.0 * v for v in _flat(p["albedo"])])
    if m in ("LowMicrofacetFit", "LowSmooth"):
        cls = models.LowMicrofacet if m == "LowMicrofacetFit" else models.LowSmooth
        return cls(A=_flat(p["A"]), B=float(p["B"]), C=float(p["C"]), eta=float(p["eta"]))
    # Bagher
    eta = p["eta"]
    if not (isinstance(eta, tuple) and len(eta) == 2 and all(isinstance(e, tuple) for e in eta)):
        raise FormatError(f"{fit.material}: Bagher's eta must be [[F0 ...], [F1 ...]], got {eta!r}")
    keys = ("alpha", "p", "K", "Lambda", "c", "k", "theta0")
    return models.BagherSGD(rho_s=_flat(p["albedo"]), f0=_flat(eta[0]), f1=_flat(eta[1]),
                            **{k: _flat(p[k]) for k in keys})  # fmt: skip


def to_model(fit: NganFit) -> Any:
    """The gonio model of one published fit: ``Lambert(albedo) + lobe`` (module docstring).

    Raises
    ------
    FormatError : an unsupported model or missing parameters.
    ParameterError : a value outside the gonio model's range (naming the material).
    """
    from gonio.brdf import models

    _check(fit)
    if fit.model in ("NganWard", "NganBlinnPhong", "NganCookTorrance"):
        return to_family(fit)[1]
    try:
        if fit.model == "NganLafortune":
            p = fit.params
            return models.Lafortune(
                cx=[float(p["Cxy"])],
                cy=[float(p["Cxy"])],
                cz=[float(p["Cz"])],
                n=[float(p["sharpness"])],
                rho_s=[_flat(p["albedo"])],
                rho_d=list(fit.diffuse_albedo),
            )
        lobe = _lobe(fit)
        values = [float(x) for x in fit.diffuse_albedo]
        if not all(math.isfinite(v) for v in values):
            raise ParameterError(f"diffuse albedo {values} is not finite")
        return models.Lambert(values) + lobe
    except ParameterError as e:
        raise ParameterError(f"{fit.material} ({fit.model}): {e}") from None
