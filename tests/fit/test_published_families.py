"""The literature's families as presets, published fits as gonio models, scores, fit options.

Formulas are checked against NumPy written here from the papers' definitions; published fits
(``../shared/data/fits``) are loaded, evaluated, scored and refitted in their own family.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import gonio.fit as gf
from gonio.brdf import models, ngan
from gonio.cli import main
from gonio.errors import FitError
from gonio.fit import presets
from gonio.fit.api import FitOptions, _degenerate
from gonio.fit.compare import summarize
from gonio.fit.data import from_arrays
from gonio.fit.params import Layout
from gonio.fit.score import score
from tests.brdf import model_checks as mc
from tests.brdf import zoo_checks as zc
from tests.conftest import shared_file
from tests.fit.synth import cosine_directions, synthetic


def _pairs(n=3000, seed=0):
    rng = np.random.default_rng(seed)
    wo = mc.random_upper(n, seed, max_theta=np.radians(85))
    wi = mc.random_upper(n, seed + 1)
    # plus pairs near the mirror direction, where the lobes live
    wi2 = wo * [-1, -1, 1] + rng.normal(scale=0.05, size=wo.shape)
    wi2[:, 2] = np.abs(wi2[:, 2]) + 1e-3
    wi2 /= np.linalg.norm(wi2, axis=-1, keepdims=True)
    return np.concatenate([wi, wi2]), np.concatenate([wo, wo])


def _cos_h(wi, wo):
    h = wi + wo
    return h[:, 2] / np.linalg.norm(h, axis=-1)


def _vcavity(wi, wo):
    h = wi + wo
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    oh = np.sum(wo * h, -1)
    return np.minimum(1, np.minimum(2 * h[:, 2] * wi[:, 2] / oh, 2 * h[:, 2] * wo[:, 2] / oh))


def test_cook_torrance_is_ngans_formula():
    rho, a, f0 = np.array([0.3, 0.2, 0.1]), 0.15, 0.3
    wi, wo = _pairs()
    got = np.asarray(models.CookTorrance(rho_s=rho, alpha=a, f0=f0).f(wi, wo))
    c = _cos_h(wi, wo)
    d = np.exp(-(1 - c * c) / (c * c) / a**2) / (math.pi * a**2 * c**4)
    h = (wi + wo) / np.linalg.norm(wi + wo, axis=-1, keepdims=True)
    fr = f0 + (1 - f0) * (1 - np.sum(wi * h, -1)) ** 5
    want = np.outer(d * _vcavity(wi, wo) * fr / (math.pi * wi[:, 2] * wo[:, 2]), rho)
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-300)


def test_ngan_blinn_phong_and_low_formulas():
    wi, wo = _pairs()
    c = _cos_h(wi, wo)
    got = np.asarray(models.NganBlinnPhong(rho_s=[0.1, 0.2], n=300.0).f(wi, wo))
    np.testing.assert_allclose(got, np.outer((302 / (2 * math.pi)) * c**300, [0.1, 0.2]),
                               rtol=1e-9, atol=1e-300)  # fmt: skip
    A, B, C, eta = np.array([2.0, 1.0]), 400.0, 0.7, 1.6
    got = np.asarray(models.LowMicrofacet(A=A, B=B, C=C, eta=eta).f(wi, wo))
    h = (wi + wo) / np.linalg.norm(wi + wo, axis=-1, keepdims=True)
    ci = np.sum(wi * h, -1)
    ct = np.sqrt(1 - (1 - ci**2) / eta**2)
    fr = 0.5 * (((ci - eta * ct) / (ci + eta * ct)) ** 2 + ((eta * ci - ct) / (eta * ci + ct)) ** 2)
    s = (1 + B * (1 - c)) ** -C
    want = np.outer(s * fr * _vcavity(wi, wo) / (math.pi * wi[:, 2] * wo[:, 2]), A)
    np.testing.assert_allclose(got, want, rtol=1e-8)


@pytest.mark.parametrize(
    "m",
    [
        models.CookTorrance(rho_s=[0.3, 0.2, 0.1], alpha=0.2, f0=0.4),
        models.NganBlinnPhong(rho_s=0.2, n=80.0),
        models.LowMicrofacet(A=1.0, B=300.0, C=0.8, eta=1.5),
    ],
    ids=["cook-torrance", "ngan-blinn-phong", "low"],
)
def test_new_lobes_sample_consistently_and_are_reciprocal(m):
    mc.check_reciprocity(m, n=500)
    mc.check_sample_weight_consistent(zc.Jitted(m), n=1000)
    again = models.Node.from_dict(m.to_dict())
    assert repr(again) == repr(m)


@pytest.mark.parametrize("fname", ["ngan_cooktorrance.fit", "ngan_ward.fit"])
def test_published_fits_load_as_the_preset_family_and_equal_bbm(fname):
    fits = ngan.parse_ngan_fits(shared_file("fits", fname).read_text())
    wi, wo = _pairs(400)
    for fit in list(fits.values())[::5]:
        preset, model = ngan.to_family(fit)
        tmpl, _fixed, _tied = presets.build(preset)
        assert set(model.params()) == set(tmpl.params())  # same structure as a gonio fit
        np.testing.assert_allclose(np.asarray(model.f(wi, wo)),
                                   np.asarray(ngan.to_model(fit).f(wi, wo)), rtol=1e-9,
                                   atol=1e-300, err_msg=fit.material)  # fmt: skip


def test_published_blinn_phong_loads_with_the_half_vector_including_huge_exponents():
    fits = ngan.parse_ngan_fits(shared_file("fits", "ngan_blinnphong.fit").read_text())
    sharp = max(fits.values(), key=lambda f: f.params["sharpness"])
    assert sharp.params["sharpness"] > 1e5  # beyond Phong's range, inside NganBlinnPhong's
    preset, _model = ngan.to_family(sharp)
    assert preset == "lambert+ngan-blinn-phong"
    assert ngan.to_family(fits["blue-acrylic"], "bbm")[0] == "lambert+phong"


def test_published_cook_torrance_is_refitted_in_its_family():
    fit = ngan.parse_ngan_fits(shared_file("fits", "ngan_cooktorrance.fit").read_text())["pvc"]
    _, truth = ngan.to_family(fit)
    rng = np.random.default_rng(3)
    wi, wo = cosine_directions(4000, rng), cosine_directions(4000, rng)
    data = from_arrays(wi, wo, np.asarray(truth.f(wi, wo)), name="pvc")
    res = gf.fit(data, "lambert+cook-torrance", loss="ngan", n_starts=12)
    s_pub, s_fit = score(truth, data), score(res.model, data)
    assert s_fit["ngan"] <= s_pub["ngan"] + 1e-9  # the published model scores 0 here
    p = res.params
    np.testing.assert_allclose(p["cooktorrance.alpha"], fit.params["roughness"], rtol=1e-3)
    np.testing.assert_allclose(p["cooktorrance.f0"], fit.params["eta"], rtol=1e-2)
    np.testing.assert_allclose(p["cooktorrance.rho_s"], fit.params["albedo"], rtol=1e-2)
    assert "cooktorrance.f0[R]" not in res.flat_names  # one F0, as published


def test_score_is_the_literatures_formulas_on_cell_measures():
    rng = np.random.default_rng(0)
    wi, wo = cosine_directions(500, rng), cosine_directions(500, rng)
    w = rng.uniform(0.5, 2.0, 500)
    m = models.Lambert(0.2) + models.CookTorrance(rho_s=0.3, alpha=0.2, f0=0.2)
    y = np.asarray(m.f(wi, wo)) * rng.uniform(0.8, 1.2, (500, 1))
    data = from_arrays(wi, wo, y, weights=w, theta_max_deg=90)
    f = np.asarray(models.Lambert(0.25).f(wi, wo))
    s = score(models.Lambert(0.25), data)
    ci = wi[:, 2:3]
    ngan_ref = np.sqrt(np.sum(w[:, None] * ((f - y) * ci) ** 2) / w.sum())
    e2_ref = np.sqrt(np.sum(w[:, None] * (np.log1p(f) - np.log1p(y)) ** 2) / w.sum())
    assert s["ngan"] == pytest.approx(ngan_ref, rel=1e-12)
    assert s["low-e2"] == pytest.approx(e2_ref, rel=1e-12)


def test_fit_options_object_and_overrides():
    data, _ = synthetic(models.Lambert(0.4), n=300, seed=1, with_sigma=False)
    a = gf.fit(data, "lambert", options=FitOptions(loss="ngan", n_starts=2))
    b = gf.fit(data, "lambert", options=FitOptions(loss="ngan"), n_starts=2)
    assert a.metric == b.metric == "ngan" and a.params == b.params
    with pytest.raises(FitError, match="unknown fit option"):
        gf.fit(data, "lambert", n_strats=3)


def test_auto_loss_is_relative_without_sigma_and_chi_square_with_it():
    no_sigma, _ = synthetic(models.Lambert(0.4), n=300, seed=2, with_sigma=False)
    with_sigma, _ = synthetic(models.Lambert(0.4), n=300, seed=2)
    assert gf.fit(no_sigma, "lambert").metric == "low-e1"
    assert gf.fit(with_sigma, "lambert").metric == "wls"


def test_spectral_fits_share_one_grey_f0_by_default():
    truth = models.Lambert(np.linspace(0.1, 0.5, 6)) + models.TorranceSparrow(
        alpha=0.2, fresnel=models.Schlick(0.05)
    )
    data, _ = synthetic(truth, n=600, seed=3)
    res = gf.fit(data, "lambert+ts", n_starts=2)
    f0 = [n for n in res.flat_names if "f0" in n]
    assert f0 == ["torrancesparrow.fresnel.f0"]
    per = gf.fit(data, "lambert+ts", n_starts=2, grey_fresnel=False)
    assert len([n for n in per.flat_names if "f0" in n]) == 6


def test_degenerate_needles_are_detected_and_not_recommended():
    tmpl, fixed, tied = presets.build("lambert+ts")
    layout = Layout(tmpl, 1, fixed=fixed, tied=tied)
    lo, _hi = layout.box()
    u = layout.initial()
    assert _degenerate(layout, u) == []
    i = layout.keys.index("torrancesparrow.alpha")
    u[layout.entries[i].offset] = lo[layout.entries[i].offset]
    assert _degenerate(layout, u) == ["torrancesparrow.alpha"]
    data, _ = synthetic(models.Lambert(0.3) + models.Phong(rho_d=0.0, rho_s=0.3, n=30.0), n=400)
    good, bad = gf.fit(data, ["lambert+phong", "lambert+ward"], n_starts=2)
    bad.optimizer["on_bounds"] = ["ward.alpha_x"]
    bad.bic = good.bic - 100.0  # better by BIC, but flagged
    comp = summarize([good, bad])
    assert comp.recommended == "lambert+phong" and "not considered: lambert+ward" in comp.reason


def test_mcmc_runs_with_every_loss_and_contains_its_mode():
    data, _ = synthetic(models.Lambert(0.3) + models.Phong(rho_d=0.0, rho_s=0.3, n=30.0), n=300,
                        seed=6, with_sigma=False)  # fmt: skip
    for loss in ("ngan", "low-e2"):
        r = gf.fit(data, "lambert+phong", loss=loss, uncertainty="mcmc", mcmc_steps=200,
                   n_starts=2)  # fmt: skip
        unc = r.uncertainty
        mode = np.array([unc.diagnostics["mode"][n] for n in unc.names])
        assert np.all((unc.interval95[:, 0] <= mode) & (mode <= unc.interval95[:, 1]))


def test_score_cli_prints_both_metrics_of_a_published_fit(tmp_path, capsys):
    fit = ngan.parse_ngan_fits(shared_file("fits", "ngan_ward.fit").read_text())["pvc"]
    _, m = ngan.to_family(fit)
    rng = np.random.default_rng(0)
    wi, wo = cosine_directions(300, rng), cosine_directions(300, rng)
    from gonio.brdf.measured import MeasuredSamples
    from gonio.io import save

    y = np.asarray(m.f(wi, wo)) * 1.1
    p = tmp_path / "pvc.brdf.h5"
    save(MeasuredSamples(wi, wo, y, meta={"name": "pvc"}), p)
    assert main(["fit", str(p), "--score", str(shared_file("fits", "ngan_ward.fit"))]) == 0
    out = capsys.readouterr().out
    assert "published lambert+ward" in out and "ngan" in out and "low-e2" in out


@pytest.mark.slow
def test_default_intervals_cover_best_in_family_parameters_of_a_wrong_model():
    """Truth: Lambert + half-vector Blinn-Phong; fitted: Lambert + Ward (the wrong lobe shape).
    The best-in-family parameters come from a fit to 40 000 noise-free samples of the same
    design; 60 replicates of 300 noisy samples without sigma (3 % relative noise) are fitted
    with the default loss and Laplace intervals (cluster sandwich, the default without sigma).
    Nominal 95 %: at least 52 of 60 covering (binomial P(X <= 51 | 0.95) = 0.003)."""
    truth = models.Lambert(0.3) + models.NganBlinnPhong(rho_s=0.15, n=40.0)
    rng = np.random.default_rng(11)
    wi, wo = cosine_directions(40000, rng), cosine_directions(40000, rng)
    big = from_arrays(wi, wo, np.asarray(truth.f(wi, wo)))
    best = gf.fit(big, "lambert+ward", n_starts=8).params
    keys = ["lambert.albedo", "ward.rho_s", "ward.alpha_x"]
    covered = {k: 0 for k in keys}
    for trial in range(60):
        r = np.random.default_rng(100 + trial)
        wi, wo = cosine_directions(300, r), cosine_directions(300, r)
        f = np.asarray(truth.f(wi, wo))
        y = f * (1 + 0.03 * r.standard_normal(f.shape))
        res = gf.fit(from_arrays(wi, wo, y), "lambert+ward", uncertainty="laplace", n_starts=4)
        assert res.uncertainty.diagnostics["covariance"] == "cluster"
        iv = res.intervals(95)
        for k in keys:
            covered[k] += float(iv[k][0]) <= best[k] <= float(iv[k][1])
    print("covered of 60:", covered)
    assert all(c >= 52 for c in covered.values()), covered


def test_fit_cli_says_which_loss_without_sigma_and_scores_fits(tmp_path, capsys):
    from gonio.brdf.measured import MeasuredSamples
    from gonio.io import save

    rng = np.random.default_rng(2)
    wi, wo = cosine_directions(300, rng), cosine_directions(300, rng)
    p = tmp_path / "grey.brdf.h5"
    save(MeasuredSamples(wi, wo, np.full((300, 1), 0.1), meta={"name": "grey"}), p)
    args = ["fit", str(p), "-m", "lambert", "--score", "--no-plots", "-o", str(tmp_path / "o")]
    assert main(args) == 0
    cap = capsys.readouterr()
    assert "has no sigma: fitting with low-e1" in cap.err
    assert "score lambert: ngan" in cap.out and "low-e2" in cap.out
