"""Ngan et al. (2005) fits: parsing, and the same parameters give the same lobes as bbm's
definitions (evaluated here independently in NumPy)."""

import numpy as np
import pytest

from gonio.brdf import models
from gonio.brdf.ngan import NganFit, parse_ngan_fits, to_model
from gonio.errors import FormatError, ParameterError
from tests.brdf import model_checks as mc
from tests.brdf import zoo_checks as zc
from tests.conftest import shared_file


def _read(name):
    return parse_ngan_fits(shared_file("fits", name).read_text())


def _pairs(n_random=1500, seed=0, lobe_width=0.05):
    """Random pairs plus pairs near the mirror direction (where sharp lobes live), (N, 3) each."""
    wo = mc.random_upper(n_random, seed, max_theta=np.radians(85))
    wi = mc.random_upper(n_random, seed + 1)
    rng = np.random.default_rng(seed + 2)
    wo2 = mc.random_upper(n_random, seed + 3, max_theta=np.radians(80))
    wi2 = wo2 * [-1, -1, 1] + rng.normal(scale=lobe_width, size=wo2.shape)
    wi2[:, 2] = np.abs(wi2[:, 2]) + 1e-3
    wi2 /= np.linalg.norm(wi2, axis=-1, keepdims=True)
    return np.concatenate([wi, wi2]), np.concatenate([wo, wo2])


def bbm_ward(albedo, a, wi, wo):
    h = wi + wo
    e = (h[:, 0] ** 2 + h[:, 1] ** 2) / (a * a * h[:, 2] ** 2)
    return np.outer(np.exp(-e) / (4 * np.pi * a * a * np.sqrt(wi[:, 2] * wo[:, 2])), albedo)


def bbm_phong(albedo, n, wi, wo):
    refl = wi * [-1, -1, 1]
    c = np.maximum(np.sum(refl * wo, -1), 0)
    return np.outer((n + 2) / (2 * np.pi) * c**n, albedo)


def bbm_cook_torrance(albedo, f0, m, wi, wo):
    h = wi + wo
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    cos2 = h[:, 2] ** 2
    d = np.exp(-(1 - cos2) / cos2 / (m * m)) / (np.pi * m * m * cos2 * cos2)
    ih, oh = np.sum(wi * h, -1), np.sum(wo * h, -1)
    g = np.minimum(1, np.minimum(2 * h[:, 2] * wi[:, 2] / ih, 2 * h[:, 2] * wo[:, 2] / oh))
    f = f0 + (1 - f0) * (1 - 0.5 * (ih + oh)) ** 5
    return np.outer(d * g * f / (np.pi * wi[:, 2] * wo[:, 2]), albedo)


REFERENCE = {
    "ngan_ward.fit": lambda p, wi, wo: bbm_ward(np.array(p["albedo"]), p["roughness"], wi, wo),
    "ngan_blinnphong.fit": lambda p, wi, wo: bbm_phong(
        np.array(p["albedo"]), p["sharpness"], wi, wo
    ),
    "ngan_cooktorrance.fit": lambda p, wi, wo: bbm_cook_torrance(
        np.array(p["albedo"]), p["eta"], p["roughness"], wi, wo
    ),
}


@pytest.mark.parametrize("name", list(REFERENCE))
def test_same_parameters_same_lobes(name):
    fits = _read(name)
    assert len(fits) == 86
    checked, too_sharp = 0, 0
    for fit in fits.values():
        if fit.params.get("sharpness", 0) > 1e5:  # beyond gonio's exponent range
            too_sharp += 1
            with pytest.raises(ParameterError, match=fit.material):
                to_model(fit)
            continue
        width = fit.params.get("roughness", 1 / np.sqrt(fit.params.get("sharpness", 400)))
        wi, wo = _pairs(lobe_width=width)
        got = np.asarray(to_model(fit).f(wi, wo))
        expect = REFERENCE[name](fit.params, wi, wo) + np.array(fit.diffuse_albedo) / np.pi
        np.testing.assert_allclose(got, expect, rtol=1e-6, atol=1e-290, err_msg=fit.material)
        checked += 1
    assert checked + too_sharp == 86 and too_sharp <= 5


def test_parser_reads_values_exactly():
    text = (
        "# comment\n\n"
        "blue-acrylic = Aggregate(Lambertian(albedo = [0.0143, 0.033, 0.0639]), "
        "NganCookTorrance(albedo = [0.0291, 0.0193, 0.0118], eta = 0.117, roughness = 1.37e-2))\n"
    )
    fit = parse_ngan_fits(text)["blue-acrylic"]
    assert fit == NganFit(
        "blue-acrylic",
        (0.0143, 0.033, 0.0639),
        "NganCookTorrance",
        {"albedo": (0.0291, 0.0193, 0.0118), "eta": 0.117, "roughness": 0.0137},
    )
    m = to_model(fit)
    assert isinstance(m, models.Sum)
    np.testing.assert_allclose(
        np.asarray(m.lobes[1].scale), 4 * np.array([0.0291, 0.0193, 0.0118]) / np.pi
    )


@pytest.mark.parametrize(
    "text",
    [
        "x = Aggregate(Lambertian(albedo = 1), NganWard(albedo = 1, roughness = __import__('os')))",
        "x = Aggregate(Lambertian(albedo = [0.1]), NganWard(albedo = [0.1], roughness = 0.1)",
        "x = Something(Lambertian(albedo = [0.1]), NganWard(albedo = [0.1], roughness = 0.1))",
        "x Aggregate(Lambertian(albedo = [0.1]), NganWard(albedo = [0.1], roughness = 0.1))",
        "x = Aggregate(Lambertian(albedo = [0.1]), NganWard(albedo = 0.1, roughness = 0.1)) extra",
    ],
)
def test_parser_rejects_bad_text(text):
    with pytest.raises(FormatError):
        parse_ngan_fits(text)


def test_unsupported_or_incomplete_models_raise():
    with pytest.raises(FormatError, match="unsupported"):
        to_model(NganFit("m", (0.1,), "NganHe", {"roughness": 0.1}))
    with pytest.raises(FormatError, match="needs"):
        to_model(NganFit("m", (0.1,), "NganWard", {"albedo": 0.1}))


def test_scaled_lobe_properties():
    fit = _read("ngan_cooktorrance.fit")["black-oxidized-steel"]
    m = to_model(fit)
    mc.check_reciprocity(m, n=500)
    mc.check_sample_weight_consistent(zc.Jitted(m), n=500)
    again = models.Node.from_dict(m.to_dict())
    assert repr(again) == repr(m)
    assert "scaled.scale" in m.params() and "scaled.lobe.alpha" in m.params()
