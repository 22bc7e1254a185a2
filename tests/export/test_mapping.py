"""Which fits each target expresses exactly (no refit), checked on the lobe split alone."""

from __future__ import annotations

import pytest

from gonio.brdf import models
from gonio.export import TARGETS
from gonio.export._lobes import NotRepresentable, split

S = models.Schlick(0.04)
C = models.Conductor(eta=[0.2, 0.9, 1.1], k=[3.9, 2.4, 1.9])
D = models.Dielectric(1.5)


def ts(dist="ggx", shadowing="smith", fresnel=S, alpha=0.2):
    return models.TorranceSparrow(
        alpha=alpha, distribution=dist, shadowing=shadowing, fresnel=fresnel
    )


L = models.Lambert([0.5, 0.4, 0.3])
HALF = (models.Scaled(L, 0.5), 0.5)

#: model -> set of targets that express it exactly
EXACT = {
    "lambert": (L, {"mitsuba", "pbrt", "blender", "openpbr"}),
    "lambert+ggx/schlick": (L + ts(), {"blender", "usd"}),
    "lambert+ggx/dielectric": (L + ts(fresnel=D), {"mitsuba", "blender"}),
    "lambert+ggx/conductor": (L + ts(fresnel=C), {"mitsuba", "blender"}),
    "lambert+beckmann/conductor": (L + ts("beckmann", fresnel=C), {"mitsuba", "blender"}),
    "lambert+beckmann/schlick": (L + ts("beckmann"), {"blender"}),  # Metallic BSDF, F82
    "ggx/conductor": (ts(fresnel=C), {"mitsuba", "pbrt", "blender"}),
    "ggx/schlick": (ts(), {"mitsuba", "blender", "openpbr", "usd"}),  # principled metal
    "lambert+ts (preset: beckmann, vcavity, schlick)": (L + ts("beckmann", "vcavity"), set()),
    "blinn": (L + ts("blinn", fresnel=C), set()),
    "mix 0.5/0.5 conductor": (HALF[0] + models.Scaled(ts(fresnel=C), 0.5), {"mitsuba", "pbrt"}),
    "mix 0.5/0.5 schlick": (HALF[0] + models.Scaled(ts(), 0.5), {"openpbr"}),
}


@pytest.mark.parametrize("key", list(EXACT))
def test_exact_families(key):
    model, exact = EXACT[key]
    lobes = split(model)
    got = {t for t, mod in TARGETS.items() if mod.check(lobes) is None}
    assert got == exact
    for t, mod in TARGETS.items():
        if t not in exact:
            assert isinstance(mod.check(lobes), str) and mod.check(lobes)  # a stated reason


@pytest.mark.parametrize(
    "model",
    [
        models.Lambert(0.2) + models.Ward(rho_s=0.1, alpha_x=0.2, alpha_y=0.2),
        models.OrenNayar(albedo=0.5, sigma=0.3),
        models.Lambert(0.2) + models.Phong(rho_s=0.5, n=50.0),
        L + ts() + ts(alpha=0.5),
    ],
)
def test_other_models_have_no_lobe_split(model):
    with pytest.raises(NotRepresentable):
        split(model)
