import numpy as np

import gonio.fit as gf
from gonio.brdf import models
from gonio.fit.compare import compare, summarize
from gonio.fit.plots import plot_result
from tests.fit.synth import synthetic


def test_plots_are_written(tmp_path):
    data, _ = synthetic(models.Phong(rho_d=0.3, rho_s=0.3, n=30.0), n=600, seed=2)
    res = gf.fit(data, model="phong", uncertainty="laplace")
    paths = plot_result(res, data, tmp_path, "phong")
    assert [p.name for p in paths] == ["phong-residuals.png", "phong-slices.png",
                                       "phong-corner.png"]  # fmt: skip
    for p in paths:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not list(tmp_path.glob(".*"))  # no temporary files left


def test_compare_prefers_the_true_model_and_penalizes_extra_parameters():
    data, _ = synthetic(models.Phong(rho_d=0.3, rho_s=0.3, n=30.0), n=800, seed=3)
    comp = compare(data, ["lambert", "phong"])
    assert comp.recommended == "phong"
    rows = {r["model"]: r for r in comp.table}
    assert rows["phong"]["bic"] < rows["lambert"]["bic"]
    assert rows["phong"]["chi2_dof"] < 1.5 < rows["lambert"]["chi2_dof"]
    # diffuse data: the extra lobe is not supported; BIC picks (or falls back to) Lambert
    flat, _ = synthetic(models.Lambert(albedo=0.4), n=800, seed=4)
    comp2 = compare(flat, ["phong", "lambert"])
    assert comp2.recommended == "lambert"
    assert "lambert" in comp2.reason
    assert set(comp2.table[0]["metrics"]) == set(gf.LOSSES)
    assert np.isfinite(comp2.table[0]["aic"])
    assert summarize(comp2.results).recommended == "lambert"
