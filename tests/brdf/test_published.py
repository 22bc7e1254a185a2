"""Every published fit file's reader: one material per file, against bbm's formulas written
out independently in NumPy (``include/bsdfmodel/`` of the BSDF benchmark library)."""

import jax
import numpy as np
import pytest

from gonio.brdf import models
from gonio.brdf.ngan import parse_ngan_fits
from gonio.brdf.published import to_model
from gonio.errors import FormatError
from tests.brdf import model_checks as mc
from tests.conftest import shared_file


def _pairs(n=100, seed=0, width=0.05):
    """Random pairs plus pairs near the mirror direction, (N, 3) each, theta <= 80 deg."""
    wo = mc.random_upper(n, seed, max_theta=np.radians(80))
    wi = mc.random_upper(n, seed + 1, max_theta=np.radians(80))
    rng = np.random.default_rng(seed + 2)
    wo2 = mc.random_upper(n, seed + 3, max_theta=np.radians(75))
    wi2 = wo2 * [-1, -1, 1] + rng.normal(scale=width, size=wo2.shape)
    wi2[:, 2] = np.abs(wi2[:, 2]) + 1e-2
    wi2 /= np.linalg.norm(wi2, axis=-1, keepdims=True)
    return np.concatenate([wi, wi2]), np.concatenate([wo, wo2])


_F = jax.jit(lambda m, wi, wo: m.f(wi, wo))


def _half(wi, wo):
    h = wi + wo
    return h / np.linalg.norm(h, axis=-1, keepdims=True)


def _cook_fresnel(eta, c):
    g = np.sqrt(eta * eta + c * c - 1.0)
    a = (g - c) / (g + c)
    b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
    return 0.5 * a * a * (1.0 + b * b)


def _vgroove(wi, wo, h):
    ih, oh = np.sum(wi * h, -1), np.sum(wo * h, -1)
    return np.minimum(1, np.minimum(2 * h[:, 2] * wi[:, 2] / ih, 2 * h[:, 2] * wo[:, 2] / oh))


def _col(x):
    return np.asarray(x, float)[None, :] if np.ndim(x) else np.asarray([[x]], float)


def ward_duer(p, wi, wo):
    a, h = p["roughness"], wi + wo
    e = (h[:, 0] ** 2 + h[:, 1] ** 2) / (a * a * h[:, 2] ** 2)
    return (np.exp(-e) / (4 * np.pi * a * a * wi[:, 2] * wo[:, 2]))[:, None] * _col(p["albedo"])


def lafortune(p, wi, wo):
    n, cxy, cz = p["sharpness"], p["Cxy"], p["Cz"]
    x = cxy * (wi[:, 0] * wo[:, 0] + wi[:, 1] * wo[:, 1]) + cz * wi[:, 2] * wo[:, 2]
    v = np.maximum(x, 0) ** n * (n + 2) / (2 * np.pi) / max(cz * cz, cxy * cxy) ** (n / 2)
    return v[:, None] * _col(p["albedo"])


def _as(p, wi, wo, fresnel):
    h = _half(wi, wo)
    ih = np.sum(wi * h, -1)
    n = p["sharpness"]
    v = (n + 1) / (8 * np.pi) * h[:, 2] ** n / (ih * np.maximum(wi[:, 2], wo[:, 2]))
    return (v * fresnel(ih))[:, None] * _col(p["albedo"])


def ngan_as(p, wi, wo):
    f0 = p["fresnelReflectance"]
    return _as(p, wi, wo, lambda c: f0 + (1 - f0) * (1 - c) ** 5)


def low_as(p, wi, wo):
    return _as(p, wi, wo, lambda c: _cook_fresnel(p["fresnelReflectance"], c))


def low_ct(p, wi, wo):
    h = _half(wi, wo)
    m, c2 = p["roughness"], h[:, 2] ** 2
    d = np.exp(-(1 - c2) / c2 / (m * m)) / (m * m * c2 * c2)  # bbm: not normalized
    f = _cook_fresnel(p["eta"], np.sum(wi * h, -1))
    v = d * _vgroove(wi, wo, h) * f / (np.pi * wi[:, 2] * wo[:, 2])
    return v[:, None] * _col(p["albedo"])


def low_microfacet(p, wi, wo):
    h = _half(wi, wo)
    s = (1 + p["B"] * (1 - h[:, 2])) ** -p["C"]
    f = _cook_fresnel(p["eta"], np.sum(wi * h, -1))
    v = s * _vgroove(wi, wo, h) * f / (np.pi * wi[:, 2] * wo[:, 2])
    return v[:, None] * _col(p["A"])


def low_smooth(p, wi, wo):
    dp2 = np.sum((wi[:, :2] + wo[:, :2]) ** 2, -1)
    cos_d = np.sqrt(1 - 0.25 * np.sum((wi[:, :2] - wo[:, :2]) ** 2, -1))
    v = (1 + p["B"] * dp2) ** -p["C"] * _cook_fresnel(p["eta"], cos_d)
    return v[:, None] * _col(p["A"])


