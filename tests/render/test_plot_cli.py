"""``gonio plot`` through the command line: PNG and SVG, shared axes, refusals.

The commands run in-process (:func:`gonio.cli.main`); plotting into a folder goes through the
real ``python -m gonio``.
"""

import json

import numpy as np
import pytest

from gonio import io
from gonio.brdf import models
from gonio.brdf.measured import MeasuredSamples
from tests.render.helpers import gonio_cli as gonio

PAINT = models.Lambert(albedo=[0.5, 0.3, 0.1]) + models.TorranceSparrow(
    alpha=0.3, fresnel=models.Schlick(f0=0.05)
)


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    d = tmp_path_factory.mktemp("plot")
    rng = np.random.default_rng(0)

    def hemi(k):
        u = rng.random((k, 2))
        r, p = np.sqrt(u[:, 0]), 2 * np.pi * u[:, 1]
        return np.stack([r * np.cos(p), r * np.sin(p), np.sqrt(1 - u[:, 0])], -1)

    wi, wo = hemi(300), hemi(300)
    io.save(MeasuredSamples(wi, wo, np.asarray(PAINT.f(wi, wo))), d / "paint.brdf.h5")
    (d / "fit.json").write_text(json.dumps({"model_spec": PAINT.to_dict()}))
    return d


def test_plot_png_and_svg_with_measured_and_fit_on_shared_axes(inputs, tmp_path):
    out = gonio("plot", inputs / "paint.brdf.h5", inputs / "fit.json", "--out", tmp_path / "p.png")
    assert out.returncode == 0, out.stderr
    data = (tmp_path / "p.png").read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    out = gonio(
        "plot", inputs / "paint.brdf.h5", inputs / "fit.json", "--out", tmp_path / "p.svg",
        "--theta-i", "45", "--kind", "in-plane",
    )  # fmt: skip
    assert out.returncode == 0, out.stderr
    svg = (tmp_path / "p.svg").read_text()
    assert svg.lstrip().startswith("<?xml") and "<svg" in svg
    # Units and angles on the axes; both inputs in the legend.
    for text in ("1/sr", "θo (deg)", "paint.brdf.h5", "fit", "θi = 45°"):
        assert text in svg, text


def test_plot_curves_are_the_materials_values(inputs):
    from gonio.render.plots import evaluate, in_plane

    wi, wo = in_plane(30.0, np.array([-60.0, 0.0, 30.0, 70.0]))
    y = evaluate(PAINT, wi, wo, "Y")
    np.testing.assert_allclose(y, np.asarray(PAINT.f(wi, wo)) @ [0.2126, 0.7152, 0.0722])
    # theta_o = theta_i is the mirror direction: the peak of a sharp specular lobe.
    sharp = models.TorranceSparrow(alpha=0.03, fresnel=models.Schlick(f0=0.05))
    grid = np.linspace(-89, 89, 179)
    wi, wo = in_plane(30.0, grid)
    assert abs(grid[np.argmax(evaluate(sharp, wi, wo, "Y"))] - 30.0) <= 1.0


@pytest.mark.parametrize(
    "out, why",
    [("a.jpg", "unsupported figure format"), ("noext", "unsupported figure format")],
)
def test_plot_refuses_bad_output_before_any_work(inputs, tmp_path, out, why):
    r = gonio("plot", inputs / "fit.json", "--out", tmp_path / out)
    assert r.returncode != 0
    assert why in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not any(tmp_path.iterdir())


def test_plot_into_a_folder(inputs, tmp_path):
    r = gonio(
        "plot", inputs / "fit.json", "--kind", "halfdiff", "--out", f"{tmp_path}/figs/", real=True
    )
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "figs" / "plot.png").is_file()


def test_plot_missing_file_is_one_line(tmp_path):
    r = gonio("plot", tmp_path / "nope.brdf.h5", "--out", tmp_path / "x.png")
    assert r.returncode == 2 and "not found" in r.stderr
    assert not (tmp_path / "x.png").exists()
