"""Ngan, Durand & Matusik (2005) published fits, in the BSDF benchmark library's conventions.

The fit files (``../shared/data/fits/ngan_*.fit``, from the bbm repository) hold one material per
line::

    blue-acrylic = Aggregate(Lambertian(albedo = [r, g, b]), NganWard(albedo = [..], roughness = a))

:func:`parse_ngan_fits` parses that text (never evaluates it) and :func:`to_model` turns one
entry into a gonio model that evaluates to the same BRDF; :func:`to_family` gives the same BRDF
as a model of the matching fit preset (``lambert+cook-torrance``, ``lambert+ward``,
``lambert+ngan-blinn-phong``), so that gonio's fits and the published ones are scored and
refitted by the same code. This module does no I/O: callers pass
the text (``gonio.brdf`` stays free of files).

Conventions (bbm's model definitions; ``cos_i``, ``cos_o`` the cosines of ``wi``, ``wo``; ``h``
the unit half vector; all diffuse terms are ``Lambertian(albedo) = albedo / pi``):

``NganWard(albedo, roughness)``
    ``albedo exp(-tan^2 theta_h / roughness^2) / (4 pi roughness^2 sqrt(cos_i cos_o))``: exactly
    ``Ward(rho_s=albedo, alpha_x=alpha_y=roughness, variant="original")``; no conversion.
``NganBlinnPhong(albedo, sharpness)``
    bbm defines it as an alias of its modified Phong lobe about the **mirror direction**:
    ``albedo (sharpness + 2) / (2 pi) max(0, reflect(wi).wo)^sharpness``. That is exactly
    ``Phong(rho_s=albedo, n=sharpness)``, which is what this module returns; gonio's
    ``BlinnPhong`` (a half-vector lobe with Giesen's normalization) is a different lobe and
    cannot reproduce it. Note: across the 86 materials fitted with all three models, the
    published sharpness is about 1.3x (median) the half-vector exponent ``2 / alpha^2 - 2``
    implied by the same material's Ward and Cook-Torrance roughness, and about 5x the
    mirror-direction exponent ``1 / (2 alpha^2)``; the values therefore look like half-vector
    (Blinn) exponents, and bbm's alias probably does not reproduce Ngan's original lobe widths.
    :func:`to_model` follows bbm (the stated source of the parameter meanings);
    :func:`to_family` defaults to the half-vector lobe ``albedo (n + 2) / (2 pi) cos^n theta_h``
    (:class:`~gonio.brdf.models.NganBlinnPhong`), which scores closer to the neural MERL
    tables than the mirror-direction reading in 107 of 114 (material, metric) pairs
    (``benchmarks/bench_published.py``, column ``published_bbm``).
    Five published sharpness values (up to 121000) exceed gonio's exponent range (1e5):
    converting those materials raises ParameterError.
``NganCookTorrance(albedo, eta, roughness)``
    ``albedo D G F / (pi cos_i cos_o)`` with the normalized Beckmann ``D`` of slope
    ``roughness``, the Torrance-Sparrow V-groove ``G = min(1, 2 h_z cos_i / (wi.h),
    2 h_z cos_o / (wo.h))`` and Schlick's ``F = F0 + (1 - F0)(1 - wi.h)^5`` where the
    parameter named ``eta`` **is F0** (bbm's ``ior::reflectance``, not an index of refraction).
    gonio's ``TorranceSparrow`` is ``D G F / (4 cos_i cos_o)`` with no free factor, so the lobe
    becomes ``Scaled(TorranceSparrow(alpha=roughness, distribution="beckmann",
    shadowing="vcavity", fresnel=Schlick(f0=eta)), scale=4 albedo / pi)``.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

from gonio.errors import FormatError

#: Models :func:`to_model` converts.
SUPPORTED = ("NganWard", "NganBlinnPhong", "NganCookTorrance")

_TOKEN = re.compile(
    r"\s*(?:(?P<num>[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)|(?P<name>[A-Za-z_][A-Za-z_0-9]*)"
    r"|(?P<punct>[()\[\],=]))"
)


@dataclass(frozen=True)
class NganFit:
    """One published fit.

    Attributes
    ----------
    material : MERL material name.
    diffuse_albedo : the Lambertian albedo per RGB channel.
    model : bbm model name of the specular lobe, e.g. ``"NganWard"``.
    params : the lobe's parameters as published (floats or tuples of floats).
    """

    material: str
    diffuse_albedo: tuple[float, ...]
    model: str
    params: dict[str, float | tuple[float, ...]] = field(default_factory=dict)


class _Parser:
    """Recursive-descent parser for ``Name(key = value, ...)`` expressions (no ``eval``)."""

    def __init__(self, text: str, line_no: int) -> None:
        self.line_no = line_no
        self.tokens: list[tuple[str, str]] = []
        pos = 0
        text = text.rstrip()
        while pos < len(text):
            m = _TOKEN.match(text, pos)
            if not m or m.end() == pos:
                raise FormatError(f"line {line_no}: unexpected text {text[pos : pos + 20]!r}")
            kind = m.lastgroup
            self.tokens.append((kind, m.group(kind)))
            pos = m.end()
        self.i = 0

    def _next(self) -> tuple[str, str]:
        if self.i >= len(self.tokens):
            raise FormatError(f"line {self.line_no}: unexpected end of line")
        tok = self.tokens[self.i]
        self.i += 1
        return tok

    def _expect(self, value: str) -> None:
        _, tok = self._next()
        if tok != value:
            raise FormatError(f"line {self.line_no}: expected {value!r}, got {tok!r}")

    def _peek(self) -> str | None:
        return self.tokens[self.i][1] if self.i < len(self.tokens) else None

    def call(self) -> tuple[str, list]:
        kind, name = self._next()
        if kind != "name":
            raise FormatError(f"line {self.line_no}: expected a model name, got {name!r}")
        self._expect("(")
        args: list = []
        if self._peek() == ")":
            self.i += 1
            return name, args
        while True:
            if self.i + 1 < len(self.tokens) and self.tokens[self.i + 1][1] == "=":
                _, key = self._next()
                self._next()
                args.append((key, self.value()))
            else:
                args.append(self.call())
            _, tok = self._next()
            if tok == ")":
                return name, args
            if tok != ",":
                raise FormatError(f"line {self.line_no}: expected ',' or ')', got {tok!r}")

    def value(self, depth: int = 0) -> float | tuple:
        """A number, or a list of values nested at most two deep (Bagher's ``eta = [[..],
        [..]]``)."""
        kind, tok = self._next()
        if kind == "num":
            return float(tok)
        if tok == "[" and depth < 2:
            values: list = []
            while True:
                values.append(self.value(depth + 1))
                kind, tok = self._next()
                if tok == "]":
                    return tuple(values)
                if tok != ",":
                    raise FormatError(f"line {self.line_no}: expected ',' or ']', got {tok!r}")
        raise FormatError(f"line {self.line_no}: expected a number or a list, got {tok!r}")

    def done(self) -> None:
        if self.i != len(self.tokens):
            raise FormatError(f"line {self.line_no}: trailing text {self.tokens[self.i][1]!r}")


def parse_ngan_fits(text: str) -> dict[str, NganFit]:
    """Parse a bbm ``.fit`` text into ``{material: NganFit}`` (file order).

    Raises FormatError (naming the line) on anything but comments, blank lines and
    ``name = Aggregate(Lambertian(albedo = [...]), Model(key = value, ...))`` entries.
    """
    fits: dict[str, NganFit] = {}
    for line_no, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        name, eq, rest = stripped.partition("=")
        name = name.strip()
        if not eq or not re.fullmatch(r"[A-Za-z0-9_.+-]+", name):
            raise FormatError(f"line {line_no}: expected 'material = Aggregate(...)'")
        p = _Parser(rest, line_no)
        head, args = p.call()
        p.done()
        if head != "Aggregate" or len(args) != 2 or not all(isinstance(a[1], list) for a in args):
            raise FormatError(f"line {line_no}: expected Aggregate(Lambertian(...), Model(...))")
        (lam_name, lam_args), (model, model_args) = args
        if lam_name != "Lambertian" or [k for k, _ in lam_args] != ["albedo"]:
            raise FormatError(f"line {line_no}: expected Lambertian(albedo = [...]) first")
        albedo = lam_args[0][1]
        params = {}
        for item in model_args:
            if not isinstance(item[1], (float, tuple)):
                raise FormatError(f"line {line_no}: nested model inside {model}")
            params[item[0]] = item[1]
        if name in fits:
            raise FormatError(f"line {line_no}: material {name!r} appears twice")
        fits[name] = NganFit(name, tuple(albedo) if isinstance(albedo, tuple) else (albedo,),
                             model, params)  # fmt: skip
    return fits


def to_model(fit: NganFit):
    """The gonio model equal to ``fit`` under bbm's conventions (see the module docstring).

    Raises FormatError for unsupported models or missing parameters, ParameterError (naming
    the material) for values outside gonio's parameter ranges.
    """
    from gonio.brdf import models
    from gonio.errors import ParameterError

    _check(fit)
    p = fit.params
    rho_d = list(fit.diffuse_albedo)
    try:
        if fit.model == "NganWard":
            a = p["roughness"]
            return models.Ward(rho_d=rho_d, rho_s=list(_tup(p["albedo"])), alpha_x=a, alpha_y=a,
                               variant="original")  # fmt: skip
        if fit.model == "NganBlinnPhong":
            return models.Phong(rho_d=rho_d, rho_s=list(_tup(p["albedo"])), n=p["sharpness"])
        lobe = models.TorranceSparrow(
            alpha=p["roughness"],
            distribution="beckmann",
            shadowing="vcavity",
            fresnel=models.Schlick(f0=p["eta"]),
        )
        scale = [4.0 * v / math.pi for v in _tup(p["albedo"])]
        return models.Lambert(rho_d) + models.Scaled(lobe, scale=scale)
    except ParameterError as e:
        raise ParameterError(f"{fit.material} ({fit.model}): {e}") from None


def _check(fit: NganFit) -> None:
    need = {
        "NganWard": ("albedo", "roughness"),
        "NganBlinnPhong": ("albedo", "sharpness"),
        "NganCookTorrance": ("albedo", "eta", "roughness"),
    }
    if fit.model not in need:
        raise FormatError(f"{fit.material}: unsupported model {fit.model!r} (have {SUPPORTED})")
    missing = [k for k in need[fit.model] if k not in fit.params]
    if missing or len(fit.params) != len(need[fit.model]):
        raise FormatError(
            f"{fit.material}: {fit.model} needs parameters {need[fit.model]}, "
            f"got {tuple(fit.params)}"
        )


#: Fit preset (``gonio.fit.presets``) of each published model's family, for :func:`to_family`.
FAMILY_PRESETS = {
    "NganCookTorrance": "lambert+cook-torrance",
    "NganWard": "lambert+ward",
    "NganBlinnPhong": "lambert+ngan-blinn-phong",
}


def to_family(fit: NganFit, blinn_phong: str = "half"):
    """``(preset name, model)``: the published fit as a model of the matching fit preset, with
    the same structure as a gonio fit of that preset (so it can be scored and refitted by the
    same code).

    ``NganCookTorrance`` -> ``Lambert(albedo) + CookTorrance(rho_s=albedo, alpha=roughness,
    f0=eta)`` (equal to :func:`to_model`'s scaled lobe); ``NganWard`` -> ``Lambert(albedo) +
    Ward(rho_s=albedo, alpha=roughness, rho_d=0)``; ``NganBlinnPhong`` -> ``Lambert(albedo) +
    NganBlinnPhong(rho_s=albedo, n=sharpness)``, the half-vector lobe ``rho_s (n + 2) / (2 pi)
    cos^n theta_h`` of the paper (``blinn_phong="half"``, default), or with
    ``blinn_phong="bbm"`` bbm's mirror-direction alias ``Lambert + Phong`` (preset
    ``"lambert+phong"``). See the module docstring for why the half vector is the default.
    """
    from gonio.brdf import models
    from gonio.errors import ParameterError

    _check(fit)
    p = fit.params
    lam = models.Lambert(list(fit.diffuse_albedo))
    rho_s = list(_tup(p["albedo"]))
    try:
        if fit.model == "NganCookTorrance":
            lobe = models.CookTorrance(rho_s=rho_s, alpha=p["roughness"], f0=p["eta"])
        elif fit.model == "NganWard":
            a = p["roughness"]
            lobe = models.Ward(rho_d=0.0, rho_s=rho_s, alpha_x=a, alpha_y=a, variant="original")
        elif blinn_phong == "bbm":
            return "lambert+phong", lam + models.Phong(rho_d=0.0, rho_s=rho_s, n=p["sharpness"])
        elif blinn_phong == "half":
            lobe = models.NganBlinnPhong(rho_s=rho_s, n=p["sharpness"])
        else:
            raise ParameterError(f"blinn_phong must be 'half' or 'bbm', got {blinn_phong!r}")
    except ParameterError as e:
        raise ParameterError(f"{fit.material} ({fit.model}): {e}") from None
    return FAMILY_PRESETS[fit.model], lam + lobe


def _tup(v: float | tuple[float, ...]) -> tuple[float, ...]:
    return v if isinstance(v, tuple) else (v,)
