"""Fitting gonio's own tables and sample sets (the contract types), with the merged models."""

import numpy as np
import pytest

import gonio.fit as gf
from gonio.brdf import models
from gonio.brdf.measured import MeasuredSamples
from gonio.brdf.tabulated import Axis, Channels, TabulatedBRDF
from gonio.fit import presets

AXES = (
    Axis("theta_h", 20, 0, np.pi / 2, warp="sqrt"),
    Axis("theta_d", 20, 0, np.pi / 2),
    Axis("phi_d", 20, 0, np.pi, periodic=True),
)


def test_table_with_masked_cells_and_solid_angle_weights():
    truth = models.Phong(rho_d=[0.3, 0.2, 0.1], rho_s=[0.2, 0.3, 0.4], n=60.0)
    table = TabulatedBRDF.from_model(truth, axes=AXES)
    mask = table.mask.copy()
    mask[3, 4, :] = False  # a hole in the measurement
    values = np.array(table.values)
    values[3, 4, :] = np.nan  # with garbage in it
    table = table.replace(values=values.astype(np.float32), mask=mask)
    data = gf.prepare(table)
    samples = MeasuredSamples.from_table(table)
    cos_ok = (samples.wi[:, 2] >= np.cos(np.radians(80)) - 1e-12) & (
        samples.wo[:, 2] >= np.cos(np.radians(80)) - 1e-12
    )
    assert data.n == int(cos_ok.sum())
    np.testing.assert_allclose(np.sort(data.weights), np.sort(samples.weights[cos_ok]))
    res = gf.fit(table, model="phong", loss="ngan")
    np.testing.assert_allclose(res.params["rho_d"], [0.3, 0.2, 0.1], rtol=2e-3)
    np.testing.assert_allclose(res.params["rho_s"], [0.2, 0.3, 0.4], rtol=2e-3)
    assert res.params["n"] == pytest.approx(60.0, rel=2e-3)
    assert res.data["kind"] == "TabulatedBRDF"


def test_measured_samples_with_sigma_spectral_channels():
    rng = np.random.default_rng(1)
    truth = models.OrenNayar(albedo=[0.2, 0.4, 0.6, 0.8], sigma=0.35)
    n = 600
    wi = rng.normal(size=(n, 3))
    wo = rng.normal(size=(n, 3))
    wi[:, 2], wo[:, 2] = np.abs(wi[:, 2]), np.abs(wo[:, 2])
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    f = np.asarray(truth.f(wi, wo))
    sigma = 0.002 + 0.02 * f
    y = f + sigma * rng.standard_normal(f.shape)
    ch = Channels.spectral([450.0, 500.0, 550.0, 600.0])
    s = MeasuredSamples(wi, wo, y, sigma, ch, meta={"name": "felt"})
    res = gf.fit(s, model="oren-nayar", uncertainty="laplace")
    assert res.data["channels"] == list(ch.names)
    assert res.data["name"] == "felt"
    lo, hi = res.intervals()["sigma"]
    assert lo < 0.35 < hi
    assert 0.5 < res.reduced_chi2 < 1.5


@pytest.mark.slow
@pytest.mark.parametrize("name", presets.available())
def test_every_preset_recovers_its_own_table(name):
    tmpl, fixed, tied = presets.build(name)
    kw = {}
    for k, spec in tmpl.param_specs().items():
        if k in fixed or k in tied:
            continue
        v = np.asarray(tmpl.params()[k], float)
        grow = 0.2 if k.split(".")[0].endswith("2") else 1.5  # a second lobe: sharper
        kw[k] = v * grow if spec.scale == "log" else np.clip(v * 0.8 + 0.05, spec.lower, spec.upper)
    truth = tmpl.replace(**kw, **{t: kw[src] for t, src in tied.items()})
    table = TabulatedBRDF.from_model(truth, axes=AXES)
    res = gf.fit(table, model=name, loss="ngan")
    for k, v in kw.items():
        np.testing.assert_allclose(res.params[k], v, rtol=0.02, atol=2e-3, err_msg=k)


@pytest.mark.slow
@pytest.mark.parametrize("name", presets.available())
def test_no_nan_gradients_at_box_corners_for_every_preset(name):
    import jax.numpy as jnp  # noqa: F401  (x64 already on)

    from gonio.fit.losses import get_loss
    from gonio.fit.objective import Problem
    from gonio.fit.params import Layout
    from tests.fit.synth import synthetic

    tmpl, fixed, tied = presets.build(name)
    data, _ = synthetic(models.Lambert(albedo=[0.3, 0.3, 0.3]), n=300, seed=1)
    lay = Layout(tmpl, 3, fixed=fixed, tied=tied)
    lo, hi = lay.box()
    rng = np.random.default_rng(0)
    corners = [lo, hi] + [np.where(rng.uniform(size=lo.size) < 0.5, lo, hi) for _ in range(6)]
    for loss in ("wls", "low-e1"):
        prob = Problem(lay, get_loss(loss), data)
        for u in corners:
            v, g = prob.value_and_grad(u)
            assert np.isfinite(v) and np.all(np.isfinite(g)), (loss, u)
            _, gg, a = prob.normal(u)
            assert np.all(np.isfinite(gg)) and np.all(np.isfinite(a)), (loss, u)
