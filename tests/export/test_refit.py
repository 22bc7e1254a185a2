"""A Ward fit of a glossy table exported to Blender is refitted to GGX; the reported refit loss
is the loss the test computes itself from the exported Blender parameters and the table."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gonio import io
from gonio.brdf import models
from gonio.brdf.measured import MeasuredSamples
from gonio.brdf.tabulated import Axis, TabulatedBRDF
from gonio.export import to_blender
from gonio.fit import fit

HALF = math.pi / 2
AXES = (
    Axis("theta_h", 24, 0.0, HALF, "sqrt", False, 0.0),
    Axis("theta_d", 16, 0.0, HALF, "linear", False, 0.0),
    Axis("phi_d", 16, 0.0, math.pi, "linear", True, 0.0),
)
GLOSSY = models.Lambert(albedo=[0.25, 0.2, 0.15]) + models.TorranceSparrow(
    alpha=0.12, distribution="ggx", shadowing="smith", fresnel=models.Schlick(0.05)
)


@pytest.fixture(scope="module")
def ward_fit(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("refit")
    table = TabulatedBRDF.from_model(GLOSSY, axes=AXES)
    path = io.save(table, tmp / "glossy.brdf.h5") or tmp / "glossy.brdf.h5"
    result = fit(str(path), model="lambert+ward", loss="wls")
    fit_json = result.save(tmp / "ward.json")
    return path, fit_json, result


def test_ward_to_blender_is_refitted_to_ggx(ward_fit):
    table_path, _, ward = ward_fit
    # the FitResult itself (DESIGN.md: export.to_blender(fit_result)); the losses, unpriced
    e = to_blender(ward, price=False)
    assert e.mapping == "refit"
    r = e.refit
    assert r["data"]["kind"] == "measurement" and r["data"]["path"] == str(table_path)
    assert r["family"] == "Lambert + TorranceSparrow(ggx, smith, Schlick)"
    assert r["metric"] == "wls" and r["original_loss"] == pytest.approx(ward.loss)
    # The original model on the refit data: the same number as the fit recorded.
    assert r["original_loss_on_refit_data"] == pytest.approx(ward.loss, rel=1e-9)

    # Independent evaluation: rebuild the material from the Blender parameters alone
    # (Roughness^2 = alpha, Base Color = Schlick f0, Diffuse Color = albedo), evaluate it on
    # the table's samples within the fit's cutoff and sum the squared residuals (wls without
    # sigma: sigma = 1).
    p = e.params
    alpha = p["Principled BSDF"]["Roughness"] ** 2
    assert p["Principled BSDF"]["Metallic"] == 1.0
    rebuilt = models.Lambert(albedo=p["Diffuse BSDF"]["Color"]) + models.TorranceSparrow(
        alpha=alpha,
        distribution="ggx",
        shadowing="smith",
        fresnel=models.Schlick(p["Principled BSDF"]["Base Color"]),
    )
    s = MeasuredSamples.from_table(io.load(table_path))
    wi, wo = np.asarray(s.wi, np.float64), np.asarray(s.wo, np.float64)
    y = np.asarray(s.values, np.float64).reshape(len(wi), -1)
    cmax = math.cos(math.radians(80.0)) - 1e-12
    keep = (wi[:, 2] >= cmax) & (wo[:, 2] >= cmax) & np.all(np.isfinite(y), axis=1)
    if getattr(s, "weights", None) is not None:
        keep &= np.asarray(s.weights) > 0
    f = np.asarray(rebuilt.f(wi[keep], wo[keep]), np.float64)
    loss = float(np.sum((f - y[keep]) ** 2))
    assert keep.sum() == r["data"]["n_samples"]
    assert r["refit_loss"] == pytest.approx(loss, rel=1e-6)
    # GGX is the table's own family: the refit must beat Ward.
    assert r["refit_loss"] < ward.loss
    assert abs(alpha - 0.12) < 0.01


def test_refit_from_model_when_the_table_is_gone(ward_fit, tmp_path):
    _, fit_json, _ = ward_fit
    rec = fit_json.read_text().replace('"path": "', '"path": "/nonexistent/')
    moved = tmp_path / "ward.json"
    moved.write_text(rec)
    e = to_blender(moved, price=False)
    assert e.mapping == "refit" and e.refit["data"]["kind"] == "sampled model"
    assert e.refit["original_loss_on_refit_data"] == pytest.approx(0.0, abs=1e-12)
