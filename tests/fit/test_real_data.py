"""Fits of the third-party measurements in ../shared/data (skipped when absent or unreadable)."""

import numpy as np
import pytest

import gonio.fit as gf
from tests.conftest import shared_file


def _load(*parts):
    path = shared_file(*parts)
    gio = pytest.importorskip("gonio.io")
    if not hasattr(gio, "load"):
        pytest.skip("gonio.io.load not available")
    return gio.load(path)


def test_rgl_paper_converges_and_round_trips(tmp_path):
    data = _load("rgl", "paper_white_rgb.bsdf")
    res = gf.fit(data, model="oren-nayar", loss="ngan", uncertainty="laplace")
    assert res.optimizer["converged"]
    assert all(np.isfinite(v) for v in res.metrics.values())
    albedo = np.asarray(res.params["albedo"])
    assert np.all((albedo > 0.3) & (albedo < 1.0))  # white paper
    model = gf.load_model(res.save(tmp_path / "paper.json"))
    assert np.allclose(model.params()["albedo"], albedo)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["acryl_blue", "cayman", "garnet_red"])
def test_cornell_spectral_fits_converge(name):
    data = _load("cornell", f"{name}.brdf")
    for model in ("lambert", "phong"):
        res = gf.fit(data, model=model, loss="ngan")
        assert res.optimizer["converged"], res.optimizer
        assert np.isfinite(res.loss)