def bagher(p, wi, wo):
    h = _half(wi, wo)
    tan2 = ((1 - h[:, 2] ** 2) / h[:, 2] ** 2)[:, None]
    a, pp = _col(p["alpha"]), _col(p["p"])
    t = a + tan2 / a
    d = _col(p["K"]) * np.exp(-t) / t**pp / (np.pi * h[:, 2:3] ** 4)

    def g1(v):
        th = np.arccos(v[:, 2])[:, None]
        t0 = _col(p["theta0"])
        with np.errstate(invalid="ignore", over="ignore"):
            g = 1 + _col(p["Lambda"]) * (1 - np.exp(_col(p["c"]) * (th - t0) ** _col(p["k"])))
        return np.where(th > t0, g, 1.0)

    x = np.sum(wi * h, -1)[:, None]
    f0, f1 = _col(p["eta"][0]), _col(p["eta"][1])
    fres = f0 + (1 - f0) * (1 - x) ** 5 - f1 * x
    return _col(p["albedo"]) * d * g1(wi) * g1(wo) * fres / (np.pi * wi[:, 2:3] * wo[:, 2:3])


CASES = {  # file: (material, reference lobe)
    "ngan_wardduer.fit": ("alum-bronze", ward_duer),
    "ngan_lafortune.fit": ("alum-bronze", lafortune),
    "ngan_ashikhminshirley.fit": ("alum-bronze", ngan_as),
    "low_ashikhminshirley_E1.fit": ("alum-bronze", low_as),
    "low_ashikhminshirley_E2.fit": ("beige-fabric", low_as),
    "low_cooktorrance_E1.fit": ("alum-bronze", low_ct),
    "low_cooktorrance_E2.fit": ("black-fabric", low_ct),
    "low_lowmicrofacet_E2.fit": ("chrome", low_microfacet),
    "low_lowsmooth_E2.fit": ("alum-bronze", low_smooth),
    # chrome-steel: the shadowing scale c reaches 1e109 (formed in log space by the model)
    "bagher_sgd.fit": ("chrome-steel", bagher),
}


@pytest.mark.parametrize("name", list(CASES))
def test_published_fit_is_bbms_model(name):
    material, reference = CASES[name]
    fit = parse_ngan_fits(shared_file("fits", name).read_text())[material]
    wi, wo = _pairs()
    got = np.asarray(_F(to_model(fit), wi, wo))
    expect = reference(fit.params, wi, wo) + np.array(fit.diffuse_albedo) / np.pi
    np.testing.assert_allclose(got, expect, rtol=1e-6, atol=1e-12, err_msg=f"{name} {material}")


@pytest.mark.parametrize(
    ("name", "material"),
    [
        ("low_cooktorrance_E1.fit", "polyurethane-foam"),
        ("low_cooktorrance_E1.fit", "white-fabric2"),
        ("low_cooktorrance_E2.fit", "polyurethane-foam"),
    ],
)
def test_low_cook_torrance_rougher_than_one_is_bbms_model(name, material):
    """Löw's three Cook-Torrance fits with m > 1 (the Beckmann distribution is normalized for
    any m): converted, and equal to bbm's formula."""
    fit = parse_ngan_fits(shared_file("fits", name).read_text())[material]
    assert fit.params["roughness"] > 1
    wi, wo = _pairs()
    got = np.asarray(_F(to_model(fit), wi, wo))
    expect = low_ct(fit.params, wi, wo) + np.array(fit.diffuse_albedo) / np.pi
    np.testing.assert_allclose(got, expect, rtol=1e-6, atol=1e-12)


def test_fits_search_torrance_sparrow_roughness_up_to_one_only():
    from gonio.fit.params import Layout

    layout = Layout(models.TorranceSparrow(alpha=0.3), 3)
    (entry,) = [e for e in layout.entries if e.key == "alpha"]
    assert entry.hi == 1.0 and np.exp(entry.box[1]) == pytest.approx(1.0)
    assert models.TorranceSparrow(alpha=2.09).alpha == 2.09


def test_ngan_he_is_refused_by_name():
    fit = parse_ngan_fits(shared_file("fits", "ngan_he.fit").read_text())["alum-bronze"]
    with pytest.raises(FormatError, match="NganHe"):
        to_model(fit)


NEW_LOBES = {
    "low-smooth": lambda: models.LowSmooth(A=[2.0, 1.0, 1.0], B=300.0, C=0.8, eta=1.5),
    "as-lobe": lambda: models.AshikhminShirleyLobe([0.5, 0.4, 0.3], 300.0, models.Dielectric(1.6)),
    "bagher": lambda: models.BagherSGD(rho_s=0.5, alpha=0.01, p=0.3, f0=0.9, f1=0.1, K=50.0),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", list(NEW_LOBES))
def test_new_lobes_sample_what_they_report(name):
    mc.check_reciprocity(NEW_LOBES[name](), n=300)
    mc.check_sample_weight_consistent(NEW_LOBES[name](), n=300)
