import json

import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

import gonio.fit as gf
from gonio.brdf import models
from gonio.errors import FitError, FormatError
from gonio.fit.data import from_arrays
from gonio.fit.losses import get_loss
from gonio.fit.objective import Problem
from gonio.fit.params import Layout
from gonio.io.fit_result import SCHEMA, read_result, schema_path, schema_text
from tests.fit.lobes import TestLobe
from tests.fit.synth import cosine_directions, synthetic

TRUTH = models.Lambert(albedo=[0.5, 0.3, 0.2]) + TestLobe(rho_s=[0.2, 0.25, 0.3], n=50.0)


def _flat_truth(result):
    out = []
    for name in result.flat_names:
        key, _, ch = name.partition("[")
        v = np.atleast_1d(np.asarray(TRUTH.params()[key]))
        out.append(v[("RGB".index(ch[0])) if ch else 0] if v.size > 1 else v[0])
    return np.array(out)


@pytest.fixture(scope="module")
def fitted():
    data, _ = synthetic(TRUTH, n=2500, seed=11)
    return data, gf.fit(data, model=models.Lambert() + TestLobe(), uncertainty="laplace")


def test_recovers_known_parameters_within_laplace_covariance(fitted):
    _, res = fitted
    unc = res.uncertainty
    truth = _flat_truth(res)
    assert res.optimizer["converged"] and not res.warnings
    # Mahalanobis distance of the estimate from the truth is chi-square with P dof
    cov = unc.correlation * np.outer(unc.std, unc.std)
    diff = unc.center - truth
    d2 = diff @ np.linalg.solve(cov, diff)
    assert d2 < stats.chi2.ppf(0.999, len(truth)), d2
    inside = (unc.interval95[:, 0] <= truth) & (truth <= unc.interval95[:, 1])
    assert inside.sum() >= len(truth) - 1
    assert res.reduced_chi2 == pytest.approx(1.0, abs=5 * np.sqrt(2 / res.dof))


def test_laplace_matches_analytic_linear_gaussian_albedo():
    # y = a / pi + N(0, s^2): MLE a = pi mean(y), sd(a) = pi s / sqrt(N), exactly.
    rng = np.random.default_rng(3)
    n, a, s = 400, 0.37, 0.02
    wi, wo = cosine_directions(n, rng), cosine_directions(n, rng)
    y = a / np.pi + s * rng.standard_normal(n)
    data = from_arrays(wi, wo, y, sigma=np.full(n, s), theta_max_deg=90)
    for method in ("gauss-newton", "hessian"):
        res = gf.fit(
            data,
            model=models.Lambert(),
            uncertainty="laplace",
            laplace_method=method,
            theta_max_deg=90,
        )
        unc = res.uncertainty
        a_hat = np.pi * np.mean(y)
        sd = np.pi * s / np.sqrt(n)
        assert res.params["albedo"] == pytest.approx(a_hat, rel=1e-8)
        # chi2/dof < 1 here or not, the scale is max(1, reduced); compare with that factor
        k = np.sqrt(max(1.0, unc.diagnostics["reduced_loss"]))
        assert unc.std[0] == pytest.approx(k * sd, rel=1e-6)
        lo, hi = unc.interval95[0]
        assert lo < a_hat < hi
        assert (hi - lo) / (2 * 1.959964 * k * sd) == pytest.approx(1.0, rel=1e-3)
    # without sigma the scale comes from the residuals: sd = pi sqrt(RSS/(N-1)) / sqrt(N)
    data2 = from_arrays(wi, wo, y, theta_max_deg=90)
    opts = dict(model=models.Lambert(), loss="wls", uncertainty="laplace", theta_max_deg=90)
    res2 = gf.fit(data2, covariance="residual", **opts)
    rss = np.sum((y - np.mean(y)) ** 2)
    assert res2.uncertainty.std[0] == pytest.approx(
        np.pi * np.sqrt(rss / (n - 1)) / np.sqrt(n), rel=1e-6
    )
    # the default without sigma is the cluster sandwich; with independent errors it estimates
    # the same spread (to the sampling error of ~200 clusters)
    res3 = gf.fit(data2, **opts)
    assert res3.uncertainty.diagnostics["covariance"] == "cluster"
    assert res3.uncertainty.std[0] == pytest.approx(res2.uncertainty.std[0], rel=0.15)


def test_mcmc_agrees_with_laplace_on_linear_case():
    rng = np.random.default_rng(4)
    n, a, s = 300, 0.6, 0.03
    wi, wo = cosine_directions(n, rng), cosine_directions(n, rng)
    y = a / np.pi + s * rng.standard_normal((n, 1))
    data = from_arrays(wi, wo, y, sigma=np.full((n, 1), s), theta_max_deg=90)
    kw = {"model": models.Lambert(), "theta_max_deg": 90}
    res = gf.fit(data, uncertainty="mcmc", mcmc_steps=800, **kw)
    lap = gf.fit(data, uncertainty="laplace", **kw).uncertainty
    unc = res.uncertainty
    assert unc.method == "mcmc" and unc.samples.shape[1] == 1
    assert unc.center[0] == pytest.approx(lap.center[0], abs=0.3 * lap.std[0])
    assert unc.std[0] == pytest.approx(lap.std[0], rel=0.25)
    d = unc.diagnostics
    assert 0.1 < d["acceptance_fraction"] < 0.9
    assert d["likelihood"] == "chi-square" and d["burnt_in"]  # sigma measured, noise reached
    assert set(d["autocorr_time"]) == {"albedo"}


