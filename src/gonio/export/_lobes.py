"""A fitted model seen as the lobes renderers know: one Lambertian term plus one microfacet lobe.

Every exporter asks the same question first: is the fit a sum of a diffuse term (``Lambert``,
``TorranceSparrow.rho_d``) and at most one ``TorranceSparrow`` lobe, each possibly multiplied by
a constant (``Scaled``)? :func:`split` answers with a :class:`Lobes` record, or with the reason
why not (a Ward or Oren-Nayar lobe, two specular lobes, ...), which sends the exporter to a refit.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if (
    TYPE_CHECKING
):  # gonio.brdf imports JAX; the target modules load without it (gonio export --help)
    from gonio.brdf.models import BRDFModel


@dataclass(frozen=True)
class Specular:
    """One microfacet lobe ``scale * D G F / (4 cos_i cos_o)``.

    Attributes
    ----------
    alpha : gonio's roughness (RMS slope for Beckmann, the GGX width), dimensionless.
    distribution, shadowing : as in :class:`~gonio.brdf.models.TorranceSparrow`.
    fresnel : ``"schlick"``, ``"conductor"``, ``"dielectric"`` or ``"none"``.
    f0 : Schlick's normal-incidence reflectance (C,), for ``"schlick"``.
    eta, k : complex index (C,) for ``"conductor"``; ``eta`` alone for ``"dielectric"``.
    scale : constant factor in front of the lobe (C,) (1 unless the fit was a ``Scaled``).
    """

    alpha: float
    distribution: str
    shadowing: str
    fresnel: str
    f0: np.ndarray | None = None
    eta: np.ndarray | None = None
    k: np.ndarray | None = None
    scale: np.ndarray | None = None


@dataclass(frozen=True)
class Lobes:
    """Diffuse albedo (C,) (None when there is none), the specular lobe (or None), and the
    constant factor in front of the diffuse term (C,) (None: 1)."""

    channels: int
    diffuse: np.ndarray | None
    specular: Specular | None
    diffuse_scale: np.ndarray | None = None


class NotRepresentable(Exception):
    """Internal: the model is not a diffuse-plus-microfacet sum (the message says why)."""


def _vec(x: object, c: int) -> np.ndarray:
    return np.broadcast_to(np.asarray(x, dtype=np.float64).reshape(-1), (c,)).copy()


def _fresnel(fr: object, c: int) -> dict[str, object]:
    from gonio.brdf import models

    if isinstance(fr, models.Schlick):
        return {"fresnel": "schlick", "f0": _vec(fr.f0, c)}
    if isinstance(fr, models.Conductor):
        return {"fresnel": "conductor", "eta": _vec(fr.eta, c), "k": _vec(fr.k, c)}
    if isinstance(fr, models.Dielectric):
        return {"fresnel": "dielectric", "eta": _vec(fr.eta, c)}
    if isinstance(fr, models.NoFresnel):
        return {"fresnel": "none"}
    raise NotRepresentable(f"Fresnel term {type(fr).__name__}")


def split(model: BRDFModel) -> Lobes:
    """The diffuse and microfacet lobes of ``model``; NotRepresentable (with the reason) when the
    model holds anything else."""
    from gonio.brdf import models

    c = int(model.channels)
    lobes = model.lobes if isinstance(model, models.Sum) else (model,)
    diffuse = np.zeros(c)
    has_diffuse = False
    diffuse_scale: np.ndarray | None = None
    spec: Specular | None = None
    for lobe in lobes:
        scale = None
        if isinstance(lobe, models.Scaled):
            scale = _vec(lobe.scale, c)
            lobe = lobe.lobe
        if isinstance(lobe, models.Lambert):
            if has_diffuse and (scale is not None or diffuse_scale is not None):
                raise NotRepresentable("two scaled diffuse terms")
            diffuse = diffuse + _vec(lobe.albedo, c)
            has_diffuse, diffuse_scale = True, scale
        elif isinstance(lobe, models.TorranceSparrow):
            if spec is not None:
                raise NotRepresentable("more than one microfacet lobe")
            rho = _vec(lobe.rho_d, c)
            if np.any(rho > 0):
                if scale is not None or diffuse_scale is not None:
                    raise NotRepresentable("a scaled lobe with its own diffuse term")
                diffuse = diffuse + rho
                has_diffuse = True
            spec = Specular(
                alpha=float(np.asarray(lobe.alpha)),
                distribution=lobe.distribution,
                shadowing=lobe.shadowing,
                scale=scale,
                **_fresnel(lobe.fresnel, c),  # type: ignore[arg-type]
            )
        else:
            raise NotRepresentable(f"a {type(lobe).__name__} lobe")
    return Lobes(c, diffuse if has_diffuse else None, spec, diffuse_scale)


def describe(model: BRDFModel) -> str:
    """Short name of a model's structure, e.g. ``"Lambert + TorranceSparrow(ggx, smith,
    Schlick)"``."""
    from gonio.brdf import models

    lobes = model.lobes if isinstance(model, models.Sum) else (model,)
    parts = []
    for lobe in lobes:
        pre = ""
        if isinstance(lobe, models.Scaled):
            pre, lobe = "Scaled ", lobe.lobe
        if isinstance(lobe, models.TorranceSparrow):
            fr = type(lobe.fresnel).__name__
            parts.append(f"{pre}TorranceSparrow({lobe.distribution}, {lobe.shadowing}, {fr})")
        else:
            parts.append(pre + type(lobe).__name__)
    return " + ".join(parts)
