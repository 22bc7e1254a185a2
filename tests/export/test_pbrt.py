"""pbrt-v4 has no Python package: parse the exported block and check it against a table.

The table states pbrt-v4's own parameter names and types (``src/pbrt/materials.cpp``:
DiffuseMaterial ``reflectance``; ConductorMaterial ``eta``, ``k``, ``roughness``,
``remaproughness``; MixMaterial ``materials``, ``amount``) and the roughness convention chosen:
``roughness`` = gonio's alpha with ``remaproughness false`` (pbrt's default remap,
``RoughnessToAlpha``, would read alpha = sqrt(roughness)).
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from gonio.brdf import models
from gonio.export import to_pbrt
from tests.export.conftest import fit_record

_STMT = re.compile(r'(MakeNamedMaterial|NamedMaterial)\s+"([^"]+)"')
_PARAM = re.compile(r'"(\w+)\s+(\w+)"\s+(\[[^\]]*\]|"[^"]*"|\S+)')


def parse(text: str) -> tuple[dict[str, dict[str, tuple[str, object]]], str]:
    """``({material: {param: (type, value)}}, bound material)`` from a pbrt-v4 block."""
    body = "\n".join(line for line in text.splitlines() if not line.lstrip().startswith("#"))
    mats: dict[str, dict[str, tuple[str, object]]] = {}
    bound = None
    pieces = _STMT.split(body)[1:]
    for kind, name, rest in zip(pieces[0::3], pieces[1::3], pieces[2::3], strict=True):
        if kind == "NamedMaterial":
            bound = name
            continue
        params = {}
        for ptype, pname, raw in _PARAM.findall(rest):
            raw = raw.strip("[] ")
            if ptype in ("float", "rgb"):
                val: object = [float(x) for x in raw.split()]
            elif ptype == "bool":
                val = raw.strip('"')
            else:
                val = re.findall(r'"([^"]*)"', raw) or [raw.strip('"')]
            params[pname] = (ptype, val)
        mats[name] = params
    return mats, bound


GOLD = models.Conductor(eta=[0.143, 0.374, 1.442], k=[3.983, 2.385, 1.603])

#: (model, expected {material: {param: (type, value)}}) per case; "NAME" is the material name.
TABLE = {
    "diffuse": (
        models.Lambert(albedo=[0.5, 0.4, 0.3]),
        {"NAME": {"type": ("string", ["diffuse"]), "reflectance": ("rgb", [0.5, 0.4, 0.3])}},
    ),
    "conductor": (
        models.TorranceSparrow(alpha=0.3, distribution="ggx", shadowing="smith", fresnel=GOLD),
        {
            "NAME": {
                "type": ("string", ["conductor"]),
                "eta": ("rgb", [0.143, 0.374, 1.442]),
                "k": ("rgb", [3.983, 2.385, 1.603]),
                "roughness": ("float", [0.3]),  # alpha itself ...
                "remaproughness": ("bool", "false"),  # ... because the remap is off
            }
        },
    ),
    "dielectric-fresnel": (
        models.TorranceSparrow(
            alpha=0.1, distribution="ggx", shadowing="smith", fresnel=models.Dielectric(1.5)
        ),
        {
            "NAME": {
                "type": ("string", ["conductor"]),
                "eta": ("rgb", [1.5, 1.5, 1.5]),
                "k": ("rgb", [0.0, 0.0, 0.0]),
                "roughness": ("float", [0.1]),
                "remaproughness": ("bool", "false"),
            }
        },
    ),
    "mix": (
        models.Scaled(models.Lambert(albedo=[0.8, 0.6, 0.4]), 0.7)
        + models.Scaled(
            models.TorranceSparrow(alpha=0.2, distribution="ggx", shadowing="smith", fresnel=GOLD),
            0.3,
        ),
        {
            "NAME_diffuse": {
                "type": ("string", ["diffuse"]),
                "reflectance": ("rgb", [0.8, 0.6, 0.4]),
            },
            "NAME_conductor": {
                "type": ("string", ["conductor"]),
                "eta": ("rgb", [0.143, 0.374, 1.442]),
                "k": ("rgb", [3.983, 2.385, 1.603]),
                "roughness": ("float", [0.2]),
                "remaproughness": ("bool", "false"),
            },
            "NAME": {
                "type": ("string", ["mix"]),
                "materials": ("string", ["NAME_diffuse", "NAME_conductor"]),
                "amount": ("float", [0.3]),
            },
        },
    ),
}


@pytest.mark.parametrize("key", list(TABLE))
def test_block_matches_table(key):
    model, expected = TABLE[key]
    e = to_pbrt(fit_record(model))
    assert e.mapping == "exact"
    mats, bound = parse(e.text)
    assert bound == e.name
    want = {
        k.replace("NAME", e.name): {
            p: (t, [x.replace("NAME", e.name) for x in v] if t == "string" else v)
            for p, (t, v) in params.items()
        }
        for k, params in expected.items()
    }
    assert set(mats) == set(want)
    for name, params in want.items():
        assert set(mats[name]) == set(params), name
        for p, (t, v) in params.items():
            got_t, got_v = mats[name][p]
            assert got_t == t, (name, p)
            if t in ("float", "rgb"):
                assert np.allclose(got_v, v, rtol=1e-8), (name, p)
            else:
                assert got_v == v, (name, p)


def test_unscaled_sum_is_refitted():
    """Lambert + GGX has no pbrt material (the conductor has no scale): it is refitted to the
    0.5 / 0.5 mix, with both losses reported."""
    model = models.Lambert(albedo=[0.3, 0.3, 0.3]) + models.TorranceSparrow(
        alpha=0.2, distribution="ggx", shadowing="smith", fresnel=GOLD
    )
    e = to_pbrt(fit_record(model), refit_from="model", price=False)
    assert e.mapping == "refit"
    mats, _ = parse(e.text)
    assert mats[e.name]["amount"] == ("float", [0.5])
    assert e.refit["original_loss_on_refit_data"] == pytest.approx(0.0, abs=1e-12)
    assert e.refit["refit_loss"] > 0
    assert any(n.startswith("REFIT, not the fit: pbrt cannot express") for n in e.notes)