def test_mcmc_discrepancy_widens_intervals_when_model_is_wrong():
    # data from Lambert + lobe, fitted with Lambert alone, sigma tiny: Laplace with s^2 = chi2
    # reduced and MCMC with the residual variance marginalized both give intervals wider than
    # the noise alone.
    data, _ = synthetic(
        models.Lambert(albedo=0.5) + TestLobe(rho_s=0.3, n=20.0),
        n=300,
        seed=2,
        rel_noise=0.001,
        abs_noise=1e-4,
    )
    res = gf.fit(data, model=models.Lambert(), uncertainty="mcmc", mcmc_steps=400)
    d = res.uncertainty.diagnostics
    assert d["likelihood"] != "chi-square" and d["residual_scale_sq"] > 100
    naive = np.pi * np.sqrt(1 / np.sum(1 / data.sigma[:, 0] ** 2))
    assert res.uncertainty.std[0] > 10 * naive


def test_json_round_trip_and_load_model(fitted, tmp_path):
    data, res = fitted
    path = res.save(tmp_path / "fit.json")
    obj = json.loads(path.read_text())
    for key in ("model", "params", "intervals", "loss", "metric", "data"):
        assert key in obj
    assert obj["intervals"]["testlobe.n"][0] < obj["params"]["testlobe.n"]
    assert len(obj["intervals"]["lambert.albedo"][0]) == 3
    model = gf.load_model(path)
    np.testing.assert_allclose(
        np.asarray(model.f(data.wi[:50], data.wo[:50])),
        np.asarray(res.model.f(data.wi[:50], data.wo[:50])),
        rtol=1e-12,
    )
    assert read_result(path)["data"]["n_samples"] == data.n


def test_published_schema_is_generated_from_code():
    assert schema_path().read_text() == schema_text()
    assert SCHEMA["properties"]["schema"]["const"] == "gonio/fit-result"


def test_load_model_rejects_bad_files(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(FormatError, match="not JSON"):
        gf.load_model(bad)
    bad.write_text(json.dumps({"schema": "gonio/fit-result", "version": 1}))
    with pytest.raises(FormatError, match="not a fit result"):
        gf.load_model(bad)
    with pytest.raises(FormatError, match="cannot read"):
        gf.load_model(tmp_path / "missing.json")


def test_laplace_draws_match_intervals_and_respect_bounds(fitted):
    # interior parameters: the draws' 2.5/97.5 percentiles are the 95 % interval (4000 draws:
    # a percentile's sampling error is ~0.1 sd, allow 0.25 sd)
    _, res = fitted
    unc = res.uncertainty
    assert unc.samples.shape == (4000, len(unc.names))
    q = np.percentile(unc.samples, [2.5, 97.5], axis=0).T
    finite = np.isfinite(unc.std)
    err = np.abs(q[finite] - unc.interval95[finite]) / unc.std[finite, None]
    assert err.max() < 0.25, err
    # a parameter on its lower bound (Oren-Nayar sigma of Lambertian data): no draw below it
    data, _ = synthetic(models.Lambert(albedo=0.5), n=400, seed=2)
    on = gf.fit(data, model="oren-nayar", uncertainty="laplace")
    i = on.flat_names.index("sigma")
    lower = models.OrenNayar().param_specs()["sigma"].lower
    assert on.uncertainty.samples[:, i].min() >= lower
    # and 2.5 % of them above its one-sided interval (binomial sd 0.25 %; 4 sd allowed)
    above = np.mean(on.uncertainty.samples[:, i] > on.uncertainty.interval95[i, 1])
    assert abs(above - 0.025) < 0.01


# -- stress ----------------------------------------------------------------------------------
def test_all_diffuse_data_puts_lobe_on_bound():
    data, _ = synthetic(models.Lambert(albedo=[0.4, 0.5, 0.6]), n=800, seed=1)
    res = gf.fit(data, model=models.Lambert() + TestLobe(), uncertainty="laplace")
    np.testing.assert_allclose(res.params["lambert.albedo"], [0.4, 0.5, 0.6], atol=0.02)
    # the lobe is either switched off or pushed to an unobservable exponent, and said so:
    # its reflectance is then unconstrained: listed as such, with no interval (NaN bounds)
    assert res.reduced_chi2 == pytest.approx(1.0, abs=5 * np.sqrt(2 / res.dof))
    off = np.asarray(res.params["testlobe.rho_s"]) < 0.01
    lo, hi = (np.asarray(b) for b in res.intervals()["testlobe.rho_s"])
    loose = [n for n in res.uncertainty.unconstrained if n.startswith("testlobe.rho_s")]
    assert np.all(off | (np.isnan(lo) & np.isnan(hi))) and (np.all(off) or loose)
    assert res.warnings
    assert all(np.isfinite(v) for v in res.metrics.values())


def test_near_mirror_lobe_is_found():
    truth = models.Lambert(albedo=0.1) + TestLobe(rho_s=0.5, n=3000.0)
    data, _ = synthetic(truth, n=4000, seed=9, with_sigma=False)
    res = gf.fit(data, model=models.Lambert() + TestLobe(), loss="low-e1")
    assert res.params["testlobe.n"] == pytest.approx(3000.0, rel=0.3)


def test_handful_of_samples():
    data, _ = synthetic(models.Lambert(albedo=0.4), n=6, seed=2, theta_max_deg=90)
    with pytest.raises(FitError, match="3 measured values for 3 parameters"):
        gf.fit(data.subset(np.arange(3)), model=models.Lambert() + TestLobe(), theta_max_deg=90)
    res = gf.fit(data, model=models.Lambert(), uncertainty="laplace", theta_max_deg=90)
    assert np.isfinite(res.params["albedo"])


def test_nan_cells_are_masked_and_zero_data_rejected():
    data, _ = synthetic(models.Lambert(albedo=0.4), n=200, seed=2)
    y = data.values.copy()
    y[::3] = np.nan
    d2 = from_arrays(data.wi, data.wo, y)
    res = gf.fit(d2, model=models.Lambert())
    assert res.data["n_samples"] == int(np.isfinite(y[:, 0]).sum())
    assert res.params["albedo"] == pytest.approx(0.4, abs=0.02)
    with pytest.raises(FitError, match="<= 0"):
        gf.fit(from_arrays(data.wi, data.wo, np.zeros(data.n)), model=models.Lambert())


def test_grazing_only_coverage():
    rng = np.random.default_rng(5)
    th = rng.uniform(np.radians(81), np.radians(88), (2, 300))
    ph = rng.uniform(0, 2 * np.pi, (2, 300))
    d = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)
    y = np.asarray(models.Lambert(albedo=0.3).f(d[0], d[1]))
    with pytest.raises(FitError, match="beyond theta_max"):
        gf.fit(from_arrays(d[0], d[1], y, theta_max_deg=90), model="lambert", theta_max_deg=80)
    res = gf.fit(from_arrays(d[0], d[1], y, theta_max_deg=90), model="lambert", theta_max_deg=90)
    assert res.params["albedo"] == pytest.approx(0.3, rel=1e-6)


