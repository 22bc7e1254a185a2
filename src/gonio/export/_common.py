"""What every exporter returns (:class:`Export`), atomic writing, and the refit templates."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from gonio.export._lobes import Lobes
from gonio.io.atomic import atomic_output

if (
    TYPE_CHECKING
):  # gonio.brdf imports JAX; the target modules load without it (gonio export --help)
    from gonio.brdf.models import BRDFModel, Fresnel

#: Fit-result JSON of an export (``gonio export --json``), version of its layout.
REPORT_VERSION = 1


@dataclass
class Export:
    """A renderer-ready material.

    Attributes
    ----------
    target : the target's name (:mod:`gonio.export.registry`), e.g. ``"mitsuba"``.
    name : material name used inside the files.
    files : ``{suffix: text}``; the first entry is the main file (e.g. ``".xml"``; Mitsuba also
        gives ``".json"``, its ``load_dict`` dictionary).
    mapping : ``"exact"`` (the target expresses the fitted model) or ``"refit"`` (the target's
        family was refitted to the fit's data; see ``refit``); ``"plugin"`` for the fragment
        of gonio's Mitsuba BSDF plugin (:mod:`gonio.export.mitsuba_plugin`).
    family : the gonio model the exported parameters describe exactly, e.g. ``"Lambert +
        TorranceSparrow(ggx, smith, Schlick)"``.
    params : the target-side values written, by target parameter name.
    refit : for ``mapping == "refit"``: family, data, metric, both losses, refitted params.
    notes : conventions and caveats of this target worth reading (documented differences
        between the target's BSDF and gonio's, spectral conversion, why a refit was needed).
    data : the dictionary form, when the target has one (Mitsuba's ``load_dict`` input).
    """

    target: str
    name: str
    files: dict[str, str]
    mapping: str
    family: str
    params: dict[str, Any]
    refit: dict[str, Any] | None = None
    notes: list[str] = field(default_factory=list)
    data: dict[str, Any] | None = None
    source: str | None = None

    @property
    def text(self) -> str:
        """The main file's text."""
        return next(iter(self.files.values()))

    def to_json(self) -> dict[str, Any]:
        """JSON-ready report (what ``gonio export --json`` prints)."""
        from gonio.io.fit_result import to_jsonable

        refit = None
        if self.refit is not None:
            refit = {k: v for k, v in self.refit.items() if k != "model"}
        return to_jsonable(
            {
                "export_version": REPORT_VERSION,
                "target": self.target,
                "name": self.name,
                "source": self.source,
                "mapping": self.mapping,
                "family": self.family,
                "params": self.params,
                "refit": refit,
                "notes": self.notes,
            }
        )

    def paths(self, out: str | Path) -> list[Path]:
        """Where :meth:`write` puts the files for ``out`` (its suffix is replaced per file)."""
        out = Path(out)
        main = next(iter(self.files))
        stem = out.name[: -len(main)] if out.name.endswith(main) else out.stem
        return [out.with_name(stem + suffix) for suffix in self.files]

    def write(self, out: str | Path) -> list[Path]:
        """Write every file atomically (temporary file, then rename); returns the paths."""
        paths = self.paths(out)
        for path, text in zip(paths, self.files.values(), strict=True):
            write_text(path, text)
        return paths


def write_text(path: Path, text: str) -> Path:
    """Atomic text write (:func:`gonio.io.atomic.atomic_output`), mode from the umask."""
    with atomic_output(path, ".tmp", make_parents=True) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return path


def fmt(x: float) -> str:
    """A number as written into material files: 9 significant digits, no exponent clutter."""
    return f"{float(x):.9g}"


def rgb(v: np.ndarray | None, fill: float = 0.0) -> list[float]:
    """Three values for a colour parameter: an RGB vector as is, a mono value repeated."""
    if v is None:
        return [fill] * 3
    v = np.asarray(v, dtype=np.float64).reshape(-1)
    return [float(x) for x in (np.repeat(v, 3) if v.size == 1 else v)]


def start_values(model: BRDFModel) -> tuple[np.ndarray | float, float]:
    """A refit's starting diffuse albedo and roughness from the original model's lobes: the
    summed diffuse albedos, and the first roughness-like value (``alpha``, Ward's ``alpha_x``,
    else 0.2)."""
    from gonio.brdf import models

    lobes = model.lobes if isinstance(model, models.Sum) else (model,)
    rho: Any = 0.0
    alpha = None
    for lobe in lobes:
        if isinstance(lobe, models.Scaled):
            lobe = lobe.lobe
        p = lobe.params()
        for key in ("albedo", "rho_d"):
            if key in p:
                rho = rho + np.asarray(p[key], dtype=np.float64)
        for key in ("alpha", "alpha_x"):
            if alpha is None and key in p:
                alpha = float(np.mean(np.asarray(p[key], dtype=np.float64)))
    if np.size(rho) not in (1, 3):  # a spectral fit is refitted in RGB: start from the mean
        rho = float(np.mean(rho))
    rho = np.clip(rho, 0.02, 0.95)
    alpha = float(np.clip(alpha if alpha is not None else 0.2, 0.01, 0.9))
    return rho, alpha


def template(
    model: BRDFModel,
    distribution: str,
    fresnel: Fresnel,
    scales: tuple[float, float] | None = None,
) -> tuple[BRDFModel, dict[str, Any]]:
    """A refit template ``Lambert + TorranceSparrow(distribution, smith, fresnel)`` started from
    ``model``'s values, with the lobe's own ``rho_d`` held at 0 (one diffuse term); with
    ``scales = (s_d, s_s)`` each lobe is wrapped in a :class:`~gonio.brdf.models.Scaled` whose
    factor is held fixed. Returns ``(template, fixed)``."""
    from gonio.brdf import models

    rho, alpha = start_values(model)
    diffuse: BRDFModel = models.Lambert(albedo=rho)
    spec: BRDFModel = models.TorranceSparrow(
        alpha=alpha, distribution=distribution, shadowing="smith", fresnel=fresnel
    )
    if scales is not None:
        diffuse = models.Scaled(models.Lambert(albedo=np.clip(rho / scales[0], 0, 0.95)), scales[0])
        spec = models.Scaled(spec, scales[1])
    tmpl = diffuse + spec
    fixed: dict[str, Any] = {}
    for key in tmpl.param_specs():
        if key.endswith("rho_d"):
            fixed[key] = 0.0
        if scales is not None and key.endswith(".scale"):
            fixed[key] = scales[0] if key.startswith("scaled.") else scales[1]
    return tmpl, fixed


def family_name(lobes: Lobes) -> str:
    """The structure of a :class:`Lobes` record in words (for reports)."""
    parts = []
    if lobes.diffuse is not None:
        s = lobes.diffuse_scale
        parts.append("Lambert" if s is None else f"{_scale_word(s)} Lambert")
    sp = lobes.specular
    if sp is not None:
        fr = {"schlick": "Schlick", "conductor": "Conductor", "dielectric": "Dielectric"}.get(
            sp.fresnel, "NoFresnel"
        )
        txt = f"TorranceSparrow({sp.distribution}, {sp.shadowing}, {fr})"
        parts.append(txt if sp.scale is None else f"{_scale_word(sp.scale)} {txt}")
    return " + ".join(parts)


def _scale_word(s: np.ndarray) -> str:
    s = np.asarray(s).reshape(-1)
    return f"{fmt(s[0])} x" if np.allclose(s, s[0]) else "scaled"


def uniform(v: np.ndarray | None) -> float | None:
    """The common value of a vector whose entries are all equal (within 1e-9), else None."""
    if v is None:
        return None
    v = np.asarray(v, dtype=np.float64).reshape(-1)
    return float(v[0]) if np.allclose(v, v[0], rtol=1e-9, atol=1e-12) else None


def mix_amount(lobes: Lobes) -> float | None:
    """``a`` when the diffuse term is scaled by ``1 - a`` and the lobe by ``a``, else None."""
    sp = lobes.specular
    if sp is None or lobes.diffuse is None:
        return None
    d = uniform(lobes.diffuse_scale) if lobes.diffuse_scale is not None else None
    s = uniform(sp.scale) if sp.scale is not None else None
    if d is None or s is None or not (0 < s < 1) or abs(d + s - 1) > 1e-9:
        return None
    return s