def test_no_nan_gradients_at_extreme_parameters():
    data, _ = synthetic(TRUTH, n=300, seed=3)
    lay = Layout(models.Lambert() + TestLobe(), 3)
    lo, hi = lay.box()
    rng = np.random.default_rng(0)
    corners = [lo, hi] + [np.where(rng.uniform(size=lo.size) < 0.5, lo, hi) for _ in range(6)]
    for name in ("wls", "low-e1", "cube-root"):  # (ngan, low-e2: same operations)
        prob = Problem(lay, get_loss(name), data)
        for u in corners:
            v, g = prob.value_and_grad(u)
            assert np.isfinite(v) and np.all(np.isfinite(g)), (name, u)
            if name == "wls":
                _, gg, a = prob.normal(u)
                assert np.all(np.isfinite(gg)) and np.all(np.isfinite(a))


def test_unknown_names_give_one_line_errors():
    data, _ = synthetic(models.Lambert(albedo=0.4), n=50, seed=2)
    for kw, pat in [
        ({"model": "wardd"}, "valid: lambert"),
        ({"loss": "l1"}, "valid: wls"),
        ({"uncertainty": "bootstrap"}, "laplace"),
        ({"optimizer": "nm"}, "lm"),
    ]:
        with pytest.raises(FitError, match=pat) as exc:
            gf.fit(data, **{"model": "lambert", **kw})
        assert "\n" not in str(exc.value)


def test_separate_channels():
    data, _ = synthetic(models.Lambert(albedo=[0.2, 0.5, 0.8]), n=300, seed=4)
    res = gf.fit(data, model="lambert", channels="separate")
    assert [r.channel for r in res] == ["R", "G", "B"]
    np.testing.assert_allclose([r.params["albedo"] for r in res], [0.2, 0.5, 0.8], atol=0.02)


def test_fixed_parameters_and_jnp_values():
    data, _ = synthetic(TRUTH, n=500, seed=5)
    res = gf.fit(data, model=models.Lambert() + TestLobe(), fixed={"testlobe.n": 50.0})
    assert res.params["testlobe.n"] == 50.0 and "testlobe.n" in res.fixed
    # fixed, not "known to be in [50, 50]": no interval, listed as fixed
    assert "testlobe.n" not in res.intervals() and "testlobe.n" not in res.to_json()["intervals"]
    assert "testlobe.n" in res.to_json()["fixed"]
    assert isinstance(res.model.params()["testlobe.n"], jnp.ndarray)
